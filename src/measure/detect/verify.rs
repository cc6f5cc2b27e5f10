//! Verification of a seed: the wide ray pass from its centre, a robust
//! fit, and the narrow pass around it (repeated until it settles), with the
//! checks of the rim itself (size, shape, contrast, one dark inside).

use super::glare::{GlareCover, glare_before_step, glare_on_light_side};
use super::search::Seed;
use super::shading::ShadedEdge;
use super::{
    Detector, Reject, SATURATED_GRAY, SHARP_STEP_OWN_PX, VEIL_MIN_GRAY, VEIL_SIGMAS, Verified,
    conic_fit, median, polar_radius, polar_radius_local, ray_directions, rim,
    smoothing_half_for_contrast, smoothing_half_for_ramp,
};
use crate::measure::ellipse::{Ellipse, ExposureSweep};
use image::GrayImage;
use std::f64::consts::TAU;

/// Rim ray spacing while candidates are compared, pixels (or the
/// configured spacing, if sparser). Fixed, not a multiple of
/// `rim_point_spacing_px`: the measuring pass's density changes what is
/// measured, not which candidates are found.
const SCOUT_SPACING_PX: f64 = 6.0;

/// Rim ray spacing of the pass that verifies the chosen candidate again at
/// full density, pixels (or the configured spacing, if sparser). Fixed for
/// the same reason: a denser measuring pass (`rim_point_spacing_px`)
/// follows the verification and changes what is measured, not which
/// candidate is the drogue.
pub(super) const VERIFY_SPACING_PX: f64 = 2.0;

/// Narrow-pass windows are widened by this factor while more than
/// [`CLIPPED_SHARE`] of the steps run into their ends (blur), up to
/// [`MAX_WIDEN`] times, and at most to [`MAX_WIDE_MARGIN_RADII`] of the
/// radius and [`MAX_WIDE_MARGIN_PX`] pixels each way (32 px of motion blur
/// is a 32 px ramp).
pub(super) const WIDEN_STEP: f64 = 2.5;
pub(super) const MAX_WIDEN: f64 = 6.25;
pub(super) const CLIPPED_SHARE: f64 = 0.25;
const MAX_WIDE_MARGIN_RADII: f64 = 0.6;
const MAX_WIDE_MARGIN_PX: f64 = 48.0;

/// Edges within this many of their robust scatter (and at least
/// `inlier_tolerance_px`) of the ellipse are on the rim.
const NOISE_TOLERANCE_SIGMAS: f64 = 3.0;

/// Relative difference of centre and axes within which two ellipses are
/// one rim ([`same_rim`]).
const SAME_RIM: f64 = 0.05;

/// Fewest rim points of a seed's wide pass worth a fit.
const MIN_WIDE_POINTS: usize = 8;
/// Straight edges among a wide pass's rim points: at least this many
/// points on a line (within the fit's tolerance) spanning at least this
/// many seed radii. Eight rays (52 degrees) of a circle lie on no line
/// within the 3 % tolerance, and the chord of a disc's rim that a line
/// could follow is shorter than its diameter only where the disc is seen
/// nearly edge on; a streak crossing the disc spans it and more.
const STRAIGHT_EDGE_MIN_POINTS: usize = 8;
const STRAIGHT_EDGE_MIN_SPAN_RADII: f64 = 1.5;
const MAX_STRAIGHT_EDGES: usize = 2;
/// A wide pass's fit without its straight edges that is within this share
/// of the first fit's size of it is that fit again: its narrow passes
/// would end as the first's did. Not [`SAME_RIM`]: narrow passes started
/// 5 % apart can settle on different edges (a probe's and the disc's).
const SAME_WIDE_FIT: f64 = 0.01;
/// A narrow pass whose ellipse moved by no more than this from its start
/// (centre or axis, pixels) has settled: candidates are compared, and their
/// ellipses checked against the fit, on settled rims.
const SETTLED_MOVE_PX: f64 = 0.5;
/// On a tracked frame, a pass has settled once it moved by no more than
/// this share of its narrowest window's half-width (at least
/// [`SETTLED_MOVE_PX`]): each ray's window is centred on the predicted rim,
/// and a step found this far from the centre lies well inside it, so that
/// a pass centred on it finds the same step (the window is at least 4 px
/// each way, a sharp step about 1.3 px each way of its middle). A near
/// drogue moves more than half a pixel between frames; repeating its pass
/// for that was about 8 % of a near tracked frame's instructions.
const SETTLED_WINDOW_SHARE: f64 = 0.25;
/// Rays round the rim on which a tracked motion's blur is predicted
/// ([`Detector::widen_for_motion`]): a share to within a few percent.
const MOTION_RAYS: usize = 64;

/// Samples per seed radius on the rays of a seed's wide first pass.
const WIDE_STEPS_PER_RADIUS: f64 = 40.0;
/// A light bar over the disc ends within this share of the gap between
/// the disc's rim and the canopy's outer rim ([`Detector::light_bars`]): the
/// canopy's darker rim band lies beyond.
const BAR_REACH_CANOPY_GAPS: f64 = 0.8;

/// One narrow rim pass around an ellipse, before its canopy evidence.
pub(super) struct RimPass {
    pub(super) ellipse: Ellipse,
    /// The rays' origin, distorted pixels.
    pub(super) centre: [f64; 2],
    pub(super) points_px: Vec<[f64; 2]>,
    /// The edges the pose is measured from, placed only once the pass is
    /// kept ([`super::evidence::MeasuredRim::near`]). The fit and the evidence use
    /// `points_px`, so that what is detected does not hang on the shading's
    /// estimate.
    pub(super) pose_edges: PoseEdges,
    pub(super) residuals: Vec<f64>,
    pub(super) inliers: Vec<usize>,
    /// Width of each point's step (twice its edge-to-light distance),
    /// pixels: wide along a motion blur.
    pub(super) step_widths_px: Vec<f64>,
    /// Share of the edges whose step still runs into its window's ends
    /// after the widest window: a blur longer than can be measured.
    pub(super) clipped_share: f64,
    /// How much the pass widened its window for blur ([`WIDEN_STEP`] at a
    /// time from its first, 1 or a tracked motion's): the one kept.
    pub(super) widened: f64,
    pub(super) rim_contrast: f64,
    /// Share of the rays in the image with their edge on the ellipse.
    pub(super) shape: f64,
    /// Share of the inside darker than the rim's mid level.
    pub(super) fill: f64,
    /// Distance from the ellipse counted as on the rim, pixels.
    pub(super) tolerance: f64,
    /// The rim's mid level by direction (angle about the ellipse's centre,
    /// gray level), for the canopy test.
    pub(super) mids: Vec<(f64, f32)>,
}

