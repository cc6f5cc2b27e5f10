//! The visual cone (eqs. 11-27): both circle poses of an image ellipse.
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

use super::CirclePose;
use crate::camera::CameraModel;
use crate::measure::ellipse::Ellipse;
use crate::spatial::{Direction, Point};
use nalgebra::{Matrix2, Matrix3, Vector3};

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
    cone_pose_parts(ellipse_px, camera, radius_m, false).map(|(both, _)| both)
}

/// [`cone_pose`] and the cone's asymmetry `s = sqrt(l_a'^2 - l_c'^2)` (zero
/// for a circle seen face-on along the cone's axis). With `face_on`, the
/// pose of the circular cone nearest to the ellipse's (`l_c' = l_a'`,
/// `s = 0`): the face-on hypothesis, where the pose is not differentiable in
/// the ellipse.
pub(super) fn cone_pose_parts(
    ellipse_px: &Ellipse,
    camera: &CameraModel,
    radius_m: f64,
    face_on: bool,
) -> Option<([CirclePose; 2], f64)> {
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
    let l_c = if face_on {
        l_a
    } else {
        l_a * (qxx / qyy).min(1.0).sqrt()
    };
    if !(l_a > 0.0 && l_c > 0.0 && l_a.is_finite() && l_c.is_finite()) {
        return None;
    }

    // Centre and normal in the virtual frame, eqs. 23-24 (corrected, see above).
    let r = radius_m;
    // sqrt(l_a'^2 - l_c'^2), from the difference of the cone's large terms.
    let s_cone = l_a * ((qyy - qxx) / qyy).max(0.0).sqrt();
    let s = if face_on { 0.0 } else { s_cone };
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
        centre_camera_m: Point::new(rot * Vector3::new(0.0, sign * centre_y, centre_z)),
        normal_camera: Direction::new(
            (rot * Vector3::new(0.0, sign * normal_y, normal_z)).normalize(),
        ),
    };
    let both = [solution(1.0), solution(-1.0)];
    let finite = both.iter().all(|p| {
        p.centre_camera_m.iter().all(|x| x.is_finite())
            && p.normal_camera.iter().all(|x| x.is_finite())
            && p.centre_camera_m.z > 0.0
    });
    finite.then_some((both, s_cone))
}
