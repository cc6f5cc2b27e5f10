//! The simulator's own camera: pinhole + plumb_bob (OpenCV's k1 k2 p1 p2 k3).
//!
//! Deliberately independent of drogue-vision's camera code: the simulator is
//! the ground truth that code is tested against.

use crate::error::SimError;
use crate::geometry::V3;
use serde_yaml::Value;

/// Intrinsics and distortion of the simulated camera.
#[derive(Clone, Debug, PartialEq)]
pub struct SimCamera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// plumb_bob k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
}

impl SimCamera {
    /// Whether any distortion coefficient is non-zero (else rays map through
    /// the pinhole alone).
    pub fn has_distortion(&self) -> bool {
        self.distortion.iter().any(|k| *k != 0.0)
    }

    /// Distorts ideal normalised coordinates (x/z, y/z).
    pub fn distort_normalized(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Inverts [`Self::distort_normalized`] by Newton's method with the
    /// analytic Jacobian (converges to ~1e-15; `None` if it does not).
    pub fn undistort_normalized(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        if !self.has_distortion() {
            return Some((xd, yd));
        }
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (fx, fy) = self.distort_normalized(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs() < 1e-15 && ey.abs() < 1e-15 {
                return Some((x, y));
            }
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
            let j11 = radial + 2.0 * x * x * dradial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x;
            let j12 = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y;
            let j21 = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y;
            let j22 = radial + 2.0 * y * y * dradial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x;
            let det = j11 * j22 - j12 * j21;
            if det.abs() < 1e-12 || !det.is_finite() {
                return None;
            }
            x -= (j22 * ex - j12 * ey) / det;
            y -= (-j21 * ex + j11 * ey) / det;
        }
        let (fx, fy) = self.distort_normalized(x, y);
        ((fx - xd).abs() < 1e-12 && (fy - yd).abs() < 1e-12).then_some((x, y))
    }

    /// Camera-frame point → undistorted (ideal pinhole) pixel; `None` behind.
    pub fn project_undistorted_px(&self, p_camera_m: &V3) -> Option<[f64; 2]> {
        (p_camera_m.z > 1e-9).then(|| {
            [
                self.fx * p_camera_m.x / p_camera_m.z + self.cx,
                self.fy * p_camera_m.y / p_camera_m.z + self.cy,
            ]
        })
    }

    /// Camera-frame point → distorted (real image) pixel; `None` behind.
    pub fn project_px(&self, p_camera_m: &V3) -> Option<[f64; 2]> {
        if p_camera_m.z <= 1e-9 {
            return None;
        }
        let (xd, yd) =
            self.distort_normalized(p_camera_m.x / p_camera_m.z, p_camera_m.y / p_camera_m.z);
        Some([self.fx * xd + self.cx, self.fy * yd + self.cy])
    }

    /// Undistorted pixel → distorted pixel (where it lies in the frame).
    pub fn distort_px(&self, p_px: [f64; 2]) -> [f64; 2] {
        let (xd, yd) =
            self.distort_normalized((p_px[0] - self.cx) / self.fx, (p_px[1] - self.cy) / self.fy);
        [self.fx * xd + self.cx, self.fy * yd + self.cy]
    }

    /// Distorted pixel → undistorted pixel.
    pub fn undistort_px(&self, p_px: [f64; 2]) -> Option<[f64; 2]> {
        let (x, y) = self
            .undistort_normalized((p_px[0] - self.cx) / self.fx, (p_px[1] - self.cy) / self.fy)?;
        Some([self.fx * x + self.cx, self.fy * y + self.cy])
    }

    /// Distorted pixel → ray (x, y, 1) in the camera frame.
    pub fn ray_camera(&self, p_px: [f64; 2]) -> Option<V3> {
        let (x, y) = self
            .undistort_normalized((p_px[0] - self.cx) / self.fx, (p_px[1] - self.cy) / self.fy)?;
        Some(V3::new(x, y, 1.0))
    }

    /// Whether a (distorted) pixel position lies on the sensor.
    pub fn in_image(&self, p_px: [f64; 2]) -> bool {
        p_px[0] >= -0.5
            && p_px[1] >= -0.5
            && p_px[0] <= self.width as f64 - 0.5
            && p_px[1] <= self.height as f64 - 0.5
    }

    /// ROS camera_info YAML, as the ROS camera_calibration tools write it.
    pub fn ros_yaml(&self, camera_name: &str) -> String {
        let f = |v: f64| format!("{v:?}");
        let d = self.distortion.map(f).join(", ");
        format!(
            "image_width: {w}\nimage_height: {h}\ncamera_name: {camera_name}\n\
camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{fx}, 0.0, {cx}, 0.0, {fy}, {cy}, 0.0, 0.0, 1.0]\n\
distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [{d}]\n\
rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n\
projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{fx}, 0.0, {cx}, 0.0, 0.0, {fy}, {cy}, 0.0, 0.0, 0.0, 1.0, 0.0]\n",
            w = self.width,
            h = self.height,
            fx = f(self.fx),
            fy = f(self.fy),
            cx = f(self.cx),
            cy = f(self.cy),
        )
    }

    /// Reads a ROS camera_info YAML (image size, camera_matrix, plumb_bob
    /// distortion). Errors name the file and the key.
    pub fn from_ros_yaml(text: &str, file: &str) -> Result<Self, SimError> {
        let err = |key: &str, msg: String| SimError::Camera {
            file: file.to_string(),
            key: key.to_string(),
            message: msg,
        };
        let root: Value = serde_yaml::from_str(text).map_err(|e| err("(yaml)", e.to_string()))?;
        let uint = |key: &str| -> Result<u32, SimError> {
            root.get(key)
                .and_then(Value::as_u64)
                .and_then(|v| u32::try_from(v).ok())
                .filter(|v| *v > 0)
                .ok_or_else(|| err(key, "expected a positive integer".into()))
        };
        let data = |key: &str, n: usize| -> Result<Vec<f64>, SimError> {
            let seq = root
                .get(key)
                .and_then(|m| m.get("data"))
                .and_then(Value::as_sequence)
                .ok_or_else(|| err(key, "expected a mapping with a `data` list".into()))?;
            let v: Vec<f64> = seq.iter().filter_map(Value::as_f64).collect();
            if v.len() != seq.len() || v.len() < n || v.iter().any(|x| !x.is_finite()) {
                return Err(err(key, format!("expected {n} finite numbers in `data`")));
            }
            Ok(v)
        };
        let width = uint("image_width")?;
        let height = uint("image_height")?;
        let k = data("camera_matrix", 9)?;
        if let Some(model) = root.get("distortion_model").and_then(Value::as_str)
            && model != "plumb_bob"
        {
            return Err(err(
                "distortion_model",
                format!("`{model}` is not supported (plumb_bob only)"),
            ));
        }
        let d = match root.get("distortion_coefficients") {
            Some(_) => data("distortion_coefficients", 0)?,
            None => Vec::new(),
        };
        let mut distortion = [0.0; 5];
        for (slot, v) in distortion.iter_mut().zip(d) {
            *slot = v;
        }
        let cam = SimCamera {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        };
        if cam.fx <= 0.0 || cam.fy <= 0.0 {
            return Err(err("camera_matrix", "focal lengths must be > 0".into()));
        }
        Ok(cam)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> SimCamera {
        SimCamera {
            width: 1280,
            height: 960,
            fx: 1336.2,
            fy: 1335.4,
            cx: 646.3,
            cy: 473.8,
            distortion: [-0.12, 0.08, 0.0007, -0.0004, -0.01],
        }
    }

    #[test]
    fn undistort_inverts_distort_over_the_image() {
        let c = cam();
        for v in (0..960).step_by(37) {
            for u in (0..1280).step_by(41) {
                let p = [u as f64, v as f64];
                let back = c.distort_px(c.undistort_px(p).unwrap());
                assert!((back[0] - p[0]).abs() < 1e-9 && (back[1] - p[1]).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn projection_is_pinhole_without_distortion() {
        let mut c = cam();
        c.distortion = [0.0; 5];
        let p = c.project_px(&V3::new(0.5, -0.25, 2.0)).unwrap();
        assert!((p[0] - (646.3 + 1336.2 * 0.25)).abs() < 1e-12);
        assert!((p[1] - (473.8 - 1335.4 * 0.125)).abs() < 1e-12);
        assert!(c.project_px(&V3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn yaml_round_trip_and_errors() {
        let c = cam();
        let back = SimCamera::from_ros_yaml(&c.ros_yaml("sim"), "x.yaml").unwrap();
        assert_eq!(back, c);
        let bad = c
            .ros_yaml("sim")
            .replace("image_width: 1280", "image_width: -3");
        let e = SimCamera::from_ros_yaml(&bad, "bad.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.yaml") && e.contains("image_width"), "{e}");
    }
}
