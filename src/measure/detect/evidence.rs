//! The evidence of a settled rim pass: the fill of its inside, the
//! sharpness of its steps, the canopy's rim where its pose puts it, and the
//! score that ranks the candidates.

use super::verify::{CLIPPED_SHARE, RimPass};
use super::{Detector, Reject, SATURATED_GRAY, Verified, angle_gap, canopy, polar_radius, rim};
use crate::measure::ellipse::Ellipse;
use image::GrayImage;
use std::f64::consts::TAU;

/// A rim step no wider than this share of the disc's minor radius (or
/// [`SHARP_STEP_PX`]) is sharp; at least [`MIN_SHARP_SHARE`] of the rim's
/// steps must be. A linear motion blur of length `L` leaves a share
/// `(2 / pi) asin(T / L)` of a disc's rim steps narrower than `T`; at the
/// longest blur that can be measured (the widest window, `1.2 r`) and
/// `T = 0.2 r`, that is 10.7 %: half of it is asked for, as the rim's own
/// softness and noise widen the steps across the blur too.
const SHARP_STEP_RADII: f64 = 0.2;
const SHARP_STEP_PX: f64 = 4.0;
const MIN_SHARP_SHARE: f64 = 0.05;

/// Share of the inside that must be dark when the canopy cannot be judged
/// (`min_fill` applies otherwise): a disc is dark all over, up to a glare
/// skirt or a highlight on the probe over a fifth of it.
const UNJUDGED_MIN_FILL: f64 = 0.8;

/// Rays and radius fractions of the fill test (inside the ellipse).
const FILL_DIRECTIONS: usize = 24;
const FILL_FRACTIONS: [f64; 5] = [0.1, 0.3, 0.5, 0.7, 0.85];

impl Detector {
    /// Share of samples inside `ellipse` (undistorted pixels) darker than
    /// the middle of the rim's step. Samples lie on [`FILL_DIRECTIONS`] rays
    /// at [`FILL_FRACTIONS`] of the ellipse's radius; each is compared with
    /// the mid level of the rim edge nearest in angle (`mids`: angle about
    /// the ellipse's centre, mid level), so that a glare veil or vignetting
    /// across the disc does not count as light. Saturated samples (glare)
    /// count neither way. 1 when nothing could be sampled.
    pub(super) fn fill_share(
        &self,
        image: &GrayImage,
        ellipse: &Ellipse,
        mids: &[(f64, f32)],
    ) -> f64 {
        if mids.is_empty() {
            return 1.0;
        }
        let (mut dark, mut counted) = (0usize, 0usize);
        for k in 0..FILL_DIRECTIONS {
            let phi = TAU * (k as f64 + 0.5) / FILL_DIRECTIONS as f64;
            let r = polar_radius(ellipse.a, ellipse.b, ellipse.theta, phi);
            let gap = |a: f64| angle_gap(a, phi);
            let Some(&(_, mid)) = mids.iter().min_by(|x, y| gap(x.0).total_cmp(&gap(y.0))) else {
                continue;
            };
            let (sin, cos) = phi.sin_cos();
            for f in FILL_FRACTIONS {
                let q = [ellipse.cx + f * r * cos, ellipse.cy + f * r * sin];
                let [u, v] = self.camera.distort_px(q);
                let Some(value) = rim::sample(image, u, v) else {
                    continue;
                };
                if value >= SATURATED_GRAY {
                    continue;
                }
                counted += 1;
                if value < mid {
                    dark += 1;
                }
            }
        }
        if counted == 0 {
            1.0
        } else {
            dark as f64 / counted as f64
        }
    }