/// The steps of a narrow pass, one per ray that found one, column by
/// column (the fits take the points as one slice), in ray order.
struct RaySteps {
    /// Where each step crosses its mid level, distorted pixels.
    points_px: Vec<[f64; 2]>,
    /// The same points, undistorted.
    undistorted: Vec<[f64; 2]>,
    /// Each step's light minus its dark level, gray.
    contrasts: Vec<f64>,
    /// The middle between its levels, gray.
    mid_levels: Vec<f32>,
    /// Its width (twice its edge-to-light distance) less the profile
    /// smoothing's own spread, pixels: wide along a motion blur.
    widths_px: Vec<f64>,
    /// Steps into saturated pixels: a glare streak's skirt.
    glares: Vec<bool>,
    /// On a measuring pass (else empty), the edge the pose is measured
    /// from, distorted pixels ...
    measured_px: Vec<[f64; 2]>,
    /// ... and what moves it for the canopy's shading ...
    shading: Vec<ShadedEdge>,
    /// ... and how far out from it the light side reaches saturation
    /// ([`clipped_light_px`]; 0 for a step below saturation).
    clip_px: Vec<f64>,
}

impl RaySteps {
    fn with_capacity(rays: usize, rim_use: RimUse) -> Self {
        let measuring = if rim_use == RimUse::Measure { rays } else { 0 };
        Self {
            points_px: Vec::with_capacity(rays),
            undistorted: Vec::with_capacity(rays),
            contrasts: Vec::with_capacity(rays),
            mid_levels: Vec::with_capacity(rays),
            widths_px: Vec::with_capacity(rays),
            glares: Vec::with_capacity(rays),
            measured_px: Vec::with_capacity(measuring),
            shading: Vec::with_capacity(measuring),
            clip_px: Vec::with_capacity(measuring),
        }
    }

    fn len(&self) -> usize {
        self.points_px.len()
    }

    /// Takes out the steps whose flag in `marked` is set.
    fn drop_marked(&mut self, marked: &[bool]) {
        if !marked.iter().any(|&m| m) {
            return;
        }
        drop_marked(&mut self.points_px, marked);
        drop_marked(&mut self.undistorted, marked);
        drop_marked(&mut self.contrasts, marked);
        drop_marked(&mut self.mid_levels, marked);
        drop_marked(&mut self.widths_px, marked);
        drop_marked(&mut self.glares, marked);
        drop_marked(&mut self.measured_px, marked);
        drop_marked(&mut self.shading, marked);
        drop_marked(&mut self.clip_px, marked);
    }
}

/// One round of a narrow pass's rays ([`Detector::ray_steps`]).
struct RayRound {
    steps: RaySteps,
    /// Rays whose window lies in the image.
    rays_in_image: usize,
    /// Share of the steps (a glare's skirts aside) that run into their
    /// window's ends.
    clipped_share: f64,
}

/// What [`Detector::drop_glares_and_bars`] took out of a pass.
struct GlareDrop {
    /// The glare's steps (undistorted pixels) with their levels, for the
    /// fill test; empty unless they were taken out.
    glare_steps: Vec<([f64; 2], FillLevels)>,
    /// Whether steps into saturation were taken out.
    glares_dropped: bool,
    /// How many (their rays do not count as the rim's).
    glared: usize,
}

/// The edges of a narrow pass that the pose is measured from, not yet
/// placed: the canopy's shading's move and the undistortion wait until the
/// pass is kept (a tracked frame's first pass is often repeated from its
/// own ellipse, and a rejected one is never measured), and then take only
/// the points near its ellipse.
pub(super) enum PoseEdges {
    /// A scouting pass's own points, undistorted (aligned with its
    /// `points_px`).
    Own(Vec<[f64; 2]>),
    /// A measuring pass's edges (distorted pixels) and what moves each for
    /// the canopy's shading ([`super::shading::shaded_points`]), with the
    /// pass's own edges undistorted (within a fraction of a pixel of
    /// them: where the ellipse is sensitive to each,
    /// [`super::shading::better_without`]).
    Shaded {
        base_px: Vec<[f64; 2]>,
        shading: Vec<ShadedEdge>,
        found_undistorted: Vec<[f64; 2]>,
        /// How far out from each edge its light side reaches saturation,
        /// pixels (0 below saturation).
        clip_px: Vec<f64>,
        /// The edges onto a band within the dark ([`Detector::bands_within_dark`]),
        /// left out of the points measured.
        within_dark: Vec<bool>,
    },
}

/// What a narrow pass's points are for: comparing candidates, or measuring
/// the pose. Only the measuring pass places its points for a faint step's
/// noise and the canopy's shading (the detection uses the unmoved points
/// either way), so that the candidates' passes do not pay for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum RimUse {
    /// Scouting and comparing candidates.
    Scout,
    /// The pass whose points the pose is measured from.
    Measure,
}

/// Levels of a rim step that the fill test compares the inside with.
#[derive(Clone, Copy, Debug)]
pub(super) struct FillLevels {
    /// The middle of the step (gray): darker inside is the disc's.
    pub mid: f32,
    /// Its light side's level (gray): the canopy or sky beyond the rim.
    pub light: f32,
}

impl FillLevels {
    /// The levels of a step with mid level `mid` and `contrast` (its light
    /// minus its dark level), gray.
    pub(super) fn of_step(mid: f32, contrast: f64) -> Self {
        Self {
            mid,
            light: mid + 0.5 * contrast as f32,
        }
    }
}

/// Removes the items of `v` whose flag in `marked` (aligned with it) is set.
fn drop_marked<T>(v: &mut Vec<T>, marked: &[bool]) {
    let mut flags = marked.iter();
    v.retain(|_| !flags.next().copied().unwrap_or(false));
}

/// Whether `b` is the rim `a` to within [`SAME_RIM`] of its size (centre
/// and axes): a narrow pass around either meets the same edges (its window
/// is [`DetectConfig::rim_search_fraction`](super::DetectConfig) of the
/// radius, 10 % by default), so both settle on the same ellipse.
fn same_rim(a: &Ellipse, b: &Ellipse) -> bool {
    within_share(a, b, SAME_RIM)
}

/// Whether `b`'s centre and axes are within `share` of `a`'s size of
/// `a`'s.
fn within_share(a: &Ellipse, b: &Ellipse, share: f64) -> bool {
    let close = |x: f64, y: f64| (x / y - 1.0).abs() <= share;
    (a.cx - b.cx).hypot(a.cy - b.cy) <= share * a.b && close(a.a, b.a) && close(a.b, b.b)
}

