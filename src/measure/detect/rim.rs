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
    // Truncation is floor here: u, v >= 0.
    let x0 = (u as usize).min(w - 2);
    let y0 = (v as usize).min(h - 2);
    let raw = img.as_raw();
    let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
    let i = y0 * w + x0;
    let (p00, p10) = (f32::from(raw[i]), f32::from(raw[i + 1]));
    let (p01, p11) = (f32::from(raw[i + w]), f32::from(raw[i + w + 1]));
    let top = p00 + fx * (p10 - p00);
    let bottom = p01 + fx * (p11 - p01);
    Some(top + fy * (bottom - top))
}

/// One rim edge found on a ray.
#[derive(Clone, Copy, Debug)]
pub struct RayEdge {
    /// Distance of the edge from the ray's origin, pixels.
    pub s: f64,
    /// Local levels inside and outside the edge, gray levels.
    pub dark: f32,
    pub light: f32,
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
    let n = ((s_max - s_min) / step).floor().max(0.0) as usize + 1;
    let at = |k: usize| {
        let s = s_min + k as f64 * step;
        (origin[0] + s * dir[0], origin[1] + s * dir[1])
    };
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (first, last) = (at(0), at(n - 1));
    let within =
        |(u, v): (f64, f64)| u >= 0.0 && v >= 0.0 && u <= (w - 1) as f64 && v <= (h - 1) as f64;
    if w >= 2 && h >= 2 && within(first) && within(last) {
        // The segment lies inside the image (it is convex): no checks per
        // sample, same arithmetic as `sample`.
        // Signed integer conversions: cheaper than unsigned ones on x86-64
        // and exact here (0 <= u, v < 2^31; truncation is floor).
        let raw = img.as_raw();
        let (x_max, y_max) = (w as i64 - 2, h as i64 - 2);
        out.extend((0..n).map(|k| {
            let (u, v) = at(k);
            let x0 = (u as i64).min(x_max);
            let y0 = (v as i64).min(y_max);
            let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
            let i = y0 as usize * w + x0 as usize;
            let (top_row, bottom_row) = (&raw[i..i + 2], &raw[i + w..i + w + 2]);
            let (p00, p10) = (f32::from(top_row[0]), f32::from(top_row[1]));
            let (p01, p11) = (f32::from(bottom_row[0]), f32::from(bottom_row[1]));
            let top = p00 + fx * (p10 - p00);
            let bottom = p01 + fx * (p11 - p01);
            top + fy * (bottom - top)
        }));
        return;
    }
    for k in 0..n {
        let s = s_min + k as f64 * step;
        match sample(img, origin[0] + s * dir[0], origin[1] + s * dir[1]) {
            Some(v) => out.push(v),
            None => break,
        }
    }
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
    })
}

/// Whether the profile beyond the rim shows the canopy's darker outer rim
/// band: a dip below the light levels on both of its sides by at least
/// `min_dip` gray levels. `p` is sampled from the inner end of the canopy
/// outward; `max_width` (samples) bounds the dip's width so that the edge
/// of a wide dark cloud is not taken for a band.
pub fn has_outer_band(p: &[f32], min_dip: f32, max_width: usize) -> bool {
    let n = p.len();
    if n < 5 {
        return false;
    }
    let (k_min, v_min) =
        p.iter().enumerate().fold(
            (0, f32::MAX),
            |(kb, vb), (k, &v)| if v < vb { (k, v) } else { (kb, vb) },
        );
    if k_min == 0 || k_min + 1 >= n {
        return false;
    }
    let left_lo = k_min.saturating_sub(max_width);
    let right_hi = (k_min + max_width).min(n - 1);
    let left = p[left_lo..k_min].iter().copied().fold(f32::MIN, f32::max);
    let right = p[k_min + 1..=right_hi]
        .iter()
        .copied()
        .fold(f32::MIN, f32::max);
    left.min(right) - v_min >= min_dip
}

#[cfg(test)]
mod tests {
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
    fn flat_profile_has_no_edge() {
        let p = vec![100.0f32; 40];
        assert!(strongest_rise(&p, 0.0, 0.5, 10.0).is_none());
    }

    #[test]
    fn band_is_found_and_a_cloud_edge_is_not() {
        let mut band = vec![180.0f32; 40];
        band[20..23].iter_mut().for_each(|v| *v = 90.0);
        assert!(has_outer_band(&band, 30.0, 8));
        let edge: Vec<f32> = (0..40).map(|k| if k < 20 { 180.0 } else { 90.0 }).collect();
        assert!(!has_outer_band(&edge, 30.0, 8));
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
}
