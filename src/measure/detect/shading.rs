//! Where a measured rim point lies on a canopy shaded toward the disc: the
//! step's mid level is taken between the disc's level and a light level a
//! little beyond the step, which on a canopy brightening away from the disc
//! is above the canopy's level at the edge itself.

use super::{median, rim};

/// One ray's edge, for placing it on a shaded canopy.
pub(super) struct ShadedEdge {
    /// The ray's direction (unit, distorted pixels).
    dir: [f64; 2],
    /// From the edge out to where its light level was taken, pixels.
    level_distance_px: f64,
    /// The profile's slope at the edge, gray levels per pixel.
    ramp_slope: f64,
    /// The light side's slope beyond the step over the step's contrast,
    /// per pixel (NaN where not measured).
    relative_slope: f64,
    /// The step's contrast, gray levels.
    contrast: f64,
    /// The step's width as seen (blur and the profile's smoothing
    /// together), pixels.
    width_px: f64,
}

impl ShadedEdge {
    /// The edge `e` found on the ray in direction `dir`, with its light
    /// side's slope ([`rim::light_side_slope`], gray levels per pixel).
    pub(super) fn new(dir: [f64; 2], e: &rim::RayEdge, light_slope: f32) -> Self {
        Self {
            dir,
            // The light level is the mean of three samples from `light_s`:
            // its centre is a sample (0.5 px) further.
            level_distance_px: e.light_s + 0.5 - e.s,
            ramp_slope: f64::from(e.ramp_slope),
            relative_slope: f64::from(light_slope / (e.light - e.dark)),
            contrast: f64::from(e.light - e.dark),
            width_px: 2.0 * (e.light_s - e.s),
        }
    }
}

/// The edges of a pass moved to where a canopy shaded toward the disc puts
/// them. The drogue's canopy brightens away from the disc, so the light
/// level taken beyond a step is above the canopy's level at the edge by
/// its slope times that distance; the mid level is too high by half that,
/// and the crossing too far out by that over the ramp's slope: nothing on a
/// sharp step, a quarter pixel at 8 px of motion blur, all round the rim
/// where the blur runs along it (the disc fitted too large, the range too
/// short by 0.1-0.6 % on average on the reference renderer's blurred and
/// hazy sets). Less the part that levels taken at the edge itself leave: a
/// box blur of width `L` (the step's width as seen, blur and smoothing
/// together) over a side of slope `g` lifts the ramp's middle by `g L / 8`.
/// The shading is one property of the canopy, so its slope is the median
/// over the pass's rays of each ray's light-side slope relative to its
/// contrast (one ray's slope, over a few samples, is mostly noise), and
/// each ray's move is at most half the distance it corrects for.
pub(super) fn shaded_points(points_px: &[[f64; 2]], edges: &[ShadedEdge]) -> Vec<[f64; 2]> {
    let mut slopes: Vec<f64> = edges
        .iter()
        .map(|e| e.relative_slope)
        .filter(|s| s.is_finite())
        .collect();
    if slopes.len() < points_px.len() / 2 || slopes.is_empty() {
        return points_px.to_vec();
    }
    let relative_slope = median(&mut slopes);
    points_px
        .iter()
        .zip(edges)
        .map(|(p, e)| {
            let excess =
                relative_slope * e.contrast * (0.5 * e.level_distance_px - 0.125 * e.width_px);
            let limit = 0.5 * e.level_distance_px.max(0.0);
            let shift = if e.ramp_slope > 0.0 {
                (-excess / e.ramp_slope).clamp(-limit, limit)
            } else {
                0.0
            };
            [p[0] + shift * e.dir[0], p[1] + shift * e.dir[1]]
        })
        .collect()
}
