//! Angles about a centre: rim points put in angular order, shared by the
//! detector's fill test (its nearest-step lookup), the fit's guard against
//! hidden stretches and the covariance's neighbour correlation (both walk
//! the rim in order).

/// Sorts `(angle, item)` pairs that are in their points' order by angle,
/// exactly as a stable `sort_by` on the angle would. Rim points come in the
/// order of the rays that found them, round the rim from some angle: one
/// ascending run, or two when the rays pass +-pi. Those are put in order by
/// a rotation (every angle of the second run strictly below every one of
/// the first, so no tie changes sides); anything else is sorted.
pub(crate) fn sort_by_angle<T>(pairs: &mut [(f64, T)]) {
    let mut descents = (1..pairs.len()).filter(|&j| pairs[j].0.total_cmp(&pairs[j - 1].0).is_lt());
    match (descents.next(), descents.next()) {
        (None, _) => {}
        (Some(k), None) if pairs[pairs.len() - 1].0.total_cmp(&pairs[0].0).is_lt() => {
            pairs.rotate_left(k);
        }
        _ => pairs.sort_by(|a, b| a.0.total_cmp(&b.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorting_by_angle_is_the_stable_sort() {
        let cases: [&[f64]; 6] = [
            &[],
            &[0.5, 1.0, 1.0, 2.0],
            &[2.0, 3.0, 3.0, -3.0, -1.0, -1.0, 1.0],
            &[2.0, 3.0, -3.0, 2.0],
            &[1.0, 0.0, 2.0, -1.0],
            &[3.0, -0.0, 0.0, 0.0, -0.0],
        ];
        for angles in cases {
            let mut fast: Vec<(f64, usize)> = angles.iter().copied().zip(0..).collect();
            let mut stable = fast.clone();
            sort_by_angle(&mut fast);
            stable.sort_by(|a, b| a.0.total_cmp(&b.0));
            let bits =
                |v: &[(f64, usize)]| v.iter().map(|(a, i)| (a.to_bits(), *i)).collect::<Vec<_>>();
            assert_eq!(bits(&fast), bits(&stable), "{angles:?}");
        }
    }
}
