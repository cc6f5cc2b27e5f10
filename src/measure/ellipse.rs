//! Ellipses in the image plane and their conic form.
//!
//! Everything here is in image pixels: u right, v down, origin at the centre of
//! the top-left pixel (OpenCV convention).

use nalgebra::{Matrix2, Matrix3, Vector2};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};

/// An ellipse in image pixels, in the architecture's JSON convention:
/// `a >= b` are the semi-axes and `theta` is the major axis' angle from +u toward
/// +v, in radians, in (-pi/2, pi/2].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ellipse {
    /// Centre u, pixels.
    pub cx: f64,
    /// Centre v, pixels.
    pub cy: f64,
    /// Semi-major axis, pixels.
    pub a: f64,
    /// Semi-minor axis, pixels (`b <= a`).
    pub b: f64,
    /// Angle of the major axis from +u toward +v, radians, in (-pi/2, pi/2].
    pub theta: f64,
}

/// The conic `A u^2 + B u v + C v^2 + D u + E v + F = 0` (paper eq. 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conic {
    /// Coefficient of u^2.
    pub a: f64,
    /// Coefficient of u v.
    pub b: f64,
    /// Coefficient of v^2.
    pub c: f64,
    /// Coefficient of u.
    pub d: f64,
    /// Coefficient of v.
    pub e: f64,
    /// Constant term.
    pub f: f64,
}

/// Wraps an axis angle into (-pi/2, pi/2]: an axis has no direction.
pub fn wrap_axis_angle(theta: f64) -> f64 {
    let mut t = theta % PI;
    if t <= -FRAC_PI_2 {
        t += PI;
    } else if t > FRAC_PI_2 {
        t -= PI;
    }
    t
}

impl Ellipse {
    /// Builds an ellipse from any semi-axes and angle, putting it in the
    /// canonical form (`a >= b`, theta wrapped).
    pub fn new(cx: f64, cy: f64, a: f64, b: f64, theta: f64) -> Self {
        let (a, b, theta) = if a >= b {
            (a, b, theta)
        } else {
            (b, a, theta + FRAC_PI_2)
        };
        Self {
            cx,
            cy,
            a,
            b,
            theta: wrap_axis_angle(theta),
        }
    }

    /// The concentric ellipse `factor` times this one's size, same
    /// orientation (the disc inside its canopy rim, or the rim around it).
    pub fn scaled(&self, factor: f64) -> Self {
        Self::new(
            self.cx,
            self.cy,
            factor * self.a,
            factor * self.b,
            self.theta,
        )
    }

    /// Whether the point `(u, v)` lies inside the ellipse or on it (`false`
    /// for a point or an ellipse that is not finite).
    pub fn contains(&self, u: f64, v: f64) -> bool {
        let (s, c) = self.theta.sin_cos();
        let (du, dv) = (u - self.cx, v - self.cy);
        let along = (du * c + dv * s) / self.a;
        let across = (dv * c - du * s) / self.b;
        along * along + across * across <= 1.0
    }

