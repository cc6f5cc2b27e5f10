//! Detection of the drogue's dark inner circle: sub-pixel rim edge points.
//!
//! 1. `coarse`: dark connected regions of a decimated frame, at a few
//!    thresholds, give candidate centres and sizes (cheap, whole frame);
//!    `edges`, gradient voting, gives more when they find no clear drogue,
//!    and when none of those verifies, the circles around its own (the disc
//!    around the probe's tip) with their rims taken out (and, opt-in,
//!    `coarse::local`: regions dark against their own neighbourhood).
//! 2. `rim`: rays from a candidate centre at full resolution give one
//!    sub-pixel dark-to-light edge each; a quick robust ellipse fit
//!    (`conic_fit`) of them moves the centre onto the disc, and a second,
//!    narrow ray pass around that ellipse gives the rim points.
//! 3. Evidence ranks the candidates: the share of rays whose edge lies on one
//!    ellipse (shape), a plausible size and axis ratio (range, tilt), enough
//!    contrast, no larger dark shape around it (the canopy right past the
//!    rim), and the canopy's darker outer rim band beyond the edge.
//!
//! With a tracking hint only step 2's narrow pass runs, around the
//! predicted ellipse; the full search follows only when that fails.
//!
//! Files: `search` (both candidate sources, their seeds and the order they
//! are tried in), `verify` (the ray passes and fits of step 2), `evidence`
//! (step 3); this module holds the types and the entry points.

pub mod canopy;
mod coarse;
pub mod conic_fit;
mod edges;
mod evidence;
mod glare;
pub mod rim;
mod search;
mod shading;
#[cfg(test)]
mod tests;
mod verify;

use super::ellipse::{Ellipse, ExposureSweep};
use super::miss::{MissReason, NotDetected};
use super::stats::median;
use crate::camera::CameraModel;
use coarse::{Blob, BlobFinder, Decimated, LocalContrast};
use image::GrayImage;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use verify::{RimUse, VERIFY_SPACING_PX};

/// Detection tunables (`[detect]` in the config).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectConfig {
    /// Block size of the decimated image used for the coarse search.
    pub decimation: u32,
    /// Dark-region thresholds, as fractions of the way from the frame's
    /// darkest level to its median level.
    pub threshold_fractions: Vec<f64>,
    /// Most distinct dark regions (at the highest threshold; their parts at
    /// lower thresholds count with them) verified at full resolution per frame.
    pub max_candidates: u32,
    /// Range limits of the drogue, metres: they bound the disc's size in pixels.
    pub min_range_m: f64,
    /// Farthest range of the drogue, metres (bounds the smallest disc).
    pub max_range_m: f64,
    /// Smallest minor/major axis ratio accepted (cos of the largest tilt).
    pub min_axis_ratio: f64,
    /// Smallest dark-to-light step at the rim, gray levels.
    pub min_contrast_gray: f64,
    /// Spacing of the rim rays along the rim on the pass the pose is
    /// measured from after a full-frame search, pixels.
    pub rim_point_spacing_px: f64,
    /// The same on a tracked frame, which verifies and measures in one pass.
    pub tracked_rim_point_spacing_px: f64,
    /// Most rim points per frame.
    pub max_rim_points: u32,
    /// Most rim points on a tracked frame (searched near the predicted
    /// ellipse): fewer rays make the search and the fit cheaper.
    pub tracked_max_rim_points: u32,
    /// Half-width of the narrow rim search around a candidate ellipse, as a
    /// fraction of its radius, and at most this many pixels.
    pub rim_search_fraction: f64,
    /// Cap of that half-width, pixels.
    pub rim_search_max_px: f64,
    /// Fewest rim points on the ellipse for a detection.
    pub min_rim_points: u32,
    /// Edge distance from the candidate's ellipse counted as "on the rim", pixels.
    pub inlier_tolerance_px: f64,
    /// Weight of the canopy rim evidence in the score (0..1).
    pub canopy_weight: f64,
    /// Disc radius (pixels) from which the canopy rim must be seen where it
    /// can be judged: below it the rim is too thin to resolve.
    pub canopy_required_from_px: f64,
    /// Smallest share of the predicted canopy rim that shows its edge,
    /// when required.
    pub min_canopy_fraction: f64,
    /// A candidate this good ends the search (the rest are not verified).
    pub accept_score: f64,
    /// Smallest score (0..1) for a detection.
    pub min_score: f64,
    /// Smallest share of the ellipse's inside darker than the middle of
    /// the rim's step (a crescent or a ring has light inside).
    pub min_fill: f64,
    /// Seed of the random sampling (the detection is deterministic).
    pub seed: u64,
    /// Whether the local-contrast source runs when the dark regions and the
    /// edges gave no clear drogue and a glare saturates part of the frame
    /// (a disc on a canopy that a glare's glow saturated is darker than
    /// its neighbourhood only; see the README's "Detection").
    #[serde(default)]
    pub local_contrast_source: bool,
}

