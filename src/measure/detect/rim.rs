//! Sub-pixel edges along rays from a candidate centre, at full resolution.
//!
//! The rim of the dark disc is a dark-to-light step seen outward. Along a ray,
//! the step is located at its strongest rise; its position is where the
//! profile crosses the middle between the dark level just inside and the
//! light level just outside. Both levels are measured locally, on that ray,
//! because the disc may be shaded and the canopy has struts: the mid-level
//! crossing of an anti-aliased, blurred step is the edge for any symmetric blur.

use image::GrayImage;

/// Bilinear sample at (u, v) in pixel-centre coordinates; `None` outside the
/// image (no extrapolation).
#[inline]
pub fn sample(img: &GrayImage, u: f64, v: f64) -> Option<f32> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 2 || h < 2 || !(u >= 0.0 && v >= 0.0 && u <= (w - 1) as f64 && v <= (h - 1) as f64) {
        return None;
    }
    // Truncation is floor here: u, v >= 0. Through `u32` (the image's
    // sides are): a cheaper saturating conversion than to `usize`.
    let x0 = (u as u32 as usize).min(w - 2);
    let y0 = (v as u32 as usize).min(h - 2);
    let raw = img.as_raw();
    let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
    let i = y0 * w + x0;
    // One bounds check for the four pixels.
    let quad = &raw[i..i + w + 2];
    let (p00, p10) = (f32::from(quad[0]), f32::from(quad[1]));
    let (p01, p11) = (f32::from(quad[w]), f32::from(quad[w + 1]));
    let top = p00 + fx * (p10 - p00);
    let bottom = p01 + fx * (p11 - p01);
    Some(top + fy * (bottom - top))
}

/// Images up to this size (either side) are sampled in fixed point.
const FIXED_MAX_SIDE: usize = 1 << 24;
/// 1.0 in the 32.32 fixed point of the ray sampler.
const FIXED_ONE: f64 = 4_294_967_296.0;

/// One rim edge found on a ray.
#[derive(Clone, Copy, Debug)]
pub struct RayEdge {
    /// Distance of the edge from the ray's origin, pixels.
    pub s: f64,
    /// Local levels inside and outside the edge, gray levels.
    pub dark: f32,
    /// Local level outside the edge, gray levels.
    pub light: f32,
    /// Distance from the ray's origin where the light level begins (the
    /// step's outer end), pixels.
    pub light_s: f64,
    /// Distance from the ray's origin where the dark level ends (the step's
    /// inner end), pixels.
    pub dark_s: f64,
    /// Slope of the profile where it crosses the mid level, gray levels per
    /// pixel.
    pub ramp_slope: f32,
    /// The step runs into the profile's first or last samples: its levels
    /// are not those of the surfaces on either side (a blurred edge wider
    /// than the profile).
    pub clipped: bool,
}

