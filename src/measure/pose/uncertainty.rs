//! Uncertainty of a circle pose from the fit: the ellipse's covariance from
//! the inlier points, propagated through the visual cone.

use super::CirclePose;
use super::cone::cone_pose_parts;
use crate::camera::CameraModel;
use crate::measure::FitQuality;
use crate::measure::ellipse::Ellipse;
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2};

/// The ellipse as centre + the symmetric matrix M that maps the unit circle
/// onto it (`p = c + M (cos t, sin t)`): `[cx, cy, m11, m12, m22]`. Unlike
/// (a, b, theta) this is smooth through circles, so covariances stay finite.
pub(crate) type EllipseParams = SVector<f64, 5>;

pub(crate) fn ellipse_params(e: &Ellipse) -> EllipseParams {
    let (s, c) = e.theta.sin_cos();
    EllipseParams::new(
        e.cx,
        e.cy,
        e.a * c * c + e.b * s * s,
        (e.a - e.b) * c * s,
        e.a * s * s + e.b * c * c,
    )
}

/// The ellipse of `EllipseParams`, or `None` if M is not positive definite.
pub(crate) fn ellipse_from_params(p: &EllipseParams) -> Option<Ellipse> {
    let eig = Matrix2::new(p[2], p[3], p[3], p[4]).symmetric_eigen();
    let (i_major, i_minor) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    let (a, b) = (eig.eigenvalues[i_major], eig.eigenvalues[i_minor]);
    if !(b > 0.0 && a.is_finite()) {
        return None;
    }
    let v = eig.eigenvectors.column(i_major);
    Some(Ellipse::new(p[0], p[1], a, b, v.y.atan2(v.x)))
}

/// Systematic rim displacement of a blurred edge, as a share of
/// `w^2 / rho` for a step of width `w` on a rim of local radius of
/// curvature `rho` (pixels). A mid-level crossing places a straight step
/// with flat levels on either side exactly; a curved one, or one with the
/// surfaces' shading within the ramp, is displaced by the ramp's width times
/// the share of the ramp over which the edge or the levels change, `w / rho`
/// (the blurred level sets of a curved edge move by `sigma_b^2 / (2 rho)`,
/// `sigma_b^2 = w^2 / 12` for a box blur; shading bands on the drogue are a
/// fixed share of its radius). The displacement has one sign all round the
/// rim (it comes from the curvature and the shading, which have one sign),
/// so it does not average out over points and does not show in the fit's
/// residual: the fit takes it as a change of size and shape. Its size
/// depends on the scene, so it enters as an uncertainty. Calibrated on the
/// simulator (`cargo run --release --example rim_bias`: the detector's
/// inlier points against the true rim, sweep seed 15, 30 frames a level,
/// the estimate's own noise removed): 0.019-0.029 over motion blur 4-16 px
/// and ranges 12-16 m, where this term is the larger; their rms is 0.023.
/// With the rim points placed for the canopy's shading (the detector's
/// `shaded_points`) the same levels give 0.013-0.022; the larger value is
/// kept.
const SYSTEMATIC_CURVATURE_FACTOR: f64 = 0.023;

/// A part of the points' scatter common to all of them, as a share of the
/// scatter: sharp rims on the simulator (baseline, haze, exposure,
/// vignetting, distortion, noise 2-20, tilt up to 60 degrees, ranges up to
/// 8 m, distractors; `examples/rim_bias.rs`) are displaced as a whole by
/// 0-0.13 of their points' rms residual beyond what the points' independent
/// noise explains (rms 0.065): the pixel grid's phase along the rim and the
/// noise's pull on each step's levels do not average out entirely. Without
/// it the covariance shrinks as 1/n with the number of points while the
/// error does not (a floor of `1 / share^2`, about 240, independent points).
const COMMON_MODE_SHARE: f64 = 0.065;

/// Sigmas of the cone's asymmetry within which a rim is taken as possibly
/// face-on: sqrt of chi-square(1)'s 99 % point.
const FACE_ON_SIGMAS: f64 = 2.576;