/// The best candidate of a frame.
#[derive(Clone, Debug)]
pub struct RimCandidate {
    /// Sub-pixel rim points, distorted image pixels (as in the frame).
    pub rim_points_px: Vec<[f64; 2]>,
    /// The same points undistorted (what the fit takes), pixels: the
    /// detector has them already.
    pub rim_points_undistorted_px: Vec<[f64; 2]>,
    /// Evidence 0..1 (dark inside, light canopy around, ellipse shape, size).
    pub score: f64,
    /// The detector's own quick ellipse of the rim, undistorted pixels: a
    /// starting point, not the measurement (that is the fit module's).
    pub ellipse_px: Ellipse,
    /// Width of each rim point's step (the blurred edge's ramp, pixels),
    /// aligned with `rim_points_px`: the pose covariance's systematic term
    /// (a blurred edge's mid-level crossing is only as sure as the levels
    /// on either side, which a ramp that wide mixes).
    pub rim_step_widths_px: Vec<f64>,
    /// How far out from each rim point its step's light side reaches
    /// saturation, distorted pixels along the point's ray (as
    /// `rim_step_widths_px`), aligned with `rim_points_px` (0 below
    /// saturation; empty when no step is clipped or it was not measured):
    /// a step into a canopy that a glare's glow lifted past 255 has its mid
    /// level taken from the clipped level, and its point lies up to this
    /// much short of the edge (the pose covariance's third systematic
    /// term).
    pub rim_clip_px: Vec<f64>,
}

/// The width a sharp rim step measures (the step's ends as the rim pass
/// finds them, the smoothing's spread taken out): the median over sharp
/// frames' steps is 2.6 px on the simulator (seed 15: baseline, haze,
/// noise, throat shadow levels) and 2.65-2.75 px on the other renderer's
/// `paper10`, `tilt`, `range` and `noise` sets. Without it the share of a
/// blurred rim's steps counted sharp fell to nothing at a blur of twice
/// the 4 px floor (a 16 px minor radius blurred 7 px: 1 of 71 steps).
const SHARP_STEP_OWN_PX: f64 = 2.6;

/// The narrow pass's profiles are smoothed so that their samples' noise
/// stays near this many gray levels: the kernel's length grows with the
/// noise's variance (see [`smoothing_half`]).
const SMOOTHED_NOISE_GRAY: f64 = 3.0;
/// The longest smoothing, half-width in samples: a kernel of at most
/// +-2 px, narrower than the narrowest rim window (+-4 px).
const MAX_SMOOTH_HALF: usize = 2;
/// Sample spacing of the narrow pass's profiles, pixels.
const NARROW_STEP_PX: f64 = 0.5;

/// Rows apart of the rows the frame's noise is measured on
/// ([`rim::noise_sigma`]): every 16th row (about 77 000 second differences
/// of a 1280x960 frame) before a full-frame search, whose smoothing decides
/// what is found on an unknown frame; every 64th (about 19 000) on a
/// tracked frame, which only re-measures a known rim and where the noise
/// estimate was a third of the work. The estimate is the median's integer
/// bin (steps of 0.6 gray levels): on the 165 readable reference frames
/// the two strides agree on all but 6, by one step.
const NOISE_ROW_STRIDE: usize = 16;
const TRACKED_NOISE_ROW_STRIDE: usize = 64;

/// Tracked frames re-measure the noise on every this many frames and keep
/// the last estimate in between (at most 0.1 s old at 30 Hz): the sensor's
/// noise follows its gain, which auto-exposure moves over seconds, not
/// from one frame to the next, and the estimate was an eighth of a tracked
/// frame's work. A full-frame search always measures it afresh.
const TRACKED_NOISE_EVERY: u32 = 4;

