//! Our default fit: Algorithm 1 made scale-aware, consensus-checked and
//! unbiased.
//!
//! 1. Random minimal subsets and their A+C=1 ellipses, as in Algorithm 1;
//!    implausible ones (far bigger than the data: conics through nearly
//!    collinear points of a probe edge) are dropped.
//! 2. Clustering with centroid linkage (eqs. 9-10) in a parameter space that
//!    is all pixels and has no singularity: (xc, yc, (a+b)/2, and the vector
//!    (a-b)/2 * (cos 2theta, sin 2theta)). The last pair is how far the
//!    outline departs from a circle and in which direction: it goes to zero
//!    for a near-circle (where theta means nothing) and is continuous across
//!    theta = +-90 deg. The stop threshold is relative to the data's size
//!    plus a pixel floor, so one setting serves 10 px and 400 px ellipses.
//! 3. Class centres are ranked by support (points within a wide band); the
//!    best few are optimised locally (select the band, Taubin refit, shrink
//!    the band towards k robust sigmas) and the one explaining the most
//!    points within a common tight band wins. With sub-pixel noise the
//!    5-point fits to a partial arc scatter widely, so the true class need
//!    not be the biggest, and a class of consistent fits to a structured
//!    outlier run must not win by size alone.
//! 4. The winner on all points: rounds of inlier selection and
//!    orthogonal-distance (geometric) refinement, the band at k robust
//!    sigmas (never below a pixel floor), until the inlier set is stable.

use super::algorithm1::subset_ellipses;
use super::cluster::agglomerate;
use super::{FitConfig, FitError, Points, geometric, taubin};
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

/// First-order (Sampson) distance of every point to `e`, into `out`.
/// Computed once per model: the inlier selection and the robust sigma both
/// read it.
fn residuals(pts: &[[f64; 2]], e: &Ellipse, out: &mut Vec<f64>) {
    let conic = e.to_conic();
    out.clear();
    out.extend(pts.iter().map(|p| conic.sampson_distance(p[0], p[1])));
}

/// Marks the points whose residual is within `band`.
fn select(residual: &[f64], band: f64, out: &mut [bool]) -> usize {
    let mut count = 0;
    for (r, k) in residual.iter().zip(out.iter_mut()) {
        *k = *r < band;
        count += usize::from(*k);
    }
    count
}

/// Robust sigma (1.4826 * median absolute first-order residual) of the
/// selected points.
fn robust_sigma(residual: &[f64], keep: &[bool], scratch: &mut Vec<f64>) -> f64 {
    scratch.clear();
    scratch.extend(
        residual
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(r, _)| *r),
    );
    if scratch.is_empty() {
        return f64::INFINITY;
    }
    let mid = scratch.len() / 2;
    let (_, median, _) = scratch.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *median
}

/// Whether a subset's ellipse could be the rim of this data (normalised
/// coordinates: the points have unit RMS radius about the origin). Rejects
/// the huge, flat conics through nearly collinear points (a probe edge).
fn plausible(e: &Ellipse) -> bool {
    e.a < MAX_AXIS_DATA && e.cx.hypot(e.cy) < MAX_AXIS_DATA
}

/// Largest plausible semi-axis (and centre offset), in units of the data's
/// RMS radius. A 60 % arc of a 2:1 ellipse has an RMS radius of about a/2.
const MAX_AXIS_DATA: f64 = 5.0;

/// Points within `band` of `e` (first-order distance).
fn support(pts: &[[f64; 2]], e: &Ellipse, band: f64) -> usize {
    let conic = e.to_conic();
    pts.iter()
        .filter(|p| conic.sampson_distance(p[0], p[1]) < band)
        .count()
}

/// The state of one candidate model during its local optimisation.
struct Candidate {
    model: Ellipse,
    band: f64,
    sigma: f64,
}

/// Local optimisation of a candidate model: alternately select the points
/// within the band and refit them with Taubin's fit; the band shrinks to
/// k robust sigmas, at most halving per round (so that a rough start is not
/// locked onto a subset of the rim) and at least 30 %, never below the floor.
fn local_optimise(
    xy: &[[f64; 2]],
    start: &Ellipse,
    band: f64,
    cfg: &FitConfig,
    min_band: f64,
    keep: &mut [bool],
    scratch: &mut Scratch,
) -> Option<Candidate> {
    let mut c = Candidate {
        model: *start,
        band,
        sigma: f64::INFINITY,
    };
    let Scratch { residual, sorted } = scratch;
    residuals(xy, &c.model, residual);
    for _ in 0..cfg.adaptive_refine_rounds {
        if select(residual, c.band, keep) < 5 {
            break;
        }
        if let Some(e) = taubin::fit_ellipse(xy, Some(keep)).filter(plausible) {
            c.model = e;
            residuals(xy, &c.model, residual);
        }
        c.sigma = robust_sigma(residual, keep, sorted);
        // Shrink to k sigmas, but by at least 30 % a round: a rough model
        // has a large sigma and would otherwise never tighten.
        let next = (cfg.adaptive_inlier_sigmas * c.sigma)
            .min(0.7 * c.band)
            .max(min_band);
        let converged = next >= c.band * 0.99;
        c.band = next;
        if converged {
            break;
        }
    }
    c.sigma.is_finite().then_some(c)
}

/// Reused buffers: residuals of every point, and the selected ones for the
/// median.
#[derive(Default)]
struct Scratch {
    residual: Vec<f64>,
    sorted: Vec<f64>,
}

