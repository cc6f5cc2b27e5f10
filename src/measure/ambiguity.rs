//! Telling the two cone solutions apart from the canopy's outer rim.
//! INTERFACE STUB (issue 2, item 5).

use super::pose::CirclePose;
use crate::camera::CameraModel;
use image::GrayImage;

/// Image evidence (0..1) that the canopy's outer rim, a circle of
/// `canopy_radius_m` concentric with the inner circle, lies where `pose`
/// predicts it. `None` where the rim is not visible enough to judge.
pub fn canopy_support(
    _image: &GrayImage,
    _camera: &CameraModel,
    _pose: &CirclePose,
    _canopy_radius_m: f64,
) -> Option<f64> {
    None
}
