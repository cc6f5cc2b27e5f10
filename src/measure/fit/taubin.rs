//! Taubin's fit: the algebraic fit normalised by the mean squared gradient,
//! which removes most of the bias (shrinkage) of the A+C=1 fit on partial
//! arcs. It seeds the orthogonal-distance refinement.
//!
//! Follows Chernov's formulation (F eliminated, a 5x5 generalised symmetric
//! eigenproblem with a positive definite right side), with the moments taken
//! about the origin of the fitter's normalised coordinates rather than the
//! selection's centroid, so that they can follow a changing selection.

use super::least_squares::conic_to_ellipse;
use crate::measure::ellipse::{Conic, Ellipse};
use nalgebra::{Matrix5, Vector5};

/// Taubin's ellipse of the selected points (normalised coordinates), or
/// `None` for degenerate data or a non-ellipse.
pub(crate) fn fit_ellipse(points: &[[f64; 2]], keep: Option<&[bool]>) -> Option<Ellipse> {
    let mut sums = Monomials::default();
    let mut count = 0usize;
    for_selected(points, keep, |p| {
        sums.add(&Monomials::of(p));
        count += 1;
    });
    fit_moments(&sums, count)
}

/// Calls `f` on each selected point, in order (a zip with the flags: no
/// index lookups, so the moment loops stay tight).
fn for_selected(points: &[[f64; 2]], keep: Option<&[bool]>, mut f: impl FnMut(&[f64; 2])) {
    match keep {
        Some(k) => points
            .iter()
            .zip(k)
            .filter(|(_, k)| **k)
            .for_each(|(p, _)| f(p)),
        None => points.iter().for_each(f),
    }
}

/// The 14 monomials `x^i y^j` (1 <= i + j <= 4) of a point: every entry of
/// Taubin's moment matrices is a mean of one of them.
#[derive(Clone, Copy, Default)]
pub(crate) struct Monomials([f64; 14]);

impl Monomials {
    pub fn of(p: &[f64; 2]) -> Self {
        let (x, y) = (p[0], p[1]);
        let (x2, xy, y2) = (x * x, x * y, y * y);
        Self([
            x,
            y,
            x2,
            xy,
            y2,
            x2 * x,
            x2 * y,
            x * y2,
            y2 * y,
            x2 * x2,
            x2 * xy,
            x2 * y2,
            xy * y2,
            y2 * y2,
        ])
    }

    fn add(&mut self, other: &Self) {
        self.0.iter_mut().zip(&other.0).for_each(|(s, v)| *s += v);
    }

    fn sub(&mut self, other: &Self) {
        self.0.iter_mut().zip(&other.0).for_each(|(s, v)| *s -= v);
    }
}

/// Taubin's moments of a selection that changes a little at a time (the
/// local optimisation drops or adds a few points a round): the sums follow
/// the selection by the points that changed, instead of a pass over all.
#[derive(Default)]
pub(crate) struct RunningMoments {
    monomials: Vec<Monomials>,
    selected: Vec<bool>,
    sums: Monomials,
    count: usize,
}

impl RunningMoments {
    /// Moments over `points`, nothing selected yet.
    pub fn new(points: &[[f64; 2]]) -> Self {
        Self {
            monomials: points.iter().map(Monomials::of).collect(),
            selected: vec![false; points.len()],
            sums: Monomials::default(),
            count: 0,
        }
    }

    /// Taubin's ellipse of the points `keep` selects (one flag a point;
    /// `None` if `keep` does not have one flag for each point).
    pub fn fit(&mut self, keep: &[bool]) -> Option<Ellipse> {
        if keep.len() != self.selected.len() {
            return None;
        }
        self.select(keep);
        fit_moments(&self.sums, self.count)
    }

    /// Brings the sums to `keep`. When more points changed than half of
    /// those selected, they are summed afresh: that is as cheap, and it keeps
    /// rounding from piling up.
    fn select(&mut self, keep: &[bool]) {
        let changed = self
            .selected
            .iter()
            .zip(keep)
            .filter(|(s, k)| s != k)
            .count();
        if changed == 0 {
            return;
        }
        if 2 * changed > self.count {
            self.sums = Monomials::default();
            self.count = 0;
            for (m, k) in self.monomials.iter().zip(keep) {
                if *k {
                    self.sums.add(m);
                    self.count += 1;
                }
            }
        } else {
            for ((m, s), k) in self.monomials.iter().zip(&self.selected).zip(keep) {
                if s != k {
                    if *k {
                        self.sums.add(m);
                        self.count += 1;
                    } else {
                        self.sums.sub(m);
                        self.count -= 1;
                    }
                }
            }
        }
        self.selected.copy_from_slice(keep);
    }
}

