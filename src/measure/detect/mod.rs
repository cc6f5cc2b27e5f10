//! Detection of the drogue's dark inner circle: sub-pixel rim edge points.
//!
//! 1. `coarse`: dark connected regions of a decimated frame, at a few
//!    thresholds, give candidate centres and sizes (cheap, whole frame).
//! 2. `rim`: rays from a candidate centre at full resolution give one
//!    sub-pixel dark-to-light edge each; a quick robust ellipse fit
//!    (`conic_fit`) of them moves the centre onto the disc, and a second,
//!    narrow ray pass around that ellipse gives the rim points.
//! 3. Evidence ranks the candidates: the share of rays whose edge lies on one
//!    ellipse (shape), a plausible size and axis ratio (range, tilt), enough
//!    contrast, and the canopy's darker outer rim band beyond the edge.
//!
//! With a tracking hint only step 2's narrow pass runs, around the
//! predicted ellipse; the full search follows only when that fails.

pub mod canopy;
mod coarse;
pub mod conic_fit;
mod edges;
pub mod rim;
#[cfg(test)]
mod tests;

use super::ellipse::Ellipse;
use crate::camera::CameraModel;
use coarse::{Blob, BlobFinder, Decimated};
use image::GrayImage;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

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
    /// Spacing of the rim rays along the rim, pixels.
    pub rim_point_spacing_px: f64,
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
}

/// Rim ray spacing while candidates are compared, in multiples of the
/// configured spacing.
const SCOUT_SPACING_FACTOR: f64 = 3.0;

/// Narrow-pass windows are widened by this factor while more than
/// [`CLIPPED_SHARE`] of the steps run into their ends (blur), up to
/// [`MAX_WIDEN`] times, and at most to [`MAX_WIDE_MARGIN_RADII`] of the
/// radius and [`MAX_WIDE_MARGIN_PX`] pixels each way (32 px of motion blur
/// is a 32 px ramp).
const WIDEN_STEP: f64 = 2.5;
const MAX_WIDEN: f64 = 6.25;
const CLIPPED_SHARE: f64 = 0.25;
const MAX_WIDE_MARGIN_RADII: f64 = 0.6;
const MAX_WIDE_MARGIN_PX: f64 = 48.0;

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

/// Edges within this many of their robust scatter (and at least
/// `inlier_tolerance_px`) of the ellipse are on the rim.
const NOISE_TOLERANCE_SIGMAS: f64 = 3.0;

/// The narrow pass's profiles are smoothed so that their samples' noise
/// stays near this many gray levels: the kernel's length grows with the
/// noise's variance (see [`smoothing_half`]).
const SMOOTHED_NOISE_GRAY: f64 = 3.0;
/// The longest smoothing, half-width in samples: a kernel of at most
/// +-2 px, narrower than the narrowest rim window (+-4 px).
const MAX_SMOOTH_HALF: usize = 2;
/// Sample spacing of the narrow pass's profiles, pixels.
const NARROW_STEP_PX: f64 = 0.5;
/// Wide-pass reach of seeds whose radius is not a rim's (the deepest
/// point's inscribed circle, the point ringed by light, an edge-voting
/// peak, whose radius comes from whatever edges voted for it), in their
/// radii.
const UNSURE_SEED_REACH: f64 = 5.0;

/// Half-width (samples) of the narrow pass's smoothing for image noise
/// `sigma` (gray levels): a box of `m = 2 h + 1` samples applied twice
/// averages about `m` samples, so `m = (sigma / SMOOTHED_NOISE_GRAY)^2`.
fn smoothing_half(sigma: f64) -> usize {
    let m = (sigma / SMOOTHED_NOISE_GRAY).powi(2);
    (((m - 1.0) / 2.0).max(0.0).round() as usize).min(MAX_SMOOTH_HALF)
}

/// An inner disc (see [`Detector::prefer_inner_disc`]) is within this share
/// of `r / R` of its outer ellipse's size, its centre within this many of
/// its radii of the outer's, and its rim step at least this share of the
/// outer's.
const INNER_SIZE_TOLERANCE: f64 = 0.25;
const INNER_OFFSET_RADII: f64 = 0.3;
const INNER_CONTRAST_SHARE: f64 = 0.5;
/// The inner disc's rays reach this share of the outer ellipse's radius.
const INNER_REACH_OUTER_RADII: f64 = 0.8;
/// Random stream of an inner-disc seed, apart from its outer seed's.
const INNER_SEED_STREAM: u64 = 0x1_0000;

