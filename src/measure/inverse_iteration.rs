//! The smallest eigenvector of a fit's normal equations by inverse
//! iteration: the fast path of the detector's quick conic fit and of
//! Taubin's fit (each falls back to a full decomposition).

use nalgebra::{SMatrix, SVector};

/// The eigenvector of `P v = l Q v` with the smallest `l` (Q the identity
/// when `q` is `None`), scaled so that `v^T Q v = 1`, by inverse iteration
/// `v <- P^-1 Q v` from `start`. Each step shrinks the other eigenvectors'
/// share by the ratio of the smallest eigenvalue to theirs, tiny for points
/// near an ellipse (the smallest is the residual, the others the data's
/// spread), so a few steps do. `None` where P is not positive definite
/// (noise-free points) or it does not converge (two close eigenvalues).
pub(crate) fn smallest_eigenvector<const N: usize>(
    p: &SMatrix<f64, N, N>,
    q: Option<&SMatrix<f64, N, N>>,
    start: SVector<f64, N>,
) -> Option<SVector<f64, N>> {
    let chol = p.cholesky()?;
    let times_q = |v: &SVector<f64, N>| q.map_or(*v, |q| q * v);
    let mut v = start;
    for _ in 0..STEPS {
        let qv = times_q(&v);
        let mut next = chol.solve(&qv);
        let norm = next.dot(&times_q(&next)).sqrt();
        if !(norm.is_finite() && norm > 0.0) {
            return None;
        }
        next /= norm;
        if next.dot(&qv) < 0.0 {
            next = -next;
        }
        let change = (next - v).amax();
        v = next;
        if change < TOLERANCE {
            return Some(v);
        }
    }
    None
}

/// Steps before the full decomposition takes over.
const STEPS: usize = 30;
/// Converged: no entry of the (Q-normalised) eigenvector moves by more.
const TOLERANCE: f64 = 1.0e-13;