/// Samples the profile along a ray from `origin` in direction `dir` (unit),
/// distances `s_min..=s_max` in steps of `step`. Stops at the image border.
pub fn profile(
    img: &GrayImage,
    origin: [f64; 2],
    dir: [f64; 2],
    s_min: f64,
    s_max: f64,
    step: f64,
    out: &mut Vec<f32>,
) {
    out.clear();
    // Saturating: a range too long for a usize (a rim projected from a pose
    // far off, found by the image_measure fuzz target) is the samples up to
    // the border, never an overflow.
    let n = (((s_max - s_min) / step).floor().max(0.0) as usize).saturating_add(1);
    let at = |k: usize| {
        let s = s_min + k as f64 * step;
        (origin[0] + s * dir[0], origin[1] + s * dir[1])
    };
    let (w, h) = (img.width() as usize, img.height() as usize);
    let within =
        |(u, v): (f64, f64)| u >= 0.0 && v >= 0.0 && u <= (w - 1) as f64 && v <= (h - 1) as f64;
    if !((2..FIXED_MAX_SIDE).contains(&w) && (2..FIXED_MAX_SIDE).contains(&h)) {
        for k in 0..n {
            let (u, v) = at(k);
            match sample(img, u, v) {
                Some(v) => out.push(v),
                None => break,
            }
        }
        return;
    }
    // The samples inside the image are the ray's first ones (the image is
    // convex): a ray that leaves it (a seed near the border) is sampled up
    // to its last inside sample, as fast as one that does not.
    let n = inside_prefix(n, |k| within(at(k)));
    if n == 0 {
        return;
    }
    // No checks per sample. Fixed point: positions with 32 fractional bits
    // stepped by an increment (a sample's position is off by at most
    // n * 2^-33 pixels), bilinear weights of 8 bits (a position rounded to
    // the nearest 1/256 pixel), integer interpolation, exact in f32.
    let raw = img.as_raw();
    let first = at(0);
    // Truncated (no libm call): off by less than 2^-32 pixels.
    let fixed = |x: f64| (x * FIXED_ONE) as i64;
    let (u, v) = (fixed(first.0), fixed(first.1));
    let (du, dv) = (fixed(step * dir[0]), fixed(step * dir[1]));
    // Positions clamped to just below the last column and row (rounding may
    // put the last one a hair outside the image): the pixel then is at most
    // the second last, and its weight towards the last is 256/256.
    let (u_max, v_max) = (((w as i64 - 1) << 32) - 1, ((h as i64 - 1) << 32) - 1);
    out.resize(n, 0.0);
    // Positions are linear in k: when the first and the last are within the
    // clamp range, all are, and the loop needs no clamps.
    let last = n as i64 - 1;
    let (u_last, v_last) = (u + last * du, v + last * dv);
    let filled = if [u, u_last].iter().all(|x| (0..=u_max).contains(x))
        && [v, v_last].iter().all(|y| (0..=v_max).contains(y))
    {
        fill_fixed(raw, w, out, (u, v), (du, dv), |x| x, |y| y)
    } else {
        fill_fixed(
            raw,
            w,
            out,
            (u, v),
            (du, dv),
            |x| x.clamp(0, u_max),
            |y| y.clamp(0, v_max),
        )
    };
    out.truncate(filled);
}

/// Fills `out` with the fixed-point bilinear samples from `start` by `step`
/// (32.32 pixel positions, each passed through `clamp_u` and `clamp_v`);
/// returns how many were filled (all, as the clamps keep every pixel's quad
/// in the image).
#[inline(always)]
fn fill_fixed(
    raw: &[u8],
    w: usize,
    out: &mut [f32],
    start: (i64, i64),
    step: (i64, i64),
    clamp_u: impl Fn(i64) -> i64,
    clamp_v: impl Fn(i64) -> i64,
) -> usize {
    let ((mut u, mut v), (du, dv)) = (start, step);
    for (k, sample) in out.iter_mut().enumerate() {
        let (uc, vc) = (clamp_u(u), clamp_v(v));
        let (x0, y0) = ((uc >> 32) as usize, (vc >> 32) as usize);
        // Weights rounded to the nearest 1/256 (no bias): 0..=256.
        let fx = (((uc & 0xffff_ffff) + (1 << 23)) >> 24) as i32;
        let fy = (((vc & 0xffff_ffff) + (1 << 23)) >> 24) as i32;
        let i = y0 * w + x0;
        let Some(quad) = raw.get(i..i + w + 2) else {
            return k;
        };
        let (p00, p10) = (i32::from(quad[0]), i32::from(quad[1]));
        let (p01, p11) = (i32::from(quad[w]), i32::from(quad[w + 1]));
        let top = (p00 << 8) + fx * (p10 - p00);
        let bottom = (p01 << 8) + fx * (p11 - p01);
        let value = (top << 8) + fy * (bottom - top);
        *sample = value as f32 * (1.0 / 65536.0);
        u += du;
        v += dv;
    }
    out.len()
}

