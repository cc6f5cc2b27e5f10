//! Telling the two cone solutions apart from the canopy's outer rim.
//!
//! A single circle's image fits two poses (mirror images about the cone's
//! widest plane). The drogue's canopy ends in a rim: a circle concentric with
//! the dark inner circle, in the same plane, with a known radius. Each pose
//! predicts where that rim must appear; the two predictions differ visibly
//! once the tilt is more than a few degrees, and only the true one lies on the
//! rim's edge in the image. Near a frontal view (tilt ~ 0) both predictions
//! coincide, both get the same support, and then the choice hardly matters:
//! the two solutions are then nearly the same pose.
//!
//! The rim is darker than the sky around it (a dark band at the canopy's edge),
//! so the edge we look for gets brighter going outward. Its inner side (band
//! against the lighter canopy) has the opposite polarity and is not counted.
//! Heavy haze can lift the band above a darker sky; when the brightening edge
//! leaves the rim unsupported, the outermost darkening edge is tried (see
//! [`canopy_supports`]). Heavier haze gives the band the sky's own level:
//! then the canopy's end, darkening outward a band's width inside the rim,
//! is looked for there.
//!
//! Far away the two predictions merge: the image is then nearly affine, and
//! an affine view maps the concentric rim of both solutions to the same
//! ellipse (the inner one scaled about its centre). At 12-16 m the two
//! predicted rims of the reference camera are often less than a pixel
//! apart, closer than the rim's edge can be placed. [`canopy_supports`]
//! therefore judges the two solutions only on the points where their
//! predicted rims are farther apart than the edge's own scatter (3 times
//! its RMS, at least [`MIN_SEPARATION_PX`]), only when there are
//! [`MIN_DISCRIMINATING`] such points, and only when the difference in
//! edges found is beyond chance ([`MIN_EVIDENCE_Z`]); otherwise the rim
//! says nothing and the answer stays `unresolved` (or goes to continuity).
//!
//! The predictions are only as good as the inner ellipse: a disc fitted from
//! half its rim (the other half under a glare streak) may be a pixel off,
//! and its predicted canopy rim, 2.2 times larger, more than two. The true
//! pose's prediction then misses the rim, and the mirror's may cross it by
//! chance. [`canopy_supports_where`] therefore also takes what the fit may
//! be ([`FitSpread`]): the rim judges only where enough of its telling
//! points lie farther from the other rim than `SEPARATION_SIGMAS` times
//! the spread of their own prediction.

use super::detect::{canopy, rim};
use super::pose::{CirclePose, EllipseSpread, ellipse_params};
use crate::camera::CameraModel;
use image::GrayImage;
use nalgebra::{Matrix2, Vector2};

/// Points sampled along the predicted rim (every 5 degrees of the circle:
/// on the reference sets 120 points, every 3 degrees, decided the same
/// frames but one of 300 noisy occlusion trials, at 1.7 times the cost).
const SAMPLES: usize = 72;
/// How far across the predicted curve the edge is looked for, pixels.
const SEARCH_PX: f64 = 3.0;
/// Step of the search across the curve, pixels.
const SEARCH_STEP_PX: f64 = 0.5;
/// How close to the predicted curve the edge must be to support the pose,
/// pixels. The two solutions' predicted rims can be only a pixel or two
/// apart at small tilts, so this is tight; it still covers the prediction's
/// own error: the inner ellipse's fit error (~0.1 px) scaled up by the
/// canopy/inner radius ratio (about 2.2), plus the edge's sub-pixel
/// localisation error.
const TOLERANCE_PX: f64 = 0.75;
/// Smallest outward brightening that counts as an edge, grey levels per pixel
/// (central difference over 2 px). Sensor noise of ~1.5 grey levels gives
/// ~1 grey level/px of derivative noise: 6 keeps noise-only maxima out, while
/// a rim against the sky gives tens.
const MIN_EDGE_GREY_PER_PX: f64 = 6.0;
/// Below this support of the better solution on a brightening edge, the
/// rim's darkening edge is tried too (`[ambiguity] canopy_min_support`'s
/// default: below it the tracker does not use the rim anyway).
const DARKENING_FALLBACK_BELOW: f64 = 0.5;
/// Share of the predicted rim that must fall inside the image to judge.
const MIN_SHARE_IN_IMAGE: f64 = 0.5;
/// Smallest predicted rim (semi-minor axis, pixels) worth judging: below this
/// the two predictions are within the search band of each other anyway.
const MIN_RIM_SIZE_PX: f64 = 4.0;

/// A rim point tells the two solutions apart only when it is at least this
/// far from the other solution's predicted rim, pixels (whatever the edge
/// scatter: an 8-bit edge placed to better than this is not to be relied on)
pub const MIN_SEPARATION_PX: f64 = 0.5;
/// ... and at least this many times the edge scatter.
pub const SEPARATION_SIGMAS: f64 = 3.0;
/// The two solutions' edge counts on their telling points must differ by at
/// least this many standard deviations of a chance difference.
pub const MIN_EVIDENCE_Z: f64 = 3.0;
/// Points (of `SAMPLES`) that must tell the solutions apart, for each
/// solution, before the rim may judge between them: with fewer, a few
/// stray edges (struts, clouds, noise) would decide.
pub const MIN_DISCRIMINATING: usize = 12;

/// Offsets searched across the curve: -SEARCH_PX..=SEARCH_PX.
const SEARCH_STEPS: usize = (2.0 * SEARCH_PX / SEARCH_STEP_PX) as usize + 1;
/// Grey values sampled across the curve: the search band plus the 1 px on
/// each side that the central difference needs.
const PROFILE_LEN: usize = SEARCH_STEPS + 2 * STEPS_PER_PX;
const STEPS_PER_PX: usize = (1.0 / SEARCH_STEP_PX) as usize;

/// Which way the grey level steps going outward across the canopy's rim.
/// The rim's dark band against a clear sky brightens outward; under heavy
/// haze the airlight lifts the band above a darker patch of sky (or a
/// vignetted corner) and the drogue's edge then darkens outward.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Polarity {
    /// The strongest outward brightening is the edge.
    Brightening,
    /// The outermost outward darkening is the edge: the band's inner side
    /// (canopy to band) darkens outward too, a band's width further in.
    Darkening,
    /// The strongest outward darkening is the edge: the canopy's light
    /// fabric ending at the band, looked for a band's width inside the rim.
    CanopyEnd,
}

/// Grey values sampled across a predicted rim point, outward.
type AcrossProfile = [f32; PROFILE_LEN];

