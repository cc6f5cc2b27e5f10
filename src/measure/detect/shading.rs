//! Where a measured rim point lies when the levels beside its step are not
//! flat: the step's mid level is taken between the disc's level and a light
//! level a little beyond the step, which on a canopy brightening away from
//! the disc is above the canopy's level at the edge itself, and next to an
//! occluder's outline just past the rim is below it.

use super::{median, rim};
use crate::measure::ellipse::Ellipse;
use nalgebra::{Matrix5, Vector5};

/// One ray's edge, for placing it on a shaded canopy.
pub(super) struct ShadedEdge {
    /// The ray's direction (unit, distorted pixels).
    dir: [f64; 2],
    /// From the edge out to where its light level was taken, pixels.
    level_distance_px: f64,
    /// From the edge in to where its dark level was taken, pixels.
    dark_distance_px: f64,
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
    /// The dark side's slope before the step over the step's contrast, per
    /// pixel (NaN where not measured).
    relative_dark_slope: f64,
    /// Standard deviation of `relative_slope` from the frame's noise alone,
    /// per pixel.
    relative_slope_sigma: f64,
}

impl ShadedEdge {
    /// The edge `e` found on the ray in direction `dir`, with its light and
    /// dark sides' slopes ([`rim::light_side_slope`],
    /// [`rim::dark_side_slope`], gray levels per pixel) and the frame's
    /// noise (gray levels).
    pub(super) fn new(
        dir: [f64; 2],
        e: &rim::RayEdge,
        [light_slope, dark_slope]: [f32; 2],
        noise_gray: f64,
    ) -> Self {
        Self {
            relative_dark_slope: f64::from(dark_slope / (e.light - e.dark)),
            relative_slope_sigma: noise_gray * rim::SLOPE_NOISE_PER_GRAY
                / f64::from(e.light - e.dark),
            dir,
            // The light level is the mean of three samples from `light_s`:
            // its centre is a sample (0.5 px) further.
            level_distance_px: e.light_s + 0.5 - e.s,
            // The dark level is the mean of three samples ending at
            // `dark_s`: its centre is a sample (0.5 px) nearer the origin.
            dark_distance_px: e.s - e.dark_s + 0.5,
            ramp_slope: f64::from(e.ramp_slope),
            relative_slope: f64::from(light_slope / (e.light - e.dark)),
            contrast: f64::from(e.light - e.dark),
            width_px: 2.0 * (e.light_s - e.s),
        }
    }

    /// How much faster the light side falls outward than the dark side
    /// before the step, over the step's contrast, per pixel: a light added
    /// over both sides (a glare's skirt, vignetting) slopes both alike and
    /// leaves the mid level where it is; something dark just beyond the
    /// step pulls only the light side down. The light side's alone where the
    /// dark side was not measured.
    fn own_fall(&self) -> f64 {
        if self.relative_dark_slope.is_finite() {
            self.relative_slope - self.relative_dark_slope
        } else {
            self.relative_slope
        }
    }