    /// The evidence score of a rim pass (the canopy's outer rim band beyond
    /// its inlier edges), and the candidate when it is good enough.
    pub(super) fn score(&mut self, image: &GrayImage, pass: RimPass) -> Result<Verified, Reject> {
        let RimPass {
            ellipse,
            centre,
            points_px,
            measured_px,
            measured_undistorted,
            residuals,
            inliers,
            step_widths_px,
            clipped_share,
            rim_contrast,
            shape,
            fill,
            tolerance: tol,
            mids,
        } = pass;
        // Canopy evidence: its outer rim where the candidate's pose puts it.
        let mut widths: Vec<(f64, f64)> = inliers
            .iter()
            .map(|&i| {
                let [u, v] = points_px[i];
                let angle = (v - centre[1]).atan2(u - centre[0]);
                (angle, step_widths_px[i])
            })
            .collect();
        // The canopy test looks both up by angle.
        widths.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut mids = mids;
        mids.sort_by(|a, b| a.0.total_cmp(&b.0));
        // A blur is measured while the widest window holds its steps (the
        // mid-level crossing of a whole blurred step is the edge); beyond
        // that the levels are not the disc's and the canopy's.
        if clipped_share > CLIPPED_SHARE {
            return Err(Reject::Blurred(clipped_share));
        }
        // Motion blur smears the rim along one direction only: across it
        // the steps stay sharp. A rim soft all round is a blob out of
        // focus (a cloud, a shadow), not the drogue's edge.
        let sharp_width = (SHARP_STEP_RADII * ellipse.b).max(SHARP_STEP_PX);
        let sharp = widths.iter().filter(|w| w.1 <= sharp_width).count();
        if (sharp as f64) < MIN_SHARP_SHARE * widths.len() as f64 {
            return Err(Reject::Soft(sharp as f64 / widths.len().max(1) as f64));
        }
        let edge = canopy::RimEdge {
            min_step_gray: (0.1 * rim_contrast).max(0.5 * self.cfg.min_contrast_gray) as f32,
            widths: &widths,
            mids: &mids,
        };
        let canopy = canopy::ring_support(
            image,
            &self.camera,
            &ellipse,
            self.drogue,
            edge,
            &mut self.profile,
            &mut self.scratch,
        );
        if let Some(seen) = canopy
            && ellipse.a >= self.cfg.canopy_required_from_px
            && seen < self.cfg.min_canopy_fraction
        {
            return Err(Reject::NoCanopy(seen));
        }
        // Without the canopy's say (its rim off the frame, too thin or
        // smeared to judge) the inside must be the disc's: dark nearly
        // everywhere, not the half of a ring's inside or a cloud's.
        if canopy.is_none() && fill < UNJUDGED_MIN_FILL {
            return Err(Reject::LightInside(fill));
        }
        tracing::debug!(
            centre_px = ?[ellipse.cx.round(), ellipse.cy.round()],
            axes_px = ?[ellipse.a.round(), ellipse.b.round()],
            shape,
            fill,
            canopy = ?canopy,
            rim_contrast,
            points = points_px.len(),
            on_rim = inliers.len(),
            tolerance_px = tol,
            "evidence"
        );
        let canopy = canopy.unwrap_or(0.0);
        let w = self.cfg.canopy_weight.clamp(0.0, 1.0);
        let score = (shape * ((1.0 - w) + w * canopy)).clamp(0.0, 1.0);
        if score < self.cfg.min_score {
            return Err(Reject::LowScore(score));
        }
        // Keep the points near the ellipse: the probe and hose outlines are
        // the fit's outliers, and fewer of them is better.
        let keep = (0.05 * ellipse.a).max(3.0 * tol);
        let near = |points: Vec<[f64; 2]>| -> Vec<[f64; 2]> {
            points
                .into_iter()
                .zip(&residuals)
                .filter(|(_, r)| **r <= keep)
                .map(|(p, _)| p)
                .collect()
        };
        let step_widths_px = step_widths_px
            .into_iter()
            .zip(&residuals)
            .filter(|(_, r)| **r <= keep)
            .map(|(w, _)| w)
            .collect();
        Ok(Verified {
            ellipse,
            points_px: near(measured_px),
            undistorted: near(measured_undistorted),
            score,
            rim_contrast,
            step_widths_px,
        })
    }
}