/// Circles of the edge source verified per frame, strongest first.
const EDGE_SEEDS: usize = 4;

/// Share of the inside that must be dark when the canopy cannot be judged
/// (`min_fill` applies otherwise): a disc is dark all over, up to a glare
/// skirt or a highlight on the probe over a fifth of it.
const UNJUDGED_MIN_FILL: f64 = 0.8;

/// Rays and radius fractions of the fill test (inside the ellipse).
const FILL_DIRECTIONS: usize = 24;
const FILL_FRACTIONS: [f64; 5] = [0.1, 0.3, 0.5, 0.7, 0.85];

/// Gray level from which a sample counts as saturated (glare): it says
/// nothing about the surface under it.
const SATURATED_GRAY: f32 = 250.0;

/// Samples per seed radius on the rays of a seed's wide first pass.
const WIDE_STEPS_PER_RADIUS: f64 = 40.0;

/// Where and how large a coarse candidate is, full-res distorted pixels.
#[derive(Clone, Debug)]
struct Seed {
    centre_px: [f64; 2],
    a_px: f64,
    b_px: f64,
    theta: f64,
    /// How far the first ray pass looks, in multiples of the seed's radius.
    reach: f64,
    /// Which point of its blob: 0 the centroid, 1 the deepest point, 2 the
    /// point best ringed by light; 3 a circle of the edge source; 4 the
    /// disc looked for inside a verified ellipse (see
    /// [`Detector::prefer_inner_disc`]).
    kind: u8,
}

impl Seed {
    /// Nearly the same seed: centres within a tenth of the smaller radius,
    /// axes within 10 %, the same reach, and (unless both are near-circles)
    /// the same orientation within 0.1 rad.
    fn same_as(&self, other: &Seed) -> bool {
        let close = |x: f64, y: f64| (x / y - 1.0).abs() <= 0.1;
        let r = self.b_px.min(other.b_px);
        let d =
            (self.centre_px[0] - other.centre_px[0]).hypot(self.centre_px[1] - other.centre_px[1]);
        let round = |s: &Seed| s.a_px <= 1.1 * s.b_px;
        let dtheta = (self.theta - other.theta).rem_euclid(std::f64::consts::PI);
        let aligned = dtheta.min(std::f64::consts::PI - dtheta) <= 0.1;
        self.reach == other.reach
            && d <= 0.1 * r
            && close(self.a_px, other.a_px)
            && close(self.b_px, other.b_px)
            && ((round(self) && round(other)) || aligned)
    }
}

/// One narrow rim pass around an ellipse, before its canopy evidence.
struct RimPass {
    ellipse: Ellipse,
    /// The rays' origin, distorted pixels.
    centre: [f64; 2],
    points_px: Vec<[f64; 2]>,
    /// The same points, undistorted.
    undistorted: Vec<[f64; 2]>,
    residuals: Vec<f64>,
    inliers: Vec<usize>,
    /// Width of each point's step (twice its edge-to-light distance),
    /// pixels: wide along a motion blur.
    step_widths_px: Vec<f64>,
    /// Share of the edges whose step still runs into its window's ends
    /// after the widest window: a blur longer than can be measured.
    clipped_share: f64,
    rim_contrast: f64,
    /// Share of the rays in the image with their edge on the ellipse.
    shape: f64,
    /// Share of the inside darker than the rim's mid level.
    fill: f64,
    /// Distance from the ellipse counted as on the rim, pixels.
    tolerance: f64,
    /// The rim's mid level by direction (angle about the ellipse's centre,
    /// gray level), for the canopy test.
    mids: Vec<(f64, f32)>,
}

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
}

/// Why a candidate was not kept: shown by `RUST_LOG=debug` (the
/// `drogue_vision::measure::detect` target), one line per candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Reject {
    /// Fewer rays than needed found an edge (wide pass or narrow pass).
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
    /// The evidence score is below `min_score`.
    LowScore(f64),
    /// More than [`CLIPPED_SHARE`] of the rim's steps run into the ends of
    /// the widest window (share that do): blurred beyond what can be
    /// measured.
    Blurred(f64),
    /// Too few of the rim's steps are sharp (share that are): a blob out
    /// of focus.
    Soft(f64),
    /// The narrow passes did not settle.
    Unsettled,
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
    profile: Vec<f32>,
    scratch: Vec<f32>,
    /// The narrow pass's profile before smoothing.
    raw_profile: Vec<f32>,
    /// Half-width (samples) of the narrow pass's profile smoothing, from
    /// this frame's noise.
    smooth_half: usize,
    /// [`rim::smoothing_spread_px`] for each half-width up to
    /// [`MAX_SMOOTH_HALF`].
    smoothing_spread_px: Vec<f64>,
}