/// Largest lag-1 correlation of neighbouring points' residuals credited:
/// beyond it the residuals are a shape the model does not have, not noise.
const MAX_NEIGHBOUR_CORRELATION: f64 = 0.8;

/// First-order covariance of the ellipse parameters (`EllipseParams`) for
/// points with geometric noise `sigma_px` normal to the curve:
/// `f sigma^2 (J^T J)^-1`, J the derivatives of each point's distance to the
/// curve, and `f = (1 + rho1) / (1 - rho1)` the variance inflation of
/// residuals correlated between neighbouring points with lag-1 correlation
/// `rho1` (measured on the residuals, ordered along the rim: rays closer
/// than the blur or the sampling footprint see the same pixels and noise),
/// plus two systematic terms: a displacement `s_i` of one sign at every
/// point moves the least-squares ellipse by `g = (J^T J)^-1 J^T s`, giving
/// `g g^T`, for `s_i = COMMON_MODE_SHARE * sigma` (the common part of the
/// scatter, [`COMMON_MODE_SHARE`]) and, when the points' step widths are
/// known, `s_i = SYSTEMATIC_CURVATURE_FACTOR * w_i^2 / rho_i` (the blurred
/// edge's, [`SYSTEMATIC_CURVATURE_FACTOR`]); and for `d_i` the distance
/// out to where a clipped step's light side saturates (`clip_px`: the edge
/// lies between the point and about there), `s_i = d_i` and, as a glow's
/// gradient clips one side of the rim more than the other,
/// `s_i = d_i cos t_i / 2` and `d_i sin t_i / 2` (`t_i` the point's place
/// on the curve), which move the centre. None shrinks with the number of
/// points. Points are assigned to the curve through `M^-1 (p - c)` (exact
/// on the curve, first-order near it).
/// Returned in two parts: all but the clipped steps' terms, and those.
fn ellipse_covariance(
    e: &Ellipse,
    points_px: &[[f64; 2]],
    sigma_px: f64,
    step_widths_px: Option<&[f64]>,
    clip_px: Option<&[f64]>,
) -> Option<(SMatrix<f64, 5, 5>, SMatrix<f64, 5, 5>)> {
    let p = ellipse_params(e);
    let m = Matrix2::new(p[2], p[3], p[3], p[4]);
    let m_inv = m.try_inverse()?;
    let det_m = m.determinant().abs();
    let mut jtj = SMatrix::<f64, 5, 5>::zeros();
    let mut jts = SVector::<f64, 5>::zeros();
    let mut jtc = SVector::<f64, 5>::zeros();
    let mut jtc_cos = SVector::<f64, 5>::zeros();
    let mut jtc_sin = SVector::<f64, 5>::zeros();
    let mut jt1 = SVector::<f64, 5>::zeros();
    // (parameter angle, residual) of each point, for the neighbours' correlation.
    let mut along = Vec::with_capacity(points_px.len());
    for (i, pt) in points_px.iter().enumerate() {
        let d = Vector2::new(pt[0] - e.cx, pt[1] - e.cy);
        // (cos t, sin t) of the point's place on the curve.
        let Some(w) = (m_inv * d).try_normalize(0.0) else {
            continue;
        };
        let (cos_t, sin_t) = (w.x, w.y);
        // Outward normal at the curve point c + M (cos t, sin t).
        let n = m_inv * Vector2::new(cos_t, sin_t);
        let n_len = n.norm();
        if !(n_len > 0.0 && n_len.is_finite()) {
            continue;
        }
        let n = n / n_len;
        let row = SVector::<f64, 5>::from([
            n.x,
            n.y,
            n.x * cos_t,
            n.x * sin_t + n.y * cos_t,
            n.y * sin_t,
        ]);
        // Upper triangle only (mirrored below): the products are the same
        // either side of the diagonal, the outer product did each twice.
        for c in 0..5 {
            for r in 0..=c {
                jtj[(r, c)] += row[r] * row[c];
            }
        }
        jt1 += row;
        along.push((sin_t.atan2(cos_t), n.dot(&(d - m * w))));
        if let Some(width) = step_widths_px.and_then(|ws| ws.get(i)) {
            // Radius of curvature at t: |M u'|^3 / det M, u = (cos t, sin t).
            let speed = (m * Vector2::new(-sin_t, cos_t)).norm();
            let rho = speed.powi(3) / det_m;
            if width.is_finite() && rho.is_finite() && rho > 0.0 {
                jts += row * (SYSTEMATIC_CURVATURE_FACTOR * width * width / rho);
            }
        }
        if let Some(&clip) = clip_px.and_then(|c| c.get(i))
            && clip > 0.0
            && clip.is_finite()
        {
            jtc += row * clip;
            jtc_cos += row * (clip * cos_t);
            jtc_sin += row * (clip * sin_t);
        }
    }
    jtj.fill_lower_triangle_with_upper_triangle();
    let inv = jtj.try_inverse()?;
    let inflation = neighbour_inflation(&mut along);
    // The systematic displacements, each common to all points: the
    // blurred edge's (per point, from its width) and the common part of
    // the scatter (the same for all points), each of unknown sign, and the
    // clipped steps' (inward, up to the distance to saturation).
    let g_edge = inv * jts;
    let g_common = inv * jt1 * (COMMON_MODE_SHARE * sigma_px);
    let g_clip = inv * jtc;
    let g_clip_cos = inv * jtc_cos * 0.5;
    let g_clip_sin = inv * jtc_sin * 0.5;
    Some((
        inv * (inflation * sigma_px * sigma_px)
            + g_edge * g_edge.transpose()
            + g_common * g_common.transpose(),
        g_clip * g_clip.transpose()
            + g_clip_cos * g_clip_cos.transpose()
            + g_clip_sin * g_clip_sin.transpose(),
    ))
}