/// How many of the samples `0..n` pass `inside`, given that those that do
/// come first (a bisection: `inside` is true up to some sample, then false).
fn inside_prefix(n: usize, inside: impl Fn(usize) -> bool) -> usize {
    if n == 0 || !inside(0) {
        return 0;
    }
    if inside(n - 1) {
        return n;
    }
    // inside(lo) and !inside(hi).
    let (mut lo, mut hi) = (0, n - 1);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if inside(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo + 1
}

/// The image noise's standard deviation, gray levels: the median absolute
/// second difference along every `row_stride`th row, scaled to the
/// deviation of white noise (a second difference of it has variance
/// `6 sigma^2`; 1.4826 turns a median absolute value into a deviation).
/// Second differences ignore the sky's gradients and vignetting; the median
/// ignores the few edges a row crosses. Saturated pixels are left out.
pub fn noise_sigma(img: &GrayImage, row_stride: usize) -> f64 {
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 3 || h == 0 || row_stride == 0 {
        return 0.0;
    }
    let raw = img.as_raw();
    // Histogram of |d2| (0..=510): the median without sorting. Windows with
    // a saturated pixel go to the extra bin 511, which is not counted. Each
    // row's bins are computed first, in a loop free of dependencies that
    // the compiler vectorises, then counted.
    const LEFT_OUT: u16 = 511;
    let saturated = |v: u8| v.wrapping_sub(1) >= 254;
    let mut counts = [0u32; LEFT_OUT as usize + 1];
    let mut bins = vec![0u16; w - 2];
    for y in (row_stride / 2..h).step_by(row_stride) {
        let row = &raw[y * w..(y + 1) * w];
        let (left, mid, right) = (&row[..w - 2], &row[1..w - 1], &row[2..]);
        for (((bin, &a), &b), &c) in bins.iter_mut().zip(left).zip(mid).zip(right) {
            let d2 = (i16::from(a) - 2 * i16::from(b) + i16::from(c)).unsigned_abs();
            *bin = if saturated(a) | saturated(b) | saturated(c) {
                LEFT_OUT
            } else {
                d2
            };
        }
        for &bin in &bins {
            // The mask (a no-op) spares the bounds test.
            counts[usize::from(bin & LEFT_OUT)] += 1;
        }
    }
    let counts = &counts[..usize::from(LEFT_OUT)];
    let total: u64 = counts.iter().map(|&c| u64::from(c)).sum();
    if total == 0 {
        return 0.0;
    }
    let half = total.div_ceil(2);
    let mut seen = 0u64;
    let median = counts
        .iter()
        .position(|&c| {
            seen += u64::from(c);
            seen >= half
        })
        .unwrap_or(0);
    1.4826 * median as f64 / 6f64.sqrt()
}

/// Smooths a profile in place with a box of `2 * half + 1` samples applied
/// twice (a triangle-like kernel of variance `half * (half + 1) / 3`
/// samples squared), the ends held at their values. A symmetric kernel
/// leaves a step's mid-level crossing where it is, and keeps the noise of
/// single samples from deciding where a wide (blurred) step's strongest rise
/// and its ends are. `scratch` is reused between calls.
pub fn smooth(p: &mut [f32], half: usize, scratch: &mut Vec<f32>) {
    let n = p.len();
    if half == 0 || n < 2 {
        return;
    }
    let window = 2 * half + 1;
    let width = window as f32;
    for _ in 0..2 {
        // The profile with its ends held `half` samples before and
        // `half + 1` after: the window slides with no clamp per sample.
        scratch.clear();
        scratch.resize(half, p[0]);
        scratch.extend_from_slice(p);
        scratch.resize(n + 2 * half + 1, p[n - 1]);
        let mut sum: f32 = scratch[..window].iter().sum();
        for ((out, &enter), &leave) in p.iter_mut().zip(&scratch[window..]).zip(&scratch[..]) {
            *out = sum / width;
            sum += enter - leave;
        }
    }
}

/// The upward crossing of `level` in profile `p` (sampled from `s_min`
/// every `step`) nearest to `near`, within `reach` of it; `None` when there
/// is none. A step located on a smoothed profile is placed where the raw
/// profile crosses its mid level: smoothing makes a sharp step shallow, and
/// a shallow step's crossing moves with any error of its levels.
pub fn crossing_near(
    p: &[f32],
    s_min: f64,
    step: f64,
    level: f32,
    near: f64,
    reach: f64,
) -> Option<f64> {
    p.windows(2)
        .enumerate()
        .filter(|(_, w)| w[0] < level && w[1] >= level)
        .map(|(j, w)| s_min + (j as f64 + f64::from((level - w[0]) / (w[1] - w[0]))) * step)
        .filter(|s| (s - near).abs() <= reach)
        .min_by(|x, y| (x - near).abs().total_cmp(&(y - near).abs()))
}

/// How much wider [`strongest_rise`] finds a sharp step on a profile
/// sampled every `step` px after [`smooth`] with `half`, than without:
/// measured on an ideal step, so that a rim's width can be told apart from
/// the smoothing's.
pub fn smoothing_spread_px(half: usize, step: f64) -> f64 {
    let width = |half: usize| {
        let mut p: Vec<f32> = (0..200)
            .map(|k| if k < 100 { 40.0 } else { 200.0 })
            .collect();
        smooth(&mut p, half, &mut Vec::new());
        strongest_rise(&p, 0.0, step, 1.0).map_or(0.0, |e| 2.0 * (e.light_s - e.s))
    };
    (width(half) - width(0)).max(0.0)
}

/// Samples beyond a step's light end that [`light_side_slope`] fits.
pub const SLOPE_SAMPLES: usize = 6;

/// Standard deviation of [`light_side_slope`] (gray levels per pixel) per
/// gray level of the samples' noise: a least-squares line's slope over
/// [`SLOPE_SAMPLES`] samples half a pixel apart, `1 / (0.5 sqrt(sum dx^2))`
/// with `sum dx^2 = 17.5` samples squared.
pub const SLOPE_NOISE_PER_GRAY: f64 = 0.478_091_443_733_757;

/// Slope of the light side beyond step `e` of profile `p` (sampled from
/// `s_min` every `step` px, the profile `e` was found on), gray levels per
/// pixel outward: the least-squares line through the [`SLOPE_SAMPLES`]
/// samples from `e.light_s`; NaN where the profile ends sooner.
pub fn light_side_slope(p: &[f32], s_min: f64, step: f64, e: &RayEdge) -> f32 {
    let from = ((e.light_s - s_min) / step).round().max(0.0) as usize;
    line_slope(p, from, step)
}

/// Slope of the dark side before step `e` of profile `p`, as
/// [`light_side_slope`] beyond it: the [`SLOPE_SAMPLES`] samples that end
/// where its dark level ends; NaN where the profile starts later.
pub fn dark_side_slope(p: &[f32], s_min: f64, step: f64, e: &RayEdge) -> f32 {
    let dark_end = ((e.dark_s - s_min) / step).round();
    let from = dark_end - (SLOPE_SAMPLES - 1) as f64;
    if from.is_nan() || from < 0.0 {
        return f32::NAN;
    }
    line_slope(p, from as usize, step)
}

/// The least-squares line's slope through [`SLOPE_SAMPLES`] samples of `p`
/// from `from` (gray levels per pixel, samples `step` px apart); NaN where
/// `p` ends sooner.
fn line_slope(p: &[f32], from: usize, step: f64) -> f32 {
    let Some(window) = p.get(from..from.saturating_add(SLOPE_SAMPLES)) else {
        return f32::NAN;
    };
    let mean_x = 0.5 * (SLOPE_SAMPLES - 1) as f32;
    let mean_y = window.iter().sum::<f32>() / SLOPE_SAMPLES as f32;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, &v) in window.iter().enumerate() {
        let dx = k as f32 - mean_x;
        sxy += dx * (v - mean_y);
        sxx += dx * dx;
    }
    sxy / sxx / step as f32
}

