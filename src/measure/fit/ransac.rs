//! Fixed-threshold RANSAC (the baseline the paper compares against): random
//! minimal samples of 5 points, each ellipse scored by how many points lie
//! within a fixed distance; stop once the agree set exceeds N_T (a fraction
//! of the points), else keep the best; refit the agree set with A+C=1 least
//! squares.

use super::{FitConfig, FitError, Points, least_squares};
use crate::measure::ellipse::Ellipse;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub(crate) fn fit(
    pts: &Points,
    cfg: &FitConfig,
    seed: u64,
) -> Result<(Ellipse, Vec<bool>), FitError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = pts.xy.len();
    let limit = cfg.ransac_threshold_px / pts.scale;
    let enough = (cfg.ransac_consensus_fraction * n as f64).ceil() as usize;
    let mut best: Option<(usize, Ellipse)> = None;
    for _ in 0..cfg.ransac_iterations {
        let idx = rand::seq::index::sample(&mut rng, n, 5);
        let Some(e) = least_squares::fit_conic(idx.iter().map(|i| &pts.xy[i]))
            .and_then(|c| least_squares::conic_to_ellipse(&c))
        else {
            continue;
        };
        let conic = e.to_conic();
        let agree = pts
            .xy
            .iter()
            .filter(|p| conic.sampson_distance(p[0], p[1]) < limit)
            .count();
        if best.is_none_or(|(c, _)| agree > c) {
            best = Some((agree, e));
        }
        if agree >= enough {
            break;
        }
    }
    let (_, model) = best.ok_or(FitError::NoEllipse)?;
    least_squares::refit_inliers(&pts.xy, &model, limit)
}