/// `(1 + rho1) / (1 - rho1)` for the lag-1 correlation `rho1` of residuals
/// ordered by their angle along the rim (pairs across a gap wider than
/// three times the median spacing, where the probe hides the rim, left
/// out), clamped to `[0, MAX_NEIGHBOUR_CORRELATION]`: the variance of a
/// mean of `n` AR(1) samples over that of `n` independent ones.
fn neighbour_inflation(along: &mut [(f64, f64)]) -> f64 {
    if along.len() < 8 {
        return 1.0;
    }
    // As a stable sort, cheaper for points that come round the rim in order.
    crate::measure::angles::sort_by_angle(along);
    let mut gaps: Vec<f64> = along.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let max_gap = 3.0 * crate::measure::stats::median(&mut gaps);
    let (mut cross, mut pairs) = (0.0, 0usize);
    for w in along.windows(2) {
        if w[1].0 - w[0].0 <= max_gap {
            cross += w[0].1 * w[1].1;
            pairs += 1;
        }
    }
    let var = along.iter().map(|a| a.1 * a.1).sum::<f64>() / along.len() as f64;
    if !(pairs > 0 && var > 0.0) {
        return 1.0;
    }
    let rho = (cross / pairs as f64 / var).clamp(0.0, MAX_NEIGHBOUR_CORRELATION);
    (1.0 + rho) / (1.0 - rho)
}

/// Uncertainty of one pose solution. NaN where it is unknown (the MAVLink
/// convention for an unknown covariance; JSON writes it as null).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseUncertainty {
    /// Covariance of the centre, camera frame, square metres.
    pub position_cov_camera_m2: Matrix3<f64>,
    /// RMS angular error of the normal (both directions together), radians.
    pub normal_sigma_rad: f64,
}

impl PoseUncertainty {
    /// Unknown (NaN): the MAVLink convention for a covariance not known.
    pub fn unknown() -> Self {
        Self {
            position_cov_camera_m2: Matrix3::from_element(f64::NAN),
            normal_sigma_rad: f64::NAN,
        }
    }
}