/// Half-width (samples) of the narrow pass's smoothing for image noise
/// `sigma` (gray levels): a box of `m = 2 h + 1` samples applied twice
/// averages about `m` samples, so `m = (sigma / SMOOTHED_NOISE_GRAY)^2`.
fn smoothing_half(sigma: f64) -> usize {
    let m = (sigma / SMOOTHED_NOISE_GRAY).powi(2);
    (((m - 1.0) / 2.0).max(0.0).round() as usize).min(MAX_SMOOTH_HALF)
}

/// The noise, as a share of a step's contrast, that a profile is smoothed
/// down to: 3 gray levels ([`SMOOTHED_NOISE_GRAY`]) on a step of 100. On
/// a faint step (haze, low exposure: 30 gray levels) the same 3 gray levels
/// decide where a blurred ramp starts and ends, so its levels are taken
/// inside the ramp and its crossing moves along the blur.
const SMOOTHED_NOISE_SHARE: f64 = 0.03;

/// The longest smoothing of a blurred ramp, half-width in samples (+-4 px).
const MAX_RAMP_SMOOTH_HALF: usize = 8;
/// The rise along a ramp is found where it stays above a fifth of its peak
/// ([`rim::strongest_rise`]); a dip below that inside the ramp is a noise
/// excursion of 0.8 of the ramp's rise per pixel, made rare (3 sigma) when
/// the noise of the rise (`sqrt 2` times the smoothed samples' noise) is at
/// most this share of it.
const RAMP_RISE_NOISE_SHARE: f64 = 0.8 / 3.0;

/// The smoothing (half-width, samples) that keeps a ramp of `width_px` and
/// `contrast` gray levels in noise `sigma` from ending inside itself: its
/// rise per pixel is `contrast / width_px`, and the smoothed samples' noise
/// must be `RAMP_RISE_NOISE_SHARE / sqrt 2` of that. A sharp step asks for
/// none (the frame's noise smoothing covers it); at most
/// [`MAX_RAMP_SMOOTH_HALF`].
fn smoothing_half_for_ramp(sigma: f64, contrast: f64, width_px: f64) -> usize {
    if !(contrast > 0.0 && width_px > 0.0 && sigma > 0.0) {
        return 0;
    }
    let target = RAMP_RISE_NOISE_SHARE / std::f64::consts::SQRT_2 * contrast / width_px;
    let m = (sigma / target).powi(2);
    (((m - 1.0) / 2.0).max(0.0).round() as usize).min(MAX_RAMP_SMOOTH_HALF)
}

/// [`smoothing_half`] for a step of `contrast` gray levels: the kernel that
/// brings the noise to [`SMOOTHED_NOISE_SHARE`] of the contrast.
fn smoothing_half_for_contrast(sigma: f64, contrast: f64) -> usize {
    if contrast.is_nan() || contrast <= 0.0 {
        return 0;
    }
    smoothing_half(sigma * SMOOTHED_NOISE_GRAY / (SMOOTHED_NOISE_SHARE * contrast))
}

/// Gray level from which a sample counts as saturated (glare): it says
/// nothing about the surface under it.
const SATURATED_LEVEL: u8 = 250;
/// The same level, for interpolated samples.
const SATURATED_GRAY: f32 = SATURATED_LEVEL as f32;

/// Noise sigmas above a rim step's light side at which a level is a
/// glare's veil (lighter than any surface beside the disc), not the
/// background seen through a hole: the fill test's margin, and a light
/// bar's least.
const VEIL_SIGMAS: f32 = 3.0;
/// Gray levels added to that margin (quantisation, a sharp frame's noise).
const VEIL_MIN_GRAY: f32 = 2.0;

/// A verified candidate.
struct Verified {
    ellipse: Ellipse,
    points_px: Vec<[f64; 2]>,
    undistorted: Vec<[f64; 2]>,
    score: f64,
    /// Median gray-level step across the rim.
    rim_contrast: f64,
    /// Step width of each of `points_px`, pixels.
    step_widths_px: Vec<f64>,
    /// How far out from each of `points_px` its step's light side reaches
    /// saturation, distorted pixels along its ray (empty when not measured
    /// or none is clipped).
    clip_px: Vec<f64>,
    /// The canopy evidence: the share of its predicted rim that shows it
    /// (`None`: not judged, the rim off the frame or too small).
    canopy: Option<f64>,
}

