//! Verification by the drogue's structure: the canopy's outer rim where the
//! candidate's pose puts it.
//!
//! The dark disc (radius r) lies inside the lighter canopy, whose outer rim
//! is a concentric circle of radius R in the same plane. A candidate ellipse
//! fits two poses (the single-circle ambiguity); each predicts where the
//! canopy's rim must appear. A true drogue shows an edge there on most of
//! it: the rim's darker band against the sky, brightening outward, or under
//! heavy haze (the band lifted above a darker sky) the drogue's outer edge
//! of either polarity; either counts only with the canopy before it lighter
//! than the disc. An ellipse inside the disc (shading, the disc's lit half),
//! the canopy's own rim taken for the disc, a crescent, a ring, a dark
//! cloud, or one arm of a dark star or flower (whose other arms and body
//! lie where the canopy should be, and whose edges cross the predicted rim
//! here and there) predicts a rim where there is none. Saturated pixels
//! (glare) and points outside the image are not judged, so glare and the
//! frame border do not count against a candidate.
//!
//! This is looser than the ambiguity module's test (which tells the two
//! poses apart to a fraction of a pixel): it asks only whether the canopy is
//! there, so it searches a band a tenth of the rim's radius wide on either
//! side, enough for a blurred rim and the fit's error scaled by R/r.

use super::{SATURATED_GRAY, rim};
use crate::camera::CameraModel;
use crate::measure::ellipse::Ellipse;
use crate::measure::pose::{CirclePose, circle_plane_basis, cone_pose};
use image::GrayImage;

/// Points along the predicted rim (every 7.5 degrees of the circle); the
/// points half-way between them too where the share is in doubt
/// ([`DOUBT_SIGMAS`]).
const SAMPLES: usize = 48;
/// Where the canopy is required, a pose's share of [`SAMPLES`] points
/// within this many binomial standard deviations of the share needed
/// (`sqrt(f (1 - f) / 48)`: 0.072 at 0.5) is in doubt, and the points
/// half-way between are read as well: the verdict is that of all 96. A
/// drogue whose rim haze, glare or the probe partly hide shows a share
/// near `min_canopy_fraction`, and so do a few shapes without a canopy, so
/// that the verdict on 48 points followed where they happened to fall. A
/// share further from the threshold (0.36 or less, 0.64 or more at 0.5)
/// is a verdict already: a rim whose true share is the threshold itself
/// reads that far out on 48 points 2.3 % of the time either way.
const DOUBT_SIGMAS: f64 = 2.0;
/// Half-width of the search across the predicted rim: this share of its
/// radius in pixels, at least [`MIN_SEARCH_PX`].
const SEARCH_RADII: f64 = 0.1;
const MIN_SEARCH_PX: f64 = 3.0;
/// How close to the predicted rim the strongest edge of the band must be:
/// this share of its radius in pixels, at least [`MIN_TOLERANCE_PX`]. The
/// rim of the right pose is predicted to about a pixel (the fit's error
/// scaled by R/r), but a real canopy is a shallow cone, not quite in the
/// disc's plane; the edges of unrelated dark shapes fall anywhere.
const TOLERANCE_RADII: f64 = 0.05;
const MIN_TOLERANCE_PX: f64 = 1.5;
/// Rim points where the disc's step is wider than this share of the canopy
/// rim's radius are not judged (the rim's band, a few percent of its
/// radius, is smeared out there).
const MAX_JUDGED_WIDTH_RADII: f64 = 0.15;
/// The narrowest step width a rim point is judged with, pixels: a step is
/// never taken narrower than this, however sharp.
const MIN_STEP_WIDTH_PX: f64 = 2.0;
/// The strongest brightening across the predicted rim must exceed this
/// many sigmas of the frame's pixel noise. The difference of two bilinear
/// samples of independent pixel noise has a standard deviation of about
/// one sigma (0.9 to 1.4); the strongest of the search band's few dozen
/// differences reaches two sigmas on noise alone about half the time, and
/// half the band lies within the tolerance of the predicted rim. Plain sky
/// around a dark shape then shows about a quarter of a canopy rim, half of
/// `min_canopy_fraction`; without this floor it showed half, and in noisy
/// frames stars' arms and flowers' petals passed the canopy test on noise
/// (simulator sweep: 8 of 480 drogue-free frames). 2.5 and 3 sigmas lose
/// drogues whose canopy rim stands 3 to 4 sigmas out of 20 gray levels of
/// noise.
const NOISE_BRIGHTENING_SIGMAS: f32 = 2.0;
/// Sampling step across the rim, pixels.
const STEP_PX: f64 = 0.5;
/// Gray level from which a sample counts as saturated.
/// Fewest rim points in the image (and not saturated) for a pose's rim to
/// be judged, of [`SAMPLES`]: a quarter of the rim (the same arc at any
/// other count of points, [`min_judged`]).
const MIN_JUDGED: usize = 12;
/// Fewest background samples beyond the predicted rim for the
/// polarity-free test ([`outer_edge_offset`]).
const OUTER_MIN_BACKGROUND: usize = 3;
/// How far below the disc's rim mid level the canopy may be, as a share of
/// the disc's step: the canopy must be lighter than a quarter of the step
/// above the disc's dark level. Not the mid level itself: a canopy shaded
/// darker outward (its lit inner ring makes the disc's step) lies near the
/// mid level beyond 1.3 disc radii, while a star's other arms and body
/// are at the disc's own dark level.
const CANOPY_FLOOR_BELOW_MID: f32 = 0.25;
/// Points of the canopy sampled by [`canopy_between`], from this share of
/// the disc's radius (past its blurred rim) to this share of the canopy
/// rim's (inside its band).
const ANNULUS_SAMPLES: usize = 5;
const ANNULUS_FROM_INNER: f64 = 1.3;
const ANNULUS_TO_OUTER: f64 = 0.85;
/// The polarity-free test reads the background out to this share of the
/// canopy rim's radius beyond it: past the rim's dark band (a few percent
/// of the radius) and its blur.
const OUTER_BACKGROUND_RADII: f64 = 0.3;
/// Share of the profile inside the drogue's outer edge that must be off
/// the background's level: the band and canopy are, a noise spike is not.
const OUTER_MIN_INSIDE_SHARE: f64 = 0.7;

/// The drogue's two circles, metres.
#[derive(Clone, Copy, Debug)]
pub struct DrogueCircles {
    /// The dark inner circle's radius.
    pub inner_radius_m: f64,
    /// The canopy's outer rim's radius.
    pub canopy_radius_m: f64,
    /// Width of the darker band at the canopy's outer edge: where haze
    /// lifts it to the sky's level, the light fabric ends this much inside
    /// the rim.
    pub canopy_band_m: f64,
}