/// Each step's light level: its mid level plus half its contrast.
fn step_lights(steps: &RaySteps) -> Vec<f64> {
    steps
        .contrasts
        .iter()
        .zip(&steps.mid_levels)
        .map(|(&c, &m)| f64::from(m) + 0.5 * c)
        .collect()
}

/// A narrow pass's profile as sampled: `raw` (kept before smoothing) when
/// it was smoothed with `half` > 0, else `profile` itself.
fn unsmoothed<'a>(raw: &'a [f32], profile: &'a [f32], half: usize) -> &'a [f32] {
    if half > 0 { raw } else { profile }
}

/// How far beyond `edge_s` profile `p` (sampled from `s_min` every `step`)
/// first reaches saturation, pixels (0 if it does not). A step whose light
/// side is clipped has its mid level taken between the dark level and the
/// clipped one, below the true one, and its crossing short of the edge:
/// for a step blurred by a symmetric spread the edge lies between that
/// crossing and about where saturation begins (beyond it only for a light
/// level more than twice the clipped one's distance above the dark), so
/// the pose's covariance takes this distance as the point's possible
/// inward displacement.
fn clipped_light_px(p: &[f32], s_min: f64, step: f64, edge_s: f64) -> f64 {
    let from = ((edge_s - s_min) / step).max(0.0) as usize;
    let Some(j) = (from..p.len()).find(|&j| p[j] >= SATURATED_GRAY) else {
        return 0.0;
    };
    // The crossing of the saturated level between the sample before and j.
    let at = if j > from && p[j] > p[j - 1] {
        (j - 1) as f64 + f64::from((SATURATED_GRAY - p[j - 1]) / (p[j] - p[j - 1]))
    } else {
        j as f64
    };
    (s_min + at * step - edge_s).max(0.0)
}

impl Detector {
    /// Verifies a coarse seed: a wide ray pass from its centre, a robust
    /// fit, then the narrow pass around that fit. A seed whose fit is the
    /// rim of a candidate in `known` stops there ([`Reject::Known`]): the
    /// narrow passes would settle on that candidate again; one whose narrow
    /// passes settle there stops before its evidence is taken.
    #[inline(never)]
    pub(super) fn verify_seed(
        &mut self,
        image: &GrayImage,
        seed: &Seed,
        index: u64,
        known: &[Verified],
    ) -> Result<Verified, Reject> {
        let rays = 48;
        let mut points = Vec::with_capacity(rays);
        let mut glares = Vec::with_capacity(rays);
        let c = seed.centre_px;
        // An elongated region (disc plus hose or probe) is not searched
        // along its length: the disc is across it.
        let longest = 2.0 * seed.b_px;
        for k in 0..rays {
            let phi = TAU * k as f64 / rays as f64;
            let r = polar_radius(seed.a_px, seed.b_px, seed.theta, phi).min(longest);
            let dir = [phi.cos(), phi.sin()];
            let s_max = seed.reach * r + 4.0;
            let s_min = (seed.from * r).max(1.0);
            // About a pixel of accuracy on a small seed, a few percent of
            // its size on a large one, is enough here (the narrow passes,
            // 10 % of the radius wide, refine it): a fixed number of steps
            // per radius, so that a large dark region (cloud, shadow) costs
            // no more than a disc.
            let step = (r / WIDE_STEPS_PER_RADIUS).max(0.5);
            rim::profile(image, c, dir, s_min, s_max, step, &mut self.profile);
            if let Some(e) = rim::strongest_rise(
                &self.profile,
                s_min,
                step,
                self.cfg.min_contrast_gray as f32,
            ) {
                let p = [c[0] + e.s * dir[0], c[1] + e.s * dir[1]];
                points.push(self.camera.undistort_px(p));
                glares.push(glare_on_light_side(&self.profile, s_min, step, &e));
            }
        }
        // As on the narrow passes: steps into saturated pixels (a glare
        // streak over the disc, whose skirt's straight edges are the
        // strongest rise on every ray that meets it) give no rim points,
        // unless they are most of them (an overexposed canopy).
        let glared = glares.iter().filter(|&&g| g).count();
        if glared > 0 && 2 * glared < glares.len() {
            drop_marked(&mut points, &glares);
        }
        if points.len() < MIN_WIDE_POINTS {
            return Err(Reject::NoRim(points.len()));
        }
        let scale = seed.b_px.max(1.0);
        let tolerance = (0.03 * scale).max(1.0);
        let first = self.wide_fit(&points, tolerance, index);
        let verified = first
            .ok_or(Reject::NoEllipse)
            .and_then(|e| self.verify_from_fit(image, &e, known));
        if matches!(verified, Ok(_) | Err(Reject::Known)) {
            return verified;
        }
        // A straight edge is no rim: a light streak's or an occluder's edge
        // across the disc is the strongest rise on every ray that meets
        // it, and the ellipse that hugs it can gather more points than the
        // disc's rim. The seed is tried once more without up to two such
        // edges (a streak's or a hose's two sides), unless its fit is the
        // first one again ([`SAME_WIDE_FIT`]).
        let mut rest = points.clone();
        for _ in 0..MAX_STRAIGHT_EDGES {
            let Some(on_edge) = conic_fit::straight_edge(
                &rest,
                tolerance,
                STRAIGHT_EDGE_MIN_POINTS,
                STRAIGHT_EDGE_MIN_SPAN_RADII * scale,
            ) else {
                break;
            };
            rest = (rest.iter().enumerate())
                .filter(|(i, _)| on_edge.binary_search(i).is_err())
                .map(|(_, p)| *p)
                .collect();
        }
        if rest.len() == points.len() || rest.len() < MIN_WIDE_POINTS {
            return verified;
        }
        let Some(second) = self
            .wide_fit(&rest, tolerance, index)
            .filter(|e| first.is_none_or(|f| !within_share(&f, e, SAME_WIDE_FIT)))
        else {
            return verified;
        };
        let again = self.verify_from_fit(image, &second, known);
        tracing::trace!(
            first = ?verified.as_ref().err(),
            dropped = points.len() - rest.len(),
            of = points.len(),
            again = ?again.as_ref().map(|v| v.score),
            "wide pass tried again without its straight edges"
        );
        if again.is_ok() { again } else { verified }
    }

