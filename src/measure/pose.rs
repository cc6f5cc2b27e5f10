//! Circle pose from its image ellipse: the paper's visual cone (eqs. 11-27).
//!
//! The ellipse (undistorted pixels) and the camera matrix K define the elliptic
//! cone of rays through the circle's rim. Following the paper, a virtual camera
//! frame is built from the two rays of maximal angle (eqs. 11-13), the virtual
//! ellipse's half-axes `l_a'`, `l_c'` are read from the cone (eqs. 14-15), and
//! the centre `F'` and normal `n'` follow in closed form (eqs. 20-24), then are
//! rotated back (eqs. 25-27). We work in normalised camera coordinates
//! (`f = 1`), so fx != fy is handled exactly by K.
//!
//! Two corrections to the printed equations, checked against exact
//! projections in `tests/pose_analytic.rs`:
//! - eq. 22: the second root of alpha/beta reads `l_a'^2 - l_c'^2` (as in
//!   eq. 23), not `l_a'^2 - f^2`; gamma is `(r/l_a') sqrt((l_c'^2+f^2)/(l_a'^2+f^2))`.
//!   Only alpha and beta enter `F'`, so eq. 23 is right as printed.
//! - eq. 24's third component is `-sqrt(l_a'^2+f^2) l_c'` (not `l_c'^2`), as
//!   its normalising denominator shows.
//!
//! The paper gives one solution; the other is its mirror in the plane of the
//! maximal-angle rays (`y' -> -y'`): both image to the very same ellipse.
//!
//! Near-circles: when the cone is nearly circular the maximal-angle plane (the
//! paper's theta) is undefined, but then `l_a' = l_c'`, the y'-components of
//! `F'` and `n'` vanish and the result does not depend on that plane: the
//! eigenvector error (~ eps / (l_a'-l_c')) is multiplied by `sqrt(l_a'^2-l_c'^2)`,
//! leaving an error of ~ sqrt(eps) ~ 1e-8 at worst. Both solutions then
//! coincide and the ambiguity does not matter.

use super::FitQuality;
use super::ellipse::Ellipse;
use crate::camera::CameraModel;
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3};

/// A circle's pose in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CirclePose {
    /// Circle centre, camera frame, metres.
    pub centre_camera_m: Vector3<f64>,
    /// Unit normal of the circle's plane, camera frame, pointing toward the camera.
    pub normal_camera: Vector3<f64>,
}

/// Two unit vectors spanning the plane of a circle with unit-ish normal `n`
/// (camera frame), orthogonal to it and to each other; `None` for a
/// non-finite or near-zero normal.
pub fn circle_plane_basis(n: &Vector3<f64>) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if !(n.iter().all(|x| x.is_finite()) && n.norm() > 0.5) {
        return None;
    }
    let n = n.normalize();
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    Some((e1, n.cross(&e1)))
}

/// The principal axes of the elliptic cone through the ellipse.
struct ConeAxes {
    /// Cone axis (camera frame, unit, z > 0).
    axis: Vector3<f64>,
    /// Unit direction of the widest opening (the ellipse's "major" side).
    major: Vector3<f64>,
    /// tan of the half-opening toward `major`.
    tan_major: f64,
}

/// The cone `X^T Q X = 0` of camera-frame rays through the ellipse: the
/// pixel conic pulled back through K. Scaled to unit norm and signed so that
/// it has two positive eigenvalues and one negative.
fn cone_matrix(ellipse_px: &Ellipse, camera: &CameraModel) -> Option<Matrix3<f64>> {
    let e = ellipse_px;
    let valid = [e.cx, e.cy, e.a, e.b, e.theta]
        .iter()
        .all(|x| x.is_finite())
        && e.a > 0.0
        && e.b > 0.0;
    if !valid {
        return None;
    }
    // Q = K^T C K with C the pixel conic, evaluated as G^T C_local G where
    // C_local is the conic about the ellipse's own centre and G = T^-1 K
    // shifts the principal point to that centre. Same matrix, but without the
    // cancellation of forming the pixel conic's constant term (~ cx^2 / a^2).
    let (s, c) = e.theta.sin_cos();
    let rot = Matrix2::new(c, -s, s, c);
    let shape =
        rot * Matrix2::new(1.0 / (e.a * e.a), 0.0, 0.0, 1.0 / (e.b * e.b)) * rot.transpose();
    let c_local = Matrix3::new(
        shape[(0, 0)],
        shape[(0, 1)],
        0.0,
        shape[(1, 0)],
        shape[(1, 1)],
        0.0,
        0.0,
        0.0,
        -1.0,
    );
    let k = &camera.k;
    let g = Matrix3::new(
        k[(0, 0)],
        k[(0, 1)],
        k[(0, 2)] - e.cx,
        0.0,
        k[(1, 1)],
        k[(1, 2)] - e.cy,
        0.0,
        0.0,
        1.0,
    );
    let q = g.transpose() * c_local * g;
    let norm = q.norm();
    if !(norm.is_finite() && norm > 0.0) {
        return None;
    }
    let q = q / norm;
    Some(if q.determinant() > 0.0 { -q } else { q })
}