/// Why a candidate was not kept: shown by `RUST_LOG=debug` (the
/// `drogue_vision::measure::detect` target), one line per candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Reject {
    /// The first (wide) pass found an edge on fewer than 8 of its rays:
    /// nothing round to fit around the seed (a vignetted corner, a cloud's
    /// soft shadow).
    NoRim(usize),
    /// Fewer rays than needed found an edge on the narrow pass.
    FewEdges(usize),
    /// Most of the narrow pass's rays leave the image.
    OutOfImage,
    /// No ellipse through the edges.
    NoEllipse,
    /// The ellipse's size or axis ratio is not the disc's at any allowed
    /// range and tilt.
    Implausible,
    /// Too few edges on the ellipse.
    FewInliers(usize),
    /// The rim's median step is below `min_contrast_gray`.
    LowContrast(f64),
    /// Too little of the ellipse's inside is darker than the middle of
    /// the rim's step (share of the inside samples that are).
    LightInside(f64),
    /// The canopy band is missing around a disc large enough to show it
    /// (share of rays that show it).
    NoCanopy(f64),
    /// The ring just outside the rim is darker than the canopy's band
    /// beyond it by more than `evidence::MAX_RISE_BEYOND` of the rim's
    /// contrast (that rise) and by more than a throat's shadow takes
    /// (`evidence::MAX_SHADED_RISE` of the full step from the disc): a dark
    /// shape inside a larger one, such as the probe's tip inside the disc.
    Nested(f64),
    /// The evidence score is below `min_score`.
    LowScore(f64),
    /// More than [`verify::CLIPPED_SHARE`] of the rim's steps run into the ends of
    /// the widest window (share that do): blurred beyond what can be
    /// measured.
    Blurred(f64),
    /// Too few of the rim's steps are sharp (share that are): a blob out
    /// of focus.
    Soft(f64),
    /// The narrow passes did not settle.
    Unsettled,
    /// The seed's first fit or settled pass is the rim of a candidate
    /// already verified, or that candidate's canopy rim; or the seed lies
    /// inside the canopy of a candidate verified with its canopy shown
    /// beyond doubt (not verified at all).
    Known,
    /// A full-frame candidate whose minor semi-axis (undistorted pixels) is below
    /// [`canopy::smallest_judged_radius_px`]: too thin for its canopy rim
    /// to be judged along that axis, it rests on its darkness alone.
    TooSmall(f64),
}

impl Reject {
    /// How far through verification a candidate got before this stopped it
    /// (the checks' order: the rim pass, then the evidence), and what it
    /// tells a user; `None` for a candidate already verified in another
    /// form ([`Reject::Known`]), which says nothing of the frame.
    fn as_miss(self) -> Option<(u8, MissReason)> {
        Some(match self {
            Reject::Known => return None,
            Reject::NoRim(_) | Reject::OutOfImage => (0, MissReason::NoRim),
            Reject::FewEdges(_) | Reject::NoEllipse | Reject::Unsettled => (1, MissReason::NoRim),
            Reject::Implausible => (2, MissReason::Implausible),
            Reject::FewInliers(n) => (3, MissReason::FewRimPoints(n)),
            Reject::LowContrast(c) => (4, MissReason::LowContrast(c)),
            Reject::LightInside(f) => (5, MissReason::LightInside(f)),
            Reject::Blurred(s) => (6, MissReason::Blurred(s)),
            Reject::Soft(s) => (7, MissReason::Soft(s)),
            Reject::Nested(r) => (8, MissReason::Nested(r)),
            Reject::NoCanopy(s) => (9, MissReason::NoCanopy(s)),
            Reject::LowScore(s) => (10, MissReason::LowScore(s)),
            Reject::TooSmall(px) => (11, MissReason::TooSmall(px)),
        })
    }
}

/// The candidates a full-frame search rejected: how many, and the one that
/// got furthest (the first of those, in the order tried), which is the
/// frame's reason when nothing verifies.
#[derive(Clone, Debug, Default)]
struct Misses {
    candidates: u32,
    closest: Option<(u8, MissReason)>,
}

