//! The evidence of a settled rim pass: the fill of its inside, the
//! sharpness of its steps, the canopy's rim where its pose puts it, and the
//! score that ranks the candidates.

use super::shading::{beside_dark, better_without, canopy_slope, shaded_points};
use super::verify::{CLIPPED_SHARE, FillLevels, PoseEdges, RimPass};
use super::{
    Detector, Reject, SATURATED_GRAY, SHARP_STEP_OWN_PX, VEIL_MIN_GRAY, VEIL_SIGMAS, Verified,
    canopy, median, polar_radius, rim,
};
use crate::camera::CameraModel;
use crate::measure::ellipse::Ellipse;
use image::GrayImage;
use std::f64::consts::{PI, TAU};

/// A rim step no wider than a sharp step's own width
/// ([`SHARP_STEP_OWN_PX`]) plus this share of the disc's minor radius (or
/// [`SHARP_STEP_PX`]) is sharp; at least [`MIN_SHARP_SHARE`] of the rim's
/// steps must be. A linear motion blur of length `L` widens a step whose
/// rim runs at angle `phi` to it by `L |cos phi|` beyond its own width,
/// which leaves a share `(2 / pi) asin(T / L)` of a disc's rim steps within
/// `T` of that width; at the longest blur that can be measured (the widest
/// window, `1.2 r`) and `T = 0.2 r`, that is 10.7 %: half of it is asked
/// for, as noise widens the steps across the blur too.
const SHARP_STEP_RADII: f64 = 0.2;
const SHARP_STEP_PX: f64 = 4.0;
const MIN_SHARP_SHARE: f64 = 0.05;

/// Share of the inside that must be dark when the canopy cannot be judged
/// (`min_fill` applies otherwise): a disc is dark all over, up to a glare
/// skirt or a highlight on the probe over a fifth of it.
const UNJUDGED_MIN_FILL: f64 = 0.8;

/// Largest rise from the ring just outside the rim to the canopy's band
/// beyond it, in units of the rim's contrast ([`Detector::rise_beyond`]),
/// for the disc: a larger rise puts the candidate inside a larger dark
/// shape whose rim is the stronger step ([`Reject::Nested`]). Calibrated on
/// the simulator's randomised frames (`robustness_sweep` seeds 12 and 3,
/// every verified candidate): the disc's 3,767 candidates rise at most
/// 0.29 (99.9 % below 0.25; noise of 20 gray levels gives the largest),
/// and 0.5 is 1.75 times that. (On the independent renderer's frames the
/// disc's candidates rise at most 0.33, the probe's tip inside a hazed disc
/// 0.68-1.1.)
const MAX_RISE_BEYOND: f64 = 0.5;
/// Largest rise beyond the rim, in units of the full step from the disc's
/// dark level up to the canopy's band, that a shaded canopy gives: a second
/// condition of [`Reject::Nested`]. A canopy darkened toward the disc by its
/// throat's shadow has a ring just outside the rim darker than its band by
/// the shadow's share of the canopy's light: the rim's own step, taken from
/// that darker ring, then makes the first measure rise past
/// [`MAX_RISE_BEYOND`] (0.47-0.54 on the simulator's 30 % throat shadow,
/// every seed) while this one stays at the shadow's depth (0.26-0.30). A
/// dark shape inside a larger one has the larger one's dark there: nearly
/// the whole step. 0.4 lies between; the strongest throat shadow the
/// simulator draws takes 30 % of the canopy's light. (On the sweep's seeds
/// 12 and 3, 30 frames a level, three candidates other than the disc rose
/// past [`MAX_RISE_BEYOND`]: two rise 0.73 and 1.3 here, and the third, a
/// shape on a drogue-free frame at 0.32, the later tests reject.)
const MAX_SHADED_RISE: f64 = 0.4;
/// Rays of [`Detector::rise_beyond`], and its samples: the ring just
/// outside the rim is [`BEYOND_NEAR_RADII`] of the radius wide, the band
/// runs from [`BEYOND_FAR_FROM`] of the radius (or the ring's end) to
/// [`BEYOND_FAR_TO_OUTER`] of the canopy rim's (inside its dark band).
const BEYOND_RAYS: usize = 24;
const BEYOND_NEAR_SAMPLES: usize = 5;
const BEYOND_FAR_SAMPLES: usize = 8;
const BEYOND_NEAR_RADII: f64 = 0.25;
const BEYOND_FAR_FROM: f64 = 1.5;
const BEYOND_FAR_TO_OUTER: f64 = 0.85;

