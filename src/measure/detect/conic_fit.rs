//! A small, fast robust ellipse fit used only to verify and rank candidates
//! (is this edge set an ellipse, and where should the rim search look?).
//! The measurement's own fit (RANSAC + clustering, unbiased refit) is the fit
//! module's job: this one only has to be right to a fraction of a pixel.

use crate::measure::ellipse::{Conic, Ellipse};
use nalgebra::{Matrix3, Matrix5, Matrix6, Vector5, Vector6};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Algebraic least-squares conic (unit coefficient norm) of the points, in
/// coordinates normalised to their centroid and RMS radius so that the
/// problem is well conditioned. Returns `None` when the points do not
/// determine an ellipse.
pub fn fit_conic(points: &[[f64; 2]]) -> Option<Conic> {
    if points.len() < 5 {
        return None;
    }
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p[0] / n, y + p[1] / n));
    let rms = (points
        .iter()
        .map(|p| (p[0] - mx).powi(2) + (p[1] - my).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    if !(rms > 1e-9 && rms.is_finite()) {
        return None;
    }
    let s = 1.0 / rms;
    // The upper triangle of the scatter matrix, mirrored: the same products
    // summed in the same order as the full outer products (x y = y x exactly).
    let mut upper = [0.0f64; 21];
    for p in points {
        let (x, y) = ((p[0] - mx) * s, (p[1] - my) * s);
        let row = [x * x, x * y, y * y, x, y, 1.0];
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                upper[k] += row[i] * row[j];
                k += 1;
            }
        }
    }
    let mut scatter = Matrix6::<f64>::zeros();
    let mut k = 0;
    for i in 0..6 {
        for j in i..6 {
            scatter[(i, j)] = upper[k];
            scatter[(j, i)] = upper[k];
            k += 1;
        }
    }
    let v = smallest_eigenvector(&scatter)?;
    let normalised = Conic {
        a: v[0],
        b: v[1],
        c: v[2],
        d: v[3],
        e: v[4],
        f: v[5],
    };
    // Back to pixels: x' = T x with T = [[s,0,-s mx],[0,s,-s my],[0,0,1]].
    let t = Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0);
    let m = t.transpose() * normalised.matrix() * t;
    Some(Conic::from_matrix(&m))
}

/// The unit eigenvector of the scatter matrix with the smallest eigenvalue:
/// inverse iteration, or the full decomposition where that does not
/// converge (noise-free points make the matrix singular).
fn smallest_eigenvector(scatter: &Matrix6<f64>) -> Option<Vector6<f64>> {
    inverse_iteration(scatter).or_else(|| {
        let eig = scatter.symmetric_eigen();
        let (imin, _) = eig
            .eigenvalues
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))?;
        Some(eig.eigenvectors.column(imin).into_owned())
    })
}

/// Inverse iteration alone; `None` when it does not converge.
fn inverse_iteration(scatter: &Matrix6<f64>) -> Option<Vector6<f64>> {
    // Start: the unit circle of the normalised coordinates.
    let start = Vector6::new(1.0, 0.0, 1.0, 0.0, 0.0, -1.0).normalize();
    crate::measure::inverse_iteration::smallest_eigenvector(scatter, None, start)
}

/// The conic through five points, solved directly (a 5 x 5 system with
/// F = 1 in coordinates centred on the points: F = 0 would put their centroid
/// on the conic, impossible for an ellipse).
pub fn conic_through_five(points: &[[f64; 2]; 5]) -> Option<Conic> {
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p[0] / 5.0, y + p[1] / 5.0));
    let mut m = Matrix5::<f64>::zeros();
    for (r, p) in points.iter().enumerate() {
        let (x, y) = (p[0] - mx, p[1] - my);
        m.set_row(r, &nalgebra::RowVector5::new(x * x, x * y, y * y, x, y));
    }
    let v = m.lu().solve(&-Vector5::repeat(1.0))?;
    let centred = Conic {
        a: v[0],
        b: v[1],
        c: v[2],
        d: v[3],
        e: v[4],
        f: 1.0,
    };
    let t = Matrix3::new(1.0, 0.0, -mx, 0.0, 1.0, -my, 0.0, 0.0, 1.0);
    let conic = Conic::from_matrix(&(t.transpose() * centred.matrix() * t));
    conic.a.is_finite().then_some(conic)
}

/// The ellipse of [`fit_conic`].
pub fn fit_ellipse(points: &[[f64; 2]]) -> Option<Ellipse> {
    fit_conic(points)?.to_ellipse()
}

