//! Orthogonal (geometric) distance to an ellipse and the least squares fit
//! that minimises it (Levenberg-Marquardt over cx, cy, a, b, theta).
//!
//! The geometric fit is the maximum-likelihood fit for isotropic Gaussian
//! noise: unlike algebraic fits it does not shrink ellipses fitted to partial
//! arcs. The foot point of each point is found by Newton's method on the
//! ellipse parameter, kept as a unit vector (cos t, sin t) so that each step
//! needs no trigonometry, and warm-started from the previous iteration.

use crate::measure::ellipse::Ellipse;
use nalgebra::{Matrix5, Vector5};

/// An ellipse prepared for distance queries.
pub(crate) struct Geometry {
    cx: f64,
    cy: f64,
    a: f64,
    b: f64,
    cos: f64,
    sin: f64,
}

/// The foot point of one query, in the ellipse's own axes.
#[derive(Clone, Copy)]
struct Foot {
    /// (cos t, sin t) of the foot point's ellipse parameter.
    ct: f64,
    st: f64,
    /// Signed orthogonal distance (positive outside).
    dist: f64,
    /// Outward unit normal at the foot, ellipse axes.
    nx: f64,
    ny: f64,
}

/// A Newton step on the foot parameter below this (radians) is the last.
const CONVERGED_PARAM: f64 = 1.0e-6;

/// (cos t, sin t) rotated by about `step` radians: the rational (half-angle)
/// rotation is exactly unit length, so it needs no square root to
/// renormalise (its angle, 2 atan(step / 2), differs from `step` only at
/// third order, which keeps Newton's convergence quadratic).
fn rotate(ct: f64, st: f64, step: f64) -> (f64, f64) {
    let t = 0.5 * step;
    let d = 1.0 / (1.0 + t * t);
    let (c, s) = ((1.0 - t * t) * d, 2.0 * t * d);
    (ct * c - st * s, st * c + ct * s)
}

impl Geometry {
    pub fn new(e: &Ellipse) -> Self {
        let (sin, cos) = e.theta.sin_cos();
        Self {
            cx: e.cx,
            cy: e.cy,
            a: e.a,
            b: e.b,
            cos,
            sin,
        }
    }

    /// The point in the ellipse's axes.
    fn local(&self, p: [f64; 2]) -> (f64, f64) {
        let (dx, dy) = (p[0] - self.cx, p[1] - self.cy);
        (
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }

    /// Starting parameter: exact for a point on the curve.
    fn initial_param(&self, x: f64, y: f64) -> (f64, f64) {
        let (u, v) = (self.b * x, self.a * y);
        let n = (u * u + v * v).sqrt();
        if n > 0.0 { (u / n, v / n) } else { (1.0, 0.0) }
    }

    fn foot(&self, p: [f64; 2], start: Option<(f64, f64)>) -> Foot {
        let (x, y) = self.local(p);
        let (a, b) = (self.a, self.b);
        let (mut ct, mut st) = start.unwrap_or_else(|| self.initial_param(x, y));
        let k = b * b - a * a;
        for _ in 0..8 {
            // f = d/dt of half the squared distance; f' its derivative.
            let f = k * st * ct + a * x * st - b * y * ct;
            let fp = k * (ct * ct - st * st) + a * x * ct + b * y * st;
            let step = if fp > 0.0 {
                (-f / fp).clamp(-0.5, 0.5)
            } else {
                -0.1 * f.signum()
            };
            (ct, st) = rotate(ct, st, step);
            // Newton converges quadratically: after a step below 1e-6 rad
            // the foot is within ~1e-12 of the ellipse's size (and the
            // distance, stationary in t, far closer).
            if step.abs() < CONVERGED_PARAM {
                break;
            }
        }
        let (fx, fy) = (a * ct, b * st);
        // Outward normal: gradient of x^2/a^2 + y^2/b^2 at the foot.
        let (gx, gy) = (ct / a, st / b);
        let gn = (gx * gx + gy * gy).sqrt();
        let (nx, ny) = (gx / gn, gy / gn);
        let dist = nx * (x - fx) + ny * (y - fy);
        Foot {
            ct,
            st,
            dist,
            nx,
            ny,
        }
    }

    /// Signed orthogonal distance of `p` (positive outside).
    #[cfg(test)]
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        self.foot(p, None).dist
    }
}