    /// The point at parameter `t` (radians) on the ellipse.
    pub fn point_at(&self, t: f64) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        let (x, y) = (self.a * t.cos(), self.b * t.sin());
        [self.cx + c * x - s * y, self.cy + s * x + c * y]
    }

    /// The conic of this ellipse, scaled so that `A + C = 1`.
    pub fn to_conic(&self) -> Conic {
        let (s, c) = self.theta.sin_cos();
        let (a2, b2) = (self.a * self.a, self.b * self.b);
        // Quadratic form of (R^T x)^T diag(1/a^2, 1/b^2) (R^T x) - 1.
        let qa = c * c / a2 + s * s / b2;
        let qb = 2.0 * c * s * (1.0 / a2 - 1.0 / b2);
        let qc = s * s / a2 + c * c / b2;
        let (x0, y0) = (self.cx, self.cy);
        let d = -2.0 * qa * x0 - qb * y0;
        let e = -qb * x0 - 2.0 * qc * y0;
        let f = qa * x0 * x0 + qb * x0 * y0 + qc * y0 * y0 - 1.0;
        let k = 1.0 / (qa + qc);
        Conic {
            a: qa * k,
            b: qb * k,
            c: qc * k,
            d: d * k,
            e: e * k,
            f: f * k,
        }
    }

    /// Largest difference to `other` in centre and semi-axes (pixels).
    pub fn max_param_error_px(&self, other: &Ellipse) -> f64 {
        [
            (self.cx - other.cx).abs(),
            (self.cy - other.cy).abs(),
            (self.a - other.a).abs(),
            (self.b - other.b).abs(),
        ]
        .into_iter()
        .fold(0.0, f64::max)
    }

    /// Difference of axis angles (radians, in [0, pi/2]).
    pub fn theta_error_rad(&self, other: &Ellipse) -> f64 {
        wrap_axis_angle(self.theta - other.theta).abs()
    }

    /// Approximate geometric distance of a point to the ellipse (Sampson
    /// distance of the conic), in pixels.
    pub fn distance_px(&self, u: f64, v: f64) -> f64 {
        self.to_conic().sampson_distance(u, v)
    }

    /// Distance from `from` along the unit direction `dir` to where the ray
    /// leaves the ellipse, pixels; `None` when `from` lies outside it.
    pub fn exit_distance_px(&self, from: [f64; 2], dir: [f64; 2]) -> Option<f64> {
        let (s, c) = self.theta.sin_cos();
        let (dx, dy) = (from[0] - self.cx, from[1] - self.cy);
        // In the axes' frame, scaled so that the ellipse is the unit circle:
        // |p + t u| = 1, t in pixels along `dir`.
        let p = [(c * dx + s * dy) / self.a, (c * dy - s * dx) / self.b];
        let u = [
            (c * dir[0] + s * dir[1]) / self.a,
            (c * dir[1] - s * dir[0]) / self.b,
        ];
        let qa = u[0] * u[0] + u[1] * u[1];
        let qb = p[0] * u[0] + p[1] * u[1];
        let qc = p[0] * p[0] + p[1] * p[1] - 1.0;
        if !(qc <= 0.0 && qa > 0.0 && qa.is_finite()) {
            return None;
        }
        Some((-qb + (qb * qb - qa * qc).sqrt()) / qa)
    }
}

/// A tracked rim's motion during one exposure (undistorted pixels): where
/// it is predicted at the exposure's start and at its end. A motion blur
/// smears each rim point from the one to the other.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExposureSweep {
    /// The rim at the start of the exposure.
    pub start: Ellipse,
    /// The rim at its end.
    pub end: Ellipse,
}

impl ExposureSweep {
    /// How far the rim moves during the exposure along the ray from `from`
    /// in the unit direction `dir`, pixels: the length of the blur's ramp
    /// that ray crosses. `None` when `from` lies outside either ellipse.
    pub fn along_ray_px(&self, from: [f64; 2], dir: [f64; 2]) -> Option<f64> {
        let start = self.start.exit_distance_px(from, dir)?;
        let end = self.end.exit_distance_px(from, dir)?;
        Some((end - start).abs())
    }

    /// At most how far the rim moves along a ray from the centre (to first
    /// order in the motion): a shift of the centre by up to `a / b` times
    /// its length (the normal is at most that oblique to such a ray), each
    /// axis' change once, a turn by up to `a / b` times its arc at the
    /// major axis' end.
    pub fn most_travel_px(&self) -> f64 {
        let (s, e) = (&self.start, &self.end);
        let a = s.a.max(e.a);
        let oblique = a / s.b.min(e.b);
        let shift = (e.cx - s.cx).hypot(e.cy - s.cy);
        let turn = a * e.theta_error_rad(s);
        (shift + turn) * oblique + (e.a - s.a).abs() + (e.b - s.b).abs()
    }
}