/// The strongest dark-to-light step (outward) of a profile sampled from
/// `s_min` with spacing `step`, located sub-pixel at its mid-level crossing.
/// `None` when no rise reaches `min_contrast` gray levels.
pub fn strongest_rise(p: &[f32], s_min: f64, step: f64, min_contrast: f32) -> Option<RayEdge> {
    let n = p.len();
    if n < 5 {
        return None;
    }
    // Central differences; the strongest rise.
    let d = |k: usize| p[k + 1] - p[k - 1];
    let (mut k_best, mut d_best) = (0usize, 0.0f32);
    for k in 1..n - 1 {
        let dk = d(k);
        if dk > d_best {
            d_best = dk;
            k_best = k;
        }
    }
    if k_best == 0 {
        return None;
    }
    // Extent of the step: where the rise fades below a fifth of its peak.
    let fade = 0.2 * d_best;
    let mut kl = k_best;
    while kl > 1 && d(kl - 1) > fade {
        kl -= 1;
    }
    let mut kr = k_best;
    while kr + 2 < n && d(kr + 1) > fade {
        kr += 1;
    }
    // Levels: a few samples beyond each end of the step.
    let dark_end = kl.saturating_sub(1);
    let dark_start = dark_end.saturating_sub(2);
    let light_start = (kr + 1).min(n - 1);
    let light_end = (light_start + 2).min(n - 1);
    let mean = |a: usize, b: usize| p[a..=b].iter().sum::<f32>() / (b - a + 1) as f32;
    let dark = mean(dark_start, dark_end);
    let light = mean(light_start, light_end);
    if light - dark < min_contrast {
        return None;
    }
    let mid = 0.5 * (dark + light);
    // The crossing of the mid level nearest to the peak, within the step.
    let lo = dark_end;
    let hi = light_start;
    let mut best: Option<(f64, usize)> = None;
    for j in lo..hi {
        let (a, b) = (p[j], p[j + 1]);
        if a < mid && b >= mid {
            let t = f64::from((mid - a) / (b - a));
            let pos = j as f64 + t;
            let dist = (pos - k_best as f64).abs();
            if best.is_none_or(|(bd, _)| dist < bd) {
                best = Some((dist, j));
            }
        }
    }
    let (_, j) = best?;
    let (a, b) = (p[j], p[j + 1]);
    let t = f64::from((mid - a) / (b - a));
    Some(RayEdge {
        s: s_min + (j as f64 + t) * step,
        dark,
        light,
        light_s: s_min + light_start as f64 * step,
        dark_s: s_min + dark_end as f64 * step,
        ramp_slope: (b - a) / step as f32,
        clipped: kl <= 1 || kr + 2 >= n,
    })
}

