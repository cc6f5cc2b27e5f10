//! The camera's mounting on the receiver: camera frame -> body FRD, and the
//! probe tip.
//!
//! Convention (shared with the simulator's scenarios): with roll = pitch =
//! yaw = 0 the camera looks along body +x, image right = body +y, image down =
//! body +z. The configured angles are aircraft Euler angles (ZYX) of that
//! forward-looking frame relative to body:
//! `R_body_cam = Rz(yaw) Ry(pitch) Rx(roll) R_body_cam0`. Positive pitch tilts
//! the camera up.

use crate::spatial::{BodyFrd, Camera, Direction, Point};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// `[mount]` in the config: degrees and metres at this edge.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MountConfig {
    /// Camera optical centre in body FRD, metres.
    pub camera_position_body_m: [f64; 3],
    /// Camera roll about its forward-looking axis, degrees.
    pub camera_roll_deg: f64,
    /// Camera pitch, degrees; positive looks up.
    pub camera_pitch_deg: f64,
    /// Camera yaw, degrees; positive looks right.
    pub camera_yaw_deg: f64,
    /// Refuelling probe tip in body FRD, metres.
    pub probe_tip_body_m: [f64; 3],
}

/// Camera -> body FRD transform and the probe tip.
#[derive(Clone, Debug, PartialEq)]
pub struct Mount {
    q_body_camera: UnitQuaternion<f64>,
    camera_position_body_m: Vector3<f64>,
    probe_tip_body_m: Vector3<f64>,
}

/// The camera axes in body FRD at zero mount angles: columns are camera x
/// (image right) = body y, camera y (image down) = body z, camera z (optical
/// axis) = body x.
fn r_body_cam0() -> Matrix3<f64> {
    Matrix3::from_columns(&[Vector3::y(), Vector3::z(), Vector3::x()])
}