    /// The robust ellipse of a wide pass's rim points (undistorted), within
    /// `tolerance` pixels.
    fn wide_fit(&self, points: &[[f64; 2]], tolerance: f64, index: u64) -> Option<Ellipse> {
        // Most rays on the rim: a trimmed least-squares fit will do; else
        // RANSAC (a hose or probe merged with the disc).
        conic_fit::fit_ellipse(points)
            .and_then(|e| conic_fit::refine(&e, points, 3.0 * tolerance, 1))
            .and_then(|e| conic_fit::refine(&e, points, tolerance, 2))
            .filter(|e| {
                let c = e.to_conic();
                let n = points
                    .iter()
                    .filter(|p| c.sampson_distance(p[0], p[1]) <= tolerance)
                    .count();
                n as f64 >= 0.8 * points.len() as f64
            })
            .or_else(|| conic_fit::ransac_ellipse(points, tolerance, 300, self.cfg.seed ^ index))
    }

    /// The rest of [`Self::verify_seed`] from its wide pass's ellipse
    /// `first`: its size and shape, the narrow passes, the evidence.
    fn verify_from_fit(
        &mut self,
        image: &GrayImage,
        first: &Ellipse,
        known: &[Verified],
    ) -> Result<Verified, Reject> {
        if !self.plausible(first, 0.5) {
            return Err(Reject::Implausible);
        }
        if self.known_rim(known, first) {
            return Err(Reject::Known);
        }
        // Candidates are compared on a sparser rim (cheaper); the winner
        // gets the full density.
        let pass = self.settled_pass(
            image,
            first,
            self.scout_spacing_px(),
            self.cfg.max_rim_points,
            RimUse::Scout,
            1.0,
            SETTLED_MOVE_PX,
        )?;
        // A seed that settles on a candidate's rim is that candidate: its
        // evidence (the canopy test above all) is not taken again.
        if self.known_rim(known, &pass.ellipse) {
            return Err(Reject::Known);
        }
        // A rim without a canopy beyond it may be the canopy's own outer
        // rim (a glare streak across the disc leaves the rim band the
        // roundest edge near it): the disc is then inside it.
        let settled = pass.ellipse;
        match self.score(image, pass) {
            Err(Reject::NoCanopy(seen)) => self
                .disc_inside_rim(image, &settled)
                .ok_or(Reject::NoCanopy(seen)),
            scored => scored,
        }
    }

    /// Whether `e` is the rim of a candidate in `known`, or that
    /// candidate's canopy rim (concentric, `R / r` times its size): the
    /// canopy around a verified disc is no disc of its own, and its rim
    /// passes and canopy test, the largest of any seed's, would only end
    /// in [`Reject::NoCanopy`].
    fn known_rim(&self, known: &[Verified], e: &Ellipse) -> bool {
        known.iter().any(|v| {
            let k = &v.ellipse;
            same_rim(k, e) || same_rim(&self.drogue.canopy_rim_around(k), e)
        })
    }

    /// Size and shape plausible for the disc (`slack` widens the limits).
    /// The shape is judged as seen along the line of sight: off the optical
    /// axis the image plane is oblique to it and stretches a small shape
    /// along the radial direction by the inverse cosine of the angle off
    /// the axis (a disc tilted 75 degrees, 22 degrees off the axis with its
    /// long axis radial, images at an axis ratio of 0.243, below cos 75 =
    /// 0.259), so that stretch is taken out before the axis ratio is held
    /// to `min_axis_ratio`.
    pub(super) fn plausible(&self, e: &Ellipse, slack: f64) -> bool {
        e.a.is_finite()
            && e.b > 0.0
            && e.a <= 2.0 * self.max_radius_px / slack
            && e.a >= slack * 0.8 * self.min_radius_px
            && self.axis_ratio_along_sight(e) >= self.cfg.min_axis_ratio * slack
    }

    /// The axis ratio of `e` (undistorted pixels) with the oblique image
    /// plane's radial stretch at its centre taken out: its second moments
    /// compressed along the radial direction by the cosine of the angle off
    /// the optical axis.
    fn axis_ratio_along_sight(&self, e: &Ellipse) -> f64 {
        let cos = 1.0 / self.camera.ray_camera([e.cx, e.cy]).norm();
        // The radial direction in pixels, where the ellipse is.
        let radial = nalgebra::Vector2::new(e.cx - self.camera.cx(), e.cy - self.camera.cy());
        let Some(radial) = radial.try_normalize(1e-12).filter(|_| cos.is_finite()) else {
            return e.b / e.a;
        };
        let (s, c) = e.theta.sin_cos();
        let axes = nalgebra::Matrix2::new(c, -s, s, c);
        let moments =
            axes * nalgebra::Matrix2::new(e.a * e.a, 0.0, 0.0, e.b * e.b) * axes.transpose();
        let compress = nalgebra::Matrix2::identity() - (1.0 - cos) * radial * radial.transpose();
        let seen = compress * moments * compress.transpose();
        let eig = seen.symmetric_eigenvalues();
        let (small, large) = (eig.min(), eig.max());
        if small > 0.0 && large > 0.0 {
            (small / large).sqrt()
        } else {
            e.b / e.a
        }
    }

    /// Narrow ray pass around an ellipse (undistorted pixels), robust refit,
    /// and the evidence score: [`Self::settled_pass`], then [`Self::score`].
    pub(super) fn verify_settled(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
        rim_use: RimUse,
    ) -> Result<Verified, Reject> {
        let pass = self.settled_pass(
            image,
            start,
            spacing_px,
            max_points,
            rim_use,
            1.0,
            SETTLED_MOVE_PX,
        )?;
        self.score(image, pass)
    }

    /// One measuring pass about `start` (the sparse rim's settled
    /// ellipse), scored as it comes, without passes walking on from it:
    /// the full-density check's second look when its settling passes fail
    /// (`Detector::search_full`).
    pub(super) fn verify_unsettled(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
    ) -> Result<Verified, Reject> {
        let pass = self.rim_pass(image, start, spacing_px, max_points, RimUse::Measure, 1.0)?;
        self.score(image, pass)
    }

    /// [`Self::verify_settled`] at a tracked frame's predicted ellipse,
    /// which verifies and measures in one pass: settled once it moves by a
    /// quarter of its narrowest window or less ([`SETTLED_WINDOW_SHARE`]).
    ///
    /// Where the track's motion during the exposure (`sweep`) smears the
    /// rim, the pass starts with the window that motion needs
    /// ([`Self::widen_for_motion`]), instead of finding it by widening.
    pub(super) fn verify_tracked(
        &mut self,
        image: &GrayImage,
        predicted: &Ellipse,
        sweep: Option<&ExposureSweep>,
    ) -> Result<Verified, Reject> {
        let narrowest_window = self.narrow_window_px(predicted.b);
        let first_widen = sweep.map_or(1.0, |s| self.widen_for_motion(predicted, s));
        let pass = self.settled_pass(
            image,
            predicted,
            self.cfg.tracked_rim_point_spacing_px,
            self.cfg.tracked_max_rim_points,
            RimUse::Measure,
            first_widen,
            (SETTLED_WINDOW_SHARE * narrowest_window).max(SETTLED_MOVE_PX),
        )?;
        tracing::trace!(
            predicted = first_widen,
            kept = pass.widened,
            "tracked pass widened for blur"
        );
        self.score(image, pass)
    }

