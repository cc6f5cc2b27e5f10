//! The paper's least squares fit (section 2.1): minimise the algebraic
//! residual of eq. 2 under the constraint A + C = 1.
//!
//! Substituting A = 1 - C turns eq. 2 into an ordinary linear least squares
//! problem in (B, C, D, E, F):
//! `x^2 + B xy + C (y^2 - x^2) + D x + E y + F = 0`.
//! The geometric parameters follow from eqs. 3-7, computed through the
//! eigen-decomposition in [`Conic::to_ellipse`] (eqs. 5-6 are that
//! decomposition written out).

use crate::measure::ellipse::{Conic, Ellipse};
use nalgebra::{Matrix5, Vector5};

/// Largest semi-axis accepted, in normalised units (the data has unit RMS
/// radius): anything larger is a near-degenerate conic through nearly
/// collinear points, not an ellipse the data supports.
pub(crate) const MAX_AXIS_NORMALISED: f64 = 1.0e3;

/// The A+C=1 conic through `points` (normalised coordinates), or `None` when
/// the system is singular.
pub(crate) fn fit_conic<'a>(points: impl IntoIterator<Item = &'a [f64; 2]>) -> Option<Conic> {
    let mut m = Matrix5::<f64>::zeros();
    let mut rhs = Vector5::<f64>::zeros();
    let mut count = 0usize;
    for p in points {
        let (x, y) = (p[0], p[1]);
        let row = Vector5::new(x * y, y * y - x * x, x, y, 1.0);
        // Symmetric rank-one update (upper triangle is enough for Cholesky,
        // but nalgebra reads the lower one: fill both through ger).
        m.ger(1.0, &row, &row, 1.0);
        rhs.axpy(-x * x, &row, 1.0);
        count += 1;
    }
    if count < 5 {
        return None;
    }
    let sol = m.cholesky()?.solve(&rhs);
    if !sol.iter().all(|v| v.is_finite()) {
        return None;
    }
    let (b, c, d, e, f) = (sol[0], sol[1], sol[2], sol[3], sol[4]);
    Some(Conic {
        a: 1.0 - c,
        b,
        c,
        d,
        e,
        f,
    })
}

/// Eqs. 3-7 with the paper's acceptance test B^2 - 4AC < 0, plus a sanity
/// bound on the axes (normalised coordinates).
pub(crate) fn conic_to_ellipse(conic: &Conic) -> Option<Ellipse> {
    let e = conic.to_ellipse()?;
    let ok = [e.cx, e.cy, e.a, e.b, e.theta]
        .iter()
        .all(|v| v.is_finite())
        && e.b > 1.0e-9
        && e.a < MAX_AXIS_NORMALISED
        && e.cx.abs() < MAX_AXIS_NORMALISED
        && e.cy.abs() < MAX_AXIS_NORMALISED;
    ok.then_some(e)
}

/// The A+C=1 least squares ellipse of `points` (normalised coordinates).
pub(crate) fn fit_ellipse(points: &[[f64; 2]]) -> Option<Ellipse> {
    conic_to_ellipse(&fit_conic(points)?)
}

/// The A+C=1 ellipse of the points selected by `keep`.
pub(crate) fn fit_ellipse_selected(points: &[[f64; 2]], keep: &[bool]) -> Option<Ellipse> {
    let selected = points.iter().zip(keep).filter(|(_, k)| **k).map(|(p, _)| p);
    conic_to_ellipse(&fit_conic(selected)?)
}

/// The baselines' last step (Algorithm 1 lines 18-19, and RANSAC's): the
/// points within `limit` (Sampson distance) of `model` are the inliers, and
/// the A+C=1 least squares of them is the result.
pub(crate) fn refit_inliers(
    points: &[[f64; 2]],
    model: &Ellipse,
    limit: f64,
) -> Result<(Ellipse, Vec<bool>), super::FitError> {
    let conic = model.to_conic();
    let inliers: Vec<bool> = points
        .iter()
        .map(|p| conic.sampson_distance(p[0], p[1]) < limit)
        .collect();
    if inliers.iter().filter(|k| **k).count() < 5 {
        return Err(super::FitError::NoEllipse);
    }
    let e = fit_ellipse_selected(points, &inliers).ok_or(super::FitError::NoEllipse)?;
    Ok((e, inliers))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_points_determine_the_ellipse() {
        let truth = Ellipse::new(0.2, -0.1, 1.3, 0.6, 0.9);
        let pts: Vec<[f64; 2]> = (0..5).map(|k| truth.point_at(k as f64 * 1.1)).collect();
        let e = fit_ellipse(&pts).unwrap();
        assert!(e.max_param_error_px(&truth) < 1e-9, "{e:?}");
        assert!(e.theta_error_rad(&truth) < 1e-9);
    }

    #[test]
    fn matches_the_closed_form_normal_equations_on_a_circle() {
        // Points on the unit circle plus a symmetric perturbation: by symmetry
        // the A+C=1 solution is a circle centred at the origin, with
        // A = C = 1/2, F = -(mean r^2)/2 (analytic).
        let mut pts = Vec::new();
        for k in 0..8 {
            let t = k as f64 * std::f64::consts::TAU / 8.0;
            let r = if k % 2 == 0 { 1.1 } else { 0.9 };
            pts.push([r * t.cos(), r * t.sin()]);
        }
        let c = fit_conic(&pts).unwrap();
        assert!((c.a - 0.5).abs() < 1e-12 && (c.c - 0.5).abs() < 1e-12);
        assert!(c.b.abs() < 1e-12 && c.d.abs() < 1e-12 && c.e.abs() < 1e-12);
        // Minimising sum (r^2/2 + F)^2 gives F = -mean(r^2)/2.
        let mean_r2 = (1.21 + 0.81) / 2.0;
        assert!((c.f + mean_r2 / 2.0).abs() < 1e-12, "{c:?}");
    }

    #[test]
    fn a_hyperbola_is_rejected() {
        // Points on x^2 - y^2 / 4 = 1 (both branches; A + C != 0).
        let pts: Vec<[f64; 2]> = (-3..=3)
            .flat_map(|k| {
                let t = k as f64 * 0.4;
                [[t.cosh(), 2.0 * t.sinh()], [-t.cosh(), 2.0 * t.sinh()]]
            })
            .collect();
        assert!(fit_ellipse(&pts).is_none());
    }
}
