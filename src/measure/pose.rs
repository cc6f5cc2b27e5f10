//! The paper's visual cone (eqs. 11-27): circle centre and normal from its
//! ellipse and radius. INTERFACE STUB (issue 2, item 5).

use super::FitQuality;
use super::ellipse::Ellipse;
use crate::camera::CameraModel;
use nalgebra::{Matrix3, Vector3};

/// A circle's pose in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CirclePose {
    /// Circle centre, camera frame, metres.
    pub centre_camera_m: Vector3<f64>,
    /// Unit normal of the circle's plane, camera frame, pointing toward the camera.
    pub normal_camera: Vector3<f64>,
}

/// Both solutions of the single-circle ambiguity for an ellipse in
/// undistorted pixels, or `None` for a degenerate ellipse.
pub fn cone_pose(
    _ellipse_px: &Ellipse,
    _camera: &CameraModel,
    _radius_m: f64,
) -> Option<[CirclePose; 2]> {
    None
}

/// Covariance of the centre, camera frame, square metres.
pub fn position_covariance_camera(
    _ellipse_px: &Ellipse,
    _camera: &CameraModel,
    _pose: &CirclePose,
    _radius_m: f64,
    _quality: &FitQuality,
) -> Matrix3<f64> {
    Matrix3::zeros()
}

/// One-sigma angular uncertainty of the normal, radians.
pub fn normal_sigma_rad(_ellipse_px: &Ellipse, _quality: &FitQuality) -> f64 {
    0.0
}