impl Misses {
    /// One candidate's outcome.
    fn tried(&mut self, outcome: Result<(), Reject>) {
        self.candidates += 1;
        if let Err(why) = outcome
            && let Some((rank, reason)) = why.as_miss()
            && self.closest.as_ref().is_none_or(|(r, _)| rank > *r)
        {
            self.closest = Some((rank, reason));
        }
    }

    /// The frame's reason when no candidate was kept.
    fn reason(&self) -> MissReason {
        self.closest
            .as_ref()
            .map_or(MissReason::NoCandidate, |(_, r)| r.clone())
    }
}

/// Finds the dark inner circle. Holds scratch buffers between frames.
#[derive(Clone)]
pub struct Detector {
    cfg: DetectConfig,
    camera: CameraModel,
    /// The drogue's circles, for the canopy rim its pose predicts.
    drogue: canopy::DrogueCircles,
    /// Disc radius limits in pixels, from the range limits.
    min_radius_px: f64,
    max_radius_px: f64,
    decimated: Decimated,
    finder: BlobFinder,
    blobs: Vec<Blob>,
    voter: edges::EdgeVoter,
    /// The local-contrast source's dark masks and their labelling (apart
    /// from `finder`'s, whose label images a frame reuses).
    local: LocalContrast,
    local_finder: BlobFinder,
    profile: Vec<f32>,
    scratch: Vec<f32>,
    /// The narrow pass's profile before smoothing.
    raw_profile: Vec<f32>,
    /// Half-width (samples) of the narrow pass's profile smoothing, from
    /// this frame's noise.
    smooth_half: usize,
    /// The frame's noise, gray levels ([`rim::noise_sigma`]).
    noise_gray: f64,
    /// Frames measured with `noise_gray` since it was measured (0: never).
    noise_age: u32,
    /// [`rim::smoothing_spread_px`] for each half-width up to
    /// [`MAX_SMOOTH_HALF`].
    smoothing_spread_px: Vec<f64>,
    /// This frame's rejected candidates (the full-frame search's).
    misses: Misses,
}

/// The angle between directions `a` and `b` (radians, each within a turn
/// of zero, as `atan2` and ray angles are, so that they differ by less than
/// two turns), 0..=pi: without the `fmod` of `rem_euclid`, which showed in
/// profiles of the canopy and fill tests (a nearest-angle lookup per
/// sample).
fn angle_gap(a: f64, b: f64) -> f64 {
    let mut d = (a - b).abs();
    if d > TAU {
        d -= TAU;
    }
    d.min(TAU - d)
}

/// Radius of an ellipse (centred at the origin) in direction `phi`.
fn polar_radius(a: f64, b: f64, theta: f64, phi: f64) -> f64 {
    let (s, c) = (phi - theta).sin_cos();
    polar_radius_local(a, b, c, s)
}

/// [`polar_radius`] from the cosine and sine of the direction's angle to
/// the major axis.
fn polar_radius_local(a: f64, b: f64, cos: f64, sin: f64) -> f64 {
    let inv2 = (cos / a).powi(2) + (sin / b).powi(2);
    1.0 / inv2.sqrt()
}

/// Unit directions at angles `2 pi k / n`, k = 0..n, by rotating the last
/// one (rounding grows by ~1e-16 a step: ~1e-14 after 400 rays), not by a
/// sine and cosine each.
fn ray_directions(n: usize) -> impl Iterator<Item = [f64; 2]> {
    let (s, c) = (TAU / n.max(1) as f64).sin_cos();
    std::iter::successors(Some([1.0, 0.0]), move |[x, y]: &[f64; 2]| {
        Some([x * c - y * s, x * s + y * c])
    })
    .take(n)
}