impl Mount {
    /// Checks and converts the config (degrees -> a quaternion inside).
    pub fn from_config(cfg: &MountConfig) -> Result<Self, String> {
        let angles = [
            ("camera_roll_deg", cfg.camera_roll_deg),
            ("camera_pitch_deg", cfg.camera_pitch_deg),
            ("camera_yaw_deg", cfg.camera_yaw_deg),
        ];
        for (key, v) in angles {
            if !(v.is_finite() && v.abs() <= 360.0) {
                return Err(format!("{key} = {v}: expected degrees in [-360, 360]"));
            }
        }
        let vectors = [
            ("camera_position_body_m", cfg.camera_position_body_m),
            ("probe_tip_body_m", cfg.probe_tip_body_m),
        ];
        for (key, v) in vectors {
            if !v.iter().all(|x| x.is_finite()) {
                return Err(format!("{key} = {v:?}: expected three finite metres"));
            }
        }
        let q_mount = UnitQuaternion::from_euler_angles(
            cfg.camera_roll_deg.to_radians(),
            cfg.camera_pitch_deg.to_radians(),
            cfg.camera_yaw_deg.to_radians(),
        );
        let q_body_cam0 =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r_body_cam0()));
        Ok(Self {
            q_body_camera: q_mount * q_body_cam0,
            camera_position_body_m: Vector3::from(cfg.camera_position_body_m),
            probe_tip_body_m: Vector3::from(cfg.probe_tip_body_m),
        })
    }

    /// Rotation camera -> body FRD.
    pub fn q_body_camera(&self) -> UnitQuaternion<f64> {
        self.q_body_camera
    }

    /// Camera optical centre, body FRD, metres.
    pub fn camera_position_body_m(&self) -> Vector3<f64> {
        self.camera_position_body_m
    }

    /// Probe tip, body FRD, metres.
    pub fn probe_tip_body_m(&self) -> Vector3<f64> {
        self.probe_tip_body_m
    }

    /// A point (metres) from the camera frame into body FRD.
    pub fn point_camera_to_body(&self, p: &Point<Camera>) -> Point<BodyFrd> {
        Point::new(self.q_body_camera * p.vector() + self.camera_position_body_m)
    }

    /// A direction from the camera frame into body FRD (no translation).
    pub fn vector_camera_to_body(&self, v: &Direction<Camera>) -> Direction<BodyFrd> {
        Direction::new(self.q_body_camera * v.vector())
    }

    /// A position covariance from camera axes into body axes: `R C R^T`.
    pub fn covariance_camera_to_body(&self, cov_camera: &Matrix3<f64>) -> Matrix3<f64> {
        let r = self.q_body_camera.to_rotation_matrix();
        r.matrix() * cov_camera * r.matrix().transpose()
    }

    /// A body-FRD point relative to the probe tip (body axes, metres).
    pub fn point_body_from_probe(&self, p: &Point<BodyFrd>) -> Point<BodyFrd> {
        Point::new(p.vector() - self.probe_tip_body_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(pos: [f64; 3], roll: f64, pitch: f64, yaw: f64) -> MountConfig {
        MountConfig {
            camera_position_body_m: pos,
            camera_roll_deg: roll,
            camera_pitch_deg: pitch,
            camera_yaw_deg: yaw,
            probe_tip_body_m: [2.0, 0.5, -0.3],
        }
    }

    fn close(a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn zero_angles_look_forward() {
        let m = Mount::from_config(&config([1.0, 0.0, -0.5], 0.0, 0.0, 0.0)).unwrap();
        // Optical axis -> forward, image right -> right, image down -> down.
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::z())),
            &Vector3::x()
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::x())),
            &Vector3::y()
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::y())),
            &Vector3::z()
        ));
        // A point 10 m ahead on the optical axis, 1 m right in the image.
        let p = *m.point_camera_to_body(&Point::new(Vector3::new(1.0, 0.0, 10.0)));
        assert!(close(&p, &Vector3::new(11.0, 1.0, -0.5)));
    }

    #[test]
    fn yaw_90_looks_right() {
        let m = Mount::from_config(&config([0.0; 3], 0.0, 0.0, 90.0)).unwrap();
        // Optical axis -> body right; image right -> body aft; image down -> down.
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::z())),
            &Vector3::y()
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::x())),
            &-Vector3::x()
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::y())),
            &Vector3::z()
        ));
    }

    #[test]
    fn pitch_30_looks_up() {
        let m = Mount::from_config(&config([0.0; 3], 0.0, 30.0, 0.0)).unwrap();
        let (s, c) = 30f64.to_radians().sin_cos();
        // Forward and up (FRD: up is -z).
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::z())),
            &Vector3::new(c, 0.0, -s)
        ));
        // Image down tilts forward-down, image right stays right.
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::y())),
            &Vector3::new(s, 0.0, c)
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::x())),
            &Vector3::y()
        ));
    }

    #[test]
    fn roll_90_turns_image_right_down() {
        let m = Mount::from_config(&config([0.0; 3], 90.0, 0.0, 0.0)).unwrap();
        // Rolled right by 90 deg: image right -> body down, image down -> body left.
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::x())),
            &Vector3::z()
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::y())),
            &-Vector3::y()
        ));
        assert!(close(
            &m.vector_camera_to_body(&Direction::new(Vector3::z())),
            &Vector3::x()
        ));
    }

    #[test]
    fn covariance_is_rotated() {
        let m = Mount::from_config(&config([0.3, 0.2, 0.1], 0.0, 0.0, 90.0)).unwrap();
        // Depth (camera z) variance 4, lateral 1 and 0.25.
        let cov_camera = Matrix3::from_diagonal(&Vector3::new(1.0, 0.25, 4.0));
        let cov_body = m.covariance_camera_to_body(&cov_camera);
        // Camera z -> body y, camera x -> body -x, camera y -> body z.
        let expected = Matrix3::from_diagonal(&Vector3::new(1.0, 4.0, 0.25));
        assert!((cov_body - expected).norm() < 1e-12, "{cov_body}");
    }

    #[test]
    fn probe_offset() {
        let m = Mount::from_config(&config([0.0; 3], 0.0, 0.0, 0.0)).unwrap();
        let d = *m.point_body_from_probe(&Point::new(Vector3::new(12.0, 0.5, -0.3)));
        assert!(close(&d, &Vector3::new(10.0, 0.0, 0.0)));
    }

    #[test]
    fn bad_values_are_named() {
        let e = Mount::from_config(&config([0.0, f64::NAN, 0.0], 0.0, 0.0, 0.0)).unwrap_err();
        assert!(e.contains("camera_position_body_m"), "{e}");
        let e = Mount::from_config(&config([0.0; 3], 0.0, 1000.0, 0.0)).unwrap_err();
        assert!(e.contains("camera_pitch_deg"), "{e}");
    }
}
