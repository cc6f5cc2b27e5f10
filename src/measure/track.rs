//! Temporal tracking: ambiguity by continuity, prediction for the ROI search,
//! track epochs. INTERFACE STUB (issue 2, item 5).

use super::Disambiguation;
use super::ellipse::Ellipse;
use super::pose::CirclePose;
use serde::{Deserialize, Serialize};

/// `[track]` in the config.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackConfig {}

/// The tracker's decision for one frame.
#[derive(Clone, Copy, Debug)]
pub struct Choice {
    pub pose: CirclePose,
    /// The other solution while unresolved.
    pub alternative: Option<CirclePose>,
    pub how: Disambiguation,
    pub track_epoch: u32,
}

pub struct Tracker {}

impl Tracker {
    pub fn new(_cfg: &TrackConfig) -> Self {
        Self {}
    }
    /// The predicted ellipse (undistorted pixels) to search near, if tracking.
    pub fn search_hint(&self) -> Option<Ellipse> {
        None
    }
    /// Picks one of the two cone solutions and updates the track.
    pub fn choose(
        &mut self,
        solutions: [CirclePose; 2],
        _canopy_support: [Option<f64>; 2],
        _capture_time_ns: u64,
        _ellipse_px: &Ellipse,
    ) -> Choice {
        Choice {
            pose: solutions[0],
            alternative: Some(solutions[1]),
            how: Disambiguation::Unresolved,
            track_epoch: 0,
        }
    }
    /// Forgets the track entirely.
    pub fn reset(&mut self) {}
    /// No detection in this frame.
    pub fn lost(&mut self, _capture_time_ns: u64) {}
}