impl DrogueCircles {
    /// The canopy's outer rim around the disc's ellipse `disc` (undistorted
    /// pixels), taken as that ellipse scaled by `R / r` about its centre:
    /// exact for a circle facing the camera, a region and a size to compare
    /// with, not a measurement (the pose's prediction is [`ring_support`]'s).
    pub fn canopy_rim_around(&self, disc: &Ellipse) -> Ellipse {
        let ratio = self.canopy_radius_m / self.inner_radius_m;
        disc.scaled(ratio)
    }
}

/// What counts as the canopy's rim edge.
#[derive(Clone, Copy, Debug)]
pub struct RimEdge<'a> {
    /// Smallest outward brightening, gray levels.
    pub min_step_gray: f32,
    /// The frame's pixel noise (standard deviation), gray levels: an
    /// outward brightening must also stand above what the noise alone
    /// makes somewhere in the search band (`NOISE_BRIGHTENING_SIGMAS`).
    pub noise_gray: f32,
    /// Width of the disc's own rim step by direction: (image angle about
    /// the ellipse's centre, radians; width, pixels), sorted by angle.
    /// Motion blur widens both rims alike along its direction: there the
    /// brightening is taken over that width (2 px at least) and its place
    /// is known to a quarter of it; where the disc's step is wider than
    /// `MAX_JUDGED_WIDTH_RADII` of the canopy rim's radius the thin rim
    /// is smeared out and not judged.
    pub widths: &'a [(f64, f64)],
    /// The disc's rim mid level by direction: (image angle about the
    /// ellipse's centre, radians; gray level), sorted by angle. An edge at
    /// the predicted rim counts only where the canopy between the disc and
    /// the rim is lighter than a quarter of the disc's step above its dark
    /// level (`mid - contrast_gray / 4`, [`canopy_between`]): a dark shape
    /// next to the candidate (a star's other arm, the probe) is not canopy,
    /// and its edges are not the canopy's rim. Without a mid level nothing
    /// counts.
    pub mids: &'a [(f64, f32)],
    /// The disc's rim step (canopy side less disc side), gray levels.
    pub contrast_gray: f32,
}

impl RimEdge<'_> {
    /// The disc's step width nearest to image angle `angle`, pixels.
    fn width_at(&self, angle: f64) -> f64 {
        nearest(self.widths, angle).map_or(2.0, |w| w.1)
    }

    /// The level the canopy must exceed in direction `angle`: a quarter
    /// of the disc's step above its dark level, from the nearest rim mid
    /// level.
    fn canopy_floor_at(&self, angle: f64) -> Option<f32> {
        nearest(self.mids, angle).map(|m| m.1 - CANOPY_FLOOR_BELOW_MID * self.contrast_gray)
    }
}

/// The smallest disc radius, undistorted pixels, at which the canopy rim can be judged
/// however sharp the disc's step: there the canopy rim's radius (`R / r`
/// times the disc's) is `MIN_STEP_WIDTH_PX / MAX_JUDGED_WIDTH_RADII`. A
/// disc whose minor semi-axis is smaller has no judged canopy point along
/// that axis.
pub fn smallest_judged_radius_px(drogue: DrogueCircles) -> f64 {
    let ratio = drogue.canopy_radius_m / drogue.inner_radius_m;
    MIN_STEP_WIDTH_PX / (MAX_JUDGED_WIDTH_RADII * ratio)
}

/// The entry of `by_angle` (sorted by angle, each within a turn of zero)
/// nearest in angle to `angle`: one of the two entries either side of it,
/// the list read as a circle. A binary search, not a scan: this runs twice
/// per canopy rim point, over lists of up to a few hundred rim points.
pub(crate) fn nearest<T>(by_angle: &[(f64, T)], angle: f64) -> Option<&(f64, T)> {
    let n = by_angle.len();
    if n == 0 {
        return None;
    }
    let above = by_angle.partition_point(|e| e.0 < angle);
    let (before, after) = (&by_angle[(above + n - 1) % n], &by_angle[above % n]);
    let gap = |e: &(f64, T)| super::angle_gap(e.0, angle);
    Some(if gap(before) <= gap(after) {
        before
    } else {
        after
    })
}

/// Fewest judged points of `samples` for a pose's rim to be judged: as
/// many as the shortest arc that holds [`MIN_JUDGED`] of [`SAMPLES`] points
/// (`MIN_JUDGED - 1` gaps of a [`SAMPLES`]th of the turn) holds of
/// `samples` evenly spaced points, so that a denser read judges the same
/// arcs of rim, not fewer (a quarter of 96 points, 24, would refuse an arc
/// in the frame that 12 of 48 points judge).
fn min_judged(samples: usize) -> usize {
    (MIN_JUDGED - 1) * samples / SAMPLES + 1
}

/// How far from `needed` a share of [`SAMPLES`] points is in doubt
/// ([`DOUBT_SIGMAS`] binomial standard deviations at `needed`).
fn doubt_about(needed: f64) -> f64 {
    let f = needed.clamp(0.0, 1.0);
    DOUBT_SIGMAS * (f * (1.0 - f) / SAMPLES as f64).sqrt()
}

/// Whether a candidate's canopy share `shown` is above `needed` beyond the
/// doubt of reading [`SAMPLES`] points ([`doubt_about`]): a candidate
/// whose share is within it may have passed by where its points fell
/// (its ellipse taking in the probe's outline can still show half of the
/// canopy's rim it predicts).
pub(super) fn shown_beyond_doubt(shown: f64, needed: f64) -> bool {
    shown >= needed + doubt_about(needed)
}