/// Geometric distances (Sampson approximation) of the points to an ellipse.
pub fn residuals(ellipse: &Ellipse, points: &[[f64; 2]], out: &mut Vec<f64>) {
    let conic = ellipse.to_conic();
    out.clear();
    out.extend(points.iter().map(|p| conic.sampson_distance(p[0], p[1])));
}

/// RANSAC over 5-point subsets, then a least-squares refit on the inliers
/// (points within `tolerance_px`). Deterministic for a given seed.
pub fn ransac_ellipse(
    points: &[[f64; 2]],
    tolerance_px: f64,
    iterations: usize,
    seed: u64,
) -> Option<Ellipse> {
    if points.len() < 5 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut best: Option<(usize, Ellipse)> = None;
    let mut sample = [[0.0; 2]; 5];
    let mut needed = iterations;
    let mut k = 0;
    while k < needed.min(iterations) {
        k += 1;
        for slot in sample.iter_mut() {
            *slot = points[rng.random_range(0..points.len())];
        }
        let Some(conic) = conic_through_five(&sample) else {
            continue;
        };
        // An ellipse: B^2 - 4AC < 0.
        if conic.b * conic.b - 4.0 * conic.a * conic.c >= 0.0 {
            continue;
        }
        let count = points
            .iter()
            .filter(|p| conic.sampson_distance(p[0], p[1]) <= tolerance_px)
            .count();
        if best.as_ref().is_none_or(|(c, _)| count > *c)
            && let Some(e) = conic.to_ellipse()
        {
            best = Some((count, e));
            // Enough draws for a 99 % chance of one all-inlier sample at the
            // best inlier share seen so far.
            let w = count as f64 / points.len() as f64;
            let p_good = w.powi(5).clamp(1e-9, 1.0 - 1e-12);
            needed = ((0.01f64).ln() / (1.0 - p_good).ln()).ceil().max(1.0) as usize;
        }
    }
    let (_, model) = best?;
    refine(&model, points, tolerance_px, 3)
}

/// Iterated trimmed refit: keeps the points within `tolerance_px` of the
/// current ellipse and refits them, a few times.
pub fn refine(
    start: &Ellipse,
    points: &[[f64; 2]],
    tolerance_px: f64,
    rounds: usize,
) -> Option<Ellipse> {
    let mut current = *start;
    let mut kept = Vec::with_capacity(points.len());
    for _ in 0..rounds {
        let conic = current.to_conic();
        kept.clear();
        kept.extend(
            points
                .iter()
                .filter(|p| conic.sampson_distance(p[0], p[1]) <= tolerance_px),
        );
        if kept.len() < 5 {
            return None;
        }
        current = fit_ellipse(&kept)?;
    }
    Some(current)
}