/// Rays and radius fractions of the fill test (inside the ellipse).
const FILL_DIRECTIONS: usize = 24;
const FILL_FRACTIONS: [f64; 5] = [0.1, 0.3, 0.5, 0.7, 0.85];

/// Which of a fill direction's samples (in order along it) are a glare's:
/// its veil (lighter than `veil_from`) and the skirt on either side of it,
/// the samples at or above the mid level (`mid`) that keep falling away
/// from the veil. A glare's light falls off smoothly from its core; a
/// sample darker than the mid level, or lighter than the one before it,
/// is the surface's again.
fn glare_skirt<const N: usize>(samples: &[Option<f32>; N], veil_from: f32, mid: f32) -> [bool; N] {
    let mut glare = samples.map(|s| s.is_some_and(|v| v > veil_from));
    // Whether sample `to`, next to `from` on the side away from the veil,
    // continues the skirt.
    let falls = |from: usize, to: usize| match (samples[from], samples[to]) {
        (Some(nearer), Some(this)) => this >= mid && this <= nearer,
        _ => false,
    };
    for to in 1..N {
        if glare[to - 1] && !glare[to] && falls(to - 1, to) {
            glare[to] = true;
        }
    }
    for to in (0..N.saturating_sub(1)).rev() {
        if glare[to + 1] && !glare[to] && falls(to + 1, to) {
            glare[to] = true;
        }
    }
    glare
}