/// Whether the light side of step `e` (from its crossing to a few samples
/// past its light end) on profile `p` (sampled from `s_min` every `step`)
/// reaches saturation.
fn glare_on_light_side(p: &[f32], s_min: f64, step: f64, e: &rim::RayEdge) -> bool {
    let Some(last) = p.len().checked_sub(1) else {
        return false;
    };
    let index = |s: f64| (((s - s_min) / step).max(0.0) as usize).min(last);
    let (from, to) = (index(e.s), (index(e.light_s) + 2).min(last));
    p[from..=to].iter().any(|&v| v >= SATURATED_GRAY)
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

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
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
            profile: Vec::new(),
            scratch: Vec::new(),
            raw_profile: Vec::new(),
            smooth_half: 0,
            smoothing_spread_px: (0..=MAX_SMOOTH_HALF)
                .map(|h| rim::smoothing_spread_px(h, NARROW_STEP_PX))
                .collect(),
        }
    }

    /// The best candidate, or `None` when the frame shows no drogue.
    /// `hint`: the tracker's predicted ellipse (undistorted pixels); search near
    /// it first, and the full frame when it is not found there.
    pub fn detect(&mut self, image: &GrayImage, hint: Option<&Ellipse>) -> Option<RimCandidate> {
        if image.width() < 8 || image.height() < 8 {
            return None;
        }
        let noise = rim::noise_sigma(image);
        self.smooth_half = smoothing_half(noise);
        tracing::debug!(noise, smooth_half = self.smooth_half, "frame noise");
        if let Some(h) = hint.filter(|h| h.a.is_finite() && h.b > 0.5 && h.a < 1e5) {
            match self.verify_settled(
                image,
                h,
                self.cfg.rim_point_spacing_px,
                self.cfg.tracked_max_rim_points,
            ) {
                Ok(v) => return Some(v.into_candidate()),
                Err(why) => tracing::debug!(?why, "not at the tracked ellipse: full search"),
            }
        }
        self.search_full(image).map(Verified::into_candidate)
    }

    /// Coarse search over the whole frame, then verification of the best
    /// coarse candidates.
    fn search_full(&mut self, image: &GrayImage) -> Option<Verified> {
        self.decimated
            .update(image, self.cfg.decimation.clamp(1, 16) as usize);
        let f = self.decimated.factor as f64;
        // Smallest disc: a third of its area must make dark blocks.
        let min_area = ((std::f64::consts::PI * (self.min_radius_px / f).powi(2)) / 3.0)
            .floor()
            .max(2.0) as usize;
        let mut blobs = std::mem::take(&mut self.blobs);
        self.finder.find(
            &self.decimated,
            &self.cfg.threshold_fractions,
            min_area,
            self.cfg.min_contrast_gray,
            &mut blobs,
        );
        blobs.retain(|b| b.a_px >= 0.5 * self.min_radius_px && b.b_px >= 0.5);
        // The budget of candidates counts distinct dark regions (at the
        // highest threshold; the lower thresholds' regions are their parts),
        // larger first: small ones are mostly noise and thin shapes. A large
        // region broken into many parts (a shaded probe) must not use up the
        // budget before a small disc elsewhere in the frame is tried.
        // Within a region, its largest part at each threshold is tried.
        blobs.sort_by(|x, y| {
            y.region_area
                .cmp(&x.region_area)
                .then(x.region.cmp(&y.region))
                .then(y.area.cmp(&x.area))
        });
        // The budget: the regions, and within each its largest part at
        // each threshold.
        let mut selected: Vec<usize> = Vec::new();
        let mut regions = 0usize;
        for i in 0..blobs.len() {
            let b = &blobs[i];
            let new_region = i == 0 || blobs[i - 1].region != b.region;
            if new_region {
                if regions >= self.cfg.max_candidates as usize {
                    break;
                }
                regions += 1;
            }
            let same_region = |k: &usize| blobs[*k].region == b.region;
            if selected
                .iter()
                .rev()
                .take_while(|k| same_region(k))
                .any(|&k| blobs[k].level == b.level)
            {
                continue;
            }
            selected.push(i);
        }
        // Verified in order of how disc-like their moments are (whole and
        // round first, the rest as they were), so that a clear view of the
        // drogue ends the search before the probe and hose are looked at.
        // The stable sort keeps the size order within each group.
        let round: Vec<bool> = selected
            .iter()
            .map(|&i| blobs[i].whole_and_round(&self.decimated, self.cfg.min_axis_ratio))
            .collect();
        let mut order: Vec<usize> = (0..selected.len()).collect();
        order.sort_by_key(|&k| !round[k]);
        let mut kept: Vec<Blob> = Vec::new();
        let mut verified: Vec<Verified> = Vec::new();
        let mut tried: Vec<Seed> = Vec::new();
        'blobs: for &k in &order {
            let index = selected[k];
            // The deepest and best-ringed points cost a distance transform
            // of the region: only for the blobs that get this far.
            self.finder
                .describe_core(&self.decimated, &mut blobs[index]);
            let b = &blobs[index];
            // Drop near-duplicates (the same region at several thresholds).
            let dup = kept.iter().any(|k| {
                let near = |p: [f64; 2], q: [f64; 2], r: f64| (p[0] - q[0]).hypot(p[1] - q[1]) < r;
                let r = 0.25 * k.b_px.min(b.b_px);
                near(k.centre_px, b.centre_px, r)
                    && near(k.core_px, b.core_px, r)
                    && near(k.ringed_px, b.ringed_px, r)
                    && (k.a_px / b.a_px - 1.0).abs() < 0.25
            });
            if dup {
                continue;
            }
            kept.push(b.clone());
            // Two seeds: the centroid with the moment ellipse, and the
            // deepest point with its inscribed circle (on the disc even when
            // a hose or probe has merged with it).
            let mut seeds = vec![Seed {
                centre_px: b.centre_px,
                a_px: b.a_px,
                b_px: b.b_px,
                theta: b.theta,
                reach: 1.8,
                kind: 0,
            }];
            let off = (b.core_px[0] - b.centre_px[0]).hypot(b.core_px[1] - b.centre_px[1]);
            if off > 0.3 * b.core_radius_px {
                seeds.push(Seed {
                    centre_px: b.core_px,
                    a_px: b.core_radius_px,
                    b_px: b.core_radius_px,
                    theta: 0.0,
                    reach: UNSURE_SEED_REACH,
                    kind: 1,
                });
            }
            let off = (b.ringed_px[0] - b.centre_px[0]).hypot(b.ringed_px[1] - b.centre_px[1]);
            let off_core = (b.ringed_px[0] - b.core_px[0]).hypot(b.ringed_px[1] - b.core_px[1]);
            if b.ringed_light >= 0.5
                && off > 0.3 * b.ringed_radius_px
                && off_core > 0.3 * b.ringed_radius_px
            {
                seeds.push(Seed {
                    centre_px: b.ringed_px,
                    a_px: b.ringed_radius_px,
                    b_px: b.ringed_radius_px,
                    theta: 0.0,
                    reach: UNSURE_SEED_REACH,
                    kind: 2,
                });
            }
            // A region that is cut by the border or elongated is mostly not
            // a disc: its centroid lies off any disc in it, the point ringed
            // by light is the likeliest disc centre, then the deepest point.
            if !round[k] {
                seeds.reverse();
            }
            for seed in &seeds {
                // The same region at another threshold often gives nearly
                // the same seed: its rays would find the same edges.
                if tried.iter().any(|t| t.same_as(seed)) {
                    continue;
                }
                tried.push(seed.clone());
                // The seed's random stream is fixed by its blob's place in
                // the size order and its kind, not by the order of trying.
                if self.try_seed(image, seed, 3 * k as u64 + seed.kind as u64, &mut verified) {
                    break 'blobs;
                }
            }
        }
        // The edge source, when the dark regions gave no clear drogue: a
        // disc merged with the hose, probe or a glare streak, or washed out
        // by haze, still has its rim.
        if !verified.iter().any(|v| v.score >= self.cfg.accept_score) {
            let circles = self.voter.find(
                &self.decimated,
                self.cfg.min_contrast_gray,
                self.min_radius_px,
                self.max_radius_px,
                EDGE_SEEDS,
            );
            for (i, c) in circles.iter().enumerate() {
                let seed = Seed {
                    centre_px: c.centre_px,
                    a_px: c.radius_px,
                    b_px: c.radius_px,
                    theta: 0.0,
                    reach: UNSURE_SEED_REACH,
                    kind: 3,
                };
                if tried.iter().any(|t| t.same_as(&seed)) {
                    continue;
                }
                tried.push(seed.clone());
                tracing::debug!(strength = c.strength, "edge source circle");
                if self.try_seed(image, &seed, 1000 + i as u64, &mut verified) {
                    break;
                }
            }
        }
        tracing::debug!(
            regions = regions,
            seeds = tried.len(),
            verified = verified.len(),
            best = ?verified.iter().map(|v| v.score).max_by(f64::total_cmp),
            "full-frame search"
        );
        self.blobs = blobs;
        // The best candidate that passes again at the full density of rim
        // points: a candidate that passed on the sparse rim only by the
        // luck of where its rays fell is not the drogue.
        verified.sort_by(|x, y| y.score.total_cmp(&x.score));
        let spacing = self.cfg.rim_point_spacing_px;
        let max_points = self.cfg.max_rim_points;
        verified.into_iter().find_map(|scouted| {
            match self.verify_settled(image, &scouted.ellipse, spacing, max_points) {
                Ok(full) => Some(full),
                Err(why) => {
                    tracing::debug!(
                        centre_px = ?[scouted.ellipse.cx.round(), scouted.ellipse.cy.round()],
                        ?why,
                        "the full-density rim pass failed: not the drogue"
                    );
                    None
                }
            }
        })
    }

    /// Verifies a seed (its random stream `index`), keeps it in `verified`
    /// when it passes, and says whether it ends the search.
    fn try_seed(
        &mut self,
        image: &GrayImage,
        seed: &Seed,
        index: u64,
        verified: &mut Vec<Verified>,
    ) -> bool {
        let r = self.verify_seed(image, seed, index);
        tracing::debug!(
            centre_px = ?[seed.centre_px[0].round(), seed.centre_px[1].round()],
            radius_px = seed.a_px.round(),
            kind = seed.kind,
            result = ?r.as_ref().map(|v| v.score),
            "candidate"
        );
        let r = r.map(|v| self.prefer_inner_disc(image, v, index));
        let Ok(v) = r else {
            return false;
        };
        let ends = v.score >= self.cfg.accept_score;
        verified.push(v);
        ends
    }

    /// The canopy's outer rim taken for the disc (under haze its step to
    /// the sky can be the strongest on every ray) has the disc inside it,
    /// concentric, at `r / R` of its size. When that inner ellipse verifies
    /// as a rim of its own, with a step of comparable contrast, it is the
    /// disc. Inside a true disc there is no such rim: the shading of its
    /// inside gives steps far weaker than its rim's.
    fn prefer_inner_disc(&mut self, image: &GrayImage, outer: Verified, index: u64) -> Verified {
        let ratio = self.drogue.inner_radius_m / self.drogue.canopy_radius_m;
        if !(ratio.is_finite() && ratio > 0.0 && ratio < 1.0) {
            return outer;
        }
        let e = outer.ellipse;
        // The inner rim is looked for from the centre out to well inside
        // the outer one: there the disc's step is the strongest rise.
        let seed = Seed {
            centre_px: self.camera.distort_px([e.cx, e.cy]),
            a_px: e.a * ratio,
            b_px: e.b * ratio,
            theta: e.theta,
            // The wide pass reaches `reach * r + 4` px (r the seed's radius).
            reach: ((INNER_REACH_OUTER_RADII * e.b - 4.0) / (ratio * e.b)).max(1.0),
            kind: 4,
        };
        let inner = match self.verify_seed(image, &seed, index ^ INNER_SEED_STREAM) {
            Ok(inner) => inner,
            Err(why) => {
                tracing::debug!(outer_axes_px = ?[e.a.round(), e.b.round()], ?why, "no inner disc");
                return outer;
            }
        };
        let size = inner.ellipse.a / e.a;
        let offset = (inner.ellipse.cx - e.cx).hypot(inner.ellipse.cy - e.cy);
        let nested = (size - ratio).abs() <= INNER_SIZE_TOLERANCE * ratio
            && offset <= INNER_OFFSET_RADII * inner.ellipse.a;
        let strong = inner.rim_contrast >= INNER_CONTRAST_SHARE * outer.rim_contrast;
        tracing::debug!(
            outer_axes_px = ?[e.a.round(), e.b.round()],
            inner_axes_px = ?[inner.ellipse.a.round(), inner.ellipse.b.round()],
            nested,
            inner_contrast = inner.rim_contrast,
            outer_contrast = outer.rim_contrast,
            "inner disc"
        );
        if nested && strong { inner } else { outer }
    }

    /// Verifies a coarse seed: a wide ray pass from its centre, a robust
    /// fit, then the narrow pass around that fit.
    #[inline(never)]
    fn verify_seed(
        &mut self,
        image: &GrayImage,
        seed: &Seed,
        index: u64,
    ) -> Result<Verified, Reject> {
        let rays = 48;
        let mut points = Vec::with_capacity(rays);
        let c = seed.centre_px;
        // An elongated region (disc plus hose or probe) is not searched
        // along its length: the disc is across it.
        let longest = 2.0 * seed.b_px;
        for k in 0..rays {
            let phi = TAU * k as f64 / rays as f64;
            let r = polar_radius(seed.a_px, seed.b_px, seed.theta, phi).min(longest);
            let dir = [phi.cos(), phi.sin()];
            let s_max = seed.reach * r + 4.0;
            // About a pixel of accuracy on a small seed, a few percent of
            // its size on a large one, is enough here (the narrow passes,
            // 10 % of the radius wide, refine it): a fixed number of steps
            // per radius, so that a large dark region (cloud, shadow) costs
            // no more than a disc.
            let step = (r / WIDE_STEPS_PER_RADIUS).max(0.5);
            rim::profile(image, c, dir, 1.0, s_max, step, &mut self.profile);
            if let Some(e) =
                rim::strongest_rise(&self.profile, 1.0, step, self.cfg.min_contrast_gray as f32)
            {
                let p = [c[0] + e.s * dir[0], c[1] + e.s * dir[1]];
                points.push(self.camera.undistort_px(p));
            }
        }
        if points.len() < 8 {
            return Err(Reject::FewEdges(points.len()));
        }
        let scale = seed.b_px.max(1.0);
        let tolerance = (0.03 * scale).max(1.0);
        // Most rays on the rim: a trimmed least-squares fit will do; else
        // RANSAC (a hose or probe merged with the disc).
        let first = conic_fit::fit_ellipse(&points)
            .and_then(|e| conic_fit::refine(&e, &points, 3.0 * tolerance, 1))
            .and_then(|e| conic_fit::refine(&e, &points, tolerance, 2))
            .filter(|e| {
                let c = e.to_conic();
                let n = points
                    .iter()
                    .filter(|p| c.sampson_distance(p[0], p[1]) <= tolerance)
                    .count();
                n as f64 >= 0.8 * points.len() as f64
            })
            .or_else(|| conic_fit::ransac_ellipse(&points, tolerance, 300, self.cfg.seed ^ index))
            .ok_or(Reject::NoEllipse)?;
        if !self.plausible(&first, 0.5) {
            return Err(Reject::Implausible);
        }
        // Candidates are compared on a sparser rim (cheaper); the winner
        // gets the full density.
        self.verify_settled(
            image,
            &first,
            SCOUT_SPACING_FACTOR * self.cfg.rim_point_spacing_px,
            self.cfg.max_rim_points,
        )
    }

    /// Size and shape plausible for the disc (`slack` widens the limits).
    fn plausible(&self, e: &Ellipse, slack: f64) -> bool {
        e.a.is_finite()
            && e.b > 0.0
            && e.a <= 2.0 * self.max_radius_px / slack
            && e.a >= slack * 0.8 * self.min_radius_px
            && e.b / e.a >= self.cfg.min_axis_ratio * slack
    }

    /// Narrow ray pass around an ellipse (undistorted pixels), robust refit,
    /// and the evidence score: [`Self::rim_pass`], repeated from its own result while that moves
    /// by more than half a pixel (the narrow search is centred on the start
    /// ellipse: a start a few pixels off gives edges near the window's ends).
    fn verify_settled(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
    ) -> Result<Verified, Reject> {
        // The canopy evidence (a second ray pass) is looked at only on the
        // pass that is kept: a pass that moves the ellipse is followed by
        // another one.
        let mut previous = *start;
        for round in 0..3 {
            let pass = self.rim_pass(image, &previous, spacing_px, max_points)?;
            if round == 2 || pass.ellipse.max_param_error_px(&previous) <= 0.5 {
                return self.score(image, pass);
            }
            previous = pass.ellipse;
        }
        Err(Reject::Unsettled)
    }

    /// The narrow ray pass around `start` and the robust refit, with the
    /// checks of the rim itself (size, shape, contrast, one dark inside).
    fn rim_pass(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
    ) -> Result<RimPass, Reject> {
        let centre = self.camera.distort_px([start.cx, start.cy]);
        let perimeter = TAU * ((start.a * start.a + start.b * start.b) / 2.0).sqrt();
        let rays =
            ((perimeter / spacing_px.max(0.1)) as usize).clamp(24, max_points.max(24) as usize);
        let min_contrast = self.cfg.min_contrast_gray as f32;
        let (w, h) = (f64::from(image.width()), f64::from(image.height()));
        let inside = |p: [f64; 2]| p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= w - 1.0 && p[1] <= h - 1.0;

        // A blurred rim is a ramp as wide as the blur: where most steps run
        // into the window's ends, their levels are not the disc's and the
        // canopy's, and the window is widened (the mid-level crossing of a
        // whole blurred step is the edge).
        let mut widen = 1.0;
        let (mut points_px, mut undistorted, mut contrasts, mut mid_levels, mut widths);
        let mut rays_in_image;
        let mut clipped_share;
        loop {
            points_px = Vec::with_capacity(rays);
            undistorted = Vec::with_capacity(rays);
            contrasts = Vec::with_capacity(rays);
            mid_levels = Vec::with_capacity(rays);
            widths = Vec::with_capacity(rays);
            rays_in_image = 0usize;
            let mut clipped = 0usize;
            let (sin_theta, cos_theta) = start.theta.sin_cos();
            for dir in ray_directions(rays) {
                // The ray's angle to the major axis: phi - theta.
                let (cos_local, sin_local) = (
                    dir[0] * cos_theta + dir[1] * sin_theta,
                    dir[1] * cos_theta - dir[0] * sin_theta,
                );
                let r = polar_radius_local(start.a, start.b, cos_local, sin_local);
                let base = (self.cfg.rim_search_fraction * r)
                    .clamp(4.0, self.cfg.rim_search_max_px.max(4.0));
                let margin = if widen > 1.0 {
                    (base * widen)
                        .min(MAX_WIDE_MARGIN_RADII * r)
                        .min(MAX_WIDE_MARGIN_PX)
                        .max(base)
                } else {
                    base
                };
                let (s0, s1) = ((r - margin).max(0.5), r + margin);
                let far = [centre[0] + s1 * dir[0], centre[1] + s1 * dir[1]];
                let near = [centre[0] + s0 * dir[0], centre[1] + s0 * dir[1]];
                if !(inside(far) && inside(near)) {
                    continue;
                }
                rays_in_image += 1;
                rim::profile(image, centre, dir, s0, s1, 0.5, &mut self.profile);
                // In noise, the step is located on the smoothed profile: its
                // ends and levels are then the step's, not the noise's.
                let half = self.smooth_half.min((0.1 * r) as usize);
                if half > 0 {
                    self.raw_profile.clone_from(&self.profile);
                    rim::smooth(&mut self.profile, half, &mut self.scratch);
                }
                if let Some(mut e) = rim::strongest_rise(&self.profile, s0, 0.5, min_contrast) {
                    // A step into saturated pixels is most likely the skirt
                    // of a glare streak lying over the disc: its width says
                    // nothing of blur. (Its point stays: the robust fit
                    // drops it when it is off the rim.)
                    let raw = if half > 0 {
                        &self.raw_profile
                    } else {
                        &self.profile
                    };
                    let glare = glare_on_light_side(raw, s0, 0.5, &e);
                    if half > 0 {
                        let mid = 0.5 * (e.dark + e.light);
                        let reach = 0.5 * self.smoothing_spread_px[half] + 1.0;
                        if let Some(s) =
                            rim::crossing_near(&self.raw_profile, s0, 0.5, mid, e.s, reach)
                        {
                            e.s = s;
                        }
                    }
                    let p = [centre[0] + e.s * dir[0], centre[1] + e.s * dir[1]];
                    points_px.push(p);
                    undistorted.push(self.camera.undistort_px(p));
                    contrasts.push(f64::from(e.light - e.dark));
                    mid_levels.push(0.5 * (e.dark + e.light));
                    // The smoothing's own spread is not the step's.
                    let spread = self.smoothing_spread_px[half];
                    widths.push((2.0 * (e.light_s - e.s) - spread).max(0.0));
                    clipped += usize::from(e.clipped && !glare);
                }
            }
            tracing::trace!(
                rays,
                rays_in_image,
                edges = points_px.len(),
                clipped,
                widen,
                "rim pass"
            );
            clipped_share = clipped as f64 / points_px.len().max(1) as f64;
            if widen >= MAX_WIDEN || clipped_share <= CLIPPED_SHARE {
                break;
            }
            widen *= WIDEN_STEP;
        }
        if rays_in_image < rays / 4 {
            return Err(Reject::OutOfImage);
        }
        if undistorted.len() < self.cfg.min_rim_points as usize {
            return Err(Reject::FewEdges(undistorted.len()));
        }
        let min_tol = self.cfg.inlier_tolerance_px.max(0.1);
        let coarse_tol = (0.05 * start.b).max(3.0 * min_tol);
        let coarse =
            conic_fit::refine(start, &undistorted, coarse_tol, 2).ok_or(Reject::NoEllipse)?;
        // The edges' own scatter sets what is "on the rim": a blurred rim in
        // noise is located to a pixel or two (noise over the ramp's slope),
        // a sharp one to a tenth.
        let mut residuals = Vec::new();
        conic_fit::residuals(&coarse, &undistorted, &mut residuals);
        let mut near: Vec<f64> = residuals
            .iter()
            .copied()
            .filter(|r| *r <= coarse_tol)
            .collect();
        let sigma = 1.4826 * median(&mut near);
        let tol = (NOISE_TOLERANCE_SIGMAS * sigma).clamp(min_tol, (0.5 * coarse_tol).max(min_tol));
        let ellipse = conic_fit::refine(&coarse, &undistorted, tol, 2).ok_or(Reject::NoEllipse)?;
        if !self.plausible(&ellipse, 1.0) {
            return Err(Reject::Implausible);
        }
        conic_fit::residuals(&ellipse, &undistorted, &mut residuals);
        let inliers: Vec<usize> = (0..residuals.len())
            .filter(|&i| residuals[i] <= tol)
            .collect();
        if inliers.len() < self.cfg.min_rim_points as usize {
            return Err(Reject::FewInliers(inliers.len()));
        }
        let mut inlier_contrast: Vec<f64> = inliers.iter().map(|&i| contrasts[i]).collect();
        let rim_contrast = median(&mut inlier_contrast);
        if rim_contrast < self.cfg.min_contrast_gray {
            return Err(Reject::LowContrast(rim_contrast));
        }
        // Dark inside: the disc fills its ellipse. A crescent (whose outer
        // arc is a fine circle), a ring, or the canopy's outer rim taken for
        // the disc's have light inside the ellipse their edges fit.
        let mids: Vec<(f64, f32)> = inliers
            .iter()
            .map(|&i| {
                let p = undistorted[i];
                let angle = (p[1] - ellipse.cy).atan2(p[0] - ellipse.cx);
                (angle, mid_levels[i])
            })
            .collect();
        let fill = self.fill_share(image, &ellipse, &mids);
        if fill < self.cfg.min_fill {
            return Err(Reject::LightInside(fill));
        }
        let shape = inliers.len() as f64 / rays_in_image as f64;
        Ok(RimPass {
            ellipse,
            centre,
            points_px,
            undistorted,
            residuals,
            inliers,
            step_widths_px: widths,
            clipped_share,
            rim_contrast,
            shape,
            fill,
            tolerance: tol,
            mids,
        })
    }

    /// Share of samples inside `ellipse` (undistorted pixels) darker than
    /// the middle of the rim's step. Samples lie on [`FILL_DIRECTIONS`] rays
    /// at [`FILL_FRACTIONS`] of the ellipse's radius; each is compared with
    /// the mid level of the rim edge nearest in angle (`mids`: angle about
    /// the ellipse's centre, mid level), so that a glare veil or vignetting
    /// across the disc does not count as light. Saturated samples (glare)
    /// count neither way. 1 when nothing could be sampled.
    fn fill_share(&self, image: &GrayImage, ellipse: &Ellipse, mids: &[(f64, f32)]) -> f64 {
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
    fn score(&mut self, image: &GrayImage, pass: RimPass) -> Result<Verified, Reject> {
        let RimPass {
            ellipse,
            centre,
            points_px,
            undistorted,
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
        let widths: Vec<(f64, f64)> = inliers
            .iter()
            .map(|&i| {
                let [u, v] = points_px[i];
                let angle = (v - centre[1]).atan2(u - centre[0]);
                (angle, step_widths_px[i])
            })
            .collect();
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
            points_px: near(points_px),
            undistorted: near(undistorted),
            score,
            rim_contrast,
            step_widths_px,
        })
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
        }
    }
}