impl Detector {
    /// A detector for frames of `camera` and a drogue of these radii.
    pub fn new(cfg: &DetectConfig, camera: &CameraModel, drogue: canopy::DrogueCircles) -> Self {
        let inner_radius_m = drogue.inner_radius_m;
        let f = camera.fx().max(camera.fy());
        let min_range = cfg.min_range_m.max(1e-3);
        let max_range = cfg.max_range_m.max(min_range);
        Self {
            cfg: cfg.clone(),
            camera: camera.clone(),
            drogue,
            min_radius_px: f * inner_radius_m / max_range,
            max_radius_px: f * inner_radius_m / min_range,
            decimated: Decimated::default(),
            finder: BlobFinder::default(),
            blobs: Vec::new(),
            voter: edges::EdgeVoter::default(),
            local: LocalContrast::default(),
            local_finder: BlobFinder::default(),
            profile: Vec::new(),
            scratch: Vec::new(),
            raw_profile: Vec::new(),
            smooth_half: 0,
            noise_gray: 0.0,
            noise_age: 0,
            smoothing_spread_px: (0..=MAX_SMOOTH_HALF.max(MAX_RAMP_SMOOTH_HALF))
                .map(|h| rim::smoothing_spread_px(h, NARROW_STEP_PX))
                .collect(),
            misses: Misses::default(),
        }
    }

    /// The best candidate, or `None` when the frame shows no drogue.
    /// `hint`: the tracker's predicted ellipse (undistorted pixels); search near
    /// it first, and the full frame when it is not found there.
    pub fn detect(&mut self, image: &GrayImage, hint: Option<&Ellipse>) -> Option<RimCandidate> {
        self.detect_explained(image, hint).ok()
    }

    /// Candidates the last [`Self::detect`]'s full-frame search verified
    /// (0 when the frame was found at its tracked ellipse).
    pub fn candidates_tried(&self) -> u32 {
        self.misses.candidates
    }

    /// [`Self::detect`], with the reason when the frame shows no drogue:
    /// that of the candidate that got furthest through verification
    /// ([`MissReason`]), and how many were tried.
    pub fn detect_explained(
        &mut self,
        image: &GrayImage,
        hint: Option<&Ellipse>,
    ) -> Result<RimCandidate, NotDetected> {
        self.detect_moving(image, hint, None)
    }

    /// [`Self::detect_explained`], with the rim's motion during the
    /// exposure that the track predicts (`sweep`, undistorted pixels): the
    /// tracked pass then starts with the window that motion's blur needs.
    pub fn detect_moving(
        &mut self,
        image: &GrayImage,
        hint: Option<&Ellipse>,
        sweep: Option<&ExposureSweep>,
    ) -> Result<RimCandidate, NotDetected> {
        self.misses = Misses::default();
        let miss = |misses: &Misses| NotDetected {
            reason: misses.reason(),
            candidates: misses.candidates,
        };
        if image.width() < 8 || image.height() < 8 {
            return Err(miss(&self.misses));
        }
        if let Some(h) = hint.filter(|h| h.a.is_finite() && h.b > 0.5 && h.a < 1e5) {
            if self.noise_age == 0 || self.noise_age >= TRACKED_NOISE_EVERY {
                self.measure_noise(image, TRACKED_NOISE_ROW_STRIDE);
            } else {
                self.noise_age += 1;
            }
            match self.verify_tracked(image, h, sweep) {
                Ok(v) => return Ok(v.into_candidate()),
                Err(why) => tracing::debug!(?why, "not at the tracked ellipse: full search"),
            }
        }
        self.measure_noise(image, NOISE_ROW_STRIDE);
        match self.search_full(image) {
            Ok(v) => Ok(v.into_candidate()),
            Err(reason) => Err(NotDetected {
                reason,
                candidates: self.misses.candidates,
            }),
        }
    }

    /// Every candidate that the full-frame search verifies, with its
    /// evidence score, as if no score ended the search early: the sparse
    /// rim's ellipse (undistorted pixels) and score. For calibrating
    /// `accept_score` and `min_score` on simulated frames
    /// (`examples/calibrate_scores.rs`); the detection itself is
    /// [`Self::detect`].
    pub fn scored_candidates(&mut self, image: &GrayImage) -> Vec<(Ellipse, f64)> {
        if image.width() < 8 || image.height() < 8 {
            return Vec::new();
        }
        self.measure_noise(image, NOISE_ROW_STRIDE);
        self.verify_candidates(image, f64::INFINITY)
            .into_iter()
            .map(|v| (v.ellipse, v.score))
            .collect()
    }

