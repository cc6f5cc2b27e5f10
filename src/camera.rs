//! Pinhole camera with plumb_bob distortion, read from ROS `camera_info` YAML or
//! OpenCV `FileStorage` YAML.
//!
//! Only contour points are undistorted (never whole images): the fit then works
//! in ideal pinhole pixels ("undistorted pixels", same intrinsic matrix K).

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde_yaml::Value;
use std::path::Path;

/// A camera file that could not be used; names the file and, when one is
/// to blame, the field (empty: the file as a whole, unreadable or not YAML).
#[derive(Debug)]
pub struct CameraError {
    /// The camera file, as given.
    pub file: String,
    /// The field at fault; empty when the file as a whole is.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for CameraError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.field.is_empty() {
            write!(f, "camera file {}: {}", self.file, self.message)
        } else {
            write!(
                f,
                "camera file {}: {}: {}",
                self.file, self.field, self.message
            )
        }
    }
}

impl std::error::Error for CameraError {}

/// Intrinsics and plumb_bob distortion of one camera.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraModel {
    /// The camera's name in its file (ROS `camera_name`), for logs.
    pub name: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Intrinsic matrix K (pixels).
    pub k: Matrix3<f64>,
    k_inv: Matrix3<f64>,
    /// plumb_bob coefficients k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
}

fn err(file: &str, field: &str, message: impl Into<String>) -> CameraError {
    CameraError {
        file: file.to_string(),
        field: field.to_string(),
        message: message.into(),
    }
}

/// Reads `key` of a YAML mapping as a list of numbers: either a plain sequence
/// or a `{rows, cols, data}` matrix (ROS and OpenCV both write the latter).
fn numbers(root: &Value, key: &str, file: &str) -> Result<Vec<f64>, CameraError> {
    let node = root.get(key).ok_or_else(|| err(file, key, "missing"))?;
    let data = match node {
        Value::Sequence(_) => node,
        Value::Mapping(_) => node
            .get("data")
            .ok_or_else(|| err(file, &format!("{key}.data"), "missing"))?,
        _ => return Err(err(file, key, "expected a matrix or a list of numbers")),
    };
    let seq = data
        .as_sequence()
        .ok_or_else(|| err(file, &format!("{key}.data"), "expected a list of numbers"))?;
    seq.iter()
        .enumerate()
        .map(|(i, v)| {
            v.as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(file, &format!("{key}.data[{i}]"), "not a finite number"))
        })
        .collect()
}

fn dimension(root: &Value, key: &str, file: &str) -> Result<u32, CameraError> {
    let v = root.get(key).ok_or_else(|| err(file, key, "missing"))?;
    v.as_u64()
        .and_then(|n| u32::try_from(n).ok())
        .filter(|&n| (1..=MAX_SIDE_PX).contains(&n))
        .ok_or_else(|| {
            err(
                file,
                key,
                format!("expected a whole number of pixels from 1 to {MAX_SIDE_PX}"),
            )
        })
}

/// Largest image side a camera file may give, pixels (the largest frame any
/// source reads: frames are sized by the calibration).
pub const MAX_SIDE_PX: u32 = 16_384;

/// The intrinsics' allowed ranges: focal lengths (0, 1e6] px, principal point
/// and skew within +-1e5 px, each plumb_bob coefficient within +-100 (real
/// lenses stay well inside; beyond it the undistortion cannot converge).
fn check_ranges(k: &Matrix3<f64>, d: &[f64; 5], file: &str) -> Result<(), CameraError> {
    let checks = [
        ("camera_matrix.data[0] (fx)", k[(0, 0)], 0.0, 1e6, true),
        ("camera_matrix.data[4] (fy)", k[(1, 1)], 0.0, 1e6, true),
        ("camera_matrix.data[1] (skew)", k[(0, 1)], -1e5, 1e5, false),
        ("camera_matrix.data[2] (cx)", k[(0, 2)], -1e5, 1e5, false),
        ("camera_matrix.data[5] (cy)", k[(1, 2)], -1e5, 1e5, false),
    ];
    for (field, v, lo, hi, lo_open) in checks {
        let above = if lo_open { v > lo } else { v >= lo };
        if !(above && v <= hi) {
            let open = if lo_open { '(' } else { '[' };
            return Err(err(
                file,
                field,
                format!("{v} is outside the allowed range {open}{lo}, {hi}]"),
            ));
        }
    }
    for (i, v) in d.iter().enumerate() {
        if !(v.is_finite() && v.abs() <= 100.0) {
            return Err(err(
                file,
                &format!("distortion_coefficients.data[{i}]"),
                format!("{v} is outside the allowed range [-100, 100]"),
            ));
        }
    }
    Ok(())
}

