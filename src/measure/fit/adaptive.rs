//! Our default fit: Algorithm 1 made scale-aware and unbiased.
//!
//! 1. Random minimal subsets and their A+C=1 ellipses, as in Algorithm 1.
//! 2. Clustering with centroid linkage (eqs. 9-10) in a parameter space that
//!    is all pixels and has no singularity: (xc, yc, (a+b)/2, and the vector
//!    (a-b)/2 * (cos 2theta, sin 2theta)). The last pair is how far the
//!    outline departs from a circle and in which direction: it goes to zero
//!    for a near-circle (where theta means nothing) and is continuous across
//!    theta = +-90 deg. The stop threshold is relative to the ellipse's size
//!    plus a pixel floor, so one setting serves 10 px and 400 px ellipses.
//! 3. The few biggest classes are scored by consensus (points within a band
//!    around their centre's ellipse) and the best one is the model: a class
//!    of consistent fits to a structured outlier run (the probe's or hose's
//!    outline) cannot win by size alone.
//! 4. Rounds of: inliers within the band; Taubin fit; orthogonal-distance
//!    refinement; the band shrinks to k robust sigmas of the inliers'
//!    residuals (never below a pixel floor). Ends when the inlier set is
//!    stable.

use super::algorithm1::subset_ellipses;
use super::cluster::agglomerate;
use super::{FitConfig, FitError, Points, geometric, mean_radius, taubin};
use crate::measure::ellipse::Ellipse;

/// The scale-free parameter vector of an ellipse (all entries in the
/// ellipse's own length unit).
fn to_vector(e: &Ellipse) -> [f64; 5] {
    let (s2, c2) = (2.0 * e.theta).sin_cos();
    let h = 0.5 * (e.a - e.b);
    [e.cx, e.cy, 0.5 * (e.a + e.b), h * c2, h * s2]
}

fn from_vector(v: &[f64; 5]) -> Option<Ellipse> {
    let h = v[3].hypot(v[4]);
    let (a, b) = (v[2] + h, v[2] - h);
    (b > 0.0 && a.is_finite()).then(|| Ellipse::new(v[0], v[1], a, b, 0.5 * v[4].atan2(v[3])))
}

/// Marks the points within `band` (first-order distance) of `e`.
fn select(pts: &[[f64; 2]], e: &Ellipse, band: f64, out: &mut [bool]) -> usize {
    let conic = e.to_conic();
    let mut count = 0;
    for (p, k) in pts.iter().zip(out.iter_mut()) {
        *k = conic.sampson_distance(p[0], p[1]) < band;
        count += usize::from(*k);
    }
    count
}

/// Robust sigma (1.4826 * median absolute residual) of the selected points.
fn robust_sigma(pts: &[[f64; 2]], e: &Ellipse, keep: &[bool], scratch: &mut Vec<f64>) -> f64 {
    let g = geometric::Geometry::new(e);
    scratch.clear();
    scratch.extend(
        pts.iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| g.distance(*p).abs()),
    );
    if scratch.is_empty() {
        return f64::INFINITY;
    }
    let mid = scratch.len() / 2;
    let (_, median, _) = scratch.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *median
}

pub(crate) fn fit(
    pts: &Points,
    cfg: &FitConfig,
    seed: u64,
) -> Result<(Ellipse, Vec<bool>), FitError> {
    let xy = &pts.xy;
    let px = pts.scale;
    // 1-2. Subset ellipses and their scale-aware clustering.
    let set: Vec<[f64; 5]> =
        subset_ellipses(pts, cfg.adaptive_subsets, cfg.adaptive_subset_size, seed)
            .iter()
            .map(to_vector)
            .collect();
    let (rel, floor) = (cfg.adaptive_cluster_relative, cfg.adaptive_cluster_px / px);
    let distance = |v: &[f64; 5], w: &[f64; 5]| {
        let d = v
            .iter()
            .zip(w)
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f64>()
            .sqrt();
        d / (rel * 0.5 * (v[2] + w[2]).abs() + floor)
    };
    let clusters = agglomerate(&set, distance, 1.0);

    // 3. Consensus among the biggest classes.
    let band_of = |e: &Ellipse| {
        cfg.adaptive_initial_band_relative * mean_radius(e) + cfg.adaptive_inlier_min_px / px
    };
    let mut keep = vec![false; xy.len()];
    let mut best: Option<(usize, Ellipse)> = None;
    for c in clusters.iter().take(cfg.adaptive_clusters_scored) {
        let Some(e) = from_vector(&c.centre) else {
            continue;
        };
        let support = select(xy, &e, band_of(&e), &mut keep);
        if best.is_none_or(|(s, _)| support > s) {
            best = Some((support, e));
        }
    }
    let (_, mut model) = best.ok_or(FitError::NoEllipse)?;

    // 4. Select, refit without bias, shrink the band; until stable.
    let initial_band = band_of(&model);
    let min_band = cfg.adaptive_inlier_min_px / px;
    let mut band = initial_band;
    let mut count = select(xy, &model, band, &mut keep);
    let mut used: Option<Vec<bool>> = None;
    let mut next = vec![false; xy.len()];
    let mut selected: Vec<[f64; 2]> = Vec::with_capacity(xy.len());
    let mut scratch = Vec::with_capacity(xy.len());
    for _ in 0..cfg.adaptive_refine_rounds {
        if count < 5 {
            break;
        }
        let start = taubin::fit_ellipse(xy, Some(&keep)).unwrap_or(model);
        selected.clear();
        selected.extend(xy.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p));
        model = geometric::refine(&selected, &start, cfg.geometric_iterations);
        used = Some(keep.clone());
        band = (cfg.adaptive_inlier_sigmas * robust_sigma(xy, &model, &keep, &mut scratch))
            .clamp(min_band, initial_band.max(min_band));
        count = select(xy, &model, band, &mut next);
        if next == keep {
            break;
        }
        std::mem::swap(&mut keep, &mut next);
    }
    let inliers = used.ok_or(FitError::NoEllipse)?;
    if !(model.a.is_finite() && model.b > 0.0) {
        return Err(FitError::NoEllipse);
    }
    Ok((model, inliers))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_vector_round_trip_and_circle_continuity() {
        let e = Ellipse::new(3.0, -2.0, 5.0, 2.0, 1.5);
        let back = from_vector(&to_vector(&e)).unwrap();
        assert!(back.max_param_error_px(&e) < 1e-12);
        assert!(back.theta_error_rad(&e) < 1e-12);
        // theta = +89.9 deg and -89.9 deg are the same axis: close vectors.
        let p = to_vector(&Ellipse::new(0.0, 0.0, 5.0, 4.0, 1.5690));
        let q = to_vector(&Ellipse::new(0.0, 0.0, 5.0, 4.0, -1.5690));
        let d: f64 = p.iter().zip(&q).map(|(x, y)| (x - y).powi(2)).sum();
        assert!(d.sqrt() < 0.01);
        // A circle's angle does not matter.
        let c1 = to_vector(&Ellipse::new(0.0, 0.0, 5.0, 5.0, 0.3));
        let c2 = to_vector(&Ellipse::new(0.0, 0.0, 5.0, 5.0, -1.2));
        assert_eq!(c1, c2);
    }
}
