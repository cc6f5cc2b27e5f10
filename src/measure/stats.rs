//! Order statistics shared by the detector, the fit and the covariance.

/// The upper median (the element at `len / 2` of the sorted values) by
/// selection, not a sort: the order of the rest is never used. 0 for no
/// values. `values` is reordered.
pub(crate) fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}