    /// The widening ([`WIDEN_STEP`] at a time, up to [`MAX_WIDEN`]) a
    /// narrow pass about `start` needs for the motion blur that `sweep`
    /// predicts: the least at which no more than [`CLIPPED_SHARE`] of the
    /// rays' steps run into their window's ends, which is where the pass
    /// itself stops widening. A step is as wide as a sharp step's own width
    /// plus the rim's travel along its ray (the width the pass measures:
    /// twice its crossing's distance to its light end), and runs into its
    /// window when half that width reaches the window's margin. In
    /// undistorted pixels about `start`'s centre, as the pass takes its
    /// rays' radii (it casts them from the distorted centre).
    pub(super) fn widen_for_motion(&self, start: &Ellipse, sweep: &ExposureSweep) -> f64 {
        // Most tracked frames: no step could reach even the narrowest
        // window's ends (the smallest radius has it).
        // (A motion that is not a number widens nothing.)
        let widest_ramp = sweep.most_travel_px() + SHARP_STEP_OWN_PX;
        let may_reach = 0.5 * widest_ramp >= self.window_margin_px(start.b, 1.0);
        if !may_reach {
            return 1.0;
        }
        let centre = [start.cx, start.cy];
        let ramps: Vec<(f64, f64)> = ray_directions(MOTION_RAYS)
            .filter_map(|dir| {
                let radius = start.exit_distance_px(centre, dir)?;
                let ramp = sweep.along_ray_px(centre, dir)? + SHARP_STEP_OWN_PX;
                Some((radius, ramp))
            })
            .collect();
        let mut widen = 1.0;
        while widen < MAX_WIDEN {
            let clipped = ramps
                .iter()
                .filter(|&&(radius, ramp)| 0.5 * ramp >= self.window_margin_px(radius, widen))
                .count();
            if clipped as f64 <= CLIPPED_SHARE * ramps.len() as f64 {
                break;
            }
            widen *= WIDEN_STEP;
        }
        widen
    }

    /// Rim ray spacing on which candidates are compared, pixels.
    fn scout_spacing_px(&self) -> f64 {
        SCOUT_SPACING_PX.max(self.cfg.rim_point_spacing_px)
    }

    /// [`Self::verify_settled`] from `start` as a seed's candidate is
    /// verified: on the scouts' sparser rim, to be compared with the others.
    pub(super) fn verify_as_scout(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
    ) -> Result<Verified, Reject> {
        self.verify_settled(
            image,
            start,
            self.scout_spacing_px(),
            self.cfg.max_rim_points,
            RimUse::Scout,
        )
    }

    /// [`Self::rim_pass`], repeated from its own result while that moves by
    /// more than `settled_px` (the narrow search is centred on the start
    /// ellipse: a start a few pixels off gives edges near the window's
    /// ends), at most three times. The evidence (the canopy's rim, a second
    /// ray pass) is looked at only on the pass that is kept.
    #[allow(clippy::too_many_arguments)]
    fn settled_pass(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
        rim_use: RimUse,
        first_widen: f64,
        settled_px: f64,
    ) -> Result<RimPass, Reject> {
        let mut previous = *start;
        for round in 0..3 {
            let pass = self.rim_pass(
                image,
                &previous,
                spacing_px,
                max_points,
                rim_use,
                first_widen,
            )?;
            if round == 2 || pass.ellipse.max_param_error_px(&previous) <= settled_px {
                return Ok(pass);
            }
            previous = pass.ellipse;
        }
        Err(Reject::Unsettled)
    }

    /// The edge the pose is measured from on the ray whose detection edge
    /// `e` was found on `self.profile` (smoothed with `half`, the raw
    /// samples then in `self.raw_profile`; from `s0` every 0.5 px), and its
    /// light and dark sides' slopes. On a faint step the raw profile is smoothed
    /// further, in proportion to the step's contrast
    /// ([`smoothing_half_for_contrast`], at most `cap`), into `faint`; the
    /// step found there is kept when it is the same step.
    fn measured_edge(
        &mut self,
        e: &rim::RayEdge,
        half: usize,
        cap: usize,
        s0: f64,
        faint: &mut Vec<f32>,
    ) -> (rim::RayEdge, [f32; 2]) {
        let min_contrast = self.cfg.min_contrast_gray as f32;
        let sides = |p: &[f32], e: &rim::RayEdge| {
            [
                rim::light_side_slope(p, s0, 0.5, e),
                rim::dark_side_slope(p, s0, 0.5, e),
            ]
        };
        let own = || (*e, sides(&self.profile, e));
        let m_half =
            smoothing_half_for_contrast(self.noise_gray, f64::from(e.light - e.dark)).min(cap);
        if m_half <= half {
            return own();
        }
        let raw = unsmoothed(&self.raw_profile, &self.profile, half);
        faint.clear();
        faint.extend_from_slice(raw);
        rim::smooth(faint, m_half, &mut self.scratch);
        let reach = 0.5 * self.smoothing_spread_px[m_half] + 1.0;
        let Some(mut m) = rim::strongest_rise(faint, s0, 0.5, min_contrast) else {
            return own();
        };
        let mid = 0.5 * (m.dark + m.light);
        if let Some(s) = rim::crossing_near(raw, s0, 0.5, mid, m.s, reach) {
            m.s = s;
        }
        // The same step, not another one in the window.
        if (m.s - e.s).abs() > reach.max(e.light_s - e.s) {
            return own();
        }
        (m, sides(faint, &m))
    }

    /// The steps that rise onto a light bar lying over the dark shape (a
    /// glare streak below saturation): their light side is lighter than the
    /// rim's others by more than the rim's contrast, and beyond it, short of
    /// where the canopy's outer rim could lie, the level falls back below
    /// the step's mid level (the dark shape again, past the bar). A canopy
    /// lit by a glare is lighter too, but stays light that far. The steps
    /// lie on rays from `centre` (both image pixels, as in the frame);
    /// `min_radius_px` is the smallest radius of the ellipse searched
    /// (undistorted pixels: a bar lies anywhere across the disc, a step onto
    /// it even near the centre).
    fn light_bars(
        &mut self,
        image: &GrayImage,
        centre: [f64; 2],
        steps: &RaySteps,
        min_radius_px: f64,
    ) -> Vec<bool> {
        let mut bars = vec![false; steps.len()];
        let lights = step_lights(steps);
        // No step can stand out by the margin when all lie within it (the
        // usual rim: no medians taken).
        let Some(margin_floor) = self.lights_spread_beyond_veil(&lights) else {
            return bars;
        };
        let contrast = median(&mut steps.contrasts.clone());
        let light = median(&mut lights.clone());
        let margin = contrast.max(margin_floor);
        for (i, bar) in bars.iter_mut().enumerate() {
            if lights[i] <= light + margin {
                continue;
            }
            *bar = self.falls_back(image, centre, steps, i, min_radius_px);
        }
        bars
    }

