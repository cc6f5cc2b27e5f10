//! Saturated pixels (a sun glare or its streak) along a rim ray: a step
//! onto them is the glare's skirt, not the disc's rim, and says nothing of
//! the surface under it.

use super::{SATURATED_GRAY, rim};

/// How much of a rim a glare may hide, for a narrow pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum GlareCover {
    /// None or a part of it: steps into saturated pixels give no rim
    /// points.
    Part,
    /// So much of the rim that too few rays found it (the pass is
    /// repeated closer): a step with saturated pixels inward of it lies
    /// beyond the glare (the canopy's edge seen past it), not on the disc's
    /// rim, and gives no rim point either.
    Most,
}

/// Whether profile `p` (sampled from `s_min` every `step`) is saturated
/// anywhere inward of step `e`'s crossing.
pub(super) fn glare_before_step(p: &[f32], s_min: f64, step: f64, e: &rim::RayEdge) -> bool {
    let end = (((e.s - s_min) / step).max(0.0) as usize).min(p.len());
    p[..end].iter().any(|&v| v >= SATURATED_GRAY)
}

/// Whether the light side of step `e` (from its crossing to a few samples
/// past its light end) on profile `p` (sampled from `s_min` every `step`)
/// reaches saturation.
pub(super) fn glare_on_light_side(p: &[f32], s_min: f64, step: f64, e: &rim::RayEdge) -> bool {
    let Some(last) = p.len().checked_sub(1) else {
        return false;
    };
    let index = |s: f64| (((s - s_min) / step).max(0.0) as usize).min(last);
    let (from, to) = (index(e.s), (index(e.light_s) + 2).min(last));
    p[from..=to].iter().any(|&v| v >= SATURATED_GRAY)
}