/// OpenCV writes `%YAML:1.0` (not valid YAML 1.1) and `!!opencv-matrix` tags;
/// turn them into plain YAML.
fn plain_yaml(text: &str) -> String {
    text.lines()
        .filter(|l| !l.trim_start().starts_with("%YAML"))
        .map(|l| l.replace("!!opencv-matrix", ""))
        .collect::<Vec<_>>()
        .join("\n")
}

impl CameraModel {
    /// A camera from its intrinsics; `distortion` is plumb_bob k1 k2 p1 p2 k3.
    pub fn new(
        name: &str,
        width: u32,
        height: u32,
        k: Matrix3<f64>,
        distortion: [f64; 5],
    ) -> Result<Self, String> {
        let ok = k[(0, 0)] > 0.0
            && k[(1, 1)] > 0.0
            && k[(1, 0)] == 0.0
            && k[(2, 0)] == 0.0
            && k[(2, 1)] == 0.0
            && k[(2, 2)] == 1.0
            && k.iter().all(|x| x.is_finite());
        if !ok {
            return Err(format!(
                "not a camera matrix (need fx, fy > 0, [0 0 1] last row): {:?}",
                k.as_slice()
            ));
        }
        let k_inv = k.try_inverse().ok_or("camera matrix is singular")?;
        Ok(Self {
            name: name.to_string(),
            width,
            height,
            k,
            k_inv,
            distortion,
        })
    }

    /// Refuses frames of another size than the calibration's: intrinsics are
    /// in pixels of one image size, and frames of another would give wrong
    /// poses (every source checks, not only V4L2). The message has both sizes.
    pub fn check_frame_size(&self, width: u32, height: u32) -> Result<(), String> {
        if (width, height) == (self.width, self.height) {
            return Ok(());
        }
        Err(format!(
            "the frames are {width}x{height} but the camera calibration `{}` is for \
             {}x{}: use the calibration made at the frames' size",
            self.name, self.width, self.height
        ))
    }

