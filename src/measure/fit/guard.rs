//! Rim points beside a hidden stretch of the rim.
//!
//! Where the probe, the hose or a glare streak hides part of the rim, the
//! rays there find no edge or the occluder's outline (the fit's outliers).
//! The ray next to such a stretch still finds the rim, but its profile's
//! footprint (the sampling's and the optics' spread, a pixel or two) takes
//! in the occluder's outline, which pulls its step off the rim by a
//! fraction of a pixel: too little to make it an outlier, and of one sign
//! at each end of the stretch, so it does not average out. Dropping the
//! point on each side of every hidden stretch removes that pull.

/// An angular gap between neighbouring points wider than this many times
/// the median gap is a hidden stretch (rays that found no edge).
const HIDDEN_GAP_FACTOR: f64 = 2.5;

/// Consecutive outliers that make a hidden stretch: one alone is noise on
/// an otherwise visible rim, and its neighbours are as good as any.
const MIN_OUTLIER_RUN: usize = 2;

/// Flags, per point, the inliers next to a hidden stretch of rim (in the
/// points' angular order about `centre`): the neighbour across a gap wider
/// than [`HIDDEN_GAP_FACTOR`] median gaps, and the inlier next to a run of
/// at least [`MIN_OUTLIER_RUN`] outliers. Outliers and non-finite points are
/// never flagged (they are out of the fit already).
pub(crate) fn beside_hidden_rim(
    points: &[[f64; 2]],
    centre: [f64; 2],
    inliers: &[bool],
) -> Vec<bool> {
    let mut flagged = vec![false; points.len()];
    let mut order: Vec<(f64, usize)> = points
        .iter()
        .enumerate()
        .filter(|(i, p)| p.iter().all(|v| v.is_finite()) && *i < inliers.len())
        .map(|(i, p)| ((p[1] - centre[1]).atan2(p[0] - centre[0]), i))
        .collect();
    let m = order.len();
    if m < 8 {
        return flagged;
    }
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Gap from point j to the next one round the rim.
    let gaps: Vec<f64> = (0..m)
        .map(|j| (order[(j + 1) % m].0 - order[j].0).rem_euclid(std::f64::consts::TAU))
        .collect();
    let mut sorted = gaps.clone();
    sorted.sort_by(f64::total_cmp);
    let wide = HIDDEN_GAP_FACTOR * sorted[m / 2];
    let outlier = |j: usize| !inliers[order[j % m].1];
    // Whether the point at j is in a run of MIN_OUTLIER_RUN outliers.
    let in_run = |j: usize| {
        (0..MIN_OUTLIER_RUN).any(|start| (0..MIN_OUTLIER_RUN).all(|k| outlier(j + m + k - start)))
    };
    let mut flag = |j: usize| {
        let i = order[j % m].1;
        if inliers[i] {
            flagged[i] = true;
        }
    };
    for (j, &gap) in gaps.iter().enumerate() {
        if gap > wide {
            flag(j);
            flag(j + 1);
        }
        if outlier(j) && in_run(j) {
            flag(j + m - 1);
            flag(j + 1);
        }
    }
    flagged
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a circle of radius 50 about (100, 100), one every `step`
    /// degrees from `from` to `to` (exclusive).
    fn arc(from: i32, to: i32, step: i32) -> Vec<[f64; 2]> {
        (from..to)
            .step_by(step as usize)
            .map(|d| {
                let t = f64::from(d).to_radians();
                [100.0 + 50.0 * t.cos(), 100.0 + 50.0 * t.sin()]
            })
            .collect()
    }

    fn angle_of(p: [f64; 2]) -> i32 {
        ((p[1] - 100.0).atan2(p[0] - 100.0).to_degrees().round() as i32).rem_euclid(360)
    }

    /// The angles (degrees) of the points flagged, in order.
    fn flagged_angles(pts: &[[f64; 2]], inliers: &[bool]) -> Vec<i32> {
        let flagged = beside_hidden_rim(pts, [100.0, 100.0], inliers);
        let mut at: Vec<i32> = pts
            .iter()
            .zip(&flagged)
            .filter(|(_, f)| **f)
            .map(|(p, _)| angle_of(*p))
            .collect();
        at.sort_unstable();
        at
    }

    #[test]
    fn a_whole_rim_loses_nothing() {
        let pts = arc(0, 360, 5);
        let inliers = vec![true; pts.len()];
        assert!(flagged_angles(&pts, &inliers).is_empty());
    }

    #[test]
    fn the_points_on_either_side_of_a_gap_are_flagged() {
        // Rays from 90 to 130 degrees found nothing.
        let mut pts = arc(0, 90, 5);
        pts.extend(arc(130, 360, 5));
        let inliers = vec![true; pts.len()];
        let at = flagged_angles(&pts, &inliers);
        assert_eq!(at, vec![85, 130]);
    }

    #[test]
    fn a_run_of_outliers_flags_its_neighbours_and_a_lone_outlier_does_not() {
        let pts = arc(0, 360, 5);
        let mut inliers = vec![true; pts.len()];
        // The probe's outline at 200-210 degrees, a noisy point at 45.
        for (i, p) in pts.iter().enumerate() {
            let a = angle_of(*p);
            if (200..=210).contains(&a) || a == 45 {
                inliers[i] = false;
            }
        }
        let at = flagged_angles(&pts, &inliers);
        assert_eq!(at, vec![195, 215]);
    }
}