#[cfg(test)]
mod tests {
    /// A range too long to count in a usize (the `image_measure` fuzz
    /// target's crash: an overflow panic where overflow is checked, and an
    /// empty profile where it wraps) gives the samples up to the border.
    #[test]
    fn a_range_too_long_to_count_is_sampled_up_to_the_border() {
        let img = GrayImage::from_fn(64, 48, |x, _| image::Luma([x as u8]));
        let mut out = Vec::new();
        profile(&img, [10.0, 20.0], [1.0, 0.0], 0.0, 1e300, 0.5, &mut out);
        // From u = 10 to the last column, u = 63, in half pixels.
        assert_eq!(out.len(), 2 * 53 + 1);
        assert_eq!((out[0], out[out.len() - 1]), (10.0, 63.0));
    }

    use super::*;

    #[test]
    fn mid_level_crossing_of_a_ramp() {
        // Dark 20 up to s = 10, linear ramp to 200 at s = 12, light after:
        // the middle (110) is crossed at s = 11.
        let step = 0.5;
        let p: Vec<f32> = (0..60)
            .map(|k| {
                let s = k as f64 * step;
                (20.0 + 180.0 * ((s - 10.0) / 2.0).clamp(0.0, 1.0)) as f32
            })
            .collect();
        let e = strongest_rise(&p, 0.0, step, 30.0).unwrap();
        assert!((e.s - 11.0).abs() < 1e-6, "{e:?}");
        assert!((e.dark - 20.0).abs() < 1e-3 && (e.light - 200.0).abs() < 1e-3);
    }