/// The canopy evidence of a candidate: the larger of its two poses'
/// shares of judged rim points with an outward brightening of at least
/// `edge.min_step_gray` near the predicted rim, read at [`SAMPLES`] points
/// evenly round each rim, and at the points half-way between as well
/// where a share is in doubt against `fails_below` ([`DOUBT_SIGMAS`]).
/// `None` when neither pose can be judged (degenerate ellipse, less than
/// about a quarter of the rim in the image, [`min_judged`]). The second
/// pose is read only as far as it could still show more than the first:
/// its points cost two profiles each, and once it cannot win (a clear
/// canopy shows on every point of the first) the larger share is known.
///
/// With `fails_below` (the share a candidate needs), a pose is read only
/// as far as it could still reach that share (or, on the first 48 points,
/// the lower end of the doubt): one that cannot gives the share of the
/// points read (below `fails_below`, as the whole ring's would be), so
/// that a candidate without a canopy, most of those a drogue-free frame
/// verifies, costs about half the reads. Whether the result is below
/// `fails_below`, and any result at or above it, are those of reading
/// every point.
#[allow(clippy::too_many_arguments)]
pub fn ring_support(
    image: &GrayImage,
    camera: &CameraModel,
    ellipse: &Ellipse,
    drogue: DrogueCircles,
    edge: RimEdge,
    fails_below: Option<f64>,
    profile: &mut Vec<f32>,
    scratch: &mut Vec<f32>,
) -> Option<f64> {
    let poses = cone_pose(ellipse, camera, drogue.inner_radius_m)?;
    let mut best: Option<Share> = None;
    for pose in &poses {
        let first = Reading {
            to_beat: best,
            fails_below: fails_below.map(|f| f - doubt_about(f)),
            after: None,
        };
        let mut share = pose_ring(image, camera, pose, drogue, edge, first, profile, scratch);
        if let (Some(f), Some(s)) = (fails_below, share)
            && s.judged >= min_judged(SAMPLES)
            && (s.fraction() - f).abs() < doubt_about(f)
        {
            let between = Reading {
                to_beat: best,
                fails_below,
                after: Some(s),
            };
            share = pose_ring(image, camera, pose, drogue, edge, between, profile, scratch);
        }
        if let Some(share) = share.filter(|s| s.judged >= min_judged(s.read))
            && best.is_none_or(|b| share.exceeds(b))
        {
            best = Some(share);
        }
    }
    best.map(Share::fraction)
}

/// Rim points judged along a pose's predicted canopy rim, and those with
/// an edge, of the points `read` round it ([`SAMPLES`], or twice that).
#[derive(Clone, Copy, Debug)]
struct Share {
    judged: usize,
    seen: usize,
    read: usize,
}

impl Share {
    /// Whether this share is larger than `other`'s (exact, in integers).
    fn exceeds(self, other: Share) -> bool {
        self.seen * other.judged > other.seen * self.judged
    }

    /// The share in `f64`, as [`ring_support`] gives it.
    fn fraction(self) -> f64 {
        self.seen as f64 / self.judged as f64
    }
}

/// How far a pose's ring is read: while its share could still exceed
/// `to_beat`'s, and reach `fails_below` ([`ring_support`]); `after`, the
/// share of its [`SAMPLES`] points already read, when these are the
/// points half-way between them.
#[derive(Clone, Copy)]
struct Reading {
    to_beat: Option<Share>,
    fails_below: Option<f64>,
    after: Option<Share>,
}

/// (judged, with an edge) along the canopy rim that `pose` predicts, at
/// [`SAMPLES`] points (added to `reading.after`'s, half a step on from
/// them, when given); `None` as soon as the points left could no longer
/// make the share larger than `reading.to_beat`'s, had every one of them
/// an edge; the share so far as soon as they could no longer lift it to
/// `reading.fails_below` (once enough points are judged, [`min_judged`]).
#[allow(clippy::too_many_arguments)]
fn pose_ring(
    image: &GrayImage,
    camera: &CameraModel,
    pose: &CirclePose,
    drogue: DrogueCircles,
    edge: RimEdge,
    reading: Reading,
    profile: &mut Vec<f32>,
    scratch: &mut Vec<f32>,
) -> Option<Share> {
    let canopy_radius_m = drogue.canopy_radius_m;
    let (e1, e2) = circle_plane_basis(&pose.normal_camera)?;
    // The rim's radius in pixels, for the width of the search.
    let centre = camera.project_px(&pose.centre_camera_m)?;
    let inner_radius_m = drogue.inner_radius_m;
    let (mut judged, mut seen) = reading.after.map_or((0, 0), |a| (a.judged, a.seen));
    let (read, phase) = match reading.after {
        Some(_) => (2 * SAMPLES, 0.5),
        None => (SAMPLES, 0.0),
    };
    for k in 0..SAMPLES {
        let left = SAMPLES - k;
        // The most the share could still be: every point left judged and
        // with an edge.
        let most = Share {
            judged: judged + left,
            seen: seen + left,
            read,
        };
        if reading.to_beat.is_some_and(|b| !most.exceeds(b)) {
            return None;
        }
        if judged >= min_judged(read) && reading.fails_below.is_some_and(|f| most.fraction() < f) {
            return Some(Share { judged, seen, read });
        }
        let t = std::f64::consts::TAU * (k as f64 + phase) / SAMPLES as f64;
        let radial = t.cos() * e1 + t.sin() * e2;
        let Some((p, d)) = camera.project_px_with_derivative(
            &(pose.centre_camera_m + canopy_radius_m * radial),
            &radial,
        ) else {
            continue;
        };
        let len = d[0].hypot(d[1]);
        if !(len > 0.0 && len.is_finite()) {
            continue;
        }
        let out = [d[0] / len, d[1] / len];
        let radius_px = (p[0] - centre[0]).hypot(p[1] - centre[1]);
        let angle = (p[1] - centre[1]).atan2(p[0] - centre[0]);
        let width = edge.width_at(angle).max(MIN_STEP_WIDTH_PX);
        if width > MAX_JUDGED_WIDTH_RADII * radius_px {
            continue;
        }
        let search = (SEARCH_RADII * radius_px).max(MIN_SEARCH_PX);
        // Half the difference's width more on each side.
        let half = 0.5 * width;
        rim::profile(
            image,
            p,
            out,
            -search - half,
            search + half,
            STEP_PX,
            profile,
        );
        // `as` truncates: the floor of this positive count, without a libm
        // call.
        let expected = (((2.0 * (search + half)) / STEP_PX) as usize).saturating_add(1);
        if profile.len() < expected || profile.iter().any(|&v| v >= SATURATED_GRAY) {
            continue;
        }
        judged += 1;
        let lag = (width / STEP_PX).round() as usize;
        // The strongest 2 px rise and where its middle lies (offset from
        // the predicted rim, pixels).
        let Some((at, strongest)) = strongest_rise_over(profile, lag) else {
            continue;
        };
        let offset = -search - half + (at as f64 + 0.5 * lag as f64) * STEP_PX;
        let tolerance = (TOLERANCE_RADII * radius_px)
            .max(MIN_TOLERANCE_PX)
            .max(0.25 * width);
        let min_rise = edge
            .min_step_gray
            .max(NOISE_BRIGHTENING_SIGMAS * edge.noise_gray);
        let brightening = strongest >= min_rise && offset.abs() <= tolerance;
        let band_px = (drogue.canopy_band_m / canopy_radius_m) * radius_px;
        let mut outer_edge = || {
            // The background is read well beyond the rim's band: a band
            // read as background would make the canopy's edge against it
            // (darkening outward, inside the true rim) look like the rim.
            let start = -search - half;
            rim::profile(
                image,
                p,
                out,
                start,
                (OUTER_BACKGROUND_RADII * radius_px).max(search + half),
                STEP_PX,
                profile,
            );
            outer_edge_offset(
                profile,
                lag,
                start,
                tolerance + half,
                edge.min_step_gray,
                min_rise,
                scratch,
            )
        };
        // Either edge is the canopy's only with the canopy before it.
        let canopy_lighter = || {
            edge.canopy_floor_at(angle).is_some_and(|floor| {
                canopy_between(
                    image,
                    camera,
                    pose,
                    &radial,
                    inner_radius_m,
                    canopy_radius_m,
                    floor,
                )
            })
        };
        // The rim's own edge or, for an edge that darkens outward, up to a
        // band's width further in: where haze has given the band the sky's
        // level, the light canopy ends there.
        let edge_seen = brightening
            || outer_edge().is_some_and(|o| {
                let inward = if o.lighter_inside { band_px } else { 0.0 };
                o.offset_px <= tolerance && o.offset_px >= -tolerance - inward
            });
        if edge_seen && canopy_lighter() {
            seen += 1;
        }
    }
    Some(Share { judged, seen, read })
}