/// The grey values across the predicted curve at `p`, along the unit image
/// direction `out`, from `SEARCH_PX + 1` px inside to as far outside;
/// `None` if they leave the image. `grey` is scratch. One profile serves
/// both polarities of [`edge_offset`].
fn across_profile(
    image: &GrayImage,
    p: [f64; 2],
    out: [f64; 2],
    grey: &mut Vec<f32>,
) -> Option<AcrossProfile> {
    // The detector's ray sampler: bilinear, stopping at the image border.
    let start = -SEARCH_PX - 1.0;
    let end = start + (PROFILE_LEN - 1) as f64 * SEARCH_STEP_PX;
    rim::profile(image, p, out, start, end, SEARCH_STEP_PX, grey);
    grey.get(..PROFILE_LEN)?.try_into().ok()
}

/// Where across the predicted curve the strongest outward brightening lies
/// on `grey` ([`across_profile`]): its offset from the predicted point
/// (pixels, sub-pixel by a parabola through the peak) if it is within
/// `SEARCH_PX` and at least `MIN_EDGE_GREY_PER_PX` strong; `None` for no
/// edge. With [`Polarity::Darkening`], the outermost local maximum of the
/// outward darkening of that strength instead.
fn edge_offset(grey: &AcrossProfile, polarity: Polarity) -> Option<f64> {
    // Central difference over 2 px at each searched offset.
    let sign = match polarity {
        Polarity::Brightening => 1.0,
        Polarity::Darkening | Polarity::CanopyEnd => -1.0,
    };
    let mut gradient = [0.0; SEARCH_STEPS];
    for (i, g) in gradient.iter_mut().enumerate() {
        *g = sign * f64::from(grey[i + 2 * STEPS_PER_PX] - grey[i]) / 2.0;
    }
    let found = match polarity {
        // The last of the greatest, as `max_by` with `total_cmp` gives it.
        // A plain comparison orders the values the same way wherever the
        // answer can be an edge (at least MIN_EDGE_GREY_PER_PX: no zero of
        // either sign, no NaN from 8-bit grey levels), and is cheaper.
        Polarity::Brightening | Polarity::CanopyEnd => {
            let mut best = (0, gradient[0]);
            for (i, &g) in gradient.iter().enumerate().skip(1) {
                if g >= best.1 {
                    best = (i, g);
                }
            }
            Some(best)
        }
        Polarity::Darkening => (0..SEARCH_STEPS).rev().find_map(|i| {
            let g = gradient[i];
            let peak =
                (i == 0 || gradient[i - 1] <= g) && (i + 1 == SEARCH_STEPS || gradient[i + 1] <= g);
            (peak && g >= MIN_EDGE_GREY_PER_PX).then_some((i, g))
        }),
    };
    let (i_best, best) = found?;
    if best < MIN_EDGE_GREY_PER_PX {
        return None;
    }
    let mut offset = i_best as f64 * SEARCH_STEP_PX - SEARCH_PX;
    if i_best > 0 && i_best + 1 < SEARCH_STEPS {
        let (l, c, r) = (gradient[i_best - 1], best, gradient[i_best + 1]);
        let curvature = l - 2.0 * c + r;
        if curvature < 0.0 {
            offset += 0.5 * (l - r) / curvature * SEARCH_STEP_PX;
        }
    }
    Some(offset)
}

/// (cos t, sin t) of the `SAMPLES` points along the rim, computed once.
fn rim_directions() -> &'static [(f64, f64); SAMPLES] {
    static TABLE: std::sync::OnceLock<[(f64, f64); SAMPLES]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|k| {
            let t = k as f64 * std::f64::consts::TAU / SAMPLES as f64;
            let (s, c) = t.sin_cos();
            (c, s)
        })
    })
}

/// Image evidence (0..1) that the canopy's outer rim, a circle of
/// `canopy_radius_m` concentric with the inner circle and in its plane, lies
/// where `pose` predicts it: the share of points along the predicted rim
/// (projected through the camera's distortion) with an outward-brightening
/// edge within `TOLERANCE_PX` of it. `None` where the rim cannot be judged: less than
/// half of it in the image, or too small. A rim hidden by clouds, glare or
/// the hose gives a low support for both solutions; the tracker then does not
/// use it.
pub fn canopy_support(
    image: &GrayImage,
    camera: &CameraModel,
    pose: &CirclePose,
    canopy_radius_m: f64,
) -> Option<f64> {
    let rim = predicted_rim(camera, pose, canopy_radius_m)?;
    support_on(image, &rim, |_| true)
}

/// The two solutions' canopy supports (as [`canopy_support`]) judged only on
/// the points that tell them apart, or `[None, None]` when the rim cannot
/// tell them apart:
///
/// - a point tells them apart when it lies farther from the other
///   solution's predicted rim than the edge can be placed: at least
///   `SEPARATION_SIGMAS` times the edge scatter (RMS offset of the edges
///   found within the tolerance of the better-supported solution's rim:
///   noise, blur and the prediction's own error), and never less than
///   `MIN_SEPARATION_PX`;
/// - each solution needs `MIN_DISCRIMINATING` such points in the image;
/// - the difference in edges found on them must be real: the counts
///   (b, c) must differ by `MIN_EVIDENCE_Z` standard deviations of a
///   chance difference, (b - c) / sqrt(b + c).
///
/// Far away (the reference camera at 12-16 m) the two predicted rims are
/// less than half a pixel apart and the answer is `None`; at 8 m they are
/// about a pixel apart, which a clear rim's edges (scatter ~0.1 px) still
/// resolve.
///
/// The edge is an outward brightening (the band against the sky); when
/// that leaves the rim without a say or its better solution below
/// `DARKENING_FALLBACK_BELOW`, the outward darkening of a band lifted by
/// haze above the sky is tried, and then (still below, and `band_m` > 0)
/// the strongest outward darkening `band_m` inside the rim: the canopy's
/// end where haze has given the band the sky's level. The answer whose
/// better solution has the most support is given.
pub fn canopy_supports(
    image: &GrayImage,
    camera: &CameraModel,
    solutions: &[CirclePose; 2],
    canopy_radius_m: f64,
    band_m: f64,
) -> [Option<f64>; 2] {
    RimEvidence::new(image, camera, solutions, None, canopy_radius_m, band_m).supports(|_| true)
}

/// What the fit of the inner circle may be, for how far the rims it
/// predicts may be off: its one-sigma ellipses (`pose::EllipseSpread`,
/// undistorted pixels) and the inner circle's radius, metres (a rim of
/// radius R is the fit scaled by R over it).
#[derive(Clone, Copy, Debug)]
pub struct FitSpread<'a> {
    /// The fit and its one-sigma ellipses.
    pub spread: &'a EllipseSpread,
    /// The radius of the circle fitted, metres.
    pub inner_radius_m: f64,
}