fn cone_axes(q: &Matrix3<f64>) -> Option<ConeAxes> {
    let eig = q.symmetric_eigen();
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let (l_neg, l_mid) = (eig.eigenvalues[idx[0]], eig.eigenvalues[idx[1]]);
    if !(l_neg < 0.0 && l_mid > 0.0) {
        return None;
    }
    let mut axis = eig.eigenvectors.column(idx[0]).into_owned();
    if axis.z < 0.0 {
        axis = -axis;
    }
    Some(ConeAxes {
        axis,
        major: eig.eigenvectors.column(idx[1]).into_owned(),
        tan_major: (-l_neg / l_mid).sqrt(),
    })
}

/// Both solutions of the single-circle ambiguity for an ellipse in
/// undistorted pixels and a circle of `radius_m`, or `None` for a degenerate
/// ellipse. The 3-D centre comes from the cone, never from back-projecting the
/// ellipse centre (the ellipse centre is not the image of the circle centre).
pub fn cone_pose(
    ellipse_px: &Ellipse,
    camera: &CameraModel,
    radius_m: f64,
) -> Option<[CirclePose; 2]> {
    if !(radius_m > 0.0 && radius_m.is_finite()) {
        return None;
    }
    let q = cone_matrix(ellipse_px, camera)?;
    let cone = cone_axes(&q)?;

    // The two rays of maximal angle, O->A and O->B (unit vectors).
    let u_oa = (cone.axis + cone.tan_major * cone.major).normalize();
    let u_ob = (cone.axis - cone.tan_major * cone.major).normalize();

    // Virtual camera frame, eqs. 11-13.
    let z_v = (u_oa + u_ob).normalize();
    let y_v = u_oa.cross(&u_ob).normalize();
    let x_v = z_v.cross(&y_v);

    // Virtual ellipse half-axes, eqs. 14-15 (f = 1, normalised coordinates).
    let f = 1.0;
    let angle_aob = u_oa.cross(&u_ob).norm().atan2(u_oa.dot(&u_ob));
    let l_a = f * (angle_aob / 2.0).tan();
    // l_c' = f tan(angle c'Od' / 2), where c', d' are the virtual ellipse's
    // points on y' (the plane through z' perpendicular to AOB). In the virtual
    // frame E' is q_xx x^2 + q_yy y^2 + q_zz f^2 = 0 (Q' = R^T Q R), so
    // l_a'^2 = -q_zz f^2 / q_xx and l_c'^2 = -q_zz f^2 / q_yy: l_c' is l_a'
    // times the square root of q_xx / q_yy. Reading it through that ratio of
    // the cone's two large terms, instead of solving for the rays c', d' on
    // their own, keeps l_a'^2 - l_c'^2 (the tilt) precise for small, nearly
    // frontal ellipses, where q_zz is a small difference of large numbers.
    let (qxx, qyy) = (x_v.dot(&(q * x_v)), y_v.dot(&(q * y_v)));
    if !(qxx > 0.0 && qyy > 0.0) {
        return None;
    }
    // qyy >= qxx (y' is the narrow side) up to rounding at a frontal circle.
    let l_c = l_a * (qxx / qyy).min(1.0).sqrt();
    if !(l_a > 0.0 && l_c > 0.0 && l_a.is_finite() && l_c.is_finite()) {
        return None;
    }

    // Centre and normal in the virtual frame, eqs. 23-24 (corrected, see above).
    let r = radius_m;
    // sqrt(l_a'^2 - l_c'^2), from the difference of the cone's large terms.
    let s = l_a * ((qyy - qxx) / qyy).max(0.0).sqrt();
    let t = (l_a * l_a + f * f).sqrt();
    let lc_f = (l_c * l_c + f * f).sqrt();
    let centre_y = r * l_c / l_a * s / lc_f;
    let centre_z = r * f / l_a * t / lc_f;
    let norm = (s * s * f * f + t * t * l_c * l_c).sqrt();
    let normal_y = s * f / norm;
    let normal_z = -t * l_c / norm;

    // Back to the camera frame, eqs. 25-27: R = [x', y', z']. (x' does not
    // enter: F' and n' have no x'-component.)
    let rot = Matrix3::from_columns(&[x_v, y_v, z_v]);
    let solution = |sign: f64| CirclePose {
        centre_camera_m: rot * Vector3::new(0.0, sign * centre_y, centre_z),
        normal_camera: (rot * Vector3::new(0.0, sign * normal_y, normal_z)).normalize(),
    };
    let both = [solution(1.0), solution(-1.0)];
    let finite = both.iter().all(|p| {
        p.centre_camera_m.iter().all(|x| x.is_finite())
            && p.normal_camera.iter().all(|x| x.is_finite())
            && p.centre_camera_m.z > 0.0
    });
    finite.then_some(both)
}

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

