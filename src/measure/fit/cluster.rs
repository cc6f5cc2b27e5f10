//! Agglomerative hierarchical clustering with centroid linkage (paper eqs.
//! 9-10): every vector starts as its own class; the two classes whose centres
//! are closest merge into one whose centre is the member-weighted mean
//! (eq. 10); merging stops when the smallest between-class distance exceeds
//! the threshold.
//!
//! Eq. 9 initialises the between-class matrix from the class distances and
//! the centre distances; with one vector per class these are the same
//! distance, and the text then updates a merged class' row and column from
//! its new centre, i.e. centroid linkage, which is what is done here.

/// One class: its centre (eq. 10) and how many vectors it holds.
#[derive(Clone, Debug)]
pub(crate) struct Cluster {
    pub centre: [f64; 5],
    pub count: usize,
}

/// Clusters `vectors` until no two centres are closer than `threshold`
/// (Euclidean distance; a vector with a NaN is infinitely far from all).
/// Returns the classes, biggest first (ties: lower index of first member
/// first, so the order is deterministic).
pub(crate) fn agglomerate(vectors: &[[f64; 5]], threshold: f64) -> Vec<Cluster> {
    let limit_sq = threshold * threshold;
    let n = vectors.len();
    let mut clusters: Vec<Cluster> = vectors
        .iter()
        .map(|v| Cluster {
            centre: *v,
            count: 1,
        })
        .collect();
    let mut active = vec![true; n];
    // Indices of the active classes, ascending (compact, so scans skip
    // merged ones).
    let mut alive: Vec<usize> = (0..n).collect();
    // Each class' nearest other class and their squared distance (ties: the
    // lowest index). Distances are recomputed from the centres when needed
    // rather than kept in an n x n matrix: a 5-vector distance costs about
    // as much as reading the matrix, and only one class changes per merge.
    let mut nearest: Vec<(usize, f64)> = vec![(NONE, f64::INFINITY); n];
    for i in 0..n {
        for j in (i + 1)..n {
            let d = distance_sq(&vectors[i], &vectors[j]);
            if d < nearest[i].1 {
                nearest[i] = (j, d);
            }
            if d < nearest[j].1 {
                nearest[j] = (i, d);
            }
        }
    }
    let nearest_of = |clusters: &[Cluster], alive: &[usize], i: usize| -> (usize, f64) {
        let mut best = (NONE, f64::INFINITY);
        for &j in alive {
            let d = distance_sq(&clusters[i].centre, &clusters[j].centre);
            if d < best.1 && j != i {
                best = (j, d);
            }
        }
        best
    };
    // A class whose nearest moved away is not searched again at once: it is
    // marked stale and keeps the old minimum as a lower bound of its new one
    // (its other distances are at least that). It is searched again only if
    // that bound becomes the smallest of all, and never if the bound is above
    // the threshold. (Searching at once for every class that pointed at a
    // merged class makes each merge into a big class cost O(n^2).)
    let mut stale = vec![false; n];
    loop {
        // The closest pair (ties: the lowest row index); a stale row's bound
        // is resolved when it comes first.
        let mut pick = (NONE, f64::INFINITY);
        for &i in &alive {
            if nearest[i].1 < pick.1 {
                pick = (i, nearest[i].1);
            }
        }
        let (i, dist_sq) = pick;
        if i == NONE || dist_sq > limit_sq {
            break;
        }
        if stale[i] {
            nearest[i] = nearest_of(&clusters, &alive, i);
            stale[i] = false;
            continue;
        }
        let j = nearest[i].0;
        // Eq. 10: the merged centre is the count-weighted mean.
        let (mi, mj) = (clusters[i].count as f64, clusters[j].count as f64);
        let mut centre = [0.0; 5];
        for (k, c) in centre.iter_mut().enumerate() {
            *c = (clusters[i].centre[k] * mi + clusters[j].centre[k] * mj) / (mi + mj);
        }
        clusters[i].centre = centre;
        clusters[i].count += clusters[j].count;
        active[j] = false;
        if let Some(pos) = alive.iter().position(|&k| k == j) {
            alive.remove(pos);
        }
        // Only the distances to i changed. A class whose nearest was i or j
        // keeps i if the new distance is no larger than that old minimum,
        // else it goes stale; a stale class takes i if i is below its bound
        // (then i is its nearest); any other class takes i if i is nearer.
        let mut best_i = (NONE, f64::INFINITY);
        for &k in &alive {
            if k == i {
                continue;
            }
            let to_i = distance_sq(&clusters[i].centre, &clusters[k].centre);
            if to_i < best_i.1 {
                best_i = (k, to_i);
            }
            let (was, was_sq) = nearest[k];
            if stale[k] {
                if to_i < was_sq {
                    nearest[k] = (i, to_i);
                    stale[k] = false;
                }
            } else if was == i || was == j {
                if to_i <= was_sq {
                    nearest[k] = (i, to_i);
                } else {
                    nearest[k] = (NONE, was_sq);
                    stale[k] = true;
                }
            } else if to_i < was_sq || (to_i == was_sq && i < was) {
                nearest[k] = (i, to_i);
            }
        }
        nearest[i] = best_i;
    }
    let mut out: Vec<(usize, Cluster)> = clusters
        .into_iter()
        .enumerate()
        .filter(|(i, _)| active[*i])
        .collect();
    out.sort_by(|a, b| b.1.count.cmp(&a.1.count).then(a.0.cmp(&b.0)));
    out.into_iter().map(|(_, c)| c).collect()
}