    /// The steps that rise onto a band lighter than an occluder but still
    /// within the dark, such as the light collar behind a probe's nozzle
    /// lying across the disc: their light side lies below the rim's typical
    /// mid level (its median light less half its median contrast), and
    /// beyond it, short of where the canopy's outer rim could lie, the level
    /// falls back below the step's mid level, as past a light bar
    /// ([`Self::light_bars`]). Taken on a measuring pass only, where they
    /// are left out of the points the pose is measured from
    /// ([`super::evidence::MeasuredRim::near`]): the detection itself is as
    /// it was (taking them out there too cost the simulator's `everything`
    /// level two drogues).
    fn bands_within_dark(
        &mut self,
        image: &GrayImage,
        centre: [f64; 2],
        steps: &RaySteps,
        min_radius_px: f64,
    ) -> Vec<bool> {
        let mut bands = vec![false; steps.len()];
        if steps.len() < 2 {
            return bands;
        }
        let lights = step_lights(steps);
        // As for a light bar: no step lies that far out when all lie
        // within the veil's margin of each other.
        if self.lights_spread_beyond_veil(&lights).is_none() {
            return bands;
        }
        let typical_mid = median(&mut lights.clone()) - 0.5 * median(&mut steps.contrasts.clone());
        for (i, band) in bands.iter_mut().enumerate() {
            if lights[i] < typical_mid {
                *band = self.falls_back(image, centre, steps, i, min_radius_px);
            }
        }
        bands
    }

    /// The fill test's margin for a glare's veil (at the least), when the
    /// steps' `lights` spread over more than it; `None` when they all lie
    /// within it of each other (the usual rim).
    fn lights_spread_beyond_veil(&self, lights: &[f64]) -> Option<f64> {
        let margin_floor = f64::from(VEIL_SIGMAS) * self.noise_gray + f64::from(VEIL_MIN_GRAY);
        let (low, high) = lights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        if high - low <= margin_floor {
            None
        } else {
            Some(margin_floor)
        }
    }

    /// Whether beyond step `i` of `steps` (on its ray from `centre`), short
    /// of where the canopy's outer rim could lie ([`BAR_REACH_CANOPY_GAPS`]
    /// of the gap at the step's radius, or at `min_radius_px` if more), the
    /// level falls below the step's mid level on two samples running: the
    /// dark again, past a bar.
    fn falls_back(
        &mut self,
        image: &GrayImage,
        centre: [f64; 2],
        steps: &RaySteps,
        i: usize,
        min_radius_px: f64,
    ) -> bool {
        let canopy_gap = (self.drogue.canopy_radius_m / self.drogue.inner_radius_m - 1.0).max(0.0);
        let p = steps.points_px[i];
        let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
        let s = dx.hypot(dy);
        if s < 1.0 {
            return false;
        }
        let dir = [dx / s, dy / s];
        let reach = BAR_REACH_CANOPY_GAPS * canopy_gap * s.max(min_radius_px);
        rim::profile(image, centre, dir, s, s + reach, 1.0, &mut self.profile);
        // Two samples running below the mid level: not one noisy one.
        let mid = steps.mid_levels[i];
        self.profile.windows(2).any(|w| w.iter().all(|&v| v < mid))
    }

    /// The narrow ray pass around `start` and the robust refit, with the
    /// checks of the rim itself (size, shape, contrast, one dark inside).
    pub(super) fn rim_pass(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
        rim_use: RimUse,
        first_widen: f64,
    ) -> Result<RimPass, Reject> {
        self.rim_pass_at(
            image,
            start,
            spacing_px,
            max_points,
            rim_use,
            GlareCover::Part,
            first_widen,
        )
    }

    /// Half-width of a narrow pass's window on a ray to a rim `radius_px`
    /// away, widened by `widen` for blur (pixels): never narrower than the
    /// unwidened window, nor wider than [`MAX_WIDE_MARGIN_RADII`] of the
    /// radius or [`MAX_WIDE_MARGIN_PX`].
    fn window_margin_px(&self, radius_px: f64, widen: f64) -> f64 {
        let base = self.narrow_window_px(radius_px);
        if widen > 1.0 {
            (base * widen)
                .min(MAX_WIDE_MARGIN_RADII * radius_px)
                .min(MAX_WIDE_MARGIN_PX)
                .max(base)
        } else {
            base
        }
    }

    /// Half-width of a narrow pass's window on a ray to a rim `radius_px`
    /// away (pixels): [`DetectConfig::rim_search_fraction`](super::DetectConfig)
    /// of it, 4 px at least and `rim_search_max_px` at most, before any
    /// widening for blur.
    fn narrow_window_px(&self, radius_px: f64) -> f64 {
        (self.cfg.rim_search_fraction * radius_px).clamp(4.0, self.cfg.rim_search_max_px.max(4.0))
    }