    /// The frame's noise, which sets the rim profiles' smoothing.
    fn measure_noise(&mut self, image: &GrayImage, row_stride: usize) {
        let noise = rim::noise_sigma(image, row_stride);
        self.smooth_half = smoothing_half(noise);
        self.noise_gray = noise;
        self.noise_age = 1;
        tracing::debug!(noise, smooth_half = self.smooth_half, "frame noise");
    }

    /// Coarse search over the whole frame, then verification of the best
    /// coarse candidates; the frame's reason when none is kept.
    fn search_full(&mut self, image: &GrayImage) -> Result<Verified, MissReason> {
        let mut verified = self.verify_candidates(image, self.cfg.accept_score);
        // The best candidate that passes again at the full density of rim
        // points: a candidate that passed on the sparse rim only by the
        // luck of where its rays fell is not the drogue.
        verified.sort_by(|x, y| y.score.total_cmp(&x.score));
        let measure_spacing = self.cfg.rim_point_spacing_px;
        let verify_spacing = VERIFY_SPACING_PX.max(measure_spacing);
        let max_points = self.cfg.max_rim_points;
        // Why the best candidate failed the full density, if all did.
        let mut first_failure: Option<Reject> = None;
        let found = verified.into_iter().find_map(|scouted| {
            match self.verify_settled(
                image,
                &scouted.ellipse,
                verify_spacing,
                max_points,
                RimUse::Measure,
            ) {
                Ok(full) => Some(full),
                Err(why) => {
                    // The settling passes can walk off a blurred or
                    // occluded disc onto the probe's or a streak's edges
                    // (or run into the widest window by the luck of where
                    // their rays fall). One full-density pass where the
                    // sparse rim settled still holds the candidate when its
                    // canopy shows beyond the doubt of its reading.
                    let once =
                        self.verify_unsettled(image, &scouted.ellipse, verify_spacing, max_points);
                    let held = once.ok().filter(|v| {
                        v.canopy.is_some_and(|c| {
                            canopy::shown_beyond_doubt(c, self.cfg.min_canopy_fraction)
                        })
                    });
                    tracing::debug!(
                        centre_px = ?[scouted.ellipse.cx.round(), scouted.ellipse.cy.round()],
                        ?why,
                        held_by_one_pass = held.is_some(),
                        "the full-density rim pass failed"
                    );
                    if held.is_none() {
                        first_failure.get_or_insert(why);
                    }
                    held
                }
            }
        });
        let Some(found) = found else {
            // A candidate that verified got further than any rejected one.
            return Err(match first_failure.and_then(Reject::as_miss) {
                Some((_, why)) => MissReason::NotAtFullDensity(Box::new(why)),
                None => self.misses.reason(),
            });
        };
        if measure_spacing >= verify_spacing {
            return Ok(found);
        }
        Ok(self.measured_densely(image, found, measure_spacing, max_points))
    }

    /// `found` with its points taken again on rays `spacing_px` apart (one
    /// narrow pass about its ellipse, placed as the verifying pass places
    /// them); `found` as it was when that pass fails its checks.
    fn measured_densely(
        &mut self,
        image: &GrayImage,
        found: Verified,
        spacing_px: f64,
        max_points: u32,
    ) -> Verified {
        match self.rim_pass(
            image,
            &found.ellipse,
            spacing_px,
            max_points,
            RimUse::Measure,
            1.0,
        ) {
            Ok(pass) => {
                let measured = evidence::MeasuredRim::near(
                    &self.camera,
                    &pass.ellipse,
                    pass.tolerance,
                    &pass.residuals,
                    &pass.points_px,
                    pass.pose_edges,
                    pass.step_widths_px,
                );
                Verified {
                    points_px: measured.points_px,
                    undistorted: measured.undistorted,
                    step_widths_px: measured.step_widths_px,
                    clip_px: measured.clip_px,
                    ..found
                }
            }
            Err(why) => {
                tracing::debug!(
                    ?why,
                    "the dense measuring pass failed: the verifying pass's points kept"
                );
                found
            }
        }
    }
}

impl Verified {
    fn into_candidate(self) -> RimCandidate {
        RimCandidate {
            rim_points_px: self.points_px,
            rim_points_undistorted_px: self.undistorted,
            score: self.score,
            ellipse_px: self.ellipse,
            rim_step_widths_px: self.step_widths_px,
            rim_clip_px: self.clip_px,
        }
    }
}