/// The strongest rise of `profile` over `lag` samples, `p[k + lag] - p[k]`,
/// and its `k` (the last of equal ones, as `Iterator::max_by` gives it);
/// `None` for a profile of `lag` samples or fewer. A plain loop: a fifth
/// fewer instructions than the iterator chain over `windows`, on every
/// point of the canopy's rim.
fn strongest_rise_over(profile: &[f32], lag: usize) -> Option<(usize, f32)> {
    let later = profile.get(lag..)?;
    let mut best: Option<(usize, f32)> = None;
    for (k, (&a, &b)) in profile.iter().zip(later).enumerate() {
        let rise = b - a;
        if best.is_none_or(|(_, most)| rise.total_cmp(&most).is_ge()) {
            best = Some((k, rise));
        }
    }
    best
}

/// Whether the canopy between the disc and its outer rim, along the 3-D
/// radial direction `radial` of `pose`'s plane, is lighter than `floor`
/// (gray level; [`RimEdge::canopy_floor_at`]): at [`ANNULUS_SAMPLES`]
/// points from [`ANNULUS_FROM_INNER`] of the disc's radius to
/// [`ANNULUS_TO_OUTER`] of the rim's, all but one lighter (one may fall on
/// a strut's shadow or a cable). Saturated samples count as light.
fn canopy_between(
    image: &GrayImage,
    camera: &CameraModel,
    pose: &CirclePose,
    radial: &nalgebra::Vector3<f64>,
    inner_radius_m: f64,
    canopy_radius_m: f64,
    floor: f32,
) -> bool {
    let from = ANNULUS_FROM_INNER * inner_radius_m;
    let to = ANNULUS_TO_OUTER * canopy_radius_m;
    if to.partial_cmp(&from) != Some(std::cmp::Ordering::Greater) {
        return false;
    }
    let mut dark = 0;
    for j in 0..ANNULUS_SAMPLES {
        let rho = from + (to - from) * j as f64 / (ANNULUS_SAMPLES - 1) as f64;
        let Some([u, v]) = camera.project_px(&(pose.centre_camera_m + rho * radial)) else {
            return false;
        };
        let Some(value) = rim::sample(image, u, v) else {
            return false;
        };
        if value < floor {
            dark += 1;
            if dark > 1 {
                return false;
            }
        }
    }
    true
}

/// The drogue's outer edge on a profile across the predicted rim.
#[derive(Clone, Copy, Debug)]
struct OuterEdge {
    /// Offset from the predicted rim, pixels (outward +).
    offset_px: f64,
    /// Whether the profile inside the edge is lighter than the background
    /// beyond it (the edge darkens outward).
    lighter_inside: bool,
}