impl Detector {
    /// Share of samples inside `ellipse` (undistorted pixels) darker than
    /// the middle of the rim's step. Samples lie on [`FILL_DIRECTIONS`] rays
    /// at [`FILL_FRACTIONS`] of the ellipse's radius; each is compared with
    /// the mid level of the rim edge nearest in angle (`levels`: angle about
    /// the ellipse's centre as `atan2` gives it, the step's levels; sorted
    /// by angle), so that a glare veil or
    /// vignetting across the disc does not count as light. A direction with
    /// a saturated sample (a glare) counts neither way, nor does a sample
    /// lighter than that edge's light side by more than the noise (a
    /// glare's veil below saturation): what a hole in a dark shape shows is
    /// the background, no lighter than the light side of the shape's own
    /// rim. 1 when nothing could be sampled.
    pub(super) fn fill_share(
        &self,
        image: &GrayImage,
        ellipse: &Ellipse,
        levels: &[(f64, FillLevels)],
    ) -> f64 {
        if levels.is_empty() {
            return 1.0;
        }
        let margin = VEIL_SIGMAS * self.noise_gray as f32 + VEIL_MIN_GRAY;
        let directions: [Option<(FillLevels, [Option<f32>; FILL_FRACTIONS.len()])>;
            FILL_DIRECTIONS] = std::array::from_fn(|k| {
            let phi = TAU * (k as f64 + 0.5) / FILL_DIRECTIONS as f64;
            let r = polar_radius(ellipse.a, ellipse.b, ellipse.theta, phi);
            // The lookup's angle in atan2's turn, as the levels' are.
            let from_atan2 = if phi > PI { phi - TAU } else { phi };
            let &(_, step) = canopy::nearest(levels, from_atan2)?;
            let (sin, cos) = phi.sin_cos();
            let samples = FILL_FRACTIONS.map(|f| {
                let q = [ellipse.cx + f * r * cos, ellipse.cy + f * r * sin];
                let [u, v] = self.camera.distort_px(q);
                rim::sample(image, u, v)
            });
            Some((step, samples))
        });
        let saturated =
            |samples: &[Option<f32>]| samples.iter().flatten().any(|&v| v >= SATURATED_GRAY);
        // A glare over the disc saturates part of its inside.
        let glare_over = directions
            .iter()
            .flatten()
            .any(|(_, samples)| saturated(samples));
        let (mut dark, mut counted) = (0usize, 0usize);
        for (step, samples) in directions.into_iter().flatten() {
            // A direction that runs through saturated pixels looks into a
            // glare: its other samples lie in the glare's skirt, which
            // lightens them smoothly, not as a light surface would.
            if saturated(&samples) {
                continue;
            }
            // A sample lighter than the rim's light side is veiled: what a
            // hole in a dark shape shows is the background beyond it, no
            // lighter than that. Under a glare over the disc, the veil is
            // its skirt, which falls off smoothly on either side: the light
            // samples next to it that keep falling away from it are that
            // skirt too, not a light inside.
            let veil_from = step.light + margin;
            let glare = if glare_over {
                glare_skirt(&samples, veil_from, step.mid)
            } else {
                samples.map(|s| s.is_some_and(|v| v > veil_from))
            };
            for (value, in_glare) in samples.into_iter().zip(glare) {
                let Some(value) = value.filter(|_| !in_glare) else {
                    continue;
                };
                counted += 1;
                if value < step.mid {
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

    /// How much lighter the canopy's band is than the ring just outside
    /// the rim ([`Rise`]): the median over
    /// [`BEYOND_RAYS`] rays of (a high level of the band from
    /// [`BEYOND_FAR_FROM`] radii to [`BEYOND_FAR_TO_OUTER`] of the canopy
    /// rim's radius) minus (the median level just past the rim's step, out
    /// to [`BEYOND_NEAR_RADII`] more). Saturated samples (glare) and samples
    /// outside the image are left out; NaN when no ray has enough of either.
    /// `widths` are the rim's step widths by angle, sorted (the ring starts
    /// past the step's light end), `mids` its mid levels by angle, sorted.
    fn rise_beyond(
        &self,
        image: &GrayImage,
        ellipse: &Ellipse,
        widths: &[(f64, f64)],
        mids: &[(f64, f32)],
        rim_contrast: f64,
    ) -> Rise {
        let ratio = self.drogue.canopy_radius_m / self.drogue.inner_radius_m;
        let centre = self.camera.distort_px([ellipse.cx, ellipse.cy]);
        let mut over_step = Vec::with_capacity(BEYOND_RAYS);
        let mut over_full = Vec::with_capacity(BEYOND_RAYS);
        let (mut near, mut far) = (Vec::new(), Vec::new());
        for k in 0..BEYOND_RAYS {
            let phi = TAU * (k as f64 + 0.5) / BEYOND_RAYS as f64;
            let r = polar_radius(ellipse.a, ellipse.b, ellipse.theta, phi);
            let width = canopy::nearest(widths, phi).map_or(2.0, |w| w.1);
            let (sin, cos) = phi.sin_cos();
            // Straight rays from the distorted centre, as the rim passes
            // take them: over a few radii the distortion bends them by
            // far less than the ring's width.
            let at = |s: f64| {
                rim::sample(image, centre[0] + s * cos, centre[1] + s * sin)
                    .filter(|&g| g < SATURATED_GRAY)
            };
            let along = |from: f64, to: f64, n: usize, out: &mut Vec<f32>| {
                out.clear();
                out.extend(
                    (0..n).filter_map(|j| at(from + (to - from) * j as f64 / (n - 1) as f64)),
                );
                out.sort_by(f32::total_cmp);
            };
            let near_from = r + 0.5 * width + 1.0;
            let near_to = near_from + BEYOND_NEAR_RADII * r;
            let far_from = near_to.max(BEYOND_FAR_FROM * r);
            let far_to = BEYOND_FAR_TO_OUTER * ratio * r;
            if far_to <= far_from {
                continue;
            }
            along(near_from, near_to, BEYOND_NEAR_SAMPLES, &mut near);
            along(far_from, far_to, BEYOND_FAR_SAMPLES, &mut far);
            if 2 * near.len() <= BEYOND_NEAR_SAMPLES || 2 * far.len() <= BEYOND_FAR_SAMPLES {
                continue;
            }
            // The second highest of the band: one sample may fall on a
            // highlight, and the band's shading or a strut's shadow lowers
            // the others.
            let high = far[far.len() - 2];
            let rise = f64::from(high - near[near.len() / 2]);
            over_step.push(rise / rim_contrast.max(1.0));
            // The disc's dark level on this ray: its rim's mid level less
            // half the rim's contrast.
            if let Some(&(_, mid)) = canopy::nearest(mids, phi) {
                let dark = f64::from(mid) - 0.5 * rim_contrast;
                over_full.push(rise / (f64::from(high) - dark).max(1.0));
            }
        }
        let median_or_nan = |v: &mut Vec<f64>| if v.is_empty() { f64::NAN } else { median(v) };
        Rise {
            over_step: median_or_nan(&mut over_step),
            over_full: median_or_nan(&mut over_full),
        }
    }

    /// The evidence score of a rim pass (the canopy's outer rim band beyond
    /// its inlier edges), and the candidate when it is good enough.
    pub(super) fn score(&mut self, image: &GrayImage, pass: RimPass) -> Result<Verified, Reject> {
        let RimPass {
            ellipse,
            centre,
            points_px,
            pose_edges,
            residuals,
            inliers,
            step_widths_px,
            clipped_share,
            widened: _,
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
        let sharp_width = (SHARP_STEP_OWN_PX + SHARP_STEP_RADII * ellipse.b).max(SHARP_STEP_PX);
        let sharp = widths.iter().filter(|w| w.1 <= sharp_width).count();
        if (sharp as f64) < MIN_SHARP_SHARE * widths.len() as f64 {
            return Err(Reject::Soft(sharp as f64 / widths.len().max(1) as f64));
        }
        // A dark shape inside a larger one (the probe's tip in the disc, a
        // darker patch of it) has the larger one's dark just outside its
        // rim and the canopy beyond: the disc has the canopy itself there.
        let rise = self.rise_beyond(image, &ellipse, &widths, &mids, rim_contrast);
        if rise.nested() {
            return Err(Reject::Nested(rise.over_step));
        }
        let edge = canopy::RimEdge {
            min_step_gray: (0.1 * rim_contrast).max(0.5 * self.cfg.min_contrast_gray) as f32,
            noise_gray: self.noise_gray as f32,
            widths: &widths,
            mids: &mids,
            contrast_gray: rim_contrast as f32,
        };
        // Where the canopy is required, a share below the least needed is
        // all that must be known of a candidate without one.
        let canopy_required = ellipse.a >= self.cfg.canopy_required_from_px;
        let canopy = canopy::ring_support(
            image,
            &self.camera,
            &ellipse,
            self.drogue,
            edge,
            canopy_required.then_some(self.cfg.min_canopy_fraction),
            &mut self.profile,
            &mut self.scratch,
        );
        if let Some(seen) = canopy
            && canopy_required
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
            rise_over_step = rise.over_step,
            rise_over_full = rise.over_full,
            shape,
            fill,
            canopy = ?canopy,
            rim_contrast,
            points = points_px.len(),
            on_rim = inliers.len(),
            tolerance_px = tol,
            "evidence"
        );
        let w = self.cfg.canopy_weight.clamp(0.0, 1.0);
        let score = (shape * ((1.0 - w) + w * canopy.unwrap_or(0.0))).clamp(0.0, 1.0);
        if score < self.cfg.min_score {
            return Err(Reject::LowScore(score));
        }
        let measured = MeasuredRim::near(
            &self.camera,
            &ellipse,
            tol,
            &residuals,
            &points_px,
            pose_edges,
            step_widths_px,
        );
        Ok(Verified {
            ellipse,
            points_px: measured.points_px,
            undistorted: measured.undistorted,
            score,
            rim_contrast,
            step_widths_px: measured.step_widths_px,
            clip_px: measured.clip_px,
            canopy,
        })
    }
}

/// The points a pass gives the pose to be measured from, with their step
/// widths (distorted and undistorted pixels, aligned).
pub(super) struct MeasuredRim {
    pub(super) points_px: Vec<[f64; 2]>,
    pub(super) undistorted: Vec<[f64; 2]>,
    pub(super) step_widths_px: Vec<f64>,
    /// How far out from each point its step's light side reaches
    /// saturation, pixels (empty for a scouting pass's points, and where
    /// no step is clipped).
    pub(super) clip_px: Vec<f64>,
}

impl MeasuredRim {
    /// The points a pass gives the pose to be measured from (`pose_edges`
    /// placed: moved for the shading and undistorted; a scouting pass's own
    /// `points_px`), with their `step_widths_px`, whose edge lies near the
    /// pass's `ellipse` (`residuals`, its tolerance `tol`): the probe and
    /// hose outlines are the fit's outliers, and fewer of them is better.
    /// Only those near are undistorted.
    pub(super) fn near(
        camera: &CameraModel,
        ellipse: &Ellipse,
        tol: f64,
        residuals: &[f64],
        points_px: &[[f64; 2]],
        pose_edges: PoseEdges,
        step_widths_px: Vec<f64>,
    ) -> Self {
        let keep = (0.05 * ellipse.a).max(3.0 * tol);
        let mut kept: Vec<bool> = residuals.iter().map(|r| *r <= keep).collect();
        fn pick<T>(items: impl IntoIterator<Item = T>, kept: &[bool]) -> Vec<T> {
            items
                .into_iter()
                .zip(kept)
                .filter(|(_, k)| **k)
                .map(|(p, _)| p)
                .collect()
        }
        let (points_px, undistorted, clip_px) = match pose_edges {
            PoseEdges::Own(undistorted) => (
                pick(points_px.iter().copied(), &kept),
                pick(undistorted, &kept),
                Vec::new(),
            ),
            PoseEdges::Shaded {
                base_px,
                shading,
                found_undistorted,
                clip_px,
                within_dark,
            } => {
                // Steps onto a band within the dark (a probe's collar
                // across the disc) are not the rim's.
                for (k, &band) in kept.iter_mut().zip(&within_dark) {
                    *k &= !band;
                }
                // Only a sharp step has its two sides' slopes where they
                // were measured: a blurred one's lie in the blur's tails.
                let sharp: Vec<bool> = step_widths_px.iter().map(|&w| w <= SHARP_STEP_PX).collect();
                let canopy = canopy_slope(&shading);
                let mut beside = beside_dark(&shading, canopy, BESIDE_DARK_SIGMAS);
                for (b, s) in beside.iter_mut().zip(&sharp) {
                    *b &= *s;
                }
                if let Some(canopy) = canopy
                    && beside.iter().zip(&kept).any(|(b, k)| *b && *k)
                {
                    let mut kept_residuals: Vec<f64> = residuals
                        .iter()
                        .zip(&kept)
                        .zip(&beside)
                        .filter(|((_, k), b)| **k && !**b)
                        .map(|((r, _), _)| r.abs())
                        .collect();
                    let sigma_px = 1.4826 * median(&mut kept_residuals);
                    if better_without(
                        ellipse,
                        &found_undistorted,
                        &shading,
                        &kept,
                        &beside,
                        canopy,
                        sigma_px,
                    ) {
                        for (k, b) in kept.iter_mut().zip(&beside) {
                            *k &= !b;
                        }
                    }
                }
                // The shading's slope is the whole pass's: moved first,
                // then picked.
                let moved = pick(shaded_points(&base_px, &shading, canopy, &sharp), &kept);
                let undistorted = moved.iter().map(|&p| camera.undistort_px(p)).collect();
                // Most rims have no clipped step: nothing to carry.
                let clip_px = if clip_px.iter().any(|&c| c > 0.0) {
                    pick(clip_px, &kept)
                } else {
                    Vec::new()
                };
                (moved, undistorted, clip_px)
            }
        };
        Self {
            points_px,
            undistorted,
            step_widths_px: pick(step_widths_px, &kept),
            clip_px,
        }
    }
}

/// A measured edge whose light side falls faster than its dark side, by
/// more than this many of the noise's standard deviations of that
/// difference below the canopy's slope, has something dark just beyond it
/// ([`beside_dark`]).
const BESIDE_DARK_SIGMAS: f64 = 3.0;

/// How much lighter the canopy's band is than the ring just outside a rim
/// ([`Detector::rise_beyond`]), median over the rays; NaN where no ray
/// could be measured.
#[derive(Clone, Copy, Debug)]
struct Rise {
    /// In units of the rim's own step contrast.
    over_step: f64,
    /// In units of the full step from the disc's dark level to the band.
    over_full: f64,
}

impl Rise {
    /// A dark shape inside a larger one: the ring just outside is the
    /// larger shape's dark, so the band rises from it by more than the rim's
    /// own step allows ([`MAX_RISE_BEYOND`]) and by more than a throat's
    /// shadow takes from the canopy ([`MAX_SHADED_RISE`]).
    fn nested(self) -> bool {
        // An unmeasured full step (NaN) leaves the rim's step to decide.
        let shaded = self.over_full <= MAX_SHADED_RISE;
        self.over_step > MAX_RISE_BEYOND && !shaded
    }
}

#[cfg(test)]
mod tests {
    use super::glare_skirt;

    /// A glare's veil (above 180) and its skirt falling off on either side
    /// down to the mid level (90); the surface's dark and light beyond.
    #[test]
    fn the_skirt_falls_away_from_the_veil_on_either_side() {
        let (veil_from, mid) = (180.0, 90.0);
        let (t, f) = (true, false);
        let cases = [
            // Veil at the centre, skirt outward, then the disc's dark.
            ([250.0, 200.0, 120.0, 60.0, 40.0].map(Some), [t, t, t, f, f]),
            // Veil near the rim, skirt inward toward the centre.
            (
                [40.0, 100.0, 150.0, 230.0, 140.0].map(Some),
                [f, t, t, t, t],
            ),
            // A light sample lighter than the one before it is the
            // surface's again (a light inside), and so is everything past
            // a dark one.
            (
                [200.0, 120.0, 150.0, 70.0, 130.0].map(Some),
                [t, t, f, f, f],
            ),
            // No veil, no glare.
            (
                [Some(60.0), Some(170.0), Some(120.0), None, Some(100.0)],
                [f; 5],
            ),
            // An unread sample ends the skirt.
            (
                [Some(220.0), None, Some(120.0), Some(100.0), Some(95.0)],
                [t, f, f, f, f],
            ),
        ];
        for (samples, glare) in cases {
            assert_eq!(glare_skirt(&samples, veil_from, mid), glare, "{samples:?}");
        }
    }
}