    /// Reads a camera file (ROS camera_info YAML or OpenCV FileStorage YAML).
    pub fn load(path: &Path) -> Result<Self, CameraError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| err(&file, "", e.to_string()))?;
        Self::from_yaml_str(&text, &file)
    }

    /// Parses camera YAML text; `file` names it in errors.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Self, CameraError> {
        let root: Value = serde_yaml::from_str(&plain_yaml(text))
            .map_err(|e| err(file, "", format!("not YAML: {e}")))?;
        if !root.is_mapping() {
            return Err(err(file, "", "expected a mapping of camera fields"));
        }
        let width = dimension(&root, "image_width", file)?;
        let height = dimension(&root, "image_height", file)?;
        let kv = numbers(&root, "camera_matrix", file)?;
        if kv.len() != 9 {
            return Err(err(
                file,
                "camera_matrix",
                format!("expected 9 numbers, found {}", kv.len()),
            ));
        }
        let k = Matrix3::from_row_slice(&kv);
        if let Some(model) = root.get("distortion_model") {
            let model = model.as_str().unwrap_or_default();
            if model != "plumb_bob" && model != "radtan" {
                return Err(err(
                    file,
                    "distortion_model",
                    format!("`{model}` is not supported (plumb_bob only)"),
                ));
            }
        }
        let dv = match root.get("distortion_coefficients") {
            Some(_) => numbers(&root, "distortion_coefficients", file)?,
            None => vec![0.0; 5],
        };
        let distortion = match dv.len() {
            0 => [0.0; 5],
            4 => [dv[0], dv[1], dv[2], dv[3], 0.0],
            5 => [dv[0], dv[1], dv[2], dv[3], dv[4]],
            n if n > 5 && dv[5..].iter().all(|&x| x == 0.0) => [dv[0], dv[1], dv[2], dv[3], dv[4]],
            n => {
                return Err(err(
                    file,
                    "distortion_coefficients",
                    format!("expected 5 plumb_bob coefficients (k1 k2 p1 p2 k3), found {n}"),
                ));
            }
        };
        check_ranges(&k, &distortion, file)?;
        let name = root
            .get("camera_name")
            .and_then(Value::as_str)
            .unwrap_or("camera")
            .to_string();
        Self::new(&name, width, height, k, distortion).map_err(|m| err(file, "camera_matrix", m))
    }

    /// ROS camera_info YAML, as the ROS calibration tools write it.
    pub fn to_ros_yaml(&self) -> String {
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "image_width: {}\nimage_height: {}\ncamera_name: {}\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [{}]\n\
             distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [{}]\n\
             rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n\
             projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{}]\n",
            self.width,
            self.height,
            self.name,
            list(&self.k_row_major()),
            list(&self.distortion),
            list(&self.projection_row_major())
        )
    }

    /// K, row-major (ROS `camera_matrix`, Foxglove `K`).
    pub fn k_row_major(&self) -> [f64; 9] {
        std::array::from_fn(|i| self.k[(i / 3, i % 3)])
    }

    /// The projection matrix [K | 0], row-major (ROS `projection_matrix`,
    /// Foxglove `P`): rim points are undistorted, not rectified.
    pub fn projection_row_major(&self) -> [f64; 12] {
        std::array::from_fn(|i| {
            let (row, col) = (i / 4, i % 4);
            if col < 3 { self.k[(row, col)] } else { 0.0 }
        })
    }

    /// Focal length along x, pixels.
    pub fn fx(&self) -> f64 {
        self.k[(0, 0)]
    }
    /// Focal length along y, pixels.
    pub fn fy(&self) -> f64 {
        self.k[(1, 1)]
    }
    /// Principal point x, pixels.
    pub fn cx(&self) -> f64 {
        self.k[(0, 2)]
    }
    /// Principal point y, pixels.
    pub fn cy(&self) -> f64 {
        self.k[(1, 2)]
    }

    /// Whether any distortion coefficient is non-zero (else undistortion is the
    /// identity).
    pub fn has_distortion(&self) -> bool {
        self.distortion.iter().any(|&d| d != 0.0)
    }

    /// plumb_bob on normalised coordinates (x/z, y/z), with its Jacobian.
    fn distort_normalised(&self, p: Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let dradial = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2); // d radial / d(x|y) = dradial * (x|y)
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        let j = Matrix2::new(
            radial + dradial * x * x + 2.0 * p1 * y + 6.0 * p2 * x,
            dradial * x * y + 2.0 * p1 * x + 2.0 * p2 * y,
            dradial * x * y + 2.0 * p1 * x + 2.0 * p2 * y,
            radial + dradial * y * y + 6.0 * p1 * y + 2.0 * p2 * x,
        );
        (Vector2::new(xd, yd), j)
    }

    fn to_normalised(&self, p_px: [f64; 2]) -> Vector2<f64> {
        let h = self.k_inv * Vector3::new(p_px[0], p_px[1], 1.0);
        Vector2::new(h.x / h.z, h.y / h.z)
    }

    fn to_pixels(&self, n: Vector2<f64>) -> [f64; 2] {
        let h = self.k * Vector3::new(n.x, n.y, 1.0);
        [h.x / h.z, h.y / h.z]
    }

    /// Distorted image pixel → undistorted (ideal pinhole) pixel, by Newton's
    /// method on the plumb_bob model (converges to 1e-12 in a few steps for
    /// any real lens; OpenCV's fixed 5 iterations stop far short of that).
    pub fn undistort_px(&self, p_px: [f64; 2]) -> [f64; 2] {
        if !self.has_distortion() {
            return p_px;
        }
        let target = self.to_normalised(p_px);
        // Start from the radial model inverted at the distorted radius: one
        // Newton step fewer than starting from the distorted point.
        let [k1, k2, _, _, k3] = self.distortion;
        let r2 = target.norm_squared();
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let mut x = if radial > 0.5 && radial < 2.0 {
            target / radial
        } else {
            target
        };
        for _ in 0..20 {
            let (xd, j) = self.distort_normalised(x);
            let r = xd - target;
            if r.x * r.x + r.y * r.y < 1e-28 {
                break;
            }
            // x -= J^-1 r, with the 2x2 inverse written out.
            let det = j.m11 * j.m22 - j.m12 * j.m21;
            if !(det.abs() > 1e-300 && det.is_finite()) {
                break;
            }
            x.x -= (j.m22 * r.x - j.m12 * r.y) / det;
            x.y -= (j.m11 * r.y - j.m21 * r.x) / det;
        }
        self.to_pixels(x)
    }

    /// Undistorted pixel → distorted image pixel.
    pub fn distort_px(&self, p_px: [f64; 2]) -> [f64; 2] {
        if !self.has_distortion() {
            return p_px;
        }
        let (xd, _) = self.distort_normalised(self.to_normalised(p_px));
        self.to_pixels(xd)
    }

    /// The ray (camera frame, z = 1) through an undistorted pixel.
    pub fn ray_camera(&self, p_undistorted_px: [f64; 2]) -> Vector3<f64> {
        let n = self.to_normalised(p_undistorted_px);
        Vector3::new(n.x, n.y, 1.0)
    }

    /// Projects a camera-frame point (metres) to undistorted pixels;
    /// `None` behind the camera.
    pub fn project_undistorted_px(&self, p_camera_m: &Vector3<f64>) -> Option<[f64; 2]> {
        (p_camera_m.z > 1e-9).then(|| {
            self.to_pixels(Vector2::new(
                p_camera_m.x / p_camera_m.z,
                p_camera_m.y / p_camera_m.z,
            ))
        })
    }

    /// Projects a camera-frame point (metres) to distorted image pixels.
    pub fn project_px(&self, p_camera_m: &Vector3<f64>) -> Option<[f64; 2]> {
        self.project_undistorted_px(p_camera_m)
            .map(|p| self.distort_px(p))
    }

    /// Projects a camera-frame point (metres) to distorted image pixels, with
    /// the image velocity of the point moving along `direction_camera`
    /// (pixels per metre of travel): the exact derivative of [`Self::project_px`],
    /// from one distortion evaluation (its Jacobian) instead of two more
    /// projections for a finite difference. `None` behind the camera.
    pub fn project_px_with_derivative(
        &self,
        p_camera_m: &Vector3<f64>,
        direction_camera: &Vector3<f64>,
    ) -> Option<([f64; 2], [f64; 2])> {
        let z = p_camera_m.z;
        if z <= 1e-9 {
            return None;
        }
        let n = Vector2::new(p_camera_m.x / z, p_camera_m.y / z);
        let dn = Vector2::new(
            (direction_camera.x - n.x * direction_camera.z) / z,
            (direction_camera.y - n.y * direction_camera.z) / z,
        );
        let (nd, dnd) = if self.has_distortion() {
            let (nd, j) = self.distort_normalised(n);
            (nd, j * dn)
        } else {
            (n, dn)
        };
        // K's last row is [0 0 1] (checked in `new`): pixels are affine in nd.
        let k = &self.k;
        let p = [
            k[(0, 0)] * nd.x + k[(0, 1)] * nd.y + k[(0, 2)],
            k[(1, 1)] * nd.y + k[(1, 2)],
        ];
        let dp = [k[(0, 0)] * dnd.x + k[(0, 1)] * dnd.y, k[(1, 1)] * dnd.y];
        Some((p, dp))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ROS: &str = "image_width: 1280\nimage_height: 960\ncamera_name: cam\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [1336.2, 0.0, 646.3, 0.0, 1335.4, 473.8, 0.0, 0.0, 1.0]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.28, 0.09, 0.001, -0.0005, -0.012]\n";

    const OPENCV: &str = "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500., 0., 320., 0., 501., 240., 0., 0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n   dt: d\n   data: [ 0.1, -0.05, 0., 0., 0. ]\n";

    #[test]
    fn reads_ros_and_opencv() {
        let c = CameraModel::from_yaml_str(ROS, "ros.yaml").expect("ros");
        assert_eq!((c.width, c.height), (1280, 960));
        assert_eq!(c.fx(), 1336.2);
        assert_eq!(c.distortion[4], -0.012);
        let o = CameraModel::from_yaml_str(OPENCV, "cv.yaml").expect("opencv");
        assert_eq!(o.fy(), 501.0);
        assert_eq!(o.distortion[1], -0.05);
        // Written YAML reads back to the same camera.
        let back = CameraModel::from_yaml_str(&c.to_ros_yaml(), "back").expect("back");
        assert_eq!(back, c);
    }

    #[test]
    fn errors_name_file_and_field() {
        let bad = ROS.replace(
            "1336.2, 0.0, 646.3, 0.0, 1335.4, 473.8, 0.0, 0.0, 1.0",
            "1, 2, 3",
        );
        let e = CameraModel::from_yaml_str(&bad, "bad.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.yaml") && e.contains("camera_matrix"), "{e}");
        let e = CameraModel::from_yaml_str("image_width: 10\n", "w.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("image_height"), "{e}");
        let e = CameraModel::from_yaml_str(&ROS.replace("plumb_bob", "equidistant"), "d.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("distortion_model"), "{e}");
        let e = CameraModel::from_yaml_str(": : :", "y.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("y.yaml"), "{e}");
    }

    #[test]
    fn undistort_inverts_distort() {
        let c = CameraModel::from_yaml_str(ROS, "ros.yaml").expect("ros");
        for &(u, v) in &[
            (0.0, 0.0),
            (1279.0, 959.0),
            (646.3, 473.8),
            (100.0, 800.0),
            (1000.0, 50.0),
        ] {
            let d = c.distort_px([u, v]);
            let back = c.undistort_px(d);
            assert!(
                (back[0] - u).abs() < 1e-8 && (back[1] - v).abs() < 1e-8,
                "{u},{v} -> {back:?}"
            );
        }
    }

    #[test]
    fn projection_matches_pinhole() {
        let c = CameraModel::from_yaml_str(ROS, "ros.yaml").expect("ros");
        let p = Vector3::new(0.5, -0.25, 5.0);
        let u = c.project_undistorted_px(&p).expect("in front");
        assert!((u[0] - (1336.2 * 0.1 + 646.3)).abs() < 1e-9);
        assert!((u[1] - (1335.4 * -0.05 + 473.8)).abs() < 1e-9);
        let ray = c.ray_camera(u);
        assert!((ray - p / 5.0).norm() < 1e-12);
        assert!(c.project_px(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn projection_derivative_matches_a_finite_difference() {
        let ros = CameraModel::from_yaml_str(ROS, "ros.yaml").expect("ros");
        let mut k = ros.k;
        k[(0, 1)] = 2.5; // skew, so that every term of K is exercised
        let skewed = CameraModel::new("skew", 1280, 960, k, ros.distortion).expect("camera");
        let pinhole = CameraModel::new("pinhole", 1280, 960, ros.k, [0.0; 5]).expect("camera");
        let dir = Vector3::new(0.3, -0.7, 0.2).normalize();
        for cam in [&ros, &skewed, &pinhole] {
            for p in [
                Vector3::new(0.5, -0.25, 5.0),
                Vector3::new(-1.2, 0.8, 2.0),
                Vector3::new(0.0, 0.0, 1.0),
            ] {
                let (q, dq) = cam.project_px_with_derivative(&p, &dir).expect("in front");
                let at = cam.project_px(&p).expect("in front");
                assert!((q[0] - at[0]).abs() < 1e-9 && (q[1] - at[1]).abs() < 1e-9);
                let h = 1e-5;
                let ahead = cam.project_px(&(p + h * dir)).expect("in front");
                let behind = cam.project_px(&(p - h * dir)).expect("in front");
                for i in 0..2 {
                    let numeric = (ahead[i] - behind[i]) / (2.0 * h);
                    assert!(
                        (dq[i] - numeric).abs() < 1e-4 * numeric.abs().max(1.0),
                        "{}: {dq:?} vs {numeric}",
                        cam.name
                    );
                }
            }
        }
        assert!(
            ros.project_px_with_derivative(&Vector3::new(0.0, 0.0, -1.0), &dir)
                .is_none()
        );
    }
}
