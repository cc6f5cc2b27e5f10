//! Ellipse fitting: the paper's least squares and Algorithm 1, fixed-threshold
//! RANSAC, and our adaptive default. INTERFACE STUB (issue 2, item 4).

use super::ellipse::Ellipse;
use serde::{Deserialize, Serialize};

/// Fit tunables (`[fit]` in the config).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {}

#[derive(Clone, Debug, PartialEq)]
pub struct FitResult {
    pub ellipse: Ellipse,
    /// One flag per input point: kept by the robust fit.
    pub inliers: Vec<bool>,
    /// RMS geometric residual of the inliers, pixels.
    pub rms_residual_px: f64,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    #[error("too few points: {0}")]
    TooFewPoints(usize),
    #[error("no ellipse fits the points")]
    NoEllipse,
}

/// Runs the configured fit method; deterministic for a given seed.
pub struct Fitter {}

impl Fitter {
    pub fn new(_cfg: &FitConfig) -> Self {
        Self {}
    }

    /// Fits an ellipse to points in undistorted pixels.
    pub fn fit(&mut self, points_px: &[[f64; 2]], _seed: u64) -> Result<FitResult, FitError> {
        Err(FitError::TooFewPoints(points_px.len()))
    }
}