/// Uncertainty of `pose` (one of `cone_pose`'s solutions for `ellipse_px`)
/// from the fit: the points' noise is the fit's RMS residual (corrected for
/// the 5 fitted parameters), giving the ellipse covariance through the
/// points' distance Jacobian at the actual inlier positions (so a partly hidden
/// rim gives a larger covariance), inflated for neighbouring points'
/// correlation and with the scatter's common part added (see
/// `ellipse_covariance`; [`pose_uncertainty_with_edges`] adds the blurred
/// edges' systematic term, which the measurement uses); that is propagated through `cone_pose`
/// along the covariance's principal directions (+- one sigma each, second
/// moments about the nominal pose). That equals `J C J^T` where the pose is
/// linear in the ellipse and stays finite at a frontal circle, where the
/// normal is not differentiable (tilt ~ sqrt of the ellipse's eccentricity);
/// where the rim cannot tell the cone from a circular one, the distance to
/// the face-on pose is added too.
///
/// Perturbed poses follow the solution whose normal is nearest to `pose`'s.
/// Unknown (NaN) with fewer than 6 inliers (a fit through 5 points has no
/// residual to estimate the noise from) or a degenerate point spread.
pub fn pose_uncertainty(
    ellipse_px: &Ellipse,
    camera: &CameraModel,
    pose: &CirclePose,
    radius_m: f64,
    quality: &FitQuality,
    inlier_points_px: &[[f64; 2]],
) -> PoseUncertainty {
    pose_uncertainty_with_edges(
        ellipse_px,
        camera,
        pose,
        radius_m,
        quality,
        inlier_points_px,
        RimSteps::default(),
    )
}

/// What the detector measured of each inlier point's step, for the
/// covariance's systematic terms: slices aligned with the points (one that
/// is empty or of another length is left out).
#[derive(Clone, Copy, Debug, Default)]
pub struct RimSteps<'a> {
    /// Each step's width, pixels along its ray (as the detector measured
    /// it): the blurred edge's term.
    pub widths_px: &'a [f64],
    /// How far out from each point its step's light side reaches
    /// saturation, pixels along the point's ray in the frame as seen (0
    /// below it), taken as a displacement normal to the curve: the clipped
    /// steps' term.
    pub clip_px: &'a [f64],
}

/// [`pose_uncertainty`] with what the detector measured of the inlier
/// points' steps ([`RimSteps`]): their widths add the blurred edges'
/// systematic displacement (see `SYSTEMATIC_CURVATURE_FACTOR`), which no
/// residual shows; how far out from each point its step's light side
/// reaches saturation adds the clipped steps' (a canopy lifted past 255 by
/// a glare's glow: each point lies up to that distance short of the edge,
/// all of them inward). Without them (empty, or of another length) only
/// the points' scatter (independent, neighbour-correlated and common
/// parts) is counted.
pub fn pose_uncertainty_with_edges(
    ellipse_px: &Ellipse,
    camera: &CameraModel,
    pose: &CirclePose,
    radius_m: f64,
    quality: &FitQuality,
    inlier_points_px: &[[f64; 2]],
    steps: RimSteps,
) -> PoseUncertainty {
    match ellipse_spread(ellipse_px, quality, inlier_points_px, steps) {
        Some(spread) => pose_uncertainty_from_spread(&spread, camera, pose, radius_m),
        None => PoseUncertainty::unknown(),
    }
}

/// The fitted ellipse and its copies moved by one sigma either way along
/// each principal direction of its covariance (`ellipse_covariance`, from
/// the inlier points and [`RimSteps`]): what the fit may be, for anything
/// computed from the ellipse (the pose's uncertainty, where the canopy's
/// rim is predicted) to be carried through by second moments about the
/// nominal. A copy whose matrix is not positive definite is left out.
#[derive(Clone, Debug)]
pub struct EllipseSpread {
    /// The fitted ellipse (undistorted pixels).
    pub nominal: Ellipse,
    /// Each carries half its direction's variance: a spread of `f` over
    /// them is `sum (f(moved) - f(nominal))^2 / 2`.
    pub moved: Vec<Ellipse>,
}