    /// One round of a narrow pass: a step looked for on each of `rays`
    /// rays from `centre` (distorted pixels), in a window about `start`'s
    /// rim widened by `widen` (see [`Self::rim_pass_at`]).
    #[allow(clippy::too_many_arguments)]
    fn ray_steps(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        centre: [f64; 2],
        rays: usize,
        widen: f64,
        rim_use: RimUse,
        cover: GlareCover,
    ) -> RayRound {
        let min_contrast = self.cfg.min_contrast_gray as f32;
        let (w, h) = (f64::from(image.width()), f64::from(image.height()));
        let inside = |p: [f64; 2]| p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= w - 1.0 && p[1] <= h - 1.0;
        let mut faint = Vec::new();
        let mut steps = RaySteps::with_capacity(rays, rim_use);
        let mut rays_in_image = 0usize;
        let mut clipped = 0usize;
        let (sin_theta, cos_theta) = start.theta.sin_cos();
        for dir in ray_directions(rays) {
            // The ray's angle to the major axis: phi - theta.
            let (cos_local, sin_local) = (
                dir[0] * cos_theta + dir[1] * sin_theta,
                dir[1] * cos_theta - dir[0] * sin_theta,
            );
            let r = polar_radius_local(start.a, start.b, cos_local, sin_local);
            let margin = self.window_margin_px(r, widen);
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
            let cap = (0.1 * r) as usize;
            let half = self.smooth_half.min(cap);
            if half > 0 {
                self.raw_profile.clone_from(&self.profile);
                rim::smooth(&mut self.profile, half, &mut self.scratch);
            }
            let mut half = half;
            let mut found = rim::strongest_rise(&self.profile, s0, 0.5, min_contrast);
            // A long blurred ramp rises little per sample: smoothed
            // only for the frame's noise, its rise dips below the fade
            // level inside the ramp, which then ends there and takes
            // its levels inside it (the rim comes out too far out along
            // the blur). On a pass whose window was widened for blur,
            // a step is found again on a profile smoothed for its own
            // rise, twice at most (the first width is short for the
            // same reason). Not a step into saturated pixels: a glare
            // streak's skirt is no blur.
            let ramp_rounds = if widen > 1.0 { 2 } else { 0 };
            for _ in 0..ramp_rounds {
                let Some(e) = found else { break };
                let raw = unsmoothed(&self.raw_profile, &self.profile, half);
                if glare_on_light_side(raw, s0, 0.5, &e) {
                    break;
                }
                let width = 2.0 * (e.light_s - e.s) - self.smoothing_spread_px[half];
                let ramp_half =
                    smoothing_half_for_ramp(self.noise_gray, f64::from(e.light - e.dark), width)
                        .min(cap);
                if ramp_half <= half {
                    break;
                }
                if half == 0 {
                    self.raw_profile.clone_from(&self.profile);
                }
                self.profile.clone_from(&self.raw_profile);
                rim::smooth(&mut self.profile, ramp_half, &mut self.scratch);
                half = ramp_half;
                found = rim::strongest_rise(&self.profile, s0, 0.5, min_contrast);
            }
            let Some(mut e) = found else {
                continue;
            };
            // A step into saturated pixels is most likely the skirt of a
            // glare streak lying over the disc: its width says nothing of
            // blur, and unless most steps are such, it gives no rim point
            // ([`Self::rim_pass_at`]).
            let raw = unsmoothed(&self.raw_profile, &self.profile, half);
            let light_clipped = glare_on_light_side(raw, s0, 0.5, &e);
            let glare =
                light_clipped || (cover == GlareCover::Most && glare_before_step(raw, s0, 0.5, &e));
            if half > 0 {
                let mid = 0.5 * (e.dark + e.light);
                let reach = 0.5 * self.smoothing_spread_px[half] + 1.0;
                if let Some(s) = rim::crossing_near(&self.raw_profile, s0, 0.5, mid, e.s, reach) {
                    e.s = s;
                }
            }
            let p = [centre[0] + e.s * dir[0], centre[1] + e.s * dir[1]];
            steps.points_px.push(p);
            steps.undistorted.push(self.camera.undistort_px(p));
            if rim_use == RimUse::Measure {
                let (measured, [light_slope, dark_slope]) =
                    self.measured_edge(&e, half, cap, s0, &mut faint);
                steps.measured_px.push([
                    centre[0] + measured.s * dir[0],
                    centre[1] + measured.s * dir[1],
                ]);
                steps.shading.push(ShadedEdge::new(
                    dir,
                    &measured,
                    [light_slope, dark_slope],
                    self.noise_gray,
                ));
                let raw = unsmoothed(&self.raw_profile, &self.profile, half);
                steps.clip_px.push(if light_clipped {
                    clipped_light_px(raw, s0, 0.5, measured.s)
                } else {
                    0.0
                });
            }
            steps.contrasts.push(f64::from(e.light - e.dark));
            steps.mid_levels.push(0.5 * (e.dark + e.light));
            // The smoothing's own spread is not the step's.
            let spread = self.smoothing_spread_px[half];
            steps
                .widths_px
                .push((2.0 * (e.light_s - e.s) - spread).max(0.0));
            clipped += usize::from(e.clipped && !glare);
            steps.glares.push(glare);
        }
        tracing::trace!(
            rays,
            rays_in_image,
            edges = steps.len(),
            clipped,
            widen,
            "rim pass"
        );
        RayRound {
            clipped_share: clipped as f64 / steps.len().max(1) as f64,
            steps,
            rays_in_image,
        }
    }

    /// The ellipse of a narrow pass's points (undistorted pixels) about
    /// `start`, and the distance from it counted as on the rim: a coarse
    /// refit within a band of 5 % of the minor axis, then one within a few
    /// sigmas of the points' own scatter about it. `residuals` is scratch.
    fn narrow_fit(
        &self,
        start: &Ellipse,
        undistorted: &[[f64; 2]],
        residuals: &mut Vec<f64>,
    ) -> Result<(Ellipse, f64), Reject> {
        let min_tol = self.cfg.inlier_tolerance_px.max(0.1);
        let coarse_tol = (0.05 * start.b).max(3.0 * min_tol);
        let coarse =
            conic_fit::refine(start, undistorted, coarse_tol, 2).ok_or(Reject::NoEllipse)?;
        // The edges' own scatter sets what is "on the rim": a blurred rim in
        // noise is located to a pixel or two (noise over the ramp's slope),
        // a sharp one to a tenth.
        conic_fit::residuals(&coarse, undistorted, residuals);
        let mut near: Vec<f64> = residuals
            .iter()
            .copied()
            .filter(|r| *r <= coarse_tol)
            .collect();
        let sigma = 1.4826 * median(&mut near);
        let tol = (NOISE_TOLERANCE_SIGMAS * sigma).clamp(min_tol, (0.5 * coarse_tol).max(min_tol));
        let ellipse = conic_fit::refine(&coarse, undistorted, tol, 2).ok_or(Reject::NoEllipse)?;
        if !self.plausible(&ellipse, 1.0) {
            return Err(Reject::Implausible);
        }
        Ok((ellipse, tol))
    }

