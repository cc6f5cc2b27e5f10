//! Detection of the drogue's dark inner circle: rim edge points, sub-pixel.
//! INTERFACE STUB: replaced by the detection work (issue 2, item 3).

use super::ellipse::Ellipse;
use crate::camera::CameraModel;
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Detection tunables (`[detect]` in the config).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectConfig {}

/// The best candidate of a frame.
#[derive(Clone, Debug)]
pub struct RimCandidate {
    /// Sub-pixel rim points, distorted image pixels (as in the frame).
    pub rim_points_px: Vec<[f64; 2]>,
    /// Evidence 0..1 (dark inside, light canopy around, ellipse shape, size).
    pub score: f64,
}

/// Finds the dark inner circle. Holds scratch buffers between frames.
pub struct Detector {}

impl Detector {
    pub fn new(_cfg: &DetectConfig, _camera: &CameraModel, _inner_radius_m: f64) -> Self {
        Self {}
    }

    /// The best candidate, or `None` when the frame shows no drogue.
    /// `hint`: the tracker's predicted ellipse (undistorted pixels); search near
    /// it first, and the full frame when it is not found there.
    pub fn detect(&mut self, _image: &GrayImage, _hint: Option<&Ellipse>) -> Option<RimCandidate> {
        None
    }
}