/// [`EllipseSpread`] of a fit; `None` with fewer than 6 inliers (a fit
/// through 5 points has no residual to estimate the noise from), a
/// non-finite residual or a degenerate point spread.
pub fn ellipse_spread(
    ellipse_px: &Ellipse,
    quality: &FitQuality,
    inlier_points_px: &[[f64; 2]],
    steps: RimSteps,
) -> Option<EllipseSpread> {
    ellipse_spreads(ellipse_px, quality, inlier_points_px, steps).map(|[all, _]| all)
}

/// [`ellipse_spread`], and the same without the clipped steps' term (a
/// bound on how far short of the edge a glow's saturation may leave the
/// points, not an estimate of it): one covariance, two spreads.
pub fn ellipse_spreads(
    ellipse_px: &Ellipse,
    quality: &FitQuality,
    inlier_points_px: &[[f64; 2]],
    steps: RimSteps,
) -> Option<[EllipseSpread; 2]> {
    let n = inlier_points_px.len();
    if n <= 5 || !(quality.rms_residual_px >= 0.0 && quality.rms_residual_px.is_finite()) {
        return None;
    }
    let sigma_px = quality.rms_residual_px * (n as f64 / (n - 5) as f64).sqrt();
    let widths = Some(steps.widths_px).filter(|w| w.len() == n);
    let clip = Some(steps.clip_px).filter(|c| c.len() == n);
    let (unclipped, clipped) =
        ellipse_covariance(ellipse_px, inlier_points_px, sigma_px, widths, clip)?;
    let p0 = ellipse_params(ellipse_px);
    let spread = |cov: SMatrix<f64, 5, 5>| {
        let eig = cov.symmetric_eigen();
        let mut moved = Vec::with_capacity(10);
        for k in 0..5 {
            let step = eig.eigenvectors.column(k) * eig.eigenvalues[k].max(0.0).sqrt();
            for sign in [1.0, -1.0] {
                if let Some(e) = ellipse_from_params(&(p0 + sign * step)) {
                    moved.push(e);
                }
            }
        }
        EllipseSpread {
            nominal: *ellipse_px,
            moved,
        }
    };
    Some([spread(unclipped + clipped), spread(unclipped)])
}

/// [`pose_uncertainty_with_edges`] from the fit's [`EllipseSpread`].
pub fn pose_uncertainty_from_spread(
    spread: &EllipseSpread,
    camera: &CameraModel,
    pose: &CirclePose,
    radius_m: f64,
) -> PoseUncertainty {
    let unknown = PoseUncertainty::unknown();
    let ellipse_px = &spread.nominal;
    let Some((_, s0)) = cone_pose_parts(ellipse_px, camera, radius_m, false) else {
        return unknown;
    };
    let mut cov_pos = Matrix3::zeros();
    let mut normal_var = 0.0;
    let mut s_var = 0.0;
    let nearest = |[s1, s2]: [CirclePose; 2]| {
        if s1.normal_camera.dot(&pose.normal_camera) >= s2.normal_camera.dot(&pose.normal_camera) {
            s1
        } else {
            s2
        }
    };
    for e in &spread.moved {
        let moved = cone_pose_parts(e, camera, radius_m, false)
            .map(|(both, s)| {
                s_var += 0.5 * (s - s0) * (s - s0);
                both
            })
            .map(nearest);
        let Some(moved) = moved else {
            continue;
        };
        let d = moved.centre_camera_m - pose.centre_camera_m;
        cov_pos += d * d.transpose() * 0.5;
        let angle = moved
            .normal_camera
            .cross(&pose.normal_camera)
            .norm()
            .atan2(moved.normal_camera.dot(&pose.normal_camera));
        normal_var += 0.5 * angle * angle;
    }
    // Near face-on the pose is not differentiable in the ellipse: the tilt
    // grows as the square root of the cone's asymmetry `s`, whose noise
    // alone makes `s` positive, so the spread about the nominal pose misses
    // the distance to the face-on pose it cannot be told from. When `s` is
    // within FACE_ON_SIGMAS of its own sigma (chi-square(1) 99 %: the rim
    // does not tell the cone from a circular one), that distance is added.
    if s0 <= FACE_ON_SIGMAS * s_var.sqrt()
        && let Some((face_on, _)) = cone_pose_parts(ellipse_px, camera, radius_m, true)
    {
        let moved = nearest(face_on);
        let d = moved.centre_camera_m - pose.centre_camera_m;
        cov_pos += d * d.transpose();
        let angle = moved
            .normal_camera
            .cross(&pose.normal_camera)
            .norm()
            .atan2(moved.normal_camera.dot(&pose.normal_camera));
        normal_var += angle * angle;
    }
    PoseUncertainty {
        position_cov_camera_m2: cov_pos,
        normal_sigma_rad: normal_var.sqrt(),
    }
}