    /// Takes out of `steps` those into saturated pixels (a glare streak over
    /// the disc), unless they are most of the rim (an overexposed canopy),
    /// and those onto a light bar over the disc ([`Self::light_bars`]),
    /// unless most are; the glare's steps come back with their levels for
    /// the fill test. `min_radius_px` as for [`Self::light_bars`].
    fn drop_glares_and_bars(
        &mut self,
        image: &GrayImage,
        centre: [f64; 2],
        steps: &mut RaySteps,
        min_radius_px: f64,
    ) -> GlareDrop {
        // Steps into saturated pixels (a glare streak over the disc) give
        // no rim points and do not count against the candidate, unless
        // they are most of the rim (an overexposed canopy).
        let glared = steps.glares.iter().filter(|&&g| g).count();
        let glares_dropped = glared > 0 && 2 * glared < steps.len();
        // Steps onto a light bar over the disc give no rim points either,
        // but count against it as an occluder's would: the disc's rim is
        // hidden there, and a sliver of the disc beside the bar must not
        // score as a whole disc.
        let mut bars = self.light_bars(image, centre, steps, min_radius_px);
        // A step into saturation is the glare's, whatever its light.
        for (bar, &glare) in bars.iter_mut().zip(&steps.glares) {
            *bar &= !glare;
        }
        let barred = bars.iter().filter(|&&b| b).count();
        // Their mid levels still say where the disc's inside is dark: the
        // glare's skirt lifts the disc's levels beside the streak. Each is
        // kept with its point (undistorted pixels) and turned into an angle
        // about the fitted ellipse for the fill test.
        let mut glare_steps: Vec<([f64; 2], FillLevels)> = Vec::new();
        if glares_dropped {
            glare_steps = (0..steps.len())
                .filter(|&i| steps.glares[i])
                .map(|i| {
                    (
                        steps.undistorted[i],
                        FillLevels::of_step(steps.mid_levels[i], steps.contrasts[i]),
                    )
                })
                .collect();
        }
        let dropped: Vec<bool> = steps
            .glares
            .iter()
            .zip(&bars)
            .map(|(&glare, &bar)| (glares_dropped && glare) || (2 * barred < bars.len() && bar))
            .collect();
        steps.drop_marked(&dropped);
        GlareDrop {
            glare_steps,
            glares_dropped,
            glared: if glares_dropped { glared } else { 0 },
        }
    }

    /// [`Self::rim_pass`]; `cover` says whether a glare hides most of the
    /// rim, so that the pass looks again, closer, at what it leaves.
    #[allow(clippy::too_many_arguments)]
    fn rim_pass_at(
        &mut self,
        image: &GrayImage,
        start: &Ellipse,
        spacing_px: f64,
        max_points: u32,
        rim_use: RimUse,
        cover: GlareCover,
        first_widen: f64,
    ) -> Result<RimPass, Reject> {
        let centre = self.camera.distort_px([start.cx, start.cy]);
        let perimeter = TAU * ((start.a * start.a + start.b * start.b) / 2.0).sqrt();
        let rays =
            ((perimeter / spacing_px.max(0.1)) as usize).clamp(24, max_points.max(24) as usize);

        // A blurred rim is a ramp as wide as the blur: where most steps run
        // into the window's ends, their levels are not the disc's and the
        // canopy's, and the window is widened (the mid-level crossing of a
        // whole blurred step is the edge). A tracked pass may start wider,
        // for the blur its motion predicts.
        let mut widen = first_widen;
        let RayRound {
            mut steps,
            mut rays_in_image,
            clipped_share,
        } = loop {
            let round = self.ray_steps(image, start, centre, rays, widen, rim_use, cover);
            if widen >= MAX_WIDEN || round.clipped_share <= CLIPPED_SHARE {
                break round;
            }
            widen *= WIDEN_STEP;
        };
        let widened = widen;
        let GlareDrop {
            glare_steps,
            glares_dropped,
            glared,
        } = self.drop_glares_and_bars(image, centre, &mut steps, start.b);
        rays_in_image -= glared;
        if rays_in_image < rays / 4 {
            return Err(Reject::OutOfImage);
        }
        // A glare over much of the rim leaves few rays on the rest: that
        // rest is looked at twice as closely (to the configured spacing at
        // most) before the pass gives up, for too few edges or (below) too
        // few of them on the ellipse.
        let closer = 0.5 * spacing_px;
        let closer_or = |this: &mut Self, short: Reject| {
            if glares_dropped && closer >= this.cfg.rim_point_spacing_px {
                this.rim_pass_at(
                    image,
                    start,
                    closer,
                    max_points,
                    rim_use,
                    GlareCover::Most,
                    first_widen,
                )
            } else {
                Err(short)
            }
        };
        let undistorted = &steps.undistorted;
        if undistorted.len() < self.cfg.min_rim_points as usize {
            return closer_or(self, Reject::FewEdges(undistorted.len()));
        }
        let mut residuals = Vec::new();
        let (ellipse, tol) = self.narrow_fit(start, undistorted, &mut residuals)?;
        conic_fit::residuals(&ellipse, undistorted, &mut residuals);
        let inliers: Vec<usize> = (0..residuals.len())
            .filter(|&i| residuals[i] <= tol)
            .collect();
        if inliers.len() < self.cfg.min_rim_points as usize {
            return closer_or(self, Reject::FewInliers(inliers.len()));
        }
        let mut inlier_contrast: Vec<f64> = inliers.iter().map(|&i| steps.contrasts[i]).collect();
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
                (angle, steps.mid_levels[i])
            })
            .collect();
        let mut fill_steps: Vec<(f64, FillLevels)> = inliers
            .iter()
            .zip(&mids)
            .map(|(&i, &(angle, mid))| (angle, FillLevels::of_step(mid, steps.contrasts[i])))
            .collect();
        fill_steps.extend(
            glare_steps
                .iter()
                .map(|&(p, levels)| ((p[1] - ellipse.cy).atan2(p[0] - ellipse.cx), levels)),
        );
        // The fill test looks each direction up by angle (the steps come
        // round the rim in ray order: mostly a rotation, not a sort).
        crate::measure::angles::sort_by_angle(&mut fill_steps);
        let fill = self.fill_share(image, &ellipse, &fill_steps);
        if fill < self.cfg.min_fill {
            return Err(Reject::LightInside(fill));
        }
        let shape = inliers.len() as f64 / rays_in_image as f64;
        let within_dark = match rim_use {
            RimUse::Measure => self.bands_within_dark(image, centre, &steps, start.b),
            RimUse::Scout => Vec::new(),
        };
        let RaySteps {
            points_px,
            undistorted,
            widths_px,
            measured_px,
            shading,
            clip_px,
            ..
        } = steps;
        let pose_edges = match rim_use {
            RimUse::Measure => PoseEdges::Shaded {
                base_px: measured_px,
                shading,
                found_undistorted: undistorted,
                clip_px,
                within_dark,
            },
            RimUse::Scout => PoseEdges::Own(undistorted),
        };
        Ok(RimPass {
            ellipse,
            centre,
            points_px,
            pose_edges,
            residuals,
            inliers,
            step_widths_px: widths_px,
            clipped_share,
            widened,
            rim_contrast,
            shape,
            fill,
            tolerance: tol,
            mids,
        })
    }
}
