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
//! 5. A short run of inliers cut off by hidden stretches on both sides (an
//!    occluder's outline near the rim, see `guard`) is tried without: the
//!    refit on all points replaces the winner when it fits them better.

use super::algorithm1::draw_subset_ellipses;
use super::cluster::agglomerate;
use super::{FitConfig, FitError, Points, geometric, guard, taubin};
use crate::measure::ellipse::Ellipse;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

mod local;

use local::{Candidate, Optimised, Scratch, local_optimise};

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

/// Squared first-order (Sampson) distance of every point to `e`, into
/// `out`. Computed once per model: the inlier selection and the robust sigma
/// both read it. Squared, because neither needs the root: a band compares
/// with its square, and the root of the median is the median of the roots.
fn residuals_sq(pts: &[[f64; 2]], e: &Ellipse, out: &mut Vec<f64>) {
    let conic = e.to_conic();
    out.clear();
    out.extend(pts.iter().map(|p| conic.sampson_distance_sq(p[0], p[1])));
}

/// Marks the points within `band` (their squared residual below its
/// square).
fn select(residual_sq: &[f64], band: f64, out: &mut [bool]) -> usize {
    let band_sq = band * band;
    let mut count = 0;
    for (r, k) in residual_sq.iter().zip(out.iter_mut()) {
        *k = *r < band_sq;
        count += usize::from(*k);
    }
    count
}

/// Robust sigma (1.4826 * median absolute first-order residual) of the
/// selected points.
fn robust_sigma(residual_sq: &[f64], keep: &[bool], scratch: &mut Vec<f64>) -> f64 {
    scratch.clear();
    scratch.extend(
        residual_sq
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(r, _)| *r),
    );
    if scratch.is_empty() {
        return f64::INFINITY;
    }
    let mid = scratch.len() / 2;
    let (_, median_sq, _) = scratch.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * median_sq.sqrt()
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
        .filter(|p| conic.within_sampson(p[0], p[1], band))
        .count()
}

/// MSAC cost of `e` on the points: the sum of squared (first-order)
/// residuals, each capped at `band` squared.
fn truncated_cost(pts: &[[f64; 2]], e: &Ellipse, band: f64) -> f64 {
    let conic = e.to_conic();
    let cap = band * band;
    pts.iter()
        .map(|p| conic.sampson_distance_sq(p[0], p[1]).min(cap))
        .sum()
}