    /// Standard deviation of [`ShadedEdge::own_fall`] from the noise alone.
    fn own_fall_sigma(&self) -> f64 {
        if self.relative_dark_slope.is_finite() {
            std::f64::consts::SQRT_2 * self.relative_slope_sigma
        } else {
            self.relative_slope_sigma
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
/// The shading is one property of the canopy, so its slope is the pass's
/// `canopy` ([`canopy_slope`]; the points stay where they are without
/// it), and each ray's move is at most half the distance it corrects for.
/// On the `sharp` steps, whose two sides' slopes were read beside them,
/// the curvature of light laid over both sides too ([`curvature_excess`]).
pub(super) fn shaded_points(
    points_px: &[[f64; 2]],
    edges: &[ShadedEdge],
    canopy: Option<f64>,
    sharp: &[bool],
) -> Vec<[f64; 2]> {
    let Some(relative_slope) = canopy else {
        return points_px.to_vec();
    };
    points_px
        .iter()
        .zip(edges)
        .zip(sharp)
        .map(|((p, e), &sharp)| {
            let mut excess =
                relative_slope * e.contrast * (0.5 * e.level_distance_px - 0.125 * e.width_px);
            if sharp {
                excess += curvature_excess(e, relative_slope);
            }
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

/// How far above the level at the edge a curved light over both sides of
/// a sharp step lifts its mid level, gray levels. The step's levels are
/// read a little either side of it; a light whose level curves across the
/// step (a glare streak's skirt, convex beyond its half width) is higher at
/// both reads than at the edge by its curvature times the squared distance
/// over two, and the crossing lies outward. The curvature is the change of
/// slope between the two sides (the canopy's own slope, which
/// [`shaded_points`] takes as a kink at the edge, taken out) over the
/// distance between where the slopes were measured. Only where the dark
/// side slopes beyond its noise ([`CURVED_LIGHT_SIGMAS`]): the disc is flat
/// but for its own shading, so light laid over both sides shows there,
/// while a canopy whose slope differs from the pass's median (its shading
/// seen at another scale round a tilted rim) changes only the light side's.
/// Sharp steps only (the caller's): a blurred step's slopes lie in the
/// blur's tails.
fn curvature_excess(e: &ShadedEdge, canopy: f64) -> f64 {
    if e.relative_dark_slope.abs() <= CURVED_LIGHT_SIGMAS * e.relative_slope_sigma {
        return 0.0;
    }
    // The slopes' windows' centres lie 0.75 px beyond the level reads.
    let span = e.level_distance_px + e.dark_distance_px + 1.5;
    let curvature = (e.relative_slope - canopy - e.relative_dark_slope) / span;
    let reads = e.level_distance_px.powi(2) + e.dark_distance_px.powi(2);
    let excess = curvature * e.contrast * 0.25 * reads;
    if excess.is_finite() { excess } else { 0.0 }
}

/// Standard deviations of its noise beyond which a dark side's slope is
/// light laid over the step ([`curvature_excess`]).
const CURVED_LIGHT_SIGMAS: f64 = 3.0;

/// The canopy's slope beside the pass's steps, relative to their contrast:
/// the median of their light sides' (one ray's, over a few samples, is
/// mostly noise); `None` where fewer than half were measured.
pub(super) fn canopy_slope(edges: &[ShadedEdge]) -> Option<f64> {
    let mut slopes: Vec<f64> = edges
        .iter()
        .map(|e| e.relative_slope)
        .filter(|s| s.is_finite())
        .collect();
    (!slopes.is_empty() && slopes.len() >= edges.len() / 2).then(|| median(&mut slopes))
}

/// The edges whose light side falls toward something dark just beyond the
/// step, by more than the frame's noise allows (`sigmas` of it) below the
/// canopy's slope (the pass's median): an occluder (the probe, the hose)
/// or a strut lies there, so the light level was taken partly on it, the
/// step's mid level is too low and its crossing too far in. The noise is
/// the raw samples': a profile smoothed for a faint step has less, so the
/// test errs toward keeping a step.
pub(super) fn beside_dark(edges: &[ShadedEdge], canopy: Option<f64>, sigmas: f64) -> Vec<bool> {
    let Some(canopy) = canopy else {
        return vec![false; edges.len()];
    };
    // A canopy shaded toward the disc brightens outward: a step whose
    // light side only stays level is no fall.
    let m = canopy.min(0.0);
    edges
        .iter()
        .map(|e| e.own_fall() < m - sigmas * e.own_fall_sigma())
        .collect()
}

/// Each edge's crossing displacement (pixels along its ray, negative
/// inward) from its own fall ([`ShadedEdge::own_fall`]) beyond the canopy's
/// `relative_slope` (the pass's median, which [`shaded_points`] corrects
/// for): the light level, taken a little beyond the step, is below the
/// level at the edge, the mid level too low and the crossing too far in.
/// The same first-order model as [`shaded_points`], at most half the
/// distance to where the level was taken.
fn own_fall_shift_px(e: &ShadedEdge, relative_slope: f64) -> f64 {
    let excess = (e.own_fall() - relative_slope)
        * e.contrast
        * (0.5 * e.level_distance_px - 0.125 * e.width_px);
    let limit = 0.5 * e.level_distance_px.max(0.0);
    if e.ramp_slope > 0.0 && excess.is_finite() {
        (excess / e.ramp_slope).clamp(-limit, limit)
    } else {
        0.0
    }
}

/// Whether the fit of `points` (undistorted pixels, those with `kept` set)
/// to `ellipse` is nearer the truth without the `beside` ones than with
/// them: their displacements ([`own_fall_shift_px`]) move the least-squares
/// ellipse by `g = N^-1 J^T s`, while leaving them out widens its scatter
/// from `sigma_px^2 tr(N^-1)` to that of the points left (`N = J^T J`, `J`
/// each point's distance derivatives). Both in the centre and the axes,
/// pixels squared: left out only when that costs less than the
/// displacement. A probe's outline a few pixels past the rim moves a
/// handful of edges by tenths of a pixel and is left out; a glare streak's
/// falling light over a third of the rim moves its edges by far less than
/// the rest of the rim could place the ellipse without them.
pub(super) fn better_without(
    ellipse: &Ellipse,
    points: &[[f64; 2]],
    edges: &[ShadedEdge],
    kept: &[bool],
    beside: &[bool],
    canopy: f64,
    sigma_px: f64,
) -> bool {
    if !(sigma_px.is_finite() && sigma_px > 0.0) {
        return false;
    }
    let (sin, cos) = ellipse.theta.sin_cos();
    // The normal matrix of all the points and that of the ones beside dark
    // (few): the rest's is the difference. Rank-one updates in place.
    let mut all = Matrix5::<f64>::zeros();
    let mut flagged = Matrix5::<f64>::zeros();
    let mut pull = Vector5::<f64>::zeros();
    // Zipped, not indexed: slices of unequal length end at the shortest.
    for (((p, e), &keep), &dark) in points.iter().zip(edges).zip(kept).zip(beside) {
        if !keep {
            continue;
        }
        let Some((j, normal)) = distance_derivatives(ellipse, sin, cos, *p) else {
            continue;
        };
        all.ger(1.0, &j, &j, 1.0);
        if dark {
            flagged.ger(1.0, &j, &j, 1.0);
            // The ray's direction is the frame's (distorted), the normal
            // the undistorted ellipse's: alike to first order over a rim.
            let along_normal = e.dir[0] * normal[0] + e.dir[1] * normal[1];
            pull += j * (own_fall_shift_px(e, canopy) * along_normal);
        }
    }
    let left = all - flagged;
    let (Some(all_inv), Some(left_inv)) = (all.try_inverse(), left.try_inverse()) else {
        return false;
    };
    let centre_and_axes = |v: &Vector5<f64>| v.rows(0, 4).norm_squared();
    let trace4 = |m: &Matrix5<f64>| (0..4).map(|k| m[(k, k)]).sum::<f64>();
    let shift = all_inv * pull;
    let with = centre_and_axes(&shift) + sigma_px * sigma_px * trace4(&all_inv);
    let without = sigma_px * sigma_px * trace4(&left_inv);
    // The rest's matrix is a difference: one that rounding has left
    // indefinite (nearly every point beside dark) is no rim to keep.
    without.is_finite() && without > 0.0 && without < with
}

/// The derivatives of a point's signed distance to the ellipse (outward
/// positive) by its centre, semi-axes and angle, to first order (the point
/// taken to the curve along the ray from the centre), and the outward
/// normal there (image axes); `None` at the centre.
fn distance_derivatives(
    e: &Ellipse,
    sin: f64,
    cos: f64,
    p: [f64; 2],
) -> Option<(Vector5<f64>, [f64; 2])> {
    let (dx, dy) = (p[0] - e.cx, p[1] - e.cy);
    let (x, y) = (cos * dx + sin * dy, -sin * dx + cos * dy);
    let (ct, st) = (x / e.a, y / e.b);
    // Plain square roots: pixel-sized values, no overflow to guard.
    let r = (ct * ct + st * st).sqrt();
    if r.is_nan() || r <= 0.0 {
        return None;
    }
    let (ct, st) = (ct / r, st / r);
    let (nx, ny) = (ct / e.a, st / e.b);
    let n = (nx * nx + ny * ny).sqrt();
    let (nx, ny) = (nx / n, ny / n);
    let (fx, fy) = (e.a * ct, e.b * st);
    let normal = [cos * nx - sin * ny, sin * nx + cos * ny];
    let j = Vector5::new(
        -normal[0],
        -normal[1],
        -nx * ct,
        -ny * st,
        nx * fy - ny * fx,
    );
    Some((j, normal))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An edge on the ray in direction `dir` at `s` px, 100 gray levels
    /// from dark to light over a 3 px ramp, with these two sides' slopes
    /// (gray levels per pixel outward) and noise of 2 gray levels.
    fn edge(dir: [f64; 2], s: f64, light_slope: f32, dark_slope: f32) -> ShadedEdge {
        let e = rim::RayEdge {
            s,
            dark: 30.0,
            light: 130.0,
            light_s: s + 1.5,
            dark_s: s - 1.5,
            ramp_slope: 50.0,
            clipped: false,
        };
        ShadedEdge::new(dir, &e, [light_slope, dark_slope], 2.0)
    }

    /// Something dark beyond the step pulls its light side down alone; a
    /// light added over both sides slopes them alike; a canopy shaded
    /// toward the disc brightens outward. Only the first is beside dark.
    #[test]
    fn only_a_light_side_falling_alone_is_beside_dark() {
        let mut edges: Vec<ShadedEdge> =
            (0..12).map(|_| edge([1.0, 0.0], 40.0, 3.0, 0.0)).collect();
        edges.push(edge([1.0, 0.0], 40.0, -40.0, 0.0));
        edges.push(edge([1.0, 0.0], 40.0, -40.0, -40.0));
        edges.push(edge([1.0, 0.0], 40.0, 12.0, 0.0));
        // Noise alone: 3 sigmas of the difference of two slopes.
        let sigma = std::f64::consts::SQRT_2 * 2.0 * rim::SLOPE_NOISE_PER_GRAY;
        edges.push(edge([1.0, 0.0], 40.0, (-2.5 * sigma) as f32, 0.0));
        let beside = beside_dark(&edges, canopy_slope(&edges), 3.0);
        assert_eq!(beside[..12], [false; 12]);
        assert_eq!(beside[12..], [true, false, false, false]);
    }

    /// A circle of 40 px, 200 edges with noise of 0.1 px. A probe's
    /// outline beside ten of them moves each in by over half a pixel: the
    /// rim is better without them. A glare's skirt over a third of the rim
    /// moves each in by 0.025 px: the ellipse moves less than the rest of
    /// the rim would place it without them, and they stay.
    #[test]
    fn edges_are_left_out_only_where_that_moves_the_ellipse_less() {
        let circle = Ellipse::new(100.0, 80.0, 40.0, 40.0, 0.0);
        let n = 200;
        let dirs: Vec<[f64; 2]> = (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                [t.cos(), t.sin()]
            })
            .collect();
        let points: Vec<[f64; 2]> = dirs
            .iter()
            .map(|d| [circle.cx + 40.0 * d[0], circle.cy + 40.0 * d[1]])
            .collect();
        let kept = vec![true; n];
        // A fall of 0.5 (contrast) per pixel on the light side: 0.625 px in.
        let with_falls = |beside: &[bool], fall: f32| -> Vec<ShadedEdge> {
            dirs.iter()
                .zip(beside)
                .map(|(&d, &b)| edge(d, 40.0, if b { -100.0 * fall } else { 0.0 }, 0.0))
                .collect()
        };
        let probe: Vec<bool> = (0..n).map(|k| (20..30).contains(&k)).collect();
        let edges = with_falls(&probe, 0.5);
        assert!((own_fall_shift_px(&edges[25], 0.0) + 0.625).abs() < 1e-9);
        assert!(better_without(
            &circle, &points, &edges, &kept, &probe, 0.0, 0.1
        ));

        let glare: Vec<bool> = (0..n).map(|k| k < n / 3).collect();
        let edges = with_falls(&glare, 0.02);
        assert!((own_fall_shift_px(&edges[5], 0.0) + 0.025).abs() < 1e-9);
        assert!(!better_without(
            &circle, &points, &edges, &kept, &glare, 0.0, 0.1
        ));
        // The same skirt moving its edges in by as much as the probe's.
        let edges = with_falls(&glare, 0.5);
        assert!(better_without(
            &circle, &points, &edges, &kept, &glare, 0.0, 0.1
        ));
    }
}
