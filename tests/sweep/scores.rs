//! Every verified candidate of the sweep's frames with its evidence score,
//! labelled by the simulator's truth: what `accept_score` and `min_score`
//! are calibrated on (`examples/calibrate_scores.rs`,
//! `tests/score_calibration.rs`).

use drogue_sim::sweep::{Sweep, standard_levels};
use drogue_vision::config::Config;
use drogue_vision::measure::detect::Detector;
use drogue_vision::testing;

/// One frame's verified candidates.
#[derive(Clone, Debug)]
pub struct ScoredFrame {
    /// The sweep factor's name (`motion blur`, `no drogue: crescent`, ...).
    pub factor: String,
    /// The level's label (factor and setting).
    pub level: String,
    /// The frame shows a drogue that should be detected.
    pub drogue: bool,
    /// The best score of a candidate on the drogue's disc (0 when none was
    /// verified, or no drogue).
    pub disc_score: f64,
    /// Scores of the other candidates (probe, hose, distractors, the
    /// canopy's rim, look-alikes).
    pub false_scores: Vec<f64>,
}

/// A candidate is the drogue's disc when its centre lies within a tenth of
/// the true ellipse's minor axis (2 px at least) and its major axis within
/// this share of the truth's.
const SAME_SIZE: f64 = 0.15;

/// Every level's first `frames` frames of `seed`, searched without the early
/// exit (`Detector::scored_candidates`), with the embedded configuration.
pub fn scored_frames(seed: u64, frames: u64) -> Vec<ScoredFrame> {
    let config = Config::embedded().measure();
    let circles = config.drogue.circles();
    let mut detectors: Vec<([f64; 5], Detector)> = Vec::new();
    let mut sim = Sweep::new(seed);
    let mut out = Vec::new();
    for level in standard_levels() {
        for index in 0..frames {
            let f = sim.frame(&level, index);
            let i = detectors
                .iter()
                .position(|(d, _)| *d == f.camera.distortion)
                .unwrap_or_else(|| {
                    let camera = testing::camera_from_sim(&f.camera, "calibrate");
                    detectors.push((
                        f.camera.distortion,
                        Detector::new(&config.detect, &camera, circles),
                    ));
                    detectors.len() - 1
                });
            let truth = f.drogue.as_ref().filter(|t| t.expect_detect);
            let mut frame = ScoredFrame {
                factor: level.factor.name().to_string(),
                level: level.label(),
                drogue: truth.is_some(),
                disc_score: 0.0,
                false_scores: Vec::new(),
            };
            for (e, score) in detectors[i].1.scored_candidates(&f.image) {
                let on_disc = truth.is_some_and(|t| {
                    let off = (e.cx - t.ellipse.cx).hypot(e.cy - t.ellipse.cy);
                    off <= (0.1 * t.ellipse.b).max(2.0)
                        && (e.a / t.ellipse.a - 1.0).abs() <= SAME_SIZE
                });
                if on_disc {
                    frame.disc_score = frame.disc_score.max(score);
                } else {
                    frame.false_scores.push(score);
                }
            }
            out.push(frame);
        }
    }
    out
}
