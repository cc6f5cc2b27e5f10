//! The paper's Algorithm 1 (section 2.3), as published: N random subsets of
//! n points, an A+C=1 least squares ellipse for each (eqs. 1-7),
//! agglomerative hierarchical clustering of their parameter vectors
//! (xc, yc, a, b, theta) with the distance of eq. 8, centroid update eq. 10
//! and stop threshold T; the centre of the biggest class is the model M*;
//! the points whose deviation from M* is below a threshold form P*, and the
//! result is the A+C=1 least squares ellipse of P*.
//!
//! Eq. 8 adds pixels and radians, and theta is plain-averaged and
//! plain-differenced (so 89.9 deg and -89.9 deg are "far apart"); that is the
//! paper's method and is kept here for comparison. The deviation is the
//! first-order geometric (Sampson) distance in pixels.

use super::cluster::agglomerate;
use super::{FitConfig, FitError, Points, least_squares};
use crate::measure::ellipse::Ellipse;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The ellipses of `subsets` random subsets of `size` points (normalised
/// coordinates); subsets whose fit is not an ellipse are discarded (sec. 2.1).
pub(crate) fn subset_ellipses(
    pts: &Points,
    subsets: usize,
    size: usize,
    seed: u64,
) -> Vec<Ellipse> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    draw_subset_ellipses(pts, &mut rng, subsets, size).collect()
}

/// The ellipses of `count` more random subsets of `size` points drawn with
/// `rng` (so that a caller can draw in rounds); non-ellipses give none.
pub(crate) fn draw_subset_ellipses<'a>(
    pts: &'a Points,
    rng: &'a mut ChaCha8Rng,
    count: usize,
    size: usize,
) -> impl Iterator<Item = Ellipse> + 'a {
    let size = size.min(pts.xy.len());
    (0..count).filter_map(move |_| {
        let idx = rand::seq::index::sample(rng, pts.xy.len(), size);
        least_squares::fit_conic(idx.iter().map(|i| &pts.xy[i]))
            .and_then(|c| least_squares::conic_to_ellipse(&c))
    })
}

/// Algorithm 1; returns the ellipse (normalised coordinates) and P*.
pub(crate) fn fit(
    pts: &Points,
    cfg: &FitConfig,
    seed: u64,
) -> Result<(Ellipse, Vec<bool>), FitError> {
    // Lines 1-5: the parameter set S, in pixels and radians as in the paper.
    let set: Vec<[f64; 5]> = subset_ellipses(
        pts,
        cfg.algorithm1_subsets,
        cfg.algorithm1_subset_size,
        seed,
    )
    .iter()
    .map(|e| {
        let p = pts.normalised_to_px(e);
        [p.cx, p.cy, p.a, p.b, p.theta]
    })
    .collect();
    // Lines 6-17: cluster with eq. 8 (the Euclidean distance of
    // (xc, yc, a, b, theta)); M* is the centre of the biggest class.
    let clusters = agglomerate(&set, cfg.algorithm1_cluster_threshold);
    let best = clusters.first().ok_or(FitError::NoEllipse)?;
    let [cx, cy, a, b, theta] = best.centre;
    let m_star = pts.px_to_normalised(&Ellipse::new(cx, cy, a, b, theta));
    if !(m_star.a > 0.0 && m_star.b > 0.0) {
        return Err(FitError::NoEllipse);
    }
    // Line 18: P* = points whose deviation from M* is below the threshold;
    // line 19: A+C=1 least squares on P*.
    let limit = cfg.algorithm1_inlier_threshold_px / pts.scale;
    least_squares::refit_inliers(&pts.xy, &m_star, limit)
}
