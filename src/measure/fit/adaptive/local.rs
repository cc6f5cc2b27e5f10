//! Stage 3's local optimisation of one candidate: alternately select the
//! points within the band and refit them with Taubin's fit, the band
//! shrinking toward k robust sigmas. Apart from the stages' driver because
//! it is the inner loop, tuned on its own (scratch buffers, a median found
//! only when it can matter).

use super::super::{FitConfig, taubin};
use super::{DUPLICATE_BAND_SHARE, plausible, residuals_sq, robust_sigma, select, to_vector};
use crate::measure::ellipse::Ellipse;

/// The state of one candidate model during its local optimisation.
#[derive(Clone, Copy)]
pub(super) struct Candidate {
    pub(super) model: Ellipse,
    pub(super) band: f64,
    pub(super) sigma: f64,
}

/// Local optimisation of a candidate model: alternately select the points
/// within the band and refit them with Taubin's fit; the band shrinks to
/// k robust sigmas, at most halving per round (so that a rough start is not
/// locked onto a subset of the rim) and at least 30 %, never below the floor.
#[allow(clippy::too_many_arguments)]
pub(super) fn local_optimise(
    xy: &[[f64; 2]],
    start: &Ellipse,
    band: f64,
    cfg: &FitConfig,
    min_band: f64,
    scratch: &mut Scratch,
    finished: &[[f64; 5]],
    memo: &mut Vec<Optimised>,
) -> Option<Candidate> {
    // A candidate that comes within this of an earlier candidate's final
    // model would select the same points and end on the same model: it is
    // dropped (on a clean rim most candidates end on one model).
    let duplicate_sq = (DUPLICATE_BAND_SHARE * min_band).powi(2);
    let is_duplicate = |v: &[f64; 5]| {
        finished
            .iter()
            .any(|f| super::super::cluster::distance_sq(f, v) < duplicate_sq)
    };
    // The same start (a class centre that did not change between rounds of
    // subsets) takes the same path: replay its recorded models against this
    // round's finished candidates instead of optimising it again. A path
    // that was cut short as a duplicate, and is none now, is optimised anew.
    if let Some(k) = memo
        .iter()
        .position(|m| m.start == *start && m.band == band)
    {
        let m = &memo[k];
        if m.path.iter().any(is_duplicate) {
            return None;
        }
        if !m.dropped {
            return m.result;
        }
        memo.swap_remove(k);
    }
    let mut path = Vec::new();
    let mut c = Candidate {
        model: *start,
        band,
        sigma: f64::INFINITY,
    };
    let Scratch {
        residual_sq,
        sorted,
        keep,
        previous,
        moments,
    } = scratch;
    keep.clear();
    keep.resize(xy.len(), false);
    previous.clear();
    residuals_sq(xy, &c.model, residual_sq);
    for _ in 0..cfg.adaptive_refine_rounds {
        if select(residual_sq, c.band, keep) < 5 {
            break;
        }
        // With the same points as the last round, the refit, its residuals
        // and their sigma would be the same as then (on a clean rim the band
        // shrinks for several rounds without dropping a point).
        if *previous != *keep {
            previous.clone_from(keep);
            if let Some(e) = moments.fit(keep).filter(plausible) {
                c.model = e;
                let v = to_vector(&e);
                path.push(v);
                if is_duplicate(&v) {
                    memo.push(Optimised {
                        start: *start,
                        band,
                        path,
                        result: None,
                        dropped: true,
                    });
                    return None;
                }
                residuals_sq(xy, &c.model, residual_sq);
            }
            c.sigma = f64::NAN;
        }
        // Shrink to k sigmas, but by at least 30 % a round: a rough model
        // has a large sigma and would otherwise never tighten.
        let next = next_band(residual_sq, previous, sorted, &mut c, cfg, min_band);
        let converged = next >= c.band * 0.99;
        c.band = next;
        if converged {
            break;
        }
    }
    if c.sigma.is_nan() {
        c.sigma = robust_sigma(residual_sq, previous, sorted);
    }
    let result = c.sigma.is_finite().then_some(c);
    memo.push(Optimised {
        start: *start,
        band,
        path,
        result,
        dropped: false,
    });
    result
}

/// The candidate's next band: k robust sigmas, but at most 70 % of the
/// current one and never below the floor. The median is only sought when it
/// can matter: a rough model, whose selected residuals are mostly above the
/// 70 % cut, just shrinks (its sigma, NaN until needed, is computed at the
/// end).
pub(super) fn next_band(
    residual_sq: &[f64],
    keep: &[bool],
    sorted: &mut Vec<f64>,
    c: &mut Candidate,
    cfg: &FitConfig,
    min_band: f64,
) -> f64 {
    let cap = 0.7 * c.band;
    if cap <= min_band {
        return min_band;
    }
    if c.sigma.is_nan()
        && median_at_least(
            residual_sq,
            keep,
            cap / (cfg.adaptive_inlier_sigmas * 1.4826),
        )
    {
        return cap;
    }
    if c.sigma.is_nan() {
        c.sigma = robust_sigma(residual_sq, keep, sorted);
    }
    (cfg.adaptive_inlier_sigmas * c.sigma)
        .min(cap)
        .max(min_band)
}

/// Whether the median (as [`robust_sigma`] picks it) of the selected
/// residuals is at least `t`, by counting: cheaper than selecting it.
pub(super) fn median_at_least(residual_sq: &[f64], keep: &[bool], t: f64) -> bool {
    let t_sq = t * t;
    let (mut n, mut below) = (0usize, 0usize);
    for (r, k) in residual_sq.iter().zip(keep) {
        if *k {
            n += 1;
            below += usize::from(*r < t_sq);
        }
    }
    n > 0 && below <= n / 2
}

/// Reused buffers: squared residuals of every point, the selected ones for the
/// median, the selection (this round's and the last one's), and Taubin's
/// moments of the local optimisation's points (which follow the selection).
pub(super) struct Scratch {
    pub(super) residual_sq: Vec<f64>,
    pub(super) sorted: Vec<f64>,
    pub(super) keep: Vec<bool>,
    pub(super) previous: Vec<bool>,
    pub(super) moments: taubin::RunningMoments,
}

/// A local optimisation: its start, the models it passed through (each
/// checked against the earlier candidates) and its result, or that it was
/// dropped at its last model as a duplicate of an earlier candidate.
pub(super) struct Optimised {
    pub(super) start: Ellipse,
    pub(super) band: f64,
    pub(super) path: Vec<[f64; 5]>,
    pub(super) result: Option<Candidate>,
    pub(super) dropped: bool,
}