/// Taubin's ellipse from the monomial sums of `count` points.
///
/// The moments are taken about the origin, not the selection's centroid, so
/// that sums can be updated point by point; the fit is invariant under
/// translation, and in the fitter's normalised coordinates (origin at the
/// data's centroid, unit RMS radius) this costs no precision.
fn fit_moments(sums: &Monomials, count: usize) -> Option<Ellipse> {
    if count < 5 {
        return None;
    }
    let nf = count as f64;
    // s[i][j]: mean of x^i y^j.
    let mut s = [[0.0f64; 5]; 5];
    const INDEX: [(usize, usize); 14] = [
        (1, 0),
        (0, 1),
        (2, 0),
        (1, 1),
        (0, 2),
        (3, 0),
        (2, 1),
        (1, 2),
        (0, 3),
        (4, 0),
        (3, 1),
        (2, 2),
        (1, 3),
        (0, 4),
    ];
    for ((i, j), v) in INDEX.iter().zip(&sums.0) {
        s[*i][*j] = v / nf;
    }
    s[0][0] = 1.0;
    // Exponents (of x, of y) of each entry of z = [x^2, xy, y^2, x, y, 1].
    const EXP: [(usize, usize); 6] = [(2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0)];
    let m = |i: usize, j: usize| s[EXP[i].0 + EXP[j].0][EXP[i].1 + EXP[j].1];
    // P: the moments of z with F eliminated (F = -(mean of z) . [A..E]).
    let p = Matrix5::<f64>::from_fn(|i, j| m(i, j) - m(i, 5) * m(j, 5));
    // Q: the mean of grad z grad z^T (z_x = [2x, y, 0, 1, 0], z_y = [0, x,
    // 2y, 0, 1]).
    let (sx, sy) = (s[1][0], s[0][1]);
    let (sxx, sxy, syy) = (s[2][0], s[1][1], s[0][2]);
    #[rustfmt::skip]
    let q = Matrix5::new(
        4.0 * sxx, 2.0 * sxy, 0.0, 2.0 * sx, 0.0,
        2.0 * sxy, sxx + syy, 2.0 * sxy, sy, sx,
        0.0, 2.0 * sxy, 4.0 * syy, 0.0, 2.0 * sy,
        2.0 * sx, sy, 0.0, 1.0, 0.0,
        0.0, sx, 2.0 * sy, 0.0, 1.0,
    );
    if !p.iter().chain(q.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let v = smallest_eigenvector(&p, &q)?;
    let (a, b, cc, d, e) = (v[0], v[1], v[2], v[3], v[4]);
    let f = -(a * sxx + b * sxy + cc * syy + d * sx + e * sy);
    let conic = Conic {
        a,
        b,
        c: cc,
        d,
        e,
        f,
    };
    conic_to_ellipse(&conic)
}

/// The generalised eigenvector of `P v = l Q v` with the smallest `l` (P
/// positive semi-definite, Q positive definite, so every `l >= 0`).
///
/// Inverse iteration, `v <- P^-1 Q v`: each step shrinks the other
/// eigenvectors' share by the ratio of the smallest eigenvalue to theirs,
/// which for points near an ellipse is tiny (the smallest is the residual,
/// the next ones the data's spread), so it converges in a few steps. Where it
/// does not (P not positive definite, as for noise-free points, or two
/// close eigenvalues) the full decomposition decides.
fn smallest_eigenvector(p: &Matrix5<f64>, q: &Matrix5<f64>) -> Option<Vector5<f64>> {
    inverse_iteration(p, q).or_else(|| eigen_decomposition(p, q))
}

/// Inverse iteration alone; `None` when it does not converge.
fn inverse_iteration(p: &Matrix5<f64>, q: &Matrix5<f64>) -> Option<Vector5<f64>> {
    // Start: the circle x^2 + y^2 (every ellipse has a share of it).
    let start = Vector5::new(1.0, 0.0, 1.0, 0.0, 0.0);
    crate::measure::inverse_iteration::smallest_eigenvector(p, Some(q), start)
}

/// The same eigenvector from the full symmetric eigen-decomposition:
/// `P v = l Q v  <=>  (L^-1 P L^-T) w = l w, v = L^-T w`.
fn eigen_decomposition(p: &Matrix5<f64>, q: &Matrix5<f64>) -> Option<Vector5<f64>> {
    let chol = q.cholesky()?;
    let l = chol.l();
    let l_inv = l.try_inverse()?;
    let c = l_inv * p * l_inv.transpose();
    let c = (c + c.transpose()) * 0.5;
    let eig = c.try_symmetric_eigen(1.0e-14, 200)?;
    let (k, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let w = eig.eigenvectors.column(k).into_owned();
    Some(l_inv.transpose() * w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_points_give_the_exact_ellipse() {
        let truth = Ellipse::new(0.3, -0.2, 1.2, 0.5, -0.7);
        let pts: Vec<[f64; 2]> = (0..40).map(|k| truth.point_at(k as f64 * 0.05)).collect();
        let e = fit_ellipse(&pts, None).unwrap();
        assert!(e.max_param_error_px(&truth) < 1e-8, "{e:?}");
        assert!(e.theta_error_rad(&truth) < 1e-8);
    }

    /// The moment matrices of `fit_ellipse` for noisy points of a partial arc.
    fn matrices(pts: &[[f64; 2]]) -> (Matrix5<f64>, Matrix5<f64>) {
        let n = pts.len() as f64;
        let (mx, my) = (
            pts.iter().map(|p| p[0]).sum::<f64>() / n,
            pts.iter().map(|p| p[1]).sum::<f64>() / n,
        );
        let z: Vec<[f64; 6]> = pts
            .iter()
            .map(|p| {
                let (x, y) = (p[0] - mx, p[1] - my);
                [x * x, x * y, y * y, x, y, 1.0]
            })
            .collect();
        let m = |i: usize, j: usize| z.iter().map(|r| r[i] * r[j]).sum::<f64>() / n;
        let mut p = Matrix5::zeros();
        for i in 0..5 {
            for j in 0..5 {
                p[(i, j)] = m(i, j)
                    - if i < 3 && j < 3 {
                        m(i, 5) * m(j, 5)
                    } else {
                        0.0
                    };
            }
        }
        let (sxx, sxy, syy) = (m(0, 5), m(1, 5), m(2, 5));
        #[rustfmt::skip]
        let q = Matrix5::new(
            4.0 * sxx, 2.0 * sxy, 0.0, 0.0, 0.0,
            2.0 * sxy, sxx + syy, 2.0 * sxy, 0.0, 0.0,
            0.0, 2.0 * sxy, 4.0 * syy, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0, 0.0,
            0.0, 0.0, 0.0, 0.0, 1.0,
        );
        (p, q)
    }

    #[test]
    fn inverse_iteration_converges_to_the_decompositions_eigenvector() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for trial in 0..200 {
            let truth = Ellipse::new(
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.2..0.2),
                rng.random_range(1.0..1.5),
                rng.random_range(0.5..1.0),
                rng.random_range(-1.5..1.5),
            );
            let arc = rng.random_range(2.0..std::f64::consts::TAU);
            let noise = [1e-4, 1e-3, 1e-2][trial % 3];
            let n = rng.random_range(6..200);
            let pts: Vec<[f64; 2]> = (0..n)
                .map(|k| {
                    let p = truth.point_at(arc * k as f64 / n as f64);
                    [
                        p[0] + noise * rng.random_range(-1.0..1.0),
                        p[1] + noise * rng.random_range(-1.0..1.0),
                    ]
                })
                .collect();
            let (p, q) = matrices(&pts);
            let fast = inverse_iteration(&p, &q).expect("converges");
            let full = eigen_decomposition(&p, &q).unwrap();
            // Same direction up to sign, both Q-normalised.
            let full = full / full.dot(&(q * full)).sqrt();
            let full = if full.dot(&fast) < 0.0 { -full } else { full };
            assert!(
                (fast - full).amax() < 1e-7,
                "trial {trial}: {fast} vs {full}"
            );
        }
    }

    #[test]
    fn running_moments_follow_the_selection() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let truth = Ellipse::new(0.1, -0.3, 1.3, 0.8, 0.6);
        let pts: Vec<[f64; 2]> = (0..200)
            .map(|k| {
                let p = truth.point_at(k as f64 * 0.025);
                [
                    p[0] + 0.002 * rng.random_range(-1.0..1.0),
                    p[1] + 0.002 * rng.random_range(-1.0..1.0),
                ]
            })
            .collect();
        let mut running = RunningMoments::new(&pts);
        let mut keep = vec![true; pts.len()];
        // Small changes (updated point by point), then a big one (summed
        // afresh), then small ones again: each fit must equal the one from
        // scratch.
        for round in 0..40 {
            let flips = if round == 20 {
                150
            } else {
                rng.random_range(1..12)
            };
            for _ in 0..flips {
                let i = rng.random_range(0..pts.len());
                keep[i] = !keep[i];
            }
            let fresh = fit_ellipse(&pts, Some(&keep)).unwrap();
            let followed = running.fit(&keep).unwrap();
            assert!(
                followed.max_param_error_px(&fresh) < 1e-9,
                "round {round}: {followed:?} vs {fresh:?}"
            );
            assert!(followed.theta_error_rad(&fresh) < 1e-9);
        }
        // A selection of the wrong length is no fit (and no panic).
        assert!(running.fit(&keep[..10]).is_none());
    }

    #[test]
    fn selection_is_respected() {
        let truth = Ellipse::new(0.0, 0.0, 1.0, 0.8, 0.2);
        let mut pts: Vec<[f64; 2]> = (0..30).map(|k| truth.point_at(k as f64 * 0.2)).collect();
        pts.push([5.0, 5.0]);
        let mut keep = vec![true; pts.len()];
        keep[30] = false;
        let e = fit_ellipse(&pts, Some(&keep)).unwrap();
        assert!(e.max_param_error_px(&truth) < 1e-8);
    }
}
