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

/// Clusters `vectors` until no two centres are closer than `threshold`;
/// `distance_sq` is the squared distance (NaN counts as infinitely far). Returns the classes, biggest first (ties: lower index of
/// first member first, so the order is deterministic).
pub(crate) fn agglomerate(
    vectors: &[[f64; 5]],
    distance_sq: impl Fn(&[f64; 5], &[f64; 5]) -> f64,
    threshold: f64,
) -> Vec<Cluster> {
    let distance_sq = |v: &[f64; 5], w: &[f64; 5]| {
        let d = distance_sq(v, w);
        if d.is_nan() { f64::INFINITY } else { d }
    };
    let threshold = threshold * threshold;
    let n = vectors.len();
    let mut clusters: Vec<Cluster> = vectors
        .iter()
        .map(|v| Cluster {
            centre: *v,
            count: 1,
        })
        .collect();
    let mut active = vec![true; n];
    // Indices of the active classes (compact, so scans skip merged ones).
    let mut alive: Vec<usize> = (0..n).collect();
    // Full symmetric distance matrix, and each row's nearest active column.
    let mut d = vec![f64::INFINITY; n * n];
    for i in 0..n {
        for j in (i + 1)..n {
            let v = distance_sq(&vectors[i], &vectors[j]);
            d[i * n + j] = v;
            d[j * n + i] = v;
        }
    }
    let nearest_of = |d: &[f64], alive: &[usize], i: usize| -> (usize, f64) {
        let row = &d[i * n..(i + 1) * n];
        let mut best = (usize::MAX, f64::INFINITY);
        for &j in alive {
            if j != i && row[j] < best.1 {
                best = (j, row[j]);
            }
        }
        best
    };
    let mut nearest: Vec<(usize, f64)> = (0..n).map(|i| nearest_of(&d, &alive, i)).collect();
    loop {
        let mut pick = (usize::MAX, f64::INFINITY);
        for &i in &alive {
            if nearest[i].1 < pick.1 {
                pick = (i, nearest[i].1);
            }
        }
        let (i, dist) = pick;
        if i == usize::MAX || dist > threshold {
            break;
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
        // Row and column i from the new centre.
        for &k in &alive {
            if k != i {
                let v = distance_sq(&clusters[i].centre, &clusters[k].centre);
                d[i * n + k] = v;
                d[k * n + i] = v;
            }
        }
        nearest[i] = nearest_of(&d, &alive, i);
        for idx in 0..alive.len() {
            let k = alive[idx];
            if k == i {
                continue;
            }
            if nearest[k].0 == i || nearest[k].0 == j {
                nearest[k] = nearest_of(&d, &alive, k);
            } else if d[k * n + i] < nearest[k].1 {
                nearest[k] = (i, d[k * n + i]);
            }
        }
    }
    let mut out: Vec<(usize, Cluster)> = clusters
        .into_iter()
        .enumerate()
        .filter(|(i, _)| active[*i])
        .collect();
    out.sort_by(|a, b| b.1.count.cmp(&a.1.count).then(a.0.cmp(&b.0)));
    out.into_iter().map(|(_, c)| c).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn euclid(a: &[f64; 5], b: &[f64; 5]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>()
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
        let c = agglomerate(&v, euclid, 1.0);
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
        assert_eq!(agglomerate(&v, euclid, 0.5).len(), 5);
        let all = agglomerate(&v, euclid, f64::INFINITY);
        assert_eq!(all.len(), 1);
        assert_eq!(all[0].count, 5);
        assert!((all[0].centre[0] - 2.0).abs() < 1e-12);
    }
}