/// No class.
const NONE: usize = usize::MAX;

/// Squared Euclidean distance; NaN (a vector with a NaN) counts as
/// infinitely far, because every comparison with it is false.
pub(crate) fn distance_sq(v: &[f64; 5], w: &[f64; 5]) -> f64 {
    let d = [
        v[0] - w[0],
        v[1] - w[1],
        v[2] - w[2],
        v[3] - w[3],
        v[4] - w[4],
    ];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + d[3] * d[3] + d[4] * d[4]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain algorithm, as eqs. 9-10 describe it: merge the closest
    /// pair of classes (ties: lowest indices) until it is farther apart than
    /// the threshold. O(n^3), obviously right.
    fn reference(vectors: &[[f64; 5]], threshold: f64) -> Vec<Cluster> {
        let mut classes: Vec<Option<Cluster>> = vectors
            .iter()
            .map(|v| {
                Some(Cluster {
                    centre: *v,
                    count: 1,
                })
            })
            .collect();
        loop {
            let mut best = (0, 0, f64::INFINITY);
            for i in 0..classes.len() {
                for j in (i + 1)..classes.len() {
                    if let (Some(a), Some(b)) = (&classes[i], &classes[j]) {
                        let d = distance_sq(&a.centre, &b.centre);
                        if d < best.2 {
                            best = (i, j, d);
                        }
                    }
                }
            }
            let (i, j, d) = best;
            if d.is_infinite() || d > threshold * threshold {
                break;
            }
            let b = classes[j].take().unwrap();
            let a = classes[i].as_mut().unwrap();
            let (mi, mj) = (a.count as f64, b.count as f64);
            for k in 0..5 {
                a.centre[k] = (a.centre[k] * mi + b.centre[k] * mj) / (mi + mj);
            }
            a.count += b.count;
        }
        let mut out: Vec<(usize, Cluster)> = classes
            .into_iter()
            .enumerate()
            .filter_map(|(i, c)| c.map(|c| (i, c)))
            .collect();
        out.sort_by(|a, b| b.1.count.cmp(&a.1.count).then(a.0.cmp(&b.0)));
        out.into_iter().map(|(_, c)| c).collect()
    }

    #[test]
    fn same_classes_as_the_plain_algorithm() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for trial in 0..40 {
            // A few tight blobs (consistent subset fits) and scatter.
            let blobs: Vec<[f64; 5]> = (0..rng.random_range(1..5))
                .map(|_| std::array::from_fn(|_| rng.random_range(-3.0..3.0)))
                .collect();
            let spread = rng.random_range(0.02..0.3);
            let v: Vec<[f64; 5]> = (0..rng.random_range(2..160))
                .map(|_| {
                    if rng.random_bool(0.7) {
                        let b = blobs[rng.random_range(0..blobs.len())];
                        std::array::from_fn(|k| b[k] + rng.random_range(-spread..spread))
                    } else {
                        std::array::from_fn(|_| rng.random_range(-3.0..3.0))
                    }
                })
                .collect();
            let threshold = rng.random_range(0.05..0.6);
            let fast = agglomerate(&v, threshold);
            let slow = reference(&v, threshold);
            assert_eq!(fast.len(), slow.len(), "trial {trial}");
            for (f, s) in fast.iter().zip(&slow) {
                assert_eq!(f.count, s.count, "trial {trial}");
                for k in 0..5 {
                    assert!((f.centre[k] - s.centre[k]).abs() < 1e-12, "trial {trial}");
                }
            }
        }
    }

    #[test]
    fn two_groups_and_a_stray() {
        let mut v = Vec::new();
        for k in 0..6 {
            v.push([k as f64 * 0.1, 0.0, 0.0, 0.0, 0.0]);
        }
        for k in 0..3 {
            v.push([10.0 + k as f64 * 0.1, 0.0, 0.0, 0.0, 0.0]);
        }
        v.push([100.0, 0.0, 0.0, 0.0, 0.0]);
        let c = agglomerate(&v, 1.0);
        assert_eq!(c.len(), 3);
        assert_eq!(c[0].count, 6);
        // Eq. 10: the centre of the first group is its mean, 0.25.
        assert!((c[0].centre[0] - 0.25).abs() < 1e-12);
        assert_eq!(c[1].count, 3);
        assert!((c[1].centre[0] - 10.1).abs() < 1e-12);
        assert_eq!(c[2].count, 1);
    }

    #[test]
    fn threshold_zero_keeps_singletons_and_infinite_merges_all() {
        let v: Vec<[f64; 5]> = (0..5).map(|k| [k as f64, 1.0, 2.0, 3.0, 4.0]).collect();
        assert_eq!(agglomerate(&v, 0.5).len(), 5);
        let all = agglomerate(&v, f64::INFINITY);
        assert_eq!(all.len(), 1);
        assert_eq!(all[0].count, 5);
        assert!((all[0].centre[0] - 2.0).abs() < 1e-12);
    }
}