/// [`canopy_supports`] for predictions as uncertain as the fit
/// (`fit_spread`; `None`: the predictions taken as exact): the rim says
/// nothing unless each solution has `MIN_DISCRIMINATING` of its telling
/// points also `SEPARATION_SIGMAS` times its own prediction's spread
/// (`prediction_spread`) from the other solution's rim. Where that leaves
/// the better solution below `DARKENING_FALLBACK_BELOW`, the same is judged
/// only on the rim points (distorted pixels) that `judge` takes (those
/// where a motion blur runs along the rim, not across it: [`SmearedRim`]);
/// the answer whose better solution has more support is given, so an
/// answer of the whole rim is never lost.
pub fn canopy_supports_where(
    image: &GrayImage,
    camera: &CameraModel,
    solutions: &[CirclePose; 2],
    fit_spread: Option<FitSpread>,
    canopy_radius_m: f64,
    band_m: f64,
    judge: impl Fn([f64; 2]) -> bool + Copy,
) -> [Option<f64>; 2] {
    let mut evidence = RimEvidence::new(
        image,
        camera,
        solutions,
        fit_spread,
        canopy_radius_m,
        band_m,
    );
    let whole = evidence.supports(|_| true);
    if best_support(&whole).is_some_and(|b| b >= DARKENING_FALLBACK_BELOW) {
        return whole;
    }
    better_supported(whole, evidence.supports(judge))
}

/// The larger of two solutions' supports, if either has one.
fn best_support(s: &[Option<f64>; 2]) -> Option<f64> {
    s.iter().flatten().copied().reduce(f64::max)
}

/// Of two answers, the one whose better solution has more support (the
/// first on a tie, or when the second has no say).
fn better_supported(a: [Option<f64>; 2], b: [Option<f64>; 2]) -> [Option<f64>; 2] {
    match (best_support(&a), best_support(&b)) {
        (_, None) => a,
        (Some(x), Some(y)) if x >= y => a,
        _ => b,
    }
}

/// Per point of a predicted curve, the edge's offset from it (`Some(None)`:
/// no edge, `None`: outside the image), as [`edge_offsets`] gives them.
type EdgeOffsets = Vec<Option<Option<f64>>>;

/// Two predicted curves (one per solution), the grey profiles across them
/// and, once asked for, the edges found on them by polarity.
struct CurvePair {
    rims: [Vec<RimPoint>; 2],
    /// Each rim point's distance to the other solution's rim, pixels.
    apart_px: [Vec<f64>; 2],
    /// Each rim point's spread as the fit may move it, pixels (0 without
    /// a spread).
    spread_px: [Vec<f64>; 2],
    profiles: [Vec<Option<AcrossProfile>>; 2],
    offsets: [Option<[EdgeOffsets; 2]>; 3],
}

impl CurvePair {
    /// The two solutions' circles of `radius_m`, when both can be judged:
    /// both rims big enough, and each with [`MIN_DISCRIMINATING`] points at
    /// least [`MIN_SEPARATION_PX`] from the other rim. Without those points
    /// no polarity and no choice of points can tell the solutions apart
    /// ([`supports_with`] needs them), so the profiles are not taken: far
    /// away, where the rims merge, that is most of a tracked frame's
    /// ambiguity test.
    fn new(
        image: &GrayImage,
        camera: &CameraModel,
        solutions: &[CirclePose; 2],
        fit_spread: Option<FitSpread>,
        radius_m: f64,
    ) -> Option<Self> {
        let [Some(rim0), Some(rim1)] = solutions.map(|pose| predicted_rim(camera, &pose, radius_m))
        else {
            return None;
        };
        let apart_px = [
            distances_to_rim(&rim0, &rim1),
            distances_to_rim(&rim1, &rim0),
        ];
        let telling = |d: &[f64]| d.iter().filter(|&&d| d >= MIN_SEPARATION_PX).count();
        if apart_px.iter().any(|d| telling(d) < MIN_DISCRIMINATING) {
            return None;
        }
        let profiles = [rim_profiles(image, &rim0), rim_profiles(image, &rim1)];
        let scale = fit_spread.map_or(1.0, |f| radius_m / f.inner_radius_m);
        let spread_px = [
            prediction_spread(&rim0, fit_spread.as_ref(), scale),
            prediction_spread(&rim1, fit_spread.as_ref(), scale),
        ];
        Some(Self {
            rims: [rim0, rim1],
            apart_px,
            spread_px,
            profiles,
            offsets: [None, None, None],
        })
    }

    fn supports(
        &mut self,
        polarity: Polarity,
        judge: impl Fn([f64; 2]) -> bool,
    ) -> [Option<f64>; 2] {
        let profiles = &self.profiles;
        let offsets = self.offsets[polarity as usize]
            .get_or_insert_with(|| profiles.each_ref().map(|p| edge_offsets(p, polarity)));
        supports_with(offsets, &self.rims, &self.apart_px, &self.spread_px, judge)
    }
}

/// What the image shows where the two solutions put the canopy's rim (and,
/// when asked, its end a band's width inside): the profiles are taken once
/// and judged on any set of points.
struct RimEvidence<'a> {
    image: &'a GrayImage,
    camera: &'a CameraModel,
    solutions: &'a [CirclePose; 2],
    fit_spread: Option<FitSpread<'a>>,
    end_radius_m: Option<f64>,
    rim: Option<CurvePair>,
    /// The canopy's end, taken on first need.
    end: Option<Option<CurvePair>>,
}

impl<'a> RimEvidence<'a> {
    fn new(
        image: &'a GrayImage,
        camera: &'a CameraModel,
        solutions: &'a [CirclePose; 2],
        fit_spread: Option<FitSpread<'a>>,
        canopy_radius_m: f64,
        band_m: f64,
    ) -> Self {
        let has_band = band_m > 0.0;
        Self {
            image,
            camera,
            solutions,
            fit_spread,
            end_radius_m: has_band.then_some(canopy_radius_m - band_m),
            rim: CurvePair::new(image, camera, solutions, fit_spread, canopy_radius_m),
            end: None,
        }
    }

    /// The supports judged on the points `judge` takes: the rim's
    /// brightening edge; below `DARKENING_FALLBACK_BELOW`, its darkening
    /// one; still below, the canopy's end (darkening, a band's width
    /// inside). The answer whose better solution has the most support.
    fn supports(&mut self, judge: impl Fn([f64; 2]) -> bool + Copy) -> [Option<f64>; 2] {
        let Some(rim) = &mut self.rim else {
            return [None, None];
        };
        let bright = rim.supports(Polarity::Brightening, judge);
        if best_support(&bright).is_some_and(|b| b >= DARKENING_FALLBACK_BELOW) {
            return bright;
        }
        let answer = better_supported(bright, rim.supports(Polarity::Darkening, judge));
        if best_support(&answer).is_some_and(|b| b >= DARKENING_FALLBACK_BELOW) {
            return answer;
        }
        // Heavy haze gives the band the sky's own level: the canopy then
        // ends, darkening outward, a band's width inside the rim.
        let Some(end_radius_m) = self.end_radius_m else {
            return answer;
        };
        let (image, camera, solutions, spread) =
            (self.image, self.camera, self.solutions, self.fit_spread);
        let end = self
            .end
            .get_or_insert_with(|| CurvePair::new(image, camera, solutions, spread, end_radius_m));
        match end {
            Some(end) => better_supported(answer, end.supports(Polarity::CanopyEnd, judge)),
            None => answer,
        }
    }
}

