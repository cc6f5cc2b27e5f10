//! Rim points beside a hidden stretch of the rim, and short runs of
//! "rim" points cut off by hidden stretches.
//!
//! Where the probe, the hose or a glare streak hides part of the rim, the
//! rays there find no edge or the occluder's outline (the fit's outliers).
//! The ray next to such a stretch still finds the rim, but its profile's
//! footprint (the sampling's and the optics' spread, a pixel or two) takes
//! in the occluder's outline, which pulls its step off the rim by a
//! fraction of a pixel: too little to make it an outlier, and of one sign
//! at each end of the stretch, so it does not average out. Dropping the
//! point on each side of every hidden stretch removes that pull.
//!
//! Where the occluder's outline comes within a few pixels of the rim, a
//! short stretch of it can pass as rim and bend the fit, which then leaves
//! the true rim points beside it out: [`isolated_inlier_runs`] names the
//! runs a fit should be tried without.

/// An angular gap between neighbouring points wider than this many times
/// the median gap is a hidden stretch (rays that found no edge).
const HIDDEN_GAP_FACTOR: f64 = 2.5;

/// Consecutive outliers that make a hidden stretch: one alone is noise on
/// an otherwise visible rim, and its neighbours are as good as any.
const MIN_OUTLIER_RUN: usize = 2;

/// How far along the rim from a hidden stretch an edge is pulled by the
/// occluder's outline, pixels: the profile's footprint (the bilinear
/// samples' and the optics' spread). One ray each side at the default
/// 2 px spacing, two at 1 px.
const OCCLUDER_PULL_PX: f64 = 2.0;

/// Flags, per point, the inliers next to a hidden stretch of rim (in the
/// points' angular order about `centre`): those within
/// [`OCCLUDER_PULL_PX`] along the rim (at least the nearest one) of a gap
/// wider than [`HIDDEN_GAP_FACTOR`] median gaps or of a run of at least
/// [`MIN_OUTLIER_RUN`] outliers. Outliers and non-finite points are never
/// flagged (they are out of the fit already).
pub(crate) fn beside_hidden_rim(
    points: &[[f64; 2]],
    centre: [f64; 2],
    inliers: &[bool],
) -> Vec<bool> {
    let mut flagged = vec![false; points.len()];
    let Some(rim) = RimOrder::new(points, centre, inliers) else {
        return flagged;
    };
    let m = rim.order.len();
    let reach = rim.neighbours_within(OCCLUDER_PULL_PX, points, centre);
    let mut flag = |j: usize| {
        let i = rim.order[j % m].1;
        if inliers[i] {
            flagged[i] = true;
        }
    };
    for (j, &gap) in rim.gaps.iter().enumerate() {
        // Point j is the last before a hidden stretch, j + 1 the first
        // after it; `m + j - k` stays a valid index round the rim.
        let hidden_after = gap > rim.wide;
        let hidden_here = rim.outlier(j) && rim.in_outlier_run(j);
        for k in 0..reach {
            if hidden_after {
                flag(m + j - k);
                flag(j + 1 + k);
            }
            if hidden_here {
                flag(m + j - 1 - k);
                flag(j + 1 + k);
            }
        }
    }
    flagged
}

/// An inlier run holding less than this share of the inliers, cut off from
/// the rest by hidden stretches on both sides, is suspect (see
/// [`isolated_inlier_runs`]).
const ISOLATED_RUN_SHARE: f64 = 0.25;

/// Flags the inliers of every short run (under [`ISOLATED_RUN_SHARE`] of
/// the inliers) that hidden stretches cut off from the rest of the rim on
/// both sides. Such a run is often an occluder's outline that happens to
/// lie near the rim: the bottom of the probe's silhouette, a pixel or two
/// outside it, which a fit can bend towards while the true rim points
/// beside it fall out of its band. It may also be true rim seen between
/// two occluders, so the caller tries the fit without it and keeps
/// whichever fits the points better (`adaptive`, stage 5). Nothing is
/// flagged while the inliers form one run.
pub(crate) fn isolated_inlier_runs(
    points: &[[f64; 2]],
    centre: [f64; 2],
    inliers: &[bool],
) -> Vec<bool> {
    let mut flagged = vec![false; points.len()];
    let Some(rim) = RimOrder::new(points, centre, inliers) else {
        return flagged;
    };
    let m = rim.order.len();
    // A hidden stretch follows point j: a wide gap, or a run of outliers.
    let break_after =
        |j: usize| rim.gaps[j % m] > rim.wide || (rim.outlier(j + 1) && rim.in_outlier_run(j + 1));
    let Some(start) = (0..m).find(|&j| break_after(j)) else {
        return flagged;
    };
    let mut runs: Vec<Vec<usize>> = Vec::new();
    let mut current = Vec::new();
    for j in start + 1..=start + m {
        if !rim.outlier(j) {
            current.push(rim.order[j % m].1);
        }
        if break_after(j) && !current.is_empty() {
            runs.push(std::mem::take(&mut current));
        }
    }
    if runs.len() < 2 {
        return flagged;
    }
    let total: usize = runs.iter().map(Vec::len).sum();
    for run in runs
        .iter()
        .filter(|r| (r.len() as f64) < ISOLATED_RUN_SHARE * total as f64)
    {
        for &i in run {
            flagged[i] = true;
        }
    }
    flagged
}

/// `d.rem_euclid(TAU)` for a difference of two angles in [-pi, pi]
/// without its `fmod` call: `fmod` of a value under TAU in magnitude is
/// that value exactly, so this is the same number (-0.0 included); only
/// +-TAU itself is left to `rem_euclid`.
fn wrap_gap(d: f64) -> f64 {
    use std::f64::consts::TAU;
    if d > -TAU && d < TAU {
        if d < 0.0 { d + TAU } else { d }
    } else {
        d.rem_euclid(TAU)
    }
}