impl Conic {
    /// The symmetric 3x3 matrix `[x y 1] M [x y 1]^T = 0` of the conic.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.a,
            self.b / 2.0,
            self.d / 2.0,
            self.b / 2.0,
            self.c,
            self.e / 2.0,
            self.d / 2.0,
            self.e / 2.0,
            self.f,
        )
    }

    /// The conic of a symmetric matrix (only the upper triangle is read).
    pub fn from_matrix(m: &Matrix3<f64>) -> Self {
        Self {
            a: m[(0, 0)],
            b: 2.0 * m[(0, 1)],
            c: m[(1, 1)],
            d: 2.0 * m[(0, 2)],
            e: 2.0 * m[(1, 2)],
            f: m[(2, 2)],
        }
    }

    /// The algebraic residual at a point (paper eq. 2 summand, unsquared).
    pub fn algebraic(&self, u: f64, v: f64) -> f64 {
        self.a * u * u + self.b * u * v + self.c * v * v + self.d * u + self.e * v + self.f
    }

    /// First-order geometric distance (Sampson): the algebraic residual over
    /// its gradient's length. Exact to first order near the curve.
    pub fn sampson_distance(&self, u: f64, v: f64) -> f64 {
        let (r, g2) = self.residual_and_gradient_sq(u, v);
        let g = g2.sqrt();
        if g > 0.0 { r.abs() / g } else { f64::INFINITY }
    }

    /// The square of [`Conic::sampson_distance`]: no square root, for
    /// comparisons and medians (which the square does not change).
    pub fn sampson_distance_sq(&self, u: f64, v: f64) -> f64 {
        let (r, g2) = self.residual_and_gradient_sq(u, v);
        if g2 > 0.0 { r * r / g2 } else { f64::INFINITY }
    }

    /// Whether a point is within `band` of the conic (first-order
    /// distance), with neither a division nor a square root.
    pub fn within_sampson(&self, u: f64, v: f64, band: f64) -> bool {
        let (r, g2) = self.residual_and_gradient_sq(u, v);
        r * r < band * band * g2
    }

    /// The algebraic residual at a point and its gradient's squared length.
    fn residual_and_gradient_sq(&self, u: f64, v: f64) -> (f64, f64) {
        let gu = 2.0 * self.a * u + self.b * v + self.d;
        let gv = self.b * u + 2.0 * self.c * v + self.e;
        (self.algebraic(u, v), gu * gu + gv * gv)
    }

    /// The ellipse of this conic (paper eqs. 3-7, computed through the
    /// eigen-decomposition so that it is exact for any scaling), or `None`
    /// when the conic is not a real ellipse.
    pub fn to_ellipse(&self) -> Option<Ellipse> {
        let disc = self.b * self.b - 4.0 * self.a * self.c;
        if disc.is_nan() || disc >= 0.0 || !disc.is_finite() {
            return None;
        }
        // Centre: gradient zero.
        let m2 = Matrix2::new(2.0 * self.a, self.b, self.b, 2.0 * self.c);
        let centre = m2.lu().solve(&Vector2::new(-self.d, -self.e))?;
        let (x0, y0) = (centre.x, centre.y);
        let f0 = self.f + (self.d * x0 + self.e * y0) / 2.0;
        let q = Matrix2::new(self.a, self.b / 2.0, self.b / 2.0, self.c);
        let eig = q.symmetric_eigen();
        let (l0, l1) = (eig.eigenvalues[0], eig.eigenvalues[1]);
        let s0 = -f0 / l0;
        let s1 = -f0 / l1;
        if !(s0 > 0.0 && s1 > 0.0 && s0.is_finite() && s1.is_finite()) {
            return None;
        }
        // The major axis belongs to the smaller |eigenvalue| (larger s).
        let (major_s, minor_s, major_vec) = if s0 >= s1 {
            (s0, s1, eig.eigenvectors.column(0).into_owned())
        } else {
            (s1, s0, eig.eigenvectors.column(1).into_owned())
        };
        let theta = wrap_axis_angle(major_vec.y.atan2(major_vec.x));
        Some(Ellipse {
            cx: x0,
            cy: y0,
            a: major_s.sqrt(),
            b: minor_s.sqrt(),
            theta,
        })
    }

    /// This conic scaled to `A + C = 1` (the paper's normalisation).
    pub fn normalised(&self) -> Option<Self> {
        let k = self.a + self.c;
        if k.abs() < f64::MIN_POSITIVE || !k.is_finite() {
            return None;
        }
        Some(Self {
            a: self.a / k,
            b: self.b / k,
            c: self.c / k,
            d: self.d / k,
            e: self.e / k,
            f: self.f / k,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contains_is_inside_or_on_the_ellipse() {
        let e = Ellipse::new(100.0, 50.0, 40.0, 20.0, 0.7);
        for (t, inside) in [(0.99, true), (1.01, false)] {
            for k in 0..12 {
                let p = e.point_at(k as f64 * std::f64::consts::TAU / 12.0);
                let (u, v) = (e.cx + t * (p[0] - e.cx), e.cy + t * (p[1] - e.cy));
                assert_eq!(e.contains(u, v), inside, "{t} {k}");
            }
        }
        assert!(e.contains(e.cx, e.cy));
        assert!(!e.contains(f64::NAN, e.cy));
        assert!(!Ellipse::new(0.0, 0.0, f64::NAN, 1.0, 0.0).contains(0.0, 0.0));
    }

    #[test]
    fn a_ray_leaves_the_ellipse_where_it_crosses_it() {
        let e = Ellipse::new(100.0, 50.0, 40.0, 20.0, 0.7);
        let (s, c) = e.theta.sin_cos();
        // From the centre: the semi-axes along the axes.
        let centre = [e.cx, e.cy];
        assert!((e.exit_distance_px(centre, [c, s]).unwrap() - 40.0).abs() < 1e-9);
        assert!((e.exit_distance_px(centre, [-s, c]).unwrap() - 20.0).abs() < 1e-9);
        // From anywhere inside, the exit point is on the ellipse.
        let from = [e.cx + 7.0, e.cy - 4.0];
        for k in 0..16 {
            let phi = k as f64 * std::f64::consts::TAU / 16.0;
            let dir = [phi.cos(), phi.sin()];
            let t = e.exit_distance_px(from, dir).unwrap();
            let p = [from[0] + t * dir[0], from[1] + t * dir[1]];
            assert!(
                e.to_conic().sampson_distance(p[0], p[1]).abs() < 1e-9,
                "{k}"
            );
        }
        // From outside: no exit.
        assert!(
            e.exit_distance_px([e.cx + 50.0, e.cy + 50.0], [1.0, 0.0])
                .is_none()
        );
        assert!(e.exit_distance_px([f64::NAN, 0.0], [1.0, 0.0]).is_none());
    }

    #[test]
    fn an_exposure_sweep_is_the_rims_travel_along_each_ray() {
        // A circle of radius 30 moving 8 px along +u during the exposure,
        // seen from its centre at mid-exposure: the rim travels 8 px along
        // the motion, nothing across it, and 8 |cos phi| to first order
        // between.
        let sweep = ExposureSweep {
            start: Ellipse::new(96.0, 50.0, 30.0, 30.0, 0.0),
            end: Ellipse::new(104.0, 50.0, 30.0, 30.0, 0.0),
        };
        let from = [100.0, 50.0];
        let along = |phi: f64| sweep.along_ray_px(from, [phi.cos(), phi.sin()]).unwrap();
        assert!((along(0.0) - 8.0).abs() < 1e-9);
        assert!((along(std::f64::consts::PI) - 8.0).abs() < 1e-9);
        assert!(along(std::f64::consts::FRAC_PI_2) < 1e-9);
        let phi = 1.0f64;
        assert!((along(phi) - 8.0 * phi.cos()).abs() < 0.1, "{}", along(phi));
        // Growing as it nears: the rim moves out all round.
        let nearing = ExposureSweep {
            start: Ellipse::new(100.0, 50.0, 30.0, 30.0, 0.0),
            end: Ellipse::new(100.0, 50.0, 31.0, 31.0, 0.0),
        };
        assert!((nearing.along_ray_px(from, [0.6, 0.8]).unwrap() - 1.0).abs() < 1e-9);
        // The bound holds all round, for motions of every kind.
        for k in 0..200 {
            let x = k as f64;
            let mid = Ellipse::new(300.0, 200.0, 20.0 + x % 37.0, 8.0 + x % 11.0, 0.1 * x);
            let d = [
                (0.37 * x).sin() * 3.0,
                (0.53 * x).cos() * 3.0,
                (0.71 * x).sin(),
                (0.29 * x).cos() * 0.5,
                (0.13 * x).sin() * 0.05,
            ];
            let at = |t: f64| {
                Ellipse::new(
                    mid.cx + t * d[0],
                    mid.cy + t * d[1],
                    mid.a + t * d[2],
                    mid.b + t * d[3],
                    mid.theta + t * d[4],
                )
            };
            let sweep = ExposureSweep {
                start: at(-0.5),
                end: at(0.5),
            };
            let most = sweep.most_travel_px();
            for j in 0..64 {
                let phi = j as f64 * std::f64::consts::TAU / 64.0;
                let along = sweep.along_ray_px([mid.cx, mid.cy], [phi.cos(), phi.sin()]);
                assert!(
                    along.unwrap() <= most * 1.05 + 1e-9,
                    "{k} {j}: {along:?} > {most}"
                );
            }
        }
    }

    #[test]
    fn conic_round_trip() {
        let cases = [
            Ellipse::new(640.0, 480.0, 120.0, 80.0, 0.3),
            Ellipse::new(10.0, -5.0, 30.0, 29.999, -1.2),
            Ellipse::new(100.0, 200.0, 50.0, 10.0, FRAC_PI_2),
        ];
        for e in cases {
            let back = e.to_conic().to_ellipse().expect("ellipse");
            assert!(e.max_param_error_px(&back) < 1e-7, "{e:?} {back:?}");
            assert!(e.theta_error_rad(&back) < 1e-6, "{e:?} {back:?}");
        }
    }

    #[test]
    fn points_lie_on_the_conic() {
        let e = Ellipse::new(300.0, 200.0, 90.0, 40.0, 0.7);
        let c = e.to_conic();
        for k in 0..36 {
            let [u, v] = e.point_at(k as f64 * 0.17);
            assert!(c.sampson_distance(u, v) < 1e-9);
        }
        // A point 2 px outside along the minor axis is about 2 px away.
        let (s, co) = e.theta.sin_cos();
        let (u, v) = (e.cx - s * (e.b + 2.0), e.cy + co * (e.b + 2.0));
        assert!((c.sampson_distance(u, v) - 2.0).abs() < 0.1);
    }

    #[test]
    fn squared_distance_and_band_test_agree_with_the_distance() {
        let e = Ellipse::new(300.0, 200.0, 90.0, 40.0, 0.7);
        let c = e.to_conic();
        // Points 0..3 px off the rim, inside and outside (the distance
        // itself is checked above).
        for k in 0..72 {
            let t = k as f64 * 0.09;
            let off = 3.0 * ((k % 7) as f64 / 6.0) * if k % 2 == 0 { 1.0 } else { -1.0 };
            let [u, v] = e.point_at(t);
            let (dx, dy) = (u - e.cx, v - e.cy);
            let n = dx.hypot(dy);
            let (u, v) = (u + off * dx / n, v + off * dy / n);
            let d = c.sampson_distance(u, v);
            assert!((c.sampson_distance_sq(u, v) - d * d).abs() <= 1e-12 * (1.0 + d * d));
            for band in [0.5, 1.0, 2.0, 2.5] {
                if (d - band).abs() > 1e-9 {
                    assert_eq!(c.within_sampson(u, v, band), d < band, "{d} {band}");
                }
            }
        }
    }

    #[test]
    fn hyperbola_is_not_an_ellipse() {
        let c = Conic {
            a: 1.0,
            b: 0.0,
            c: -1.0,
            d: 0.0,
            e: 0.0,
            f: -1.0,
        };
        assert!(c.to_ellipse().is_none());
    }

    #[test]
    fn canonical_form() {
        let e = Ellipse::new(0.0, 0.0, 10.0, 20.0, 0.0);
        assert_eq!(e.a, 20.0);
        assert!((e.theta - FRAC_PI_2).abs() < 1e-12);
        assert!((wrap_axis_angle(-FRAC_PI_2) - FRAC_PI_2).abs() < 1e-12);
    }
}