/// The points of the strongest straight edge among `points` (a ray pass's
/// rim points, pixels, in ray order; their indices, ascending): of the
/// lines through two points at most
/// three apart in the list, the one with the most points within
/// `tolerance_px`. `None` when it has fewer than `min_points` or they span
/// less than `min_span_px` along it. Neighbouring rays' points define the
/// lines: an edge crossing the rays gives runs of them, and the pairs are
/// a few per point, not all pairs.
pub fn straight_edge(
    points: &[[f64; 2]],
    tolerance_px: f64,
    min_points: usize,
    min_span_px: f64,
) -> Option<Vec<usize>> {
    let n = points.len();
    // A line: a point on it and its unit normal.
    let distance = |p: [f64; 2], normal: [f64; 2], s: &[f64; 2]| {
        ((s[0] - p[0]) * normal[0] + (s[1] - p[1]) * normal[1]).abs()
    };
    let mut best: Option<(usize, [f64; 2], [f64; 2])> = None;
    for i in 0..n {
        for j in (i + 1..=i + 3).map(|j| j % n).filter(|&j| j != i) {
            let (p, q) = (points[i], points[j]);
            let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
            let len = dx.hypot(dy);
            if !(len > 0.0 && len.is_finite()) {
                continue;
            }
            let normal = [-dy / len, dx / len];
            let count = points
                .iter()
                .filter(|s| distance(p, normal, s) <= tolerance_px)
                .count();
            if best.is_none_or(|b| count > b.0) {
                best = Some((count, p, normal));
            }
        }
    }
    let (count, p, normal) = best?;
    if count < min_points {
        return None;
    }
    let on: Vec<usize> = (0..n)
        .filter(|&i| distance(p, normal, &points[i]) <= tolerance_px)
        .collect();
    let along = |i: &usize| (points[*i][0] - p[0]) * normal[1] - (points[*i][1] - p[1]) * normal[0];
    let (lo, hi) = on
        .iter()
        .map(along)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t), hi.max(t))
        });
    (hi - lo >= min_span_px).then_some(on)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_points_give_the_exact_ellipse() {
        let truth = Ellipse::new(412.3, 287.9, 95.0, 51.5, 0.61);
        let pts: Vec<[f64; 2]> = (0..40).map(|k| truth.point_at(k as f64 * 0.157)).collect();
        let e = fit_ellipse(&pts).unwrap();
        assert!(truth.max_param_error_px(&e) < 1e-6, "{e:?}");
    }

    #[test]
    fn inverse_iteration_gives_the_decompositions_eigenvector() {
        // Noisy rim points (a scatter matrix of full rank): the fast path
        // must converge, to the full decomposition's eigenvector.
        use rand::SeedableRng;
        let truth = Ellipse::new(300.0, 200.0, 80.0, 50.0, 0.7);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for round in 0..20 {
            let pts: Vec<[f64; 2]> = (0..60)
                .map(|k| {
                    let p = truth.point_at(k as f64 * 0.07 * (1.0 + round as f64 * 0.1));
                    [
                        p[0] + rng.random_range(-0.3..0.3),
                        p[1] + rng.random_range(-0.3..0.3),
                    ]
                })
                .collect();
            let mut s = Matrix6::<f64>::zeros();
            for p in &pts {
                let (x, y) = ((p[0] - 300.0) / 70.0, (p[1] - 200.0) / 70.0);
                let row = nalgebra::Vector6::new(x * x, x * y, y * y, x, y, 1.0);
                s += row * row.transpose();
            }
            let fast = inverse_iteration(&s).expect("converges");
            let eig = s.symmetric_eigen();
            let (k, _) = eig
                .eigenvalues
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .unwrap();
            let full = eig.eigenvectors.column(k).into_owned();
            let full = if full.dot(&fast) < 0.0 { -full } else { full };
            assert!(
                (fast - full).amax() < 1e-9,
                "round {round}: {fast} vs {full}"
            );
        }
    }

    #[test]
    fn five_points_determine_the_ellipse() {
        let truth = Ellipse::new(-40.0, 700.0, 33.0, 12.0, 1.1);
        let pts = [0.1, 1.3, 2.0, 3.9, 5.0].map(|t| truth.point_at(t));
        let e = conic_through_five(&pts).unwrap().to_ellipse().unwrap();
        assert!(truth.max_param_error_px(&e) < 1e-6, "{e:?}");
    }

    #[test]
    fn ransac_ignores_a_straight_line_of_outliers() {
        let truth = Ellipse::new(200.0, 150.0, 60.0, 40.0, -0.3);
        // 60 % of the rim, then 30 points on a line through it (a probe side).
        let mut pts: Vec<[f64; 2]> = (0..60)
            .map(|k| truth.point_at(k as f64 * 0.6 * std::f64::consts::TAU / 60.0))
            .collect();
        pts.extend((0..30).map(|k| [150.0 + k as f64 * 3.0, 190.0 + k as f64 * 0.5]));
        let e = ransac_ellipse(&pts, 1.0, 200, 7).unwrap();
        assert!(truth.max_param_error_px(&e) < 1e-6, "{e:?}");
    }

    /// A ray pass's rim points around a circle: one per ray, every 7.5
    /// degrees.
    fn circle_points(r: f64) -> Vec<[f64; 2]> {
        (0..48)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 48.0;
                [100.0 + r * t.cos(), 100.0 + r * t.sin()]
            })
            .collect()
    }

    #[test]
    fn a_circles_rim_has_no_straight_edge() {
        for r in [10.0_f64, 30.0, 100.0] {
            let tolerance = (0.03 * r).max(1.0);
            assert_eq!(
                straight_edge(&circle_points(r), tolerance, 8, 1.5 * r),
                None
            );
        }
    }

    #[test]
    fn an_edge_across_the_rays_is_found_and_only_it() {
        // The rays from the centre toward a line 10 px off it, at x = 110,
        // meet it instead of the rim of radius 30 (a streak over the disc):
        // 19 rays, over 48 px of it.
        let mut points = circle_points(30.0);
        let mut on_line = Vec::new();
        for (k, p) in points.iter_mut().enumerate() {
            let (dx, dy) = (p[0] - 100.0, p[1] - 100.0);
            if dx > 10.0 {
                *p = [110.0, 100.0 + dy * 10.0 / dx];
                on_line.push(k);
            }
        }
        assert!(on_line.len() >= 8, "{on_line:?}");
        assert_eq!(straight_edge(&points, 1.0, 8, 45.0), Some(on_line));
    }
}