/// First-order covariance of the ellipse parameters (`EllipseParams`) for
/// points with independent geometric noise `sigma_px` normal to the curve:
/// `sigma^2 (J^T J)^-1`, J the derivatives of each point's distance to the
/// curve. Points are assigned to the curve through `M^-1 (p - c)` (exact on
/// the curve, first-order near it).
fn ellipse_covariance(
    e: &Ellipse,
    points_px: &[[f64; 2]],
    sigma_px: f64,
) -> Option<SMatrix<f64, 5, 5>> {
    let p = ellipse_params(e);
    let m = Matrix2::new(p[2], p[3], p[3], p[4]);
    let m_inv = m.try_inverse()?;
    let mut jtj = SMatrix::<f64, 5, 5>::zeros();
    for pt in points_px {
        // (cos t, sin t) of the point's place on the curve.
        let Some(w) = (m_inv * Vector2::new(pt[0] - e.cx, pt[1] - e.cy)).try_normalize(0.0) else {
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
        let row = [
            n.x,
            n.y,
            n.x * cos_t,
            n.x * sin_t + n.y * cos_t,
            n.y * sin_t,
        ];
        for i in 0..5 {
            for j in i..5 {
                jtj[(i, j)] += row[i] * row[j];
            }
        }
    }
    jtj.fill_lower_triangle_with_upper_triangle();
    jtj.try_inverse().map(|inv| inv * (sigma_px * sigma_px))
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

/// Uncertainty of `pose` (one of `cone_pose`'s solutions for `ellipse_px`)
/// from the fit: the points' noise is the fit's RMS residual (corrected for
/// the 5 fitted parameters), giving the ellipse covariance through the
/// points' distance Jacobian at the actual inlier positions (so a partly hidden
/// rim gives a larger covariance); that is propagated through `cone_pose`
/// along the covariance's principal directions (+- one sigma each, second
/// moments about the nominal pose). That equals `J C J^T` where the pose is
/// linear in the ellipse and stays finite at a frontal circle, where the
/// normal is not differentiable (tilt ~ sqrt of the ellipse's eccentricity).
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
    let unknown = PoseUncertainty {
        position_cov_camera_m2: Matrix3::from_element(f64::NAN),
        normal_sigma_rad: f64::NAN,
    };
    let n = inlier_points_px.len();
    if n <= 5 || !(quality.rms_residual_px >= 0.0 && quality.rms_residual_px.is_finite()) {
        return unknown;
    }
    let sigma_px = quality.rms_residual_px * (n as f64 / (n - 5) as f64).sqrt();
    let Some(cov_e) = ellipse_covariance(ellipse_px, inlier_points_px, sigma_px) else {
        return unknown;
    };
    let eig = cov_e.symmetric_eigen();
    let p0 = ellipse_params(ellipse_px);
    let mut cov_pos = Matrix3::zeros();
    let mut normal_var = 0.0;
    for k in 0..5 {
        let step = eig.eigenvectors.column(k) * eig.eigenvalues[k].max(0.0).sqrt();
        for sign in [1.0, -1.0] {
            let moved = ellipse_from_params(&(p0 + sign * step))
                .and_then(|e| cone_pose(&e, camera, radius_m))
                .map(|[s1, s2]| {
                    if s1.normal_camera.dot(&pose.normal_camera)
                        >= s2.normal_camera.dot(&pose.normal_camera)
                    {
                        s1
                    } else {
                        s2
                    }
                });
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
    }
    PoseUncertainty {
        position_cov_camera_m2: cov_pos,
        normal_sigma_rad: normal_var.sqrt(),
    }
}
