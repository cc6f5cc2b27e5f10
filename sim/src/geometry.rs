//! Rotations and quaternions of the simulator's own (independent) geometry.
//!
//! Conventions (common to the whole project): NED world, FRD body, OpenCV
//! camera; Euler angles are aircraft ZYX (R = Rz(yaw) Ry(pitch) Rx(roll));
//! quaternions are Hamilton, w first, `q_<to>_<from>`.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

/// A 3-vector (positions metres, directions unit), in the frame its name says.
pub type V3 = Vector3<f64>;
/// A 3x3 matrix, mostly rotations `r_<to>_<from>`.
pub type M3 = Matrix3<f64>;

/// Rotation `R = Rz(yaw) * Ry(pitch) * Rx(roll)`, angles in radians.
pub fn euler_zyx(roll: f64, pitch: f64, yaw: f64) -> M3 {
    *Rotation3::from_euler_angles(roll, pitch, yaw).matrix()
}

/// The camera's zero-angle mount: looking along body +x, image right = body
/// +y, image down = body +z (columns are the camera axes in body FRD).
pub fn r_body_cam0() -> M3 {
    M3::new(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// Camera → body rotation of a mount given in degrees (the shared convention).
pub fn r_body_cam(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> M3 {
    euler_zyx(
        roll_deg.to_radians(),
        pitch_deg.to_radians(),
        yaw_deg.to_radians(),
    ) * r_body_cam0()
}

/// Rotation matrix → Hamilton quaternion `[w, x, y, z]` with w >= 0.
pub fn quat_from_matrix(m: &M3) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m));
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// Hamilton quaternion `[w, x, y, z]` (normalised here) → rotation matrix;
/// `None` for a zero or non-finite quaternion.
pub fn matrix_from_quat(q: [f64; 4]) -> Option<M3> {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !n.is_finite() || n < 1e-12 {
        return None;
    }
    let uq = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
    Some(*uq.to_rotation_matrix().matrix())
}

/// A unit vector perpendicular to `n` (unit).
pub fn perpendicular(n: &V3) -> V3 {
    let a = if n.x.abs() < 0.9 { V3::x() } else { V3::y() };
    (a - n * a.dot(n)).normalize()
}

/// The vector's components `[x, y, z]`.
pub fn to_array(v: &V3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mount_zero_looks_forward() {
        let r = r_body_cam(0.0, 0.0, 0.0);
        // camera z (optical axis) is body +x, camera x is body +y.
        assert!((r * V3::z() - V3::x()).norm() < 1e-15);
        assert!((r * V3::x() - V3::y()).norm() < 1e-15);
        assert!((r * V3::y() - V3::z()).norm() < 1e-15);
    }

    #[test]
    fn positive_pitch_tilts_camera_up() {
        let r = r_body_cam(0.0, 10.0, 0.0);
        let axis_body = r * V3::z();
        // Up in FRD is -z.
        assert!(axis_body.z < -0.17 && axis_body.z > -0.18, "{axis_body}");
    }

    #[test]
    fn euler_matches_explicit_product() {
        let (r, p, y) = (0.1_f64, -0.2_f64, 0.7_f64);
        let rx = M3::new(1.0, 0.0, 0.0, 0.0, r.cos(), -r.sin(), 0.0, r.sin(), r.cos());
        let ry = M3::new(p.cos(), 0.0, p.sin(), 0.0, 1.0, 0.0, -p.sin(), 0.0, p.cos());
        let rz = M3::new(y.cos(), -y.sin(), 0.0, y.sin(), y.cos(), 0.0, 0.0, 0.0, 1.0);
        assert!((euler_zyx(r, p, y) - rz * ry * rx).norm() < 1e-14);
    }

    #[test]
    fn quaternion_round_trip() {
        let m = euler_zyx(0.3, -0.4, 2.0);
        let q = quat_from_matrix(&m);
        assert!((matrix_from_quat(q).unwrap() - m).norm() < 1e-12);
        assert!(matrix_from_quat([0.0; 4]).is_none());
    }
}