    #[test]
    fn noise_sigma_of_white_noise_on_a_gradient() {
        // Gaussian noise of known deviation on a vignetted gradient: the
        // estimate is within 10 % (the gradient does not count).
        use rand::{Rng, SeedableRng};
        for sigma in [2.0, 5.0, 10.0] {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
            // Box-Muller.
            let mut gauss = || {
                let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
                (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
            };
            let img = GrayImage::from_fn(640, 480, |x, y| {
                let base = 60.0 + 0.15 * f64::from(x) + 0.1 * f64::from(y);
                image::Luma([(base + sigma * gauss()).round().clamp(1.0, 254.0) as u8])
            });
            // Every 16th row (the full search's) and every 64th (a tracked
            // frame's: 7 rows here).
            for stride in [16, 64] {
                let est = noise_sigma(&img, stride);
                assert!(
                    (est / sigma - 1.0).abs() < 0.1,
                    "sigma {sigma}, stride {stride}: {est}"
                );
            }
        }
        assert_eq!(noise_sigma(&GrayImage::new(2, 2), 16), 0.0);
        assert_eq!(noise_sigma(&GrayImage::new(8, 8), 0), 0.0);
    }

    #[test]
    fn smoothing_keeps_a_ramps_mid_level_crossing() {
        let step = 0.5;
        let p: Vec<f32> = (0..80)
            .map(|k| {
                let s = k as f64 * step;
                (20.0 + 180.0 * ((s - 15.0) / 8.0).clamp(0.0, 1.0)) as f32
            })
            .collect();
        let mut q = p.clone();
        smooth(&mut q, 3, &mut Vec::new());
        let e = strongest_rise(&q, 0.0, step, 30.0).unwrap();
        assert!((e.s - 19.0).abs() < 1e-3, "{e:?}");
    }

    #[test]
    fn smoothing_spread_grows_with_the_kernel() {
        assert_eq!(smoothing_spread_px(0, 0.5), 0.0);
        let spreads: Vec<f64> = (1..=4).map(|h| smoothing_spread_px(h, 0.5)).collect();
        // The kernel's half-support is h px; the step's ends lie within it.
        for (h, w) in (1..=4).zip(&spreads) {
            assert!(*w > 0.5 * h as f64 && *w < 4.0 * h as f64, "h {h}: {w}");
        }
        assert!(spreads.windows(2).all(|p| p[1] > p[0]), "{spreads:?}");
    }

    #[test]
    fn crossing_near_picks_the_nearest_upward_crossing() {
        // Up at 2.5 and 7.5 (samples 1 apart), down at 5.5.
        let p = [0.0f32, 0.0, 0.0, 10.0, 10.0, 10.0, 0.0, 0.0, 10.0, 10.0];
        assert_eq!(crossing_near(&p, 0.0, 1.0, 5.0, 3.0, 2.0), Some(2.5));
        assert_eq!(crossing_near(&p, 0.0, 1.0, 5.0, 6.5, 2.0), Some(7.5));
        assert_eq!(crossing_near(&p, 10.0, 0.5, 5.0, 11.0, 1.0), Some(11.25));
        assert_eq!(crossing_near(&p, 0.0, 1.0, 5.0, 5.0, 1.0), None);
    }

    #[test]
    fn flat_profile_has_no_edge() {
        let p = vec![100.0f32; 40];
        assert!(strongest_rise(&p, 0.0, 0.5, 10.0).is_none());
    }

    #[test]
    fn ray_profile_is_the_bilinear_sample_of_each_position() {
        // Fixed-point profile vs the f64 bilinear `sample` at the same
        // positions: positions quantised to 1/256 pixel move a sample by at
        // most 255 / 256 gray levels (the steepest bilinear slope is 255
        // per pixel along each axis, half a quantum each way).
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let img = GrayImage::from_fn(97, 61, |_, _| image::Luma([rng.random::<u8>()]));
        let mut out = Vec::new();
        for k in 0..200 {
            // Some rays start outside the image (they have no samples).
            let origin = if k % 10 == 9 {
                [rng.random_range(-20.0..116.0), rng.random_range(-20.0..0.0)]
            } else {
                [rng.random_range(0.0..96.0), rng.random_range(0.0..60.0)]
            };
            let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let dir = [phi.cos(), phi.sin()];
            let (s_min, step) = (rng.random_range(0.0..3.0), rng.random_range(0.3..2.0));
            // Up to the border exactly on some rays.
            let to_border = |o: f64, d: f64, hi: f64| {
                if d > 1e-9 {
                    (hi - o) / d
                } else if d < -1e-9 {
                    -o / d
                } else {
                    f64::INFINITY
                }
            };
            let s_border =
                to_border(origin[0], dir[0], 96.0).min(to_border(origin[1], dir[1], 60.0));
            let s_max = if k % 2 == 0 {
                s_border
            } else {
                s_min + rng.random_range(0.0..40.0)
            };
            profile(&img, origin, dir, s_min, s_max, step, &mut out);
            let n = ((s_max - s_min) / step).floor().max(0.0) as usize + 1;
            let expected: Vec<f32> = (0..n)
                .map_while(|j| {
                    let s = s_min + j as f64 * step;
                    sample(&img, origin[0] + s * dir[0], origin[1] + s * dir[1])
                })
                .collect();
            // The same samples: up to the border, exactly (rays that leave
            // the image, end on its border or start outside it).
            assert_eq!(out.len(), expected.len(), "ray {k}");
            assert!(!out.is_empty() || expected.len() <= 1, "ray {k}");
            for (j, (a, b)) in out.iter().zip(&expected).enumerate() {
                assert!(
                    (a - b).abs() <= 1.0 + 1e-3,
                    "ray {k} sample {j}: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn sampling_is_bilinear_and_stops_at_the_border() {
        let img = GrayImage::from_fn(4, 3, |x, _| image::Luma([(x * 10) as u8]));
        assert_eq!(sample(&img, 1.5, 1.0), Some(15.0));
        assert_eq!(sample(&img, 3.0, 2.0), Some(30.0));
        assert_eq!(sample(&img, 3.2, 1.0), None);
        assert_eq!(sample(&img, -0.1, 1.0), None);
        assert_eq!(sample(&img, f64::NAN, 1.0), None);
    }

    /// A step between two sloping sides, sampled every half pixel: the
    /// dark side rises 2 gray levels a pixel up to the step, the light side
    /// falls 3 a pixel beyond it; each side's slope is read outside the
    /// step's ramp, where its levels were taken.
    #[test]
    fn each_sides_slope_is_read_beyond_the_step() {
        let step = 0.5;
        let edge = 20.0;
        let p: Vec<f32> = (0..80)
            .map(|k| {
                let s = k as f64 * step;
                let level = if s < edge {
                    40.0 + 2.0 * s
                } else {
                    200.0 - 3.0 * (s - edge)
                };
                level as f32
            })
            .collect();
        let e = strongest_rise(&p, 0.0, step, 10.0).expect("a step");
        assert!(e.dark_s < e.s && e.s < e.light_s, "{e:?}");
        assert!((dark_side_slope(&p, 0.0, step, &e) - 2.0).abs() < 1e-4);
        assert!((light_side_slope(&p, 0.0, step, &e) + 3.0).abs() < 1e-4);
        // No samples that far in: not measured.
        assert!(
            dark_side_slope(
                &p[38..],
                0.0,
                step,
                &strongest_rise(&p[38..], 0.0, step, 10.0).unwrap()
            )
            .is_nan()
        );
    }

    /// The slope's noise per gray level of the samples' noise: white
    /// noise of deviation 1 under 20,000 lines.
    #[test]
    fn the_slopes_noise_is_the_lines() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let draws = 20_000;
        let mut sum_sq = 0.0;
        for _ in 0..draws {
            let p: Vec<f32> = (0..SLOPE_SAMPLES)
                .map(|_| {
                    let (r1, r2): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
                    ((-2.0 * r1.ln()).sqrt() * (std::f64::consts::TAU * r2).cos()) as f32
                })
                .collect();
            sum_sq += f64::from(line_slope(&p, 0, 0.5)).powi(2);
        }
        let sigma = (sum_sq / f64::from(draws)).sqrt();
        assert!(
            (sigma / SLOPE_NOISE_PER_GRAY - 1.0).abs() < 0.02,
            "{sigma} per gray level"
        );
    }
}