/// `u`, the uncertainty of `given`, widened for an unresolved ambiguity:
/// the answer given is one of two solutions the image cannot tell apart, so
/// about the truth it is off by nothing or by the distance `d` to `other`
/// with equal odds, a second moment of `u`'s plus `d d^T / 2` (and half the
/// squared angle between the normals). Without it, a mirror answer at 20-45
/// degrees of tilt is 5-10 mm off with a sigma of 0.5-2 mm (NEES in the
/// hundreds to thousands on the reference sets); with it, the sent
/// covariance covers either solution.
pub fn with_unresolved_mirror(
    u: PoseUncertainty,
    given: &CirclePose,
    other: &CirclePose,
) -> PoseUncertainty {
    let d = other.centre_camera_m - given.centre_camera_m;
    let angle = other
        .normal_camera
        .cross(&given.normal_camera)
        .norm()
        .atan2(other.normal_camera.dot(&given.normal_camera));
    PoseUncertainty {
        position_cov_camera_m2: u.position_cov_camera_m2 + d * d.transpose() * 0.5,
        normal_sigma_rad: (u.normal_sigma_rad.powi(2) + 0.5 * angle * angle).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// Points all round a circle whose steps were clipped, each of them up
    /// to `d` short of the edge: the covariance then holds `d^2` in each
    /// of M's diagonal terms (the radius moved by `d`, analytic for a
    /// circle: `(J^T J)^-1 J^T d` is `d` on both) and `d^2 / 4` in the
    /// centre's (the clipping's first harmonic, at half of `d`, is a shift
    /// of the circle by half of `d`). Without them, next to nothing: the
    /// points lie on the circle.
    #[test]
    fn clipped_steps_add_the_radius_and_the_centre_they_may_move() {
        let (r, d) = (40.0, 0.3);
        let e = Ellipse::new(300.0, 200.0, r, r, 0.0);
        let points: Vec<[f64; 2]> = (0..360)
            .map(|k| {
                let t = TAU * f64::from(k) / 360.0;
                [e.cx + r * t.cos(), e.cy + r * t.sin()]
            })
            .collect();
        let clip = vec![d; points.len()];
        let sigma = 1e-9;
        let (without, none) = ellipse_covariance(&e, &points, sigma, None, None).unwrap();
        assert!(
            without.amax() < 1e-12 && none.amax() == 0.0,
            "{without} {none}"
        );
        let (unclipped, clipped) =
            ellipse_covariance(&e, &points, sigma, None, Some(&clip)).unwrap();
        assert_eq!(unclipped, without);
        let with = unclipped + clipped;
        // EllipseParams: cx, cy, M11, M12, M22.
        for (k, expected) in [(0, d * d / 4.0), (1, d * d / 4.0), (2, d * d), (4, d * d)] {
            assert!((with[(k, k)] - expected).abs() < 1e-9, "{k}: {with}");
        }
        assert!(with[(3, 3)].abs() < 1e-9, "{with}");
    }
}