/// Where the drogue ends along a profile across the predicted rim (samples
/// [`STEP_PX`] apart from offset `start`, pixels): the outermost place where
/// the profile leaves the background's level by at least `min_step`, next
/// to a place off it by `noise_step` (the step the frame's noise does not
/// make, at least `min_step`), with the level changing by `min_step` across
/// it and most of the profile inside it off that level too (band and
/// canopy), or `None`. The background is the median of the samples beyond
/// offset `outside_from`. `scratch` is reused between calls (this runs per
/// rim point).
///
/// Either polarity counts. The rim band is darker than a clear sky, but haze
/// lifts the band toward the airlight, above a darker patch of sky or a
/// vignetted corner; the band then darkens outward to the sky instead of
/// brightening, and only the polarity-free test sees the canopy's edge.
fn outer_edge_offset(
    profile: &[f32],
    lag: usize,
    start: f64,
    outside_from: f64,
    min_step: f32,
    noise_step: f32,
    scratch: &mut Vec<f32>,
) -> Option<OuterEdge> {
    let first_outside = ((outside_from - start) / STEP_PX).ceil().max(0.0) as usize;
    scratch.clear();
    scratch.extend_from_slice(profile.get(first_outside..)?);
    if scratch.len() < OUTER_MIN_BACKGROUND {
        return None;
    }
    let mid = scratch.len() / 2;
    let background = *scratch.select_nth_unstable_by(mid, f32::total_cmp).1;
    // Box means of `lag + 1` samples (the disc's step width): the noise of
    // single samples would leave the background anywhere.
    let n = lag + 1;
    if profile.len() < 2 * n {
        return None;
    }
    scratch.clear();
    scratch.extend(profile.windows(n).map(|w| w.iter().sum::<f32>() / n as f32));
    let means: &[f32] = scratch;
    let off = |m: f32| (m - background).abs() >= min_step;
    // The edge is followed out from the outermost mean off the background
    // by a step that noise does not make (`noise_step`), through the means
    // next to it off by `min_step`: in noise a box mean out in the sky
    // leaves the background's level by `min_step` now and then, and taking
    // the outermost such mean placed the drogue's end out in the sky, where
    // most of the profile inside it is not off (refused). Without a mean
    // that far off, the outermost off by `min_step`.
    let edge = match means
        .iter()
        .rposition(|&m| (m - background).abs() >= noise_step)
    {
        Some(strong) => strong + means[strong + 1..].iter().take_while(|&&m| off(m)).count(),
        None => means.iter().rposition(|&m| off(m))?,
    };
    // An end is a step: the level changes by `min_step` across it within
    // a box either side (a sky brightening slowly across the predicted
    // rim leaves the background somewhere too, and is no edge).
    let (inward, outward) = (
        means[edge.saturating_sub(n)],
        means[(edge + n).min(means.len() - 1)],
    );
    if (inward - outward).abs() < min_step {
        return None;
    }
    let inside = &means[..=edge];
    let away = inside.iter().filter(|&&m| off(m)).count();
    if (away as f64) < OUTER_MIN_INSIDE_SHARE * inside.len() as f64 {
        return None;
    }
    // The crossing of the level halfway between the background and the
    // level one window further in: the edge's middle.
    let level = means[edge.saturating_sub(n)];
    let half_way = 0.5 * (level + background);
    let crossing = (0..=edge)
        .rev()
        .find(|&i| (means[i] - background).abs() >= (half_way - background).abs())
        .unwrap_or(edge);
    Some(OuterEdge {
        offset_px: start + (crossing as f64 + 0.5 * lag as f64) * STEP_PX,
        lighter_inside: level > background,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A canopy at 175 ending 10 px into a profile (samples [`STEP_PX`]
    /// apart from -10 px) on a sky at 135, with a level 14 gray levels
    /// above the sky over 2.5 px (a box of the tests' 5 samples) at +20 px.
    fn canopy_then_sky_with_a_blip() -> Vec<f32> {
        (0..80)
            .map(|k| {
                let at = -10.0 + f64::from(k) * STEP_PX;
                if at < 0.0 {
                    175.0
                } else if (20.0..22.5).contains(&at) {
                    149.0
                } else {
                    135.0
                }
            })
            .collect()
    }

    #[test]
    fn a_blip_of_noise_out_in_the_sky_is_not_the_drogues_end() {
        // In noise whose steps reach 16 gray levels, the blip of 14 is
        // noise: the drogue ends where the canopy does.
        let profile = canopy_then_sky_with_a_blip();
        let mut scratch = Vec::new();
        let edge = outer_edge_offset(&profile, 4, -10.0, 3.0, 12.0, 16.0, &mut scratch)
            .expect("the canopy's end");
        assert!(edge.offset_px.abs() <= 1.0, "{}", edge.offset_px);
        assert!(edge.lighter_inside);
        // Without noise a step of 14 is a step: the outermost one is the
        // drogue's end, and most of the profile inside it is sky (refused),
        // as before the noise was taken into account.
        let quiet = outer_edge_offset(&profile, 4, -10.0, 3.0, 12.0, 12.0, &mut scratch);
        assert!(quiet.is_none(), "{:?}", quiet.map(|e| e.offset_px));
    }

    #[test]
    fn a_sky_brightening_slowly_across_the_rim_is_no_end() {
        // 40 gray levels over 40 px, 0.5 per sample: it leaves the
        // background's level (by 12) with most of the profile inside it
        // off too, but changes by 5 across two boxes: no step.
        let ramp: Vec<f32> = (0..120)
            .map(|k| 175.0 - 0.5 * (k as f32).min(80.0))
            .collect();
        let mut scratch = Vec::new();
        let end = outer_edge_offset(&ramp, 4, -10.0, 3.0, 12.0, 12.0, &mut scratch);
        assert!(end.is_none(), "{:?}", end.map(|e| e.offset_px));
        // The same 40 levels as a step at 0 px are an end there.
        let step: Vec<f32> = (0..120)
            .map(|k| if k < 20 { 175.0 } else { 135.0 })
            .collect();
        let end = outer_edge_offset(&step, 4, -10.0, 3.0, 12.0, 12.0, &mut scratch)
            .expect("a step's end");
        assert!(end.offset_px.abs() <= 1.0, "{}", end.offset_px);
    }

    #[test]
    fn strongest_rise_over_a_lag_is_the_windows_max_by() {
        let windows = |p: &[f32], lag: usize| {
            p.windows(lag + 1)
                .map(|w| w[lag] - w[0])
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(&b.1))
        };
        // Equal rises (the last one wins), a fall, too short a profile.
        let p = [1.0f32, 3.0, 5.0, 5.0, 7.0, 9.0, 2.0, 0.0, 2.0];
        for lag in 0..=p.len() + 1 {
            assert_eq!(strongest_rise_over(&p, lag), windows(&p, lag), "lag {lag}");
        }
        assert_eq!(strongest_rise_over(&[], 0), None);
    }

    #[test]
    fn nearest_by_angle_is_the_scans_answer_across_the_turn() {
        // Rim angles as atan2 gives them (sorted, one turn), and queries
        // all round, including past either end of the list.
        let by_angle: Vec<(f64, usize)> = [-3.05, -2.0, -0.4, 0.3, 1.7, 2.95]
            .into_iter()
            .enumerate()
            .map(|(i, a)| (a, i))
            .collect();
        for k in 0..720 {
            let angle = -std::f64::consts::PI + f64::from(k) * std::f64::consts::TAU / 720.0;
            let scan = by_angle
                .iter()
                .min_by(|x, y| {
                    super::super::angle_gap(x.0, angle)
                        .total_cmp(&super::super::angle_gap(y.0, angle))
                })
                .map(|e| e.1);
            assert_eq!(nearest(&by_angle, angle).map(|e| e.1), scan, "at {angle}");
        }
        // Directions over 0..2 pi (the fill test's), brought into atan2's
        // turn for the lookup: the scan's answer for the direction itself.
        for k in 0..720 {
            let phi = f64::from(k) * std::f64::consts::TAU / 720.0;
            let scan = by_angle
                .iter()
                .min_by(|x, y| {
                    super::super::angle_gap(x.0, phi).total_cmp(&super::super::angle_gap(y.0, phi))
                })
                .map(|e| e.1);
            let turned = if phi > std::f64::consts::PI {
                phi - std::f64::consts::TAU
            } else {
                phi
            };
            assert_eq!(nearest(&by_angle, turned).map(|e| e.1), scan, "at {phi}");
        }
        assert!(nearest::<usize>(&[], 0.0).is_none());
    }
    use image::Luma;
    use nalgebra::Matrix3;

    fn camera() -> CameraModel {
        let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
        CameraModel::new("t", 640, 480, k, [0.0; 5]).unwrap()
    }

    /// A drogue seen face on at 2 m: disc (r 0.15 m, 60 px), canopy to
    /// 0.30 m, a dark rim band to 0.33 m, sky; or the disc alone.
    fn render(with_canopy: bool) -> GrayImage {
        if with_canopy {
            render_levels([30, 150, 70, 170])
        } else {
            render_levels([30, 170, 170, 170])
        }
    }

    /// The drogue of [`render`] under haze: the airlight lifts the rim's
    /// band above a darker sky, so the band darkens outward to the sky.
    fn render_hazy() -> GrayImage {
        render_levels([120, 175, 150, 135])
    }

    /// Disc, canopy, band and sky levels of the drogue of [`render`].
    fn render_levels(levels: [u8; 4]) -> GrayImage {
        GrayImage::from_fn(640, 480, |x, y| {
            let r = (f64::from(x) - 320.0).hypot(f64::from(y) - 240.0) * 2.0 / 800.0;
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

    const DROGUE: DrogueCircles = DrogueCircles {
        inner_radius_m: 0.15,
        canopy_radius_m: 0.33,
        canopy_band_m: 0.018,
    };

    const EDGE: RimEdge = RimEdge {
        min_step_gray: 20.0,
        noise_gray: 0.0,
        widths: &[(0.0, 2.0)],
        mids: &[(0.0, 90.0)],
        contrast_gray: 140.0,
    };

    /// The canopy evidence of `ellipse` on `image` through [`camera`].
    fn support(image: &GrayImage, ellipse: &Ellipse, edge: RimEdge) -> Option<f64> {
        ring_support(
            image,
            &camera(),
            ellipse,
            DROGUE,
            edge,
            None,
            &mut Vec::new(),
            &mut Vec::new(),
        )
    }

    /// The canopy evidence of [`disc`] on `image` where a share of
    /// `needed` is required.
    fn support_needing(image: &GrayImage, needed: f64) -> Option<f64> {
        ring_support(
            image,
            &camera(),
            &disc(),
            DROGUE,
            EDGE,
            Some(needed),
            &mut Vec::new(),
            &mut Vec::new(),
        )
    }

    /// One pose's rim of `ellipse` read whole: at [`SAMPLES`] points, and
    /// with `between` the points half-way between as well.
    fn read_whole(image: &GrayImage, ellipse: &Ellipse, pose: usize, between: bool) -> Share {
        let poses = cone_pose(ellipse, &camera(), DROGUE.inner_radius_m).unwrap();
        let read = |after: Option<Share>| {
            let reading = Reading {
                to_beat: None,
                fails_below: None,
                after,
            };
            let (mut profile, mut scratch) = (Vec::new(), Vec::new());
            pose_ring(
                image,
                &camera(),
                &poses[pose],
                DROGUE,
                EDGE,
                reading,
                &mut profile,
                &mut scratch,
            )
            .unwrap()
        };
        let first = read(None);
        if between { read(Some(first)) } else { first }
    }

    fn disc() -> Ellipse {
        Ellipse {
            cx: 320.0,
            cy: 240.0,
            a: 60.0,
            b: 60.0,
            theta: 0.0,
        }
    }

    #[test]
    fn a_drogue_shows_its_canopy_rim() {
        let s = support(&render(true), &disc(), EDGE);
        assert!(s.is_some_and(|s| s > 0.9), "{s:?}");
    }

    #[test]
    fn a_hazy_drogue_whose_band_is_lighter_than_the_sky_shows_its_rim() {
        // As the detector asks: a tenth of the disc's rim step (55), at
        // least half of `min_contrast_gray` (12).
        let edge = RimEdge {
            min_step_gray: 6.0,
            noise_gray: 0.0,
            widths: &[(0.0, 2.0)],
            mids: &[(0.0, 147.0)],
            contrast_gray: 55.0,
        };
        let s = support(&render_hazy(), &disc(), edge);
        assert!(s.is_some_and(|s| s > 0.9), "{s:?}");
        // Without the disc's mid level the canopy cannot be told from a
        // dark shape beside the disc: nothing counts.
        let blind = RimEdge { mids: &[], ..edge };
        let s = support(&render_hazy(), &disc(), blind);
        assert!(s.is_some_and(|s| s < 0.1), "{s:?}");
        // An ellipse inside the disc predicts a rim inside the canopy:
        // the canopy-to-band edge there is not the drogue's outer edge.
        for a in [35.0, 54.0] {
            let inner = Ellipse { a, b: a, ..disc() };
            let s = support(&render_hazy(), &inner, edge);
            assert!(s.is_some_and(|s| s < 0.1), "{a}: {s:?}");
        }
    }

    /// Heavier haze: the band takes the sky's level, and the light canopy
    /// ends a band's width (0.018 m, `DROGUE`'s) inside the rim, darkening
    /// outward straight to the sky. That end is the drogue's outer edge
    /// there; taken for nothing (as before), the evidence was 0.
    #[test]
    fn a_hazy_drogue_whose_band_has_the_sky_level_shows_its_canopy_end() {
        let rim_m = DROGUE.canopy_radius_m;
        let end_m = rim_m - DROGUE.canopy_band_m;
        let image = GrayImage::from_fn(640, 480, |x, y| {
            let r = (f64::from(x) - 320.0).hypot(f64::from(y) - 240.0) * 2.0 / 800.0;
            Luma([if r < 0.15 {
                120
            } else if r < end_m {
                175
            } else {
                135
            }])
        });
        let edge = RimEdge {
            min_step_gray: 6.0,
            noise_gray: 0.0,
            widths: &[(0.0, 2.0)],
            mids: &[(0.0, 147.0)],
            contrast_gray: 55.0,
        };
        let s = support(&image, &disc(), edge);
        assert!(s.is_some_and(|s| s > 0.9), "{s:?}");
        // An ellipse 15 % smaller predicts its rim inside the canopy: the
        // canopy's end lies outside that rim, where no band's allowance
        // reaches, and does not count.
        let smaller = Ellipse {
            a: 60.0 * end_m / rim_m * 0.9,
            b: 60.0 * end_m / rim_m * 0.9,
            ..disc()
        };
        let s = support(&image, &smaller, edge);
        assert!(s.is_some_and(|s| s < 0.1), "{s:?}");
    }

    /// The drogue of [`render`] with its canopy shown over `shown` of the
    /// turn only (the rest the disc alone on the sky).
    fn render_partly(shown: f64) -> GrayImage {
        let (whole, bare) = (render(true), render(false));
        GrayImage::from_fn(640, 480, |x, y| {
            let angle = (f64::from(y) - 240.0).atan2(f64::from(x) - 320.0);
            let turn = (angle / std::f64::consts::TAU).rem_euclid(1.0);
            if turn < shown {
                *whole.get_pixel(x, y)
            } else {
                *bare.get_pixel(x, y)
            }
        })
    }

    /// The share [`ring_support`] gives with `needed`, every point of its
    /// reading plan read: each pose's 48 points, and the 96 where the 48's
    /// share is in doubt; the larger of the poses that can be judged.
    fn planned_whole(image: &GrayImage, ellipse: &Ellipse, needed: f64) -> Option<f64> {
        let doubt = doubt_about(needed);
        (0..2)
            .map(|pose| {
                let first = read_whole(image, ellipse, pose, false);
                if (first.fraction() - needed).abs() < doubt {
                    read_whole(image, ellipse, pose, true)
                } else {
                    first
                }
            })
            .filter(|s| s.judged >= min_judged(s.read))
            .map(Share::fraction)
            .max_by(f64::total_cmp)
    }

    /// Read only while it could pass (and, on its first 48 points, while it
    /// could reach the doubt's lower end), a ring gives the verdict of its
    /// plan read whole ([`planned_whole`]), and any share at or above the
    /// one needed exactly.
    #[test]
    fn a_ring_read_only_while_it_could_pass_gives_the_whole_rings_verdict() {
        let needed = 0.5;
        let (mut passed, mut failed, mut near) = (0, 0, 0);
        for shown in [0.0, 0.2, 0.4, 0.45, 0.5, 0.55, 0.6, 0.8, 1.0] {
            for image in [
                render_partly(shown),
                with_noise(&render_partly(shown), 8.0, 3),
            ] {
                let whole = planned_whole(&image, &disc(), needed);
                let limited = support_needing(&image, needed);
                match whole {
                    Some(w) if w >= needed => assert_eq!(limited, whole, "{shown}"),
                    Some(_) => assert!(limited.is_some_and(|l| l < needed), "{shown}: {limited:?}"),
                    None => assert_eq!(limited, None, "{shown}"),
                }
                let w = whole.unwrap_or(f64::NAN);
                if w >= needed {
                    passed += 1;
                } else {
                    failed += 1;
                }
                if (w - needed).abs() <= 0.1 {
                    near += 1;
                }
            }
        }
        // Both verdicts, and shares close to the one needed, are covered.
        assert!(
            passed >= 6 && failed >= 6 && near >= 4,
            "{passed} {failed} {near}"
        );
    }

    #[test]
    fn a_disc_without_canopy_and_a_wrong_size_show_none() {
        let bare = support(&render(false), &disc(), EDGE);
        assert!(bare.is_some_and(|s| s < 0.1), "{bare:?}");
        // An ellipse inside the disc predicts a rim inside the canopy.
        let inner = Ellipse {
            a: 35.0,
            b: 35.0,
            ..disc()
        };
        let s = support(&render(true), &inner, EDGE);
        assert!(s.is_some_and(|s| s < 0.1), "{s:?}");
    }

    /// `image` with Gaussian pixel noise of `sigma` gray levels added
    /// (fixed seed), clipped to 0-255.
    fn with_noise(image: &GrayImage, sigma: f64, seed: u64) -> GrayImage {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut noisy = image.clone();
        for p in noisy.pixels_mut() {
            // Box-Muller.
            let (u, v): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
            let n = (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos();
            p.0[0] = (f64::from(p.0[0]) + sigma * n).round().clamp(0.0, 255.0) as u8;
        }
        noisy
    }

    /// The smallest judged radius, from its definition: a 2 px step is
    /// judged up to 15 % of the canopy rim's radius, which is `R / r` disc
    /// radii: 2 / (0.15 x 0.33 / 0.15) = 6.06 px for the test's drogue.
    #[test]
    fn the_smallest_judged_radius_follows_from_the_widest_judged_step() {
        let r = smallest_judged_radius_px(DROGUE);
        assert!((r - 2.0 / (0.15 * 0.33 / 0.15)).abs() < 1e-9, "{r}");
    }

    /// A dark disc in plain sky, in noise: there is no canopy rim, and the
    /// strongest brightening across each predicted rim point is the
    /// noise's. What the test finds must stay well below the share the
    /// detector requires (`min_canopy_fraction`, 0.5); before the noise
    /// floor it found about half (0.46 to 0.56 here).
    #[test]
    fn noise_alone_shows_no_canopy_rim() {
        // A weak disc (47 gray levels, as a star's arm in haze) judged with
        // the least step the detector asks: 6 gray levels.
        let bare = render_levels([120, 167, 167, 167]);
        for (sigma, seed) in [(4.0, 1), (7.0, 2), (12.0, 3), (20.0, 4)] {
            let edge = RimEdge {
                min_step_gray: 6.0,
                noise_gray: sigma as f32,
                widths: &[(0.0, 2.0)],
                mids: &[(0.0, 143.0)],
                contrast_gray: 47.0,
            };
            let image = with_noise(&bare, sigma, seed);
            let s = support(&image, &disc(), edge);
            assert!(s.is_some_and(|s| s < 0.35), "noise {sigma}: {s:?}");
        }
    }

    /// Any arc of the rim (in the frame, not saturated) that 12 of 48
    /// points judge is judged by 96 points too, wherever the
    /// points fall on it, and 23 is the most the denser read may ask: some
    /// arc holding 22 of its points holds fewer than 12 of the 48.
    #[test]
    fn a_denser_read_judges_every_arc_the_comparing_read_judges() {
        let held = |arc: f64, phase: f64, samples: usize| {
            (0..samples)
                .filter(|&k| ((k as f64 + phase) / samples as f64).rem_euclid(1.0) < arc)
                .count()
        };
        let mut tightest = false;
        for a in 0..=1000 {
            let arc = f64::from(a) / 1000.0;
            for p in 0..20 {
                let phase = f64::from(p) / 20.0;
                // The two reads' points as `pose_ring` places them: the
                // 48 are every other one of the 96.
                let (coarse, dense) = (held(arc, phase, SAMPLES), held(arc, 2.0 * phase, 96));
                if coarse >= MIN_JUDGED {
                    assert!(dense >= min_judged(96), "{arc} {phase}: {coarse} {dense}");
                }
                tightest |= dense == min_judged(96) - 1 && coarse < MIN_JUDGED;
            }
        }
        assert!(tightest);
        assert_eq!(min_judged(SAMPLES), MIN_JUDGED);
        assert_eq!(min_judged(2 * SAMPLES), 23);
    }

    /// The points half-way between are other points, not the same ones
    /// read again: on a drogue whose canopy shows over a share of the
    /// turn, each read's share is that share to within about one of its
    /// own points (a point at either end of the arc may go either way), and
    /// the 96 points' count with an edge is not always twice the 48's, as
    /// two reads of the same 48 points would make it.
    #[test]
    fn the_points_in_between_are_the_rims_other_points() {
        let whole = read_whole(&render(true), &disc(), 0, true);
        assert_eq!(
            (whole.judged, whole.seen, whole.read),
            (2 * SAMPLES, 2 * SAMPLES, 2 * SAMPLES)
        );
        let mut not_twice = 0;
        for shown in [0.3, 0.41, 0.47, 0.52, 0.58, 0.66] {
            let image = render_partly(shown);
            let (first, both) = (
                read_whole(&image, &disc(), 0, false),
                read_whole(&image, &disc(), 0, true),
            );
            assert_eq!((first.judged, both.judged), (SAMPLES, 2 * SAMPLES));
            for share in [first, both] {
                assert!(
                    (share.fraction() - shown).abs() <= 1.5 / share.read as f64,
                    "{shown}: {share:?}"
                );
            }
            not_twice += usize::from(both.seen != 2 * first.seen);
        }
        assert!(not_twice >= 2, "{not_twice}");
    }

    /// Where the canopy is required, a share of 48 points in doubt
    /// (within [`DOUBT_SIGMAS`] of the share needed) is the share of all
    /// 96 points; one clear of it is the 48 points' share: on canopies
    /// shown over 0-100 % of the turn, as [`read_whole`] reads them.
    #[test]
    fn a_share_in_doubt_is_read_again_between_its_points() {
        let needed = 0.5;
        let doubt = doubt_about(needed);
        let (mut in_doubt, mut clear) = (0, 0);
        for shown in [0.1, 0.3, 0.4, 0.45, 0.5, 0.55, 0.6, 0.7, 0.9] {
            let image = render_partly(shown);
            let given = support_needing(&image, needed).unwrap();
            // Face on, the two poses' rims are one.
            let first = read_whole(&image, &disc(), 0, false);
            if (first.fraction() - needed).abs() < doubt {
                in_doubt += 1;
                let both = read_whole(&image, &disc(), 0, true);
                if both.fraction() >= needed {
                    assert_eq!(given, both.fraction(), "{shown}");
                } else {
                    assert!(given < needed, "{shown}: {given}");
                }
            } else {
                clear += 1;
                if first.fraction() >= needed {
                    assert_eq!(given, first.fraction(), "{shown}");
                } else {
                    assert!(given < needed, "{shown}: {given}");
                }
            }
        }
        assert!(in_doubt >= 3 && clear >= 4, "{in_doubt} {clear}");
    }

    /// The second pose, read only while it could still show more than the
    /// first, gives the share both poses read whole give: on ellipses of
    /// the drogue, tilted and not, beside it and inside it, in noise.
    #[test]
    fn the_second_pose_read_in_part_gives_the_share_read_whole() {
        let whole = |image: &GrayImage, ellipse: &Ellipse, edge: RimEdge| {
            let poses = cone_pose(ellipse, &camera(), DROGUE.inner_radius_m)?;
            poses
                .iter()
                .filter_map(|pose| {
                    let (mut profile, mut scratch) = (Vec::new(), Vec::new());
                    let s = pose_ring(
                        image,
                        &camera(),
                        pose,
                        DROGUE,
                        edge,
                        Reading {
                            to_beat: None,
                            fails_below: None,
                            after: None,
                        },
                        &mut profile,
                        &mut scratch,
                    )?;
                    (s.judged >= min_judged(s.read)).then(|| s.fraction())
                })
                .max_by(f64::total_cmp)
        };
        let mut compared = 0;
        for (image, sigma) in [(render(true), 0.0), (render(false), 0.0)]
            .into_iter()
            .chain(
                [(4.0, 1), (12.0, 2)]
                    .map(|(sigma, seed)| (with_noise(&render(true), sigma, seed), sigma)),
            )
        {
            let edge = RimEdge {
                noise_gray: sigma as f32,
                ..EDGE
            };
            for (a, b, theta, dx) in [
                (60.0, 60.0, 0.0, 0.0),
                (60.0, 45.0, 0.4, 0.0),
                (60.0, 30.0, -1.0, 3.0),
                (45.0, 45.0, 0.0, 20.0),
                (35.0, 30.0, 0.2, 0.0),
            ] {
                let ellipse = Ellipse {
                    cx: 320.0 + dx,
                    a,
                    b,
                    theta,
                    ..disc()
                };
                let expected = whole(&image, &ellipse, edge);
                assert_eq!(support(&image, &ellipse, edge), expected, "{ellipse:?}");
                compared += usize::from(expected.is_some());
            }
        }
        assert!(compared >= 15, "{compared}");
    }

    /// The drogue's canopy rim, a band 40 gray levels darker than the sky,
    /// is still seen nearly all round in noise of a tenth to a third of
    /// that step.
    #[test]
    fn a_canopy_rim_in_noise_is_seen() {
        let drogue = render_levels([60, 150, 110, 150]);
        for (sigma, seed) in [(4.0, 5), (8.0, 6), (12.0, 7)] {
            let edge = RimEdge {
                min_step_gray: 9.0,
                noise_gray: sigma as f32,
                widths: &[(0.0, 2.0)],
                mids: &[(0.0, 105.0)],
                contrast_gray: 90.0,
            };
            let image = with_noise(&drogue, sigma, seed);
            let s = support(&image, &disc(), edge);
            assert!(s.is_some_and(|s| s > 0.9), "noise {sigma}: {s:?}");
        }
    }

    /// A dark flower whose round centre is the candidate: four arms, each
    /// 50 degrees wide, as dark as the disc, reach exactly to the predicted
    /// rim and end against the sky there; between them is sky. Along 56 %
    /// of the rim the arms' ends brighten outward where the canopy's rim
    /// should, but nothing lighter than the disc lies before them.
    #[test]
    fn edges_beyond_dark_arms_are_not_the_canopy_rim() {
        let image = GrayImage::from_fn(640, 480, |x, y| {
            let (dx, dy) = (f64::from(x) - 320.0, f64::from(y) - 240.0);
            let r = dx.hypot(dy) * 2.0 / 800.0;
            let angle = dy.atan2(dx).to_degrees().rem_euclid(90.0);
            let in_arm = r < 0.33 && angle < 50.0;
            Luma([if r < 0.15 || in_arm { 30 } else { 170 }])
        });
        let s = support(&image, &disc(), EDGE);
        assert!(s.is_some_and(|s| s < 0.1), "{s:?}");
    }
}