/// What stages 2-3 computed in earlier rounds of subsets, by class centre:
/// its support, and its local optimisation.
#[derive(Default)]
struct Memo {
    scores: Vec<([f64; 5], usize)>,
    optimised: Vec<Optimised>,
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

/// Subsets the RANSAC bound asks for: `log(1 - p) / log(1 - w^n)`, the
/// number of random `n`-point subsets that hold at least one outlier-free
/// subset with probability `p` when a share `w` of the points are inliers.
fn required_subsets(inlier_share: f64, subset_size: usize, confidence: f64) -> usize {
    let clean = inlier_share.clamp(0.0, 1.0).powi(subset_size as i32);
    if clean >= 1.0 {
        return 0;
    }
    if clean <= 0.0 {
        return usize::MAX;
    }
    let n = (1.0 - confidence).ln() / (1.0 - clean).ln();
    if n.is_finite() {
        n.ceil().max(0.0) as usize
    } else {
        usize::MAX
    }
}

/// The result of stages 2-3 on the subset vectors drawn so far.
struct Stage3 {
    model: Ellipse,
    band: f64,
    /// Points of `lo_pts` within the common tight band of the winner.
    support: usize,
}

/// Stages 2-3: cluster the subset vectors, score the class centres, optimise
/// the best few locally and let them compete by consensus.
#[allow(clippy::too_many_arguments)]
fn best_candidate(
    set: &[[f64; 5]],
    tolerance: f64,
    score_pts: &[[f64; 2]],
    lo_pts: &[[f64; 2]],
    cfg: &FitConfig,
    initial_band: f64,
    min_band: f64,
    scratch: &mut Scratch,
    memo: &mut Memo,
) -> Option<Stage3> {
    let clusters = agglomerate(set, tolerance);
    let mut scored: Vec<(usize, usize, Ellipse)> = clusters
        .iter()
        .enumerate()
        .filter_map(|(i, c)| from_vector(&c.centre).map(|e| (i, e)))
        .map(|(i, e)| {
            // A class centre scored in an earlier round has the same support.
            let known = memo.scores.iter().find(|(c, _)| *c == clusters[i].centre);
            let s = match known {
                Some((_, s)) => *s,
                None => {
                    let s = support(score_pts, &e, initial_band);
                    memo.scores.push((clusters[i].centre, s));
                    s
                }
            };
            (s, i, e)
        })
        .collect();
    // Most support first; ties: the bigger class (lower index).
    scored.sort_by(|x, y| y.0.cmp(&x.0).then(x.1.cmp(&y.1)));
    let mut candidates: Vec<Candidate> = Vec::with_capacity(cfg.adaptive_clusters_scored);
    for (_, _, e) in scored.iter().take(cfg.adaptive_clusters_scored) {
        let finished: Vec<[f64; 5]> = candidates.iter().map(|c| to_vector(&c.model)).collect();
        if let Some(c) = local_optimise(
            lo_pts,
            e,
            initial_band,
            cfg,
            min_band,
            scratch,
            &finished,
            &mut memo.optimised,
        ) {
            candidates.push(c);
        }
    }
    let best_sigma = candidates
        .iter()
        .map(|c| c.sigma)
        .fold(f64::INFINITY, f64::min);
    let score_band = (cfg.adaptive_inlier_sigmas * best_sigma).max(min_band);
    let mut best: Option<(usize, &Candidate)> = None;
    for c in &candidates {
        let s = support(lo_pts, &c.model, score_band);
        if best.is_none_or(|(b, _)| s > b) {
            best = Some((s, c));
        }
    }
    best.map(|(support, c)| Stage3 {
        model: c.model,
        band: c.band,
        support,
    })
}

/// A candidate is dropped when it comes within this share of the smallest
/// inlier band of an earlier candidate's final model.
const DUPLICATE_BAND_SHARE: f64 = 0.02;

pub(crate) fn fit(
    pts: &Points,
    cfg: &FitConfig,
    seed: u64,
) -> Result<(Ellipse, Vec<bool>), FitError> {
    let xy = &pts.xy;
    let px = pts.scale;
    // 1-3. Subset ellipses, their scale-aware clustering, and the best class
    // centre after local optimisation. In normalised coordinates the data's
    // RMS radius is 1, so the tolerance `relative * radius + px` is a
    // constant. The number of subsets adapts: first the floor, then as many
    // as the RANSAC bound asks for the winner's inlier share (at most
    // adaptive_subsets), so that a clean rim costs a few dozen subsets and a
    // rim with many outliers still gets an outlier-free subset.
    let tolerance = cfg.adaptive_cluster_relative + cfg.adaptive_cluster_px / px;
    let min_band = cfg.adaptive_inlier_min_px / px;
    let initial_band = cfg.adaptive_initial_band_relative + min_band;
    let score_pts = subsample(xy, MAX_SCORE_POINTS);
    let lo_pts = subsample(xy, MAX_LO_POINTS);
    let mut scratch = Scratch {
        residual_sq: Vec::with_capacity(xy.len()),
        sorted: Vec::with_capacity(xy.len()),
        keep: Vec::with_capacity(xy.len()),
        previous: Vec::with_capacity(xy.len()),
        moments: taubin::RunningMoments::new(&lo_pts),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let max_subsets = cfg.adaptive_subsets;
    let mut drawn = 0;
    let mut target = cfg.adaptive_min_subsets.min(max_subsets);
    let mut set: Vec<[f64; 5]> = Vec::with_capacity(max_subsets);
    let mut memo = Memo::default();
    let winner = loop {
        set.extend(
            draw_subset_ellipses(pts, &mut rng, target - drawn, cfg.adaptive_subset_size)
                .filter(plausible)
                .map(|e| to_vector(&e)),
        );
        drawn = target;
        let found = best_candidate(
            &set,
            tolerance,
            &score_pts,
            &lo_pts,
            cfg,
            initial_band,
            min_band,
            &mut scratch,
            &mut memo,
        );
        if drawn >= max_subsets {
            break found;
        }
        let share = found
            .as_ref()
            .map_or(0.0, |w| w.support as f64 / lo_pts.len() as f64);
        let needed = required_subsets(share, cfg.adaptive_subset_size, cfg.adaptive_confidence);
        if needed <= drawn {
            break found;
        }
        target = needed.min(max_subsets);
    };
    let winner = winner.ok_or(FitError::NoEllipse)?;

    let Scratch {
        residual_sq,
        sorted,
        ..
    } = &mut scratch;
    let (mut model, mut inliers, band) = refit_on_all(
        xy,
        winner.model,
        winner.band,
        cfg,
        min_band,
        residual_sq,
        sorted,
    )
    .ok_or(FitError::NoEllipse)?;

    // 5. A short inlier run cut off by hidden stretches on both sides may be
    // an occluder's outline the fit has bent towards (see `guard`): the fit
    // without it, refitted on all points, replaces this one when it has the
    // lower truncated cost within the tightest of the two bands and this
    // fit's noise band. A count of points within the band cannot tell them
    // apart: both bands are often at the pixel floor, which both fits'
    // points are well within.
    let isolated = guard::isolated_inlier_runs(xy, [model.cx, model.cy], &inliers);
    if isolated.iter().any(|&f| f) {
        let selected: Vec<[f64; 2]> = xy
            .iter()
            .zip(inliers.iter().zip(&isolated))
            .filter(|(_, (k, f))| **k && !**f)
            .map(|(p, _)| *p)
            .collect();
        let start = geometric::refine(&selected, &model, cfg.geometric_iterations);
        let alternative = (selected.len() >= 5 && plausible(&start))
            .then(|| refit_on_all(xy, start, band, cfg, min_band, residual_sq, sorted))
            .flatten();
        if let Some((alt_model, alt_inliers, alt_band)) = alternative {
            // A point left out is priced by the points' noise (the first
            // fit's, which the alternative cannot shrink by leaving points
            // out), not by the band's pixel floor: the floor (for blurred,
            // wobbling edges) is often several sigmas wide, and a run a
            // pixel off the rim then costs the alternative more than the
            // bend it puts into the first fit costs that one.
            let noise = noise_band(xy, &model, &inliers, cfg, residual_sq, sorted);
            let common = band.min(alt_band).min(noise);
            if truncated_cost(xy, &alt_model, common) < truncated_cost(xy, &model, common) {
                model = alt_model;
                inliers = alt_inliers;
            }
        }
    }
    Ok((model, inliers))
}

/// `adaptive_inlier_sigmas` robust sigmas of `model`'s residuals on its
/// inliers, without the band's pixel floor.
fn noise_band(
    xy: &[[f64; 2]],
    model: &Ellipse,
    inliers: &[bool],
    cfg: &FitConfig,
    residual_sq: &mut Vec<f64>,
    sorted: &mut Vec<f64>,
) -> f64 {
    residuals_sq(xy, model, residual_sq);
    cfg.adaptive_inlier_sigmas * robust_sigma(residual_sq, inliers, sorted)
}

/// Stage 4, a model on all points: Taubin rounds from `model` until the
/// inlier set is stable (cheap), then the geometric refit of that set; if
/// its band then selects other points, one more geometric refit. Returns
/// the model, its inliers and its final band (`None` under 5 inliers).
fn refit_on_all(
    xy: &[[f64; 2]],
    mut model: Ellipse,
    mut band: f64,
    cfg: &FitConfig,
    min_band: f64,
    residual_sq: &mut Vec<f64>,
    sorted: &mut Vec<f64>,
) -> Option<(Ellipse, Vec<bool>, f64)> {
    let mut keep = vec![false; xy.len()];
    residuals_sq(xy, &model, residual_sq);
    let mut count = select(residual_sq, band, &mut keep);
    let mut next = vec![false; xy.len()];
    for _ in 0..3 {
        if count < 5 {
            break;
        }
        if let Some(e) = taubin::fit_ellipse(xy, Some(&keep)).filter(plausible) {
            model = e;
            residuals_sq(xy, &model, residual_sq);
        }
        band =
            (cfg.adaptive_inlier_sigmas * robust_sigma(residual_sq, &keep, sorted)).max(min_band);
        count = select(residual_sq, band, &mut next);
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
        residuals_sq(xy, &model, residual_sq);
        let sigma = robust_sigma(residual_sq, &keep, sorted);
        band = (cfg.adaptive_inlier_sigmas * sigma).max(min_band);
        count = select(residual_sq, band, &mut next);
        if next == keep {
            break;
        }
        std::mem::swap(&mut keep, &mut next);
    }
    used.map(|inliers| (model, inliers, band))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ransac_bound_matches_hand_computed_values() {
        // w = 0.6, n = 5, p = 0.99: ln(0.01) / ln(1 - 0.6^5) = 56.9.
        assert_eq!(required_subsets(0.6, 5, 0.99), 57);
        // w = 0.5, n = 5, p = 0.999: ln(0.001) / ln(1 - 1/32) = 217.6.
        assert_eq!(required_subsets(0.5, 5, 0.999), 218);
        // A clean rim needs nothing beyond the floor, no inliers everything.
        assert_eq!(required_subsets(1.0, 5, 0.999), 0);
        assert_eq!(required_subsets(0.0, 5, 0.999), usize::MAX);
    }

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