/// (row, column) of the upper triangle of a 5x5 matrix, column by column.
const UPPER: [(usize, usize); 15] = [
    (0, 0),
    (0, 1),
    (1, 1),
    (0, 2),
    (1, 2),
    (2, 2),
    (0, 3),
    (1, 3),
    (2, 3),
    (3, 3),
    (0, 4),
    (1, 4),
    (2, 4),
    (3, 4),
    (4, 4),
];

/// Sum of squared distances, and the Gauss-Newton normal equations.
fn evaluate(
    e: &Ellipse,
    points: &[[f64; 2]],
    params: &mut [(f64, f64)],
    warm: bool,
) -> (f64, Matrix5<f64>, Vector5<f64>) {
    let g = Geometry::new(e);
    // H's upper triangle (column by column) and the gradient, summed in
    // plain arrays: the same sums in the same order as into the matrices,
    // but they stay in registers and vectorise (one point's 15 products are
    // independent), about half the instructions of the matrix updates.
    let mut upper = [0.0; 15];
    let mut grad = [0.0; 5];
    let mut cost = 0.0;
    for (p, t) in points.iter().zip(params.iter_mut()) {
        let foot = g.foot(*p, warm.then_some(*t));
        *t = (foot.ct, foot.st);
        let r = foot.dist;
        // Normal in image axes.
        let (nwx, nwy) = (
            g.cos * foot.nx - g.sin * foot.ny,
            g.sin * foot.nx + g.cos * foot.ny,
        );
        let (fx, fy) = (e.a * foot.ct, e.b * foot.st);
        let j = [
            -nwx,
            -nwy,
            -foot.nx * foot.ct,
            -foot.ny * foot.st,
            foot.nx * fy - foot.ny * fx,
        ];
        // Upper triangle only: H is symmetric.
        for (u, (row, col)) in upper.iter_mut().zip(UPPER) {
            *u += j[row] * j[col];
        }
        for (g, j) in grad.iter_mut().zip(j) {
            *g += r * j;
        }
        cost += r * r;
    }
    let mut h = Matrix5::zeros();
    for (u, (row, col)) in upper.into_iter().zip(UPPER) {
        h[(row, col)] = u;
        h[(col, row)] = u;
    }
    (cost, h, Vector5::from(grad))
}

/// A Levenberg-Marquardt step shorter than this (normalised coordinates:
/// the data has unit RMS radius) ends the refinement.
const CONVERGED_STEP: f64 = 1.0e-7;

/// A step shorter than this (normalised coordinates) is the last, and is
/// taken without checking that it lowers the cost.
const UNCHECKED_STEP: f64 = 1.0e-6;