/// [`canopy_supports`] for one polarity of the rim's edge, from the edges
/// found on the two rims (`offsets`, [`edge_offsets`]) and each rim
/// point's distance to the other rim (`apart_px`), judged on the points
/// `judge` takes.
fn supports_with(
    offsets: &[EdgeOffsets; 2],
    rims: &[Vec<RimPoint>; 2],
    apart_px: &[Vec<f64>; 2],
    spread_px: &[Vec<f64>; 2],
    judge: impl Fn([f64; 2]) -> bool,
) -> [Option<f64>; 2] {
    let in_image = |o: &[Option<Option<f64>>]| o.iter().filter(|x| x.is_some()).count();
    if offsets
        .iter()
        .any(|o| (in_image(o) as f64) < MIN_SHARE_IN_IMAGE * SAMPLES as f64)
    {
        return [None, None];
    }
    let matched = |o: &Option<Option<f64>>| match o {
        Some(Some(x)) if x.abs() <= TOLERANCE_PX => Some(*x),
        _ => None,
    };
    // Edge scatter along the better-supported rim.
    let found = offsets.each_ref().map(|o| {
        let mut found = Vec::with_capacity(o.len());
        found.extend(o.iter().filter_map(matched));
        found
    });
    let better = if found[0].len() >= found[1].len() {
        0
    } else {
        1
    };
    let scatter = if found[better].is_empty() {
        TOLERANCE_PX
    } else {
        (found[better].iter().map(|x| x * x).sum::<f64>() / found[better].len() as f64).sqrt()
    };
    let min_separation = (SEPARATION_SIGMAS * scatter).max(MIN_SEPARATION_PX);
    let apart = [0, 1].map(|i| {
        apart_px[i]
            .iter()
            .zip(&rims[i])
            .map(|(&d, p)| d >= min_separation && judge(p.at))
            .collect::<Vec<bool>>()
    });
    // Of those, the points whose own prediction the fit could not have
    // moved onto the other rim: too few, and the rim cannot tell. (They
    // are not what is counted: leaving out the points both rims share
    // would raise the counts' z by itself.)
    let firm = [0, 1].map(|i| {
        let spread = |k: usize| spread_px[i].get(k).copied().unwrap_or(0.0);
        (apart[i]
            .iter()
            .zip(&apart_px[i])
            .zip(&offsets[i])
            .enumerate())
        .filter(|&(k, ((&use_it, &d), o))| {
            use_it && o.is_some() && d >= SEPARATION_SIGMAS * spread(k)
        })
        .count()
    });
    if firm.iter().any(|&n| n < MIN_DISCRIMINATING) {
        return [None, None];
    }
    let mut judged = [0usize; 2];
    let mut edges = [0usize; 2];
    for i in 0..2 {
        for (o, use_it) in offsets[i].iter().zip(&apart[i]) {
            if *use_it && o.is_some() {
                judged[i] += 1;
                edges[i] += usize::from(matched(o).is_some());
            }
        }
    }
    if judged.iter().any(|&n| n < MIN_DISCRIMINATING) {
        return [None, None];
    }
    let (b, c) = (edges[0] as f64, edges[1] as f64);
    if b + c == 0.0 || (b - c).abs() / (b + c).sqrt() < MIN_EVIDENCE_Z {
        return [None, None];
    }
    [Some(b / judged[0] as f64), Some(c / judged[1] as f64)]
}

/// Each point of `rim` (a prediction for a circle `scale` times the fit's)
/// as the fit may move it, pixels across the curve: the root of half the
/// sum of its squared displacements over the fit's one-sigma ellipses
/// ([`FitSpread`]); zeros without one. To first order the predicted rim is
/// the fit's ellipse scaled about its centre (`q = c + k M u`), so a fit
/// moved by `(dc, dM)` moves it across the curve by `n . (dc + k dM u)`,
/// with `u` the point's place on the unit circle and `n` the curve's normal
/// there (computed before the lens, where the fit is; the lens changes the
/// figure by a few per cent at the frame's edges).
fn prediction_spread(rim: &[RimPoint], fit: Option<&FitSpread>, scale: f64) -> Vec<f64> {
    let Some(fit) = fit else {
        return vec![0.0; rim.len()];
    };
    let nominal = ellipse_params(&fit.spread.nominal);
    let m = Matrix2::new(nominal[2], nominal[3], nominal[3], nominal[4]);
    let Some(m_inv) = m.try_inverse() else {
        return vec![0.0; rim.len()];
    };
    // Each moved fit as (dc, k dM), undistorted pixels: once, not per point.
    let moved: Vec<(Vector2<f64>, Matrix2<f64>)> = (fit.spread.moved.iter())
        .map(|e| {
            let dp = ellipse_params(e) - nominal;
            let dm = Matrix2::new(dp[2], dp[3], dp[3], dp[4]);
            (Vector2::new(dp[0], dp[1]), scale * dm)
        })
        .collect();
    rim.iter()
        .map(|p| {
            let [x, y] = p.at_undistorted;
            let d = Vector2::new(x - nominal[0], y - nominal[1]);
            let Some(u) = (m_inv * d).try_normalize(0.0) else {
                return 0.0;
            };
            let Some(n) = (m_inv * u).try_normalize(0.0) else {
                return 0.0;
            };
            let var: f64 = (moved.iter())
                .map(|(dc, k_dm)| 0.5 * n.dot(&(dc + k_dm * u)).powi(2))
                .sum();
            var.sqrt()
        })
        .collect()
}

/// Distance of each point of `from` to the closed polyline through `to`,
/// pixels ([`distance_to_rim`], each query starting from the last one's
/// nearest point).
fn distances_to_rim(from: &[RimPoint], to: &[RimPoint]) -> Vec<f64> {
    let mut near = None;
    from.iter()
        .map(|p| {
            let (d, k) = distance_to_rim(p.at, to, near);
            near = Some(k);
            d
        })
        .collect()
}