/// The finite points in angular order about a centre, with the gaps
/// between neighbours and the inlier flags.
struct RimOrder<'a> {
    /// (angle, index into the points), by angle.
    order: Vec<(f64, usize)>,
    /// Gap from the j-th point to the next one round the rim, radians.
    gaps: Vec<f64>,
    /// A gap wider than this is a hidden stretch.
    wide: f64,
    /// The median gap, radians.
    median_gap: f64,
    inliers: &'a [bool],
}

impl<'a> RimOrder<'a> {
    /// `None` under 8 points: too few to tell a stretch from noise.
    fn new(points: &[[f64; 2]], centre: [f64; 2], inliers: &'a [bool]) -> Option<Self> {
        // Sized for every point: a filtered collect would grow it by
        // reallocations.
        let mut order: Vec<(f64, usize)> = Vec::with_capacity(points.len());
        order.extend(
            points
                .iter()
                .enumerate()
                .filter(|(i, p)| p.iter().all(|v| v.is_finite()) && *i < inliers.len())
                .map(|(i, p)| ((p[1] - centre[1]).atan2(p[0] - centre[0]), i)),
        );
        let m = order.len();
        if m < 8 {
            return None;
        }
        crate::measure::angles::sort_by_angle(&mut order);
        let gaps: Vec<f64> = (0..m)
            .map(|j| wrap_gap(order[(j + 1) % m].0 - order[j].0))
            .collect();
        let median_gap = crate::measure::stats::median(&mut gaps.clone());
        Some(Self {
            order,
            gaps,
            wide: HIDDEN_GAP_FACTOR * median_gap,
            median_gap,
            inliers,
        })
    }

    /// How many neighbours of a point lie within `distance_px` along the
    /// rim (at least one): the median gap times the points' median
    /// distance from `centre` is the rays' spacing.
    fn neighbours_within(&self, distance_px: f64, points: &[[f64; 2]], centre: [f64; 2]) -> usize {
        let mut radii: Vec<f64> = self
            .order
            .iter()
            .map(|&(_, i)| (points[i][0] - centre[0]).hypot(points[i][1] - centre[1]))
            .collect();
        let spacing_px = self.median_gap * crate::measure::stats::median(&mut radii);
        if spacing_px.is_nan() || spacing_px <= 0.0 {
            return 1;
        }
        ((distance_px / spacing_px).round() as usize).clamp(1, (self.order.len() / 4).max(1))
    }

    /// Whether the j-th point (round the rim, any j) is an outlier.
    fn outlier(&self, j: usize) -> bool {
        !self.inliers[self.order[j % self.order.len()].1]
    }

    /// Whether the j-th point is in a run of [`MIN_OUTLIER_RUN`] outliers.
    fn in_outlier_run(&self, j: usize) -> bool {
        let m = self.order.len();
        (0..MIN_OUTLIER_RUN)
            .any(|start| (0..MIN_OUTLIER_RUN).all(|k| self.outlier(j + m + k - start)))
    }
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

    /// On a denser rim the occluder's outline pulls as far along it: rays
    /// one degree apart on a circle of radius 50 (0.87 px) lose the two
    /// nearest on each side, as rays five degrees apart lose one.
    #[test]
    fn a_denser_rim_loses_the_points_as_far_from_a_gap() {
        let mut pts = arc(0, 90, 1);
        pts.extend(arc(130, 360, 1));
        let inliers = vec![true; pts.len()];
        assert_eq!(flagged_angles(&pts, &inliers), vec![88, 89, 130, 131]);
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

    /// The angles (degrees) of the points in isolated inlier runs, in order.
    fn isolated_angles(pts: &[[f64; 2]], inliers: &[bool]) -> Vec<i32> {
        let flagged = isolated_inlier_runs(pts, [100.0, 100.0], inliers);
        let mut at: Vec<i32> = pts
            .iter()
            .zip(&flagged)
            .filter(|(_, f)| **f)
            .map(|(p, _)| angle_of(*p))
            .collect();
        at.sort_unstable();
        at
    }

    fn outliers_at(pts: &[[f64; 2]], hidden: &[std::ops::RangeInclusive<i32>]) -> Vec<bool> {
        pts.iter()
            .map(|p| !hidden.iter().any(|r| r.contains(&angle_of(*p))))
            .collect()
    }

    #[test]
    fn a_short_run_between_hidden_stretches_is_isolated() {
        // The probe's outline at 200-260 degrees, with a short run of
        // inliers (its concave bottom) at 225-235; a gap at 265-340.
        let mut pts = arc(0, 265, 5);
        pts.extend(arc(340, 360, 5));
        let inliers = outliers_at(&pts, &[200..=220, 240..=260]);
        assert_eq!(isolated_angles(&pts, &inliers), vec![225, 230, 235]);
    }

    #[test]
    fn one_run_or_long_runs_are_not_isolated() {
        // One hidden stretch (outliers, then a gap): one run.
        let mut pts = arc(0, 300, 5);
        pts.extend(arc(340, 360, 5));
        let inliers = outliers_at(&pts, &[280..=295]);
        assert!(isolated_angles(&pts, &inliers).is_empty());
        // Two stretches cutting the rim into halves: both runs are long.
        let pts = arc(0, 360, 5);
        let inliers = outliers_at(&pts, &[80..=100, 260..=280]);
        assert!(isolated_angles(&pts, &inliers).is_empty());
        // A lone outlier does not cut the rim.
        let inliers = outliers_at(&pts, &[45..=45, 260..=280]);
        assert!(isolated_angles(&pts, &inliers).is_empty());
    }
}