/// Minimises the orthogonal distances of `points` to the ellipse, starting
/// from `init`. Never returns a worse ellipse than `init`, but for a last
/// step below `UNCHECKED_STEP` (1e-6 of the data's size), taken unchecked.
pub(crate) fn refine(points: &[[f64; 2]], init: &Ellipse, iterations: usize) -> Ellipse {
    if points.len() < 5 {
        return *init;
    }
    let mut params = vec![(1.0, 0.0); points.len()];
    let mut best = *init;
    let (mut cost, mut h, mut grad) = evaluate(&best, points, &mut params, false);
    if !cost.is_finite() {
        return *init;
    }
    let mut trial_params = params.clone();
    let mut lambda = 1.0e-4;
    for _ in 0..iterations {
        let scale = h.trace().abs() * 1.0e-12 + f64::MIN_POSITIVE;
        let mut damped = h;
        for i in 0..5 {
            damped[(i, i)] += lambda * (h[(i, i)] + scale);
        }
        let Some(chol) = damped.cholesky() else {
            lambda *= 10.0;
            continue;
        };
        let delta = chol.solve(&(-grad));
        let cand = Ellipse {
            cx: best.cx + delta[0],
            cy: best.cy + delta[1],
            a: best.a + delta[2],
            b: best.b + delta[3],
            theta: best.theta + delta[4],
        };
        if !(cand.a > 0.0 && cand.b > 0.0 && delta.iter().all(|v| v.is_finite())) {
            lambda *= 10.0;
            continue;
        }
        // Converged: near the optimum Gauss-Newton converges quadratically
        // (steps of 1e-4, 1e-7, 1e-11 of the data's size), so a step this
        // small is taken without a pass over the points to check its cost:
        // it moves the outline by < 1e-6 of the data's size, and the one
        // after it would be far smaller still.
        if delta.norm() < UNCHECKED_STEP {
            best = cand;
            break;
        }
        trial_params.copy_from_slice(&params);
        let (c2, h2, g2) = evaluate(&cand, points, &mut trial_params, true);
        if c2.is_finite() && c2 <= cost {
            let gain = cost - c2;
            best = cand;
            std::mem::swap(&mut params, &mut trial_params);
            (cost, h, grad) = (c2, h2, g2);
            lambda = (lambda * 0.1).max(1.0e-12);
            // Converged: the step moves the outline by < 1e-7 of the data's
            // size (normalised coordinates), or the cost stopped falling.
            if delta.norm() < CONVERGED_STEP || gain <= 1.0e-10 * cost {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1.0e12 {
                break;
            }
        }
    }
    Ellipse::new(best.cx, best.cy, best.a, best.b, best.theta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_is_exact_along_the_axes_and_for_a_circle() {
        let e = Ellipse::new(1.0, 2.0, 3.0, 1.0, 0.5);
        let g = Geometry::new(&e);
        let (s, c) = e.theta.sin_cos();
        // 0.5 outside the end of the major axis, 0.25 inside the minor one.
        let p = [1.0 + c * 3.5, 2.0 + s * 3.5];
        assert!((g.distance(p) - 0.5).abs() < 1e-12);
        let q = [1.0 - s * 0.75, 2.0 + c * 0.75];
        assert!((g.distance(q) + 0.25).abs() < 1e-12);
        let circle = Geometry::new(&Ellipse::new(0.0, 0.0, 2.0, 2.0, 0.0));
        assert!((circle.distance([3.0, 4.0]) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn distance_matches_brute_force() {
        let e = Ellipse::new(0.0, 0.0, 2.0, 0.7, 0.3);
        let g = Geometry::new(&e);
        for k in 0..50 {
            let t = k as f64 * 0.37;
            let r = 0.5 + (k % 7) as f64 * 0.25;
            let p = [r * 2.0 * t.cos(), r * t.sin()];
            let brute = (0..200_000)
                .map(|i| {
                    let q = e.point_at(i as f64 * std::f64::consts::TAU / 200_000.0);
                    ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt()
                })
                .fold(f64::INFINITY, f64::min);
            assert!((g.distance(p).abs() - brute).abs() < 1e-5, "{p:?}");
        }
    }

    #[test]
    fn refinement_converges_from_a_perturbed_start() {
        let truth = Ellipse::new(0.1, 0.2, 1.5, 0.9, 0.4);
        let pts: Vec<[f64; 2]> = (0..30).map(|k| truth.point_at(k as f64 * 0.12)).collect();
        let start = Ellipse::new(0.15, 0.1, 1.3, 1.0, 0.3);
        let e = refine(&pts, &start, 50);
        assert!(e.max_param_error_px(&truth) < 1e-7, "{e:?}");
        assert!(e.theta_error_rad(&truth) < 1e-7);
    }
}