/// Per rim point, its [`across_profile`] (`None`: outside the image).
fn rim_profiles(image: &GrayImage, rim: &[RimPoint]) -> Vec<Option<AcrossProfile>> {
    let mut grey = Vec::with_capacity(PROFILE_LEN);
    rim.iter()
        .map(|p| across_profile(image, p.at, p.out, &mut grey))
        .collect()
}

/// Per rim point, the outward edge's offset from it (`Some(None)`: no edge,
/// `None`: outside the image).
fn edge_offsets(profiles: &[Option<AcrossProfile>], polarity: Polarity) -> EdgeOffsets {
    profiles
        .iter()
        .map(|p| p.as_ref().map(|p| edge_offset(p, polarity)))
        .collect()
}

/// One point of a predicted rim: where it is and the image direction in
/// which it moves as the radius grows (unit).
#[derive(Clone, Copy, Debug)]
struct RimPoint {
    at: [f64; 2],
    out: [f64; 2],
    /// `at` before the lens (undistorted pixels), where the fit's ellipse is.
    at_undistorted: [f64; 2],
}

/// Distance from `p` to the closed polyline through `rim` (pixels), and the
/// index of the rim point nearest to `p`. The nearest point is found by
/// climbing from `start` (the previous query's, as consecutive queries go
/// round the rim in order), so a query costs a few steps, not the whole rim;
/// without a start it is searched among all. The distance is to the two
/// segments either side of it.
fn distance_to_rim(p: [f64; 2], rim: &[RimPoint], start: Option<usize>) -> (f64, usize) {
    let n = rim.len();
    let d2 = |k: usize| (rim[k].at[0] - p[0]).powi(2) + (rim[k].at[1] - p[1]).powi(2);
    // Neighbours round the rim without an integer division each.
    let next_of = |k: usize| if k + 1 == n { 0 } else { k + 1 };
    let prev_of = |k: usize| if k == 0 { n - 1 } else { k - 1 };
    let mut k = match start {
        Some(k) => k % n,
        None => (0..n).min_by(|&a, &b| d2(a).total_cmp(&d2(b))).unwrap_or(0),
    };
    // The current point's squared distance is kept, not recomputed for
    // each comparison.
    let mut here_d2 = d2(k);
    loop {
        let next = next_of(k);
        let next_d2 = d2(next);
        if next_d2 < here_d2 {
            (k, here_d2) = (next, next_d2);
            continue;
        }
        let prev = prev_of(k);
        let prev_d2 = d2(prev);
        if prev_d2 < here_d2 {
            (k, here_d2) = (prev, prev_d2);
        } else {
            break;
        }
    }
    let segment = |a: [f64; 2], b: [f64; 2]| {
        let d = [b[0] - a[0], b[1] - a[1]];
        let len2 = d[0] * d[0] + d[1] * d[1];
        let t = if len2 > 0.0 {
            (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
    };
    let here = rim[k].at;
    let dist = segment(rim[prev_of(k)].at, here).min(segment(here, rim[next_of(k)].at));
    (dist, k)
}

/// The rim `pose` predicts (points projected through the lens) when it is
/// big enough to judge; `None` otherwise.
fn predicted_rim(
    camera: &CameraModel,
    pose: &CirclePose,
    canopy_radius_m: f64,
) -> Option<Vec<RimPoint>> {
    if canopy_radius_m.is_nan() || canopy_radius_m <= 0.0 {
        return None;
    }
    let (e1, e2) = super::pose::circle_plane_basis(&pose.normal_camera)?;

    let mut rim = Vec::with_capacity(SAMPLES);
    let (mut min_u, mut max_u, mut min_v, mut max_v) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(cos_t, sin_t) in rim_directions() {
        let radial = cos_t * e1 + sin_t * e2;
        let point = pose.centre_camera_m + canopy_radius_m * radial;
        // The image's outward direction is where the rim point moves as the
        // radius grows: the projection's derivative along `radial`.
        let (Some((p, d)), Some(at_undistorted)) = (
            camera.project_px_with_derivative(&point, &radial),
            camera.project_undistorted_px(&point),
        ) else {
            continue;
        };
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if !(len > 0.0 && len.is_finite()) {
            continue;
        }
        min_u = min_u.min(p[0]);
        max_u = max_u.max(p[0]);
        min_v = min_v.min(p[1]);
        max_v = max_v.max(p[1]);
        rim.push(RimPoint {
            at: p,
            out: [d[0] / len, d[1] / len],
            at_undistorted,
        });
    }
    let big_enough = (max_u - min_u).min(max_v - min_v) >= 2.0 * MIN_RIM_SIZE_PX;
    (big_enough && rim.len() >= 3).then_some(rim)
}

/// Share of the rim points picked by `use_point` (by index) with an edge
/// within the tolerance; `None` when less than `MIN_SHARE_IN_IMAGE` of all
/// `SAMPLES` could be judged (outside the image), or none was picked.
fn support_on(
    image: &GrayImage,
    rim: &[RimPoint],
    use_point: impl Fn(usize) -> bool,
) -> Option<f64> {
    let (mut in_image, mut judged, mut with_edge) = (0usize, 0usize, 0usize);
    let mut grey = Vec::with_capacity(PROFILE_LEN);
    for (k, p) in rim.iter().enumerate() {
        let Some(profile) = across_profile(image, p.at, p.out, &mut grey) else {
            continue;
        };
        let edge = edge_offset(&profile, Polarity::Brightening);
        in_image += 1;
        if use_point(k) {
            judged += 1;
            with_edge += usize::from(edge.is_some_and(|o| o.abs() <= TOLERANCE_PX));
        }
    }
    if (in_image as f64) < MIN_SHARE_IN_IMAGE * SAMPLES as f64 || judged == 0 {
        return None;
    }
    Some(with_edge as f64 / judged as f64)
}

/// The values at two quantiles `q` (ascending) of `values`, each the
/// element at `((len - 1) * q) as usize` of the sorted values, as a full
/// sort would give them; `None` for no values. Two selections instead of
/// the sort: the order of the rest is never used. `values` is reordered.
fn percentiles(values: &mut [f64], q: [f64; 2]) -> Option<[f64; 2]> {
    if values.is_empty() {
        return None;
    }
    let at = |q: f64| ((values.len() as f64 - 1.0) * q) as usize;
    let (lo, hi) = (at(q[0]), at(q[1]));
    let (below, &mut high, _) = values.select_nth_unstable_by(hi, f64::total_cmp);
    // Everything before `hi` is at most `high`: the lower one is among them.
    let low = if lo < hi {
        *below.select_nth_unstable_by(lo, f64::total_cmp).1
    } else {
        high
    };
    Some([low, high])
}

/// Where a motion blur smears the disc's rim: the directions (about the
/// disc's centre, distorted pixels) whose rim steps are wider than the
/// sharp ones (the 10th percentile of the widths) by more than half the
/// blur (the 90th percentile less the sharp width). The canopy's rim,
/// concentric, is smeared in the same directions: there its edge is a
/// ramp as long as the blur, whose steepest point noise and the band's
/// own blurred edge move, and [`canopy_supports_where`] leaves those
/// points out.
pub struct SmearedRim {
    centre: [f64; 2],
    /// (angle, width) of the rim steps, sorted by angle (empty when there
    /// is no blur to speak of: then none is looked up).
    widths: Vec<(f64, f64)>,
    /// Steps wider than this are smeared (infinite: no blur to speak of).
    limit_px: f64,
}

impl SmearedRim {
    /// A blur shorter than this leaves every point judged: shorter than the
    /// band searched across the predicted rim (`2 * SEARCH_PX`), it leaves
    /// the edge's steepest point within it. (Tried at 3 px with the judged
    /// points alone, before the whole rim was kept first: the simulator's
    /// 4 px blur lost resolutions on six of nine seeds; at 6 px none.)
    const MIN_BLUR_PX: f64 = 2.0 * SEARCH_PX;

    /// From the disc's rim points (`points`, distorted pixels, about
    /// `centre`) and their step widths (pixels, aligned with them).
    pub fn new(centre: [f64; 2], points: &[[f64; 2]], widths: &[f64]) -> Self {
        let finite = || {
            points
                .iter()
                .zip(widths)
                .filter(|(_, w)| w.is_finite())
                .map(|(p, &w)| (p, w))
        };
        // The percentiles lie between the least and the greatest width: when
        // those are closer than a blur, so are the percentiles, and no
        // selection is needed to know there is none.
        let (least, greatest) = finite()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, w)| {
                (lo.min(w), hi.max(w))
            });
        let mut limit_px = f64::INFINITY;
        if greatest - least >= Self::MIN_BLUR_PX {
            let mut sorted: Vec<f64> = Vec::with_capacity(widths.len());
            sorted.extend(finite().map(|(_, w)| w));
            if let Some([sharp, wide]) = percentiles(&mut sorted, [0.1, 0.9])
                && wide - sharp >= Self::MIN_BLUR_PX
            {
                limit_px = sharp + 0.5 * (wide - sharp);
            }
        }
        // Without a blur no point is ever looked up: the angles (an atan2
        // a point) and their sort are only taken when there is one.
        let mut by_angle: Vec<(f64, f64)> = Vec::new();
        if limit_px.is_finite() {
            let angle = |p: &[f64; 2]| (p[1] - centre[1]).atan2(p[0] - centre[0]);
            by_angle.reserve_exact(widths.len());
            by_angle.extend(finite().map(|(p, w)| (angle(p), w)));
            by_angle.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        Self {
            centre,
            widths: by_angle,
            limit_px,
        }
    }

    /// Whether the rim is smeared in the direction of `p`.
    pub fn at(&self, p: [f64; 2]) -> bool {
        if !self.limit_px.is_finite() {
            return false;
        }
        let angle = (p[1] - self.centre[1]).atan2(p[0] - self.centre[0]);
        canopy::nearest(&self.widths, angle).is_some_and(|&(_, width)| width > self.limit_px)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::ellipse::Ellipse;
    use crate::spatial::{Direction, Point};
    use crate::testing::vga_camera;
    use image::Luma;
    use nalgebra::Vector3;

    fn camera() -> CameraModel {
        vga_camera([0.0; 5])
    }

    /// Width of the painted drogue's dark band at the rim, metres.
    const BAND_M: f64 = 0.03;

    /// Paints a synthetic drogue, exact per pixel centre: sky 170, canopy 150,
    /// dark band at the rim (r in [0.30, 0.33]) 70, inner circle 30.
    fn render(cam: &CameraModel, pose: &CirclePose) -> GrayImage {
        render_levels(cam, pose, [30, 150, 70, 170])
    }

    /// Disc, canopy, band and sky levels.
    fn render_levels(cam: &CameraModel, pose: &CirclePose, levels: [u8; 4]) -> GrayImage {
        let n = pose.normal_camera;
        GrayImage::from_fn(640, 480, |x, y| {
            let ray = cam.ray_camera(cam.undistort_px([f64::from(x), f64::from(y)]));
            let t = n.dot(&pose.centre_camera_m) / n.dot(&ray);
            let r = (ray * t - *pose.centre_camera_m).norm();
            let g = if r < 0.15 {
                levels[0]
            } else if r < 0.30 {
                levels[1]
            } else if r < 0.33 {
                levels[2]
            } else {
                levels[3]
            };
            Luma([g])
        })
    }

    /// A drogue 3 m away tilted about 36 degrees, and its mirror pose.
    fn tilted_and_mirrored() -> [CirclePose; 2] {
        let n = nalgebra::Rotation3::new(Vector3::new(0.0, 0.6, 0.2)) * -Vector3::z();
        let truth = CirclePose {
            centre_camera_m: Point::new(Vector3::new(0.1, -0.05, 3.0)),
            normal_camera: Direction::new(n.normalize()),
        };
        let mirrored = CirclePose {
            normal_camera: Direction::new(Vector3::new(-n.x, -n.y, n.z).normalize()),
            ..truth
        };
        [truth, mirrored]
    }

    /// Under haze the band (150) is lighter than the sky (130): the
    /// brightening test sees no rim, the darkening one tells the true pose
    /// from its mirror, and neither takes the canopy-to-band edge (r = 0.30,
    /// also darkening outward) for the rim.
    #[test]
    fn a_hazy_rim_that_darkens_outward_decides_for_the_true_pose() {
        let cam = camera();
        let [truth, mirrored] = tilted_and_mirrored();
        let image = render_levels(&cam, &truth, [110, 180, 150, 130]);
        let bright = canopy_support(&image, &cam, &truth, 0.33).unwrap();
        assert!(bright < 0.1, "brightening support {bright}");
        let [t, m] = canopy_supports(&image, &cam, &[truth, mirrored], 0.33, BAND_M);
        let (t, m) = (t.expect("decided"), m.expect("decided"));
        assert!(t > 0.9 && m < 0.5, "true {t}, mirror {m}");
        let [t, m] = canopy_supports(&image, &cam, &[mirrored, truth], 0.33, BAND_M);
        assert!(t.unwrap() < 0.5 && m.unwrap() > 0.9, "order swapped");
    }

    /// Under heavy haze the band takes the sky's own level (130): there is
    /// no edge at the rim at all, only the canopy ending, darkening
    /// outward, a band's width inside it. Looked for there, it tells the
    /// true pose from its mirror; without the band's width, nothing does.
    #[test]
    fn a_hazy_canopy_whose_band_has_the_sky_level_decides_by_its_end() {
        let cam = camera();
        let [truth, mirrored] = tilted_and_mirrored();
        let image = render_levels(&cam, &truth, [110, 180, 130, 130]);
        let [t, m] = canopy_supports(&image, &cam, &[truth, mirrored], 0.33, BAND_M);
        let (t, m) = (t.expect("decided"), m.expect("decided"));
        assert!(t > 0.9 && m < 0.5, "true {t}, mirror {m}");
        let [t, m] = canopy_supports(&image, &cam, &[mirrored, truth], 0.33, BAND_M);
        assert!(t.unwrap() < 0.5 && m.unwrap() > 0.9, "order swapped");
        assert_eq!(
            canopy_supports(&image, &cam, &[truth, mirrored], 0.33, 0.0),
            [None, None]
        );
    }

    /// Rim points round a 40 px disc whose steps are 2 px wide plus a
    /// horizontal blur of `blur_px` (its share along each point's normal).
    fn blurred_rim(centre: [f64; 2], blur_px: f64) -> SmearedRim {
        let (points, widths): (Vec<[f64; 2]>, Vec<f64>) = (0..90)
            .map(|k| {
                let t = f64::from(k).to_radians() * 4.0;
                let p = [centre[0] + 40.0 * t.cos(), centre[1] + 40.0 * t.sin()];
                (p, 2.0 + blur_px * t.cos().abs())
            })
            .unzip();
        SmearedRim::new(centre, &points, &widths)
    }

    #[test]
    fn a_blur_smears_the_rim_where_it_runs_across_it() {
        let c = [300.0, 200.0];
        let rim = blurred_rim(c, 12.0);
        // Across the blur (left, right) smeared; along it (top, bottom) not.
        assert!(rim.at([c[0] + 100.0, c[1] + 5.0]) && rim.at([c[0] - 90.0, c[1]]));
        assert!(!rim.at([c[0], c[1] + 100.0]) && !rim.at([c[0] + 3.0, c[1] - 80.0]));
        // A blur shorter than the band searched leaves every point judged.
        let short = blurred_rim(c, 4.0);
        assert!(!short.at([c[0] + 100.0, c[1]]));
    }

    /// A drogue under a 12 px horizontal blur and noise: across the blur
    /// the canopy rim is a ramp whose steepest point noise moves, so on the
    /// whole rim neither pose reaches the support the tracker asks
    /// (`canopy_min_support`, 0.5); judged only where the blur runs along
    /// the rim, the true pose does and its mirror does not.
    #[test]
    fn a_blurred_rim_is_judged_where_the_blur_runs_along_it() {
        use rand::{Rng, SeedableRng};
        let cam = camera();
        let [truth, mirrored] = tilted_and_mirrored();
        let sharp = render(&cam, &truth);
        let taps = 12;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let image = GrayImage::from_fn(640, 480, |x, y| {
            let sum: u32 = (0..taps)
                .map(|k| {
                    let u = (i64::from(x) + k - taps / 2).clamp(0, 639) as u32;
                    u32::from(sharp.get_pixel(u, y)[0])
                })
                .sum();
            // Noise of sigma 4 (a sum of 12 uniforms).
            let noise = 4.0 * ((0..12).map(|_| rng.random::<f64>()).sum::<f64>() - 6.0);
            Luma([(f64::from(sum) / taps as f64 + noise)
                .round()
                .clamp(0.0, 255.0) as u8])
        });
        let whole = canopy_supports(&image, &cam, &[truth, mirrored], 0.33, BAND_M);
        assert!(best_support(&whole).is_none_or(|b| b < 0.5), "{whole:?}");
        let centre = cam.project_px(&truth.centre_camera_m).unwrap();
        let rim = blurred_rim(centre, 12.0);
        let judged = |p| !rim.at(p);
        let [t, m] =
            canopy_supports_where(&image, &cam, &[truth, mirrored], None, 0.33, BAND_M, judged);
        let (t, m) = (t.expect("decided"), m.expect("decided"));
        assert!(t > 0.5 && m < 0.5, "true {t}, mirror {m}");
    }

    #[test]
    fn the_true_pose_has_the_support() {
        support_through(&camera(), Vector3::new(0.1, -0.05, 3.0));
    }

    #[test]
    fn the_true_pose_has_the_support_through_lens_distortion() {
        // Strong barrel distortion: an undistorted prediction would miss.
        // Off-centre, where it moves the rim by several pixels.
        support_through(
            &vga_camera([-0.3, 0.1, 0.001, -0.001, 0.0]),
            Vector3::new(0.6, 0.4, 3.0),
        );
    }

    fn support_through(cam: &CameraModel, centre_camera_m: Vector3<f64>) {
        let cam = cam.clone();
        let n = nalgebra::Rotation3::new(Vector3::new(0.0, 0.6, 0.2)) * -Vector3::z();
        let truth = CirclePose {
            centre_camera_m: Point::new(centre_camera_m),
            normal_camera: Direction::new(n.normalize()),
        };
        let image = render(&cam, &truth);
        let good = canopy_support(&image, &cam, &truth, 0.33).unwrap();
        assert!(good > 0.95, "true pose support {good}");
        // A pose with the same centre and a mirrored tilt.
        let mirrored = CirclePose {
            normal_camera: Direction::new(Vector3::new(-n.x, -n.y, n.z).normalize()),
            ..truth
        };
        let bad = canopy_support(&image, &cam, &mirrored, 0.33).unwrap();
        assert!(bad < 0.5, "wrong pose support {bad}");
        // Wrong polarity: the band's inner edge (r = 0.30) is not the rim.
        let inner = canopy_support(&image, &cam, &truth, 0.30).unwrap();
        assert!(inner < 0.1, "inner edge support {inner}");
    }

    /// On the optical axis the two cone solutions are exact mirrors:
    /// (nx, ny, nz) and (-nx, -ny, nz) about the same centre.
    fn on_axis_pair(range_m: f64) -> [CirclePose; 2] {
        let n =
            (nalgebra::Rotation3::new(Vector3::new(0.0, 0.35, 0.0)) * -Vector3::z()).normalize();
        let truth = CirclePose {
            centre_camera_m: Point::new(Vector3::new(0.0, 0.0, range_m)),
            normal_camera: Direction::new(n),
        };
        let mirror = CirclePose {
            normal_camera: Direction::new(Vector3::new(-n.x, -n.y, n.z)),
            ..truth
        };
        [truth, mirror]
    }

    #[test]
    fn rims_apart_decide_and_rims_together_do_not() {
        let cam = camera();
        // 2 m: the predicted rims are pixels apart; the truth has the edges.
        let near = on_axis_pair(2.0);
        let image = render(&cam, &near[0]);
        let [s0, s1] = canopy_supports(&image, &cam, &near, 0.33, BAND_M);
        let (s0, s1) = (s0.unwrap(), s1.unwrap());
        assert!(s0 > 0.9 && s1 < 0.1, "near: {s0} {s1}");
        // 10 m (a 26 px rim at f = 800 px): the two rims are within half a
        // pixel of each other, and the rim must not decide, though the
        // whole-rim supports are both high.
        let far = on_axis_pair(10.0);
        let image = render(&cam, &far[0]);
        let whole = far.map(|p| canopy_support(&image, &cam, &p, 0.33).unwrap());
        assert!(whole[0] > 0.8 && whole[1] > 0.8, "{whole:?}");
        assert_eq!(
            canopy_supports(&image, &cam, &far, 0.33, BAND_M),
            [None, None]
        );
    }

    /// A fit of the pair's inner circle (a circle of its size about its
    /// centre's image: where the spread is read, not what it is) and its
    /// copies moved by `d_px` either way along x and y: the spread of a fit
    /// that may be that far off.
    fn shifted_fits(cam: &CameraModel, pose: &CirclePose, d_px: f64) -> EllipseSpread {
        let [cx, cy] = cam.project_px(&pose.centre_camera_m).expect("in view");
        let r = 800.0 * 0.15 / pose.centre_camera_m.z;
        let circle = |dx: f64, dy: f64| Ellipse::new(cx + dx, cy + dy, r, r, 0.0);
        EllipseSpread {
            nominal: circle(0.0, 0.0),
            moved: vec![
                circle(d_px, 0.0),
                circle(-d_px, 0.0),
                circle(0.0, d_px),
                circle(0.0, -d_px),
            ],
        }
    }

    /// A prediction is as good as the fit it comes from: the same drogue
    /// decides for the true pose when the fit is exact or a tenth of a
    /// pixel off, but not when it may be 4 px off (the canopy rims then
    /// move by more than the two solutions' rims are apart, and a rim
    /// crossing the mirror's prediction by chance would decide).
    #[test]
    fn a_fit_that_may_be_off_by_more_than_the_rims_are_apart_does_not_decide() {
        let cam = camera();
        let pair = tilted_and_mirrored();
        let image = render(&cam, &pair[0]);
        let all = |_: [f64; 2]| true;
        let (tenth, four) = (
            shifted_fits(&cam, &pair[0], 0.1),
            shifted_fits(&cam, &pair[0], 4.0),
        );
        let fit = |spread| FitSpread {
            spread,
            inner_radius_m: 0.15,
        };
        for spread in [None, Some(fit(&tenth))] {
            let [t, m] = canopy_supports_where(&image, &cam, &pair, spread, 0.33, BAND_M, all);
            let (t, m) = (t.expect("decided"), m.expect("decided"));
            assert!(t > 0.9 && m < 0.5, "{spread:?}: true {t}, mirror {m}");
        }
        assert_eq!(
            canopy_supports_where(&image, &cam, &pair, Some(fit(&four)), 0.33, BAND_M, all),
            [None, None]
        );
    }

    /// Over the four shifts (either way along x and y) a point's squared
    /// displacements across the curve sum to twice the shift squared,
    /// whatever the curve's direction there: its spread is the shift. A
    /// fit one pixel larger moves a rim 2.2 times as large by 2.2 px.
    #[test]
    fn a_rims_spread_is_what_the_moved_fits_move_it_by() {
        let cam = camera();
        let pair = tilted_and_mirrored();
        let rim = predicted_rim(&cam, &pair[0], 0.33).expect("a rim");
        let fits = shifted_fits(&cam, &pair[0], 1.5);
        let fit = FitSpread {
            spread: &fits,
            inner_radius_m: 0.15,
        };
        let spread = prediction_spread(&rim, Some(&fit), 2.2);
        assert_eq!(spread.len(), rim.len());
        assert!(spread.iter().all(|s| (s - 1.5).abs() < 1e-9), "{spread:?}");
        let n = fits.nominal;
        let larger = EllipseSpread {
            nominal: n,
            moved: vec![Ellipse::new(n.cx, n.cy, n.a + 1.0, n.b + 1.0, 0.0)],
        };
        let fit = FitSpread {
            spread: &larger,
            inner_radius_m: 0.15,
        };
        // One moved fit carries half its variance: sqrt(2.2^2 / 2).
        let expected = 2.2 / 2f64.sqrt();
        for s in prediction_spread(&rim, Some(&fit), 2.2) {
            assert!((s - expected).abs() < 1e-9, "{s}, not {expected}");
        }
        assert!(prediction_spread(&rim, None, 2.2).iter().all(|&s| s == 0.0));
    }

    #[test]
    fn distance_to_rim_matches_a_full_search() {
        let rim: Vec<RimPoint> = (0..SAMPLES)
            .map(|k| {
                let t = k as f64 * std::f64::consts::TAU / SAMPLES as f64;
                let at = [100.0 + 80.0 * t.cos(), 50.0 + 20.0 * t.sin()];
                RimPoint {
                    at,
                    out: [t.cos(), t.sin()],
                    at_undistorted: at,
                }
            })
            .collect();
        let mut near = None;
        for k in 0..SAMPLES {
            let t = (k as f64 + 0.5) * std::f64::consts::TAU / SAMPLES as f64;
            let p = [100.0 + 81.0 * t.cos(), 50.0 + 21.0 * t.sin()];
            let (d, i) = distance_to_rim(p, &rim, near);
            near = Some(i);
            let (full, _) = distance_to_rim(p, &rim, None);
            assert!((d - full).abs() < 1e-12, "{k}: {d} vs {full}");
            assert!(d > 0.3 && d < 1.1, "{k}: {d}");
        }
    }

    #[test]
    fn rim_outside_the_image_cannot_be_judged() {
        let cam = camera();
        let pose = CirclePose {
            centre_camera_m: Point::new(Vector3::new(0.0, 0.0, 0.3)),
            normal_camera: Direction::new(-Vector3::z()),
        };
        let image = GrayImage::new(640, 480);
        assert_eq!(canopy_support(&image, &cam, &pose, 0.33), None);
        // Far away the rim is a few pixels: no judgement either.
        let far = CirclePose {
            centre_camera_m: Point::new(Vector3::new(0.0, 0.0, 200.0)),
            ..pose
        };
        assert_eq!(canopy_support(&image, &cam, &far, 0.33), None);
        // A blank image gives no support at all.
        let near = CirclePose {
            centre_camera_m: Point::new(Vector3::new(0.0, 0.0, 3.0)),
            ..pose
        };
        assert_eq!(canopy_support(&image, &cam, &near, 0.33), Some(0.0));
    }
}