/// Points used to score class centres and to optimise candidates locally
/// (every k-th point); the final refit uses all points.
const MAX_SCORE_POINTS: usize = 150;
const MAX_LO_POINTS: usize = 200;

/// Every k-th point, so that at most `max` remain.
fn subsample(xy: &[[f64; 2]], max: usize) -> Vec<[f64; 2]> {
    let stride = xy.len().div_ceil(max).max(1);
    xy.iter().step_by(stride).copied().collect()
}

pub(crate) fn fit(
    pts: &Points,
    cfg: &FitConfig,
    seed: u64,
) -> Result<(Ellipse, Vec<bool>), FitError> {
    let xy = &pts.xy;
    let px = pts.scale;
    // 1-2. Subset ellipses and their scale-aware clustering. In normalised
    // coordinates the data's RMS radius is 1, so the tolerance
    // `relative * radius + px` is a constant.
    let set: Vec<[f64; 5]> =
        subset_ellipses(pts, cfg.adaptive_subsets, cfg.adaptive_subset_size, seed)
            .iter()
            .filter(|e| plausible(e))
            .map(to_vector)
            .collect();
    let tolerance = cfg.adaptive_cluster_relative + cfg.adaptive_cluster_px / px;
    let clusters = agglomerate(&set, tolerance);

    // 3. Every class centre (an average of consistent subset fits, eq. 10)
    // is scored by its support within a wide band on a subsample; the best
    // few are optimised locally, and the one that then explains the most
    // points within a common tight band wins. Support, not class size,
    // decides: with sub-pixel noise, 5-point fits to a partial arc scatter
    // by more than any useful tolerance, so the true class can be small.
    let min_band = cfg.adaptive_inlier_min_px / px;
    let initial_band = cfg.adaptive_initial_band_relative + min_band;
    let score_pts = subsample(xy, MAX_SCORE_POINTS);
    let mut scored: Vec<(usize, usize, Ellipse)> = clusters
        .iter()
        .enumerate()
        .filter_map(|(i, c)| from_vector(&c.centre).map(|e| (i, e)))
        .map(|(i, e)| (support(&score_pts, &e, initial_band), i, e))
        .collect();
    // Most support first; ties: the bigger class (lower index).
    scored.sort_by(|x, y| y.0.cmp(&x.0).then(x.1.cmp(&y.1)));
    let lo_pts = subsample(xy, MAX_LO_POINTS);
    let mut keep = vec![false; xy.len()];
    let mut scratch = Scratch {
        residual: Vec::with_capacity(xy.len()),
        sorted: Vec::with_capacity(xy.len()),
    };
    let candidates: Vec<Candidate> = scored
        .iter()
        .take(cfg.adaptive_clusters_scored)
        .filter_map(|(_, _, e)| {
            local_optimise(
                &lo_pts,
                e,
                initial_band,
                cfg,
                min_band,
                &mut keep[..lo_pts.len()],
                &mut scratch,
            )
        })
        .collect();
    let best_sigma = candidates
        .iter()
        .map(|c| c.sigma)
        .fold(f64::INFINITY, f64::min);
    let score_band = (cfg.adaptive_inlier_sigmas * best_sigma).max(min_band);
    let mut best: Option<(usize, &Candidate)> = None;
    for c in &candidates {
        let s = support(&lo_pts, &c.model, score_band);
        if best.is_none_or(|(b, _)| s > b) {
            best = Some((s, c));
        }
    }
    let (_, winner) = best.ok_or(FitError::NoEllipse)?;

    // 4. The winner on all points: Taubin rounds until the inlier set is
    // stable (cheap), then the geometric refit of that set; if its band
    // then selects other points, one more geometric refit.
    let Scratch { residual, sorted } = &mut scratch;
    let (mut model, mut band) = (winner.model, winner.band);
    residuals(xy, &model, residual);
    let mut count = select(residual, band, &mut keep);
    let mut next = vec![false; xy.len()];
    for _ in 0..3 {
        if count < 5 {
            break;
        }
        if let Some(e) = taubin::fit_ellipse(xy, Some(&keep)).filter(plausible) {
            model = e;
            residuals(xy, &model, residual);
        }
        band = (cfg.adaptive_inlier_sigmas * robust_sigma(residual, &keep, sorted)).max(min_band);
        count = select(residual, band, &mut next);
        let stable = next == keep;
        std::mem::swap(&mut keep, &mut next);
        if stable {
            break;
        }
    }
    // Until a geometric refit succeeds, the result is the Taubin model and
    // the points within its band.
    let mut used = (count >= 5).then(|| keep.clone());
    let mut selected: Vec<[f64; 2]> = Vec::with_capacity(xy.len());
    for _ in 0..2 {
        if count < 5 {
            break;
        }
        selected.clear();
        selected.extend(xy.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p));
        let refined = geometric::refine(&selected, &model, cfg.geometric_iterations);
        if !plausible(&refined) {
            break;
        }
        model = refined;
        used = Some(keep.clone());
        residuals(xy, &model, residual);
        let sigma = robust_sigma(residual, &keep, sorted);
        band = (cfg.adaptive_inlier_sigmas * sigma).max(min_band);
        count = select(residual, band, &mut next);
        if next == keep {
            break;
        }
        std::mem::swap(&mut keep, &mut next);
    }
    let inliers = used.ok_or(FitError::NoEllipse)?;
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
