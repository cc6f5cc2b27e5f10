//! From radiance to 8-bit pixels: motion blur during the exposure, the
//! glare streak, vignetting, gain, shot and read noise, quantisation. The
//! sensor loop is branch-free so it vectorises.

use super::sky::{add_lerp_columns, sky_row};
use super::{FrameScene, GRID, GlareGlow, GlareStreak, PixelBox, Renderer};
use image::GrayImage;

/// Inverse normal CDF (Acklam's rational approximation, |error| < 1.2e-9).
pub(super) fn inv_normal(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let pl = 0.02425;
    if p < pl {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - pl {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -inv_normal(1.0 - p)
    }
}

/// Adds the glare streak's light to image row `v` (gain applied).
pub(super) fn add_streak(row: &mut [f32], v: usize, s: &GlareStreak, gain: f32) {
    let finite = [s.through_px[0], s.through_px[1], s.angle_rad, s.strength]
        .iter()
        .all(|x| x.is_finite());
    if !(finite && s.width_px > 0.0 && s.width_px.is_finite()) {
        return;
    }
    let sigma = s.width_px / (8.0 * std::f64::consts::LN_2).sqrt();
    let reach = 4.0 * sigma;
    let (sn, cs) = s.angle_rad.sin_cos();
    // Signed distance of pixel u of this row to the centre line: a u + b.
    let a = -sn;
    let b = s.through_px[0] * sn + (v as f64 - s.through_px[1]) * cs;
    let last = row.len().saturating_sub(1) as f64;
    let (lo, hi) = if a.abs() < 1e-12 {
        if b.abs() > reach {
            return;
        }
        (0.0, last)
    } else {
        let (x0, x1) = ((-reach - b) / a, (reach - b) / a);
        (x0.min(x1).max(0.0).ceil(), x0.max(x1).min(last).floor())
    };
    if lo > hi {
        return;
    }
    let first = lo as usize;
    for (k, r) in row[first..=hi as usize].iter_mut().enumerate() {
        let d = (a * (first + k) as f64 + b) / sigma;
        *r += (s.strength * (-0.5 * d * d).exp()) as f32 * gain;
    }
}

/// Adds the glare glow's light to image row `v` (gain applied), out to
/// four standard deviations from its centre.
pub(super) fn add_glow(row: &mut [f32], v: usize, g: &GlareGlow, gain: f32) {
    let finite = [g.centre_px[0], g.centre_px[1], g.strength]
        .iter()
        .all(|x| x.is_finite());
    if !(finite && g.sigma_px > 0.0 && g.sigma_px.is_finite()) {
        return;
    }
    let reach = 4.0 * g.sigma_px;
    let dv = v as f64 - g.centre_px[1];
    if dv.abs() > reach {
        return;
    }
    let half = (reach * reach - dv * dv).sqrt();
    let last = row.len().saturating_sub(1) as f64;
    let (lo, hi) = (
        (g.centre_px[0] - half).max(0.0).ceil(),
        (g.centre_px[0] + half).min(last).floor(),
    );
    if lo > hi {
        return;
    }
    let first = lo as usize;
    let inv = 1.0 / (2.0 * g.sigma_px * g.sigma_px);
    let across = g.strength * (-dv * dv * inv).exp();
    for (k, r) in row[first..=hi as usize].iter_mut().enumerate() {
        let du = (first + k) as f64 - g.centre_px[0];
        *r += (across * (-du * du * inv).exp()) as f32 * gain;
    }
}

/// 2^23: adding it to a float in [0, 2^23) leaves the float's integer
/// part (rounded to nearest) in the low mantissa bits.
pub(super) const F32_INT_MAGIC: f32 = 8_388_608.0;

/// `floor(x)` for 0 <= x < 2^23 (a digital number), without a float to int
/// cast: Rust's saturating `as` casts are scalar code, this vectorises.
/// Bit-identical to `x as i32 as f32` on that range.
#[inline]
pub(super) fn floor_dn(x: f32) -> f32 {
    let nearest = (x + F32_INT_MAGIC) - F32_INT_MAGIC;
    if nearest > x { nearest - 1.0 } else { nearest }
}

/// `x.clamp(0.0, 255.0) as i32 as u8` (truncation, NaN to 0), vectorisable.
#[inline]
pub(super) fn dn_to_u8(x: f32) -> u8 {
    (floor_dn(x.clamp(0.0, 255.0)) + F32_INT_MAGIC).to_bits() as u8
}

impl Renderer {
    /// Box blur along `m` (pixels, centred) within the box; `m` comes
    /// through [`bounded_blur`], so its taps are at most a few image sizes.
    #[inline(never)]
    pub(super) fn blur(&mut self, rad: &mut [f32], b: PixelBox, m: [f64; 2]) {
        let len = (m[0] * m[0] + m[1] * m[1]).sqrt();
        let pad = (len / 2.0).ceil() as usize + 2;
        let (u0, v0) = (b.0.saturating_sub(pad), b.1.saturating_sub(pad));
        let (u1, v1) = ((b.2 + pad).min(self.w - 1), (b.3 + pad).min(self.h - 1));
        let (bw, bh) = (u1 - u0 + 1, v1 - v0 + 1);
        self.scratch.clear();
        for v in v0..=v1 {
            self.scratch
                .extend_from_slice(&rad[v * self.w + u0..=v * self.w + u1]);
        }
        let taps = ((2.0 * len).ceil() as usize + 1).max(3);
        let src = &self.scratch;
        let sample = |x: f64, y: f64| -> f32 {
            let x = x.clamp(0.0, (bw - 1) as f64);
            let y = y.clamp(0.0, (bh - 1) as f64);
            let (xi, yi) = (
                (x as usize).min(bw.saturating_sub(2)),
                (y as usize).min(bh.saturating_sub(2)),
            );
            let (fx, fy) = ((x - xi as f64) as f32, (y - yi as f64) as f32);
            let p = |xx: usize, yy: usize| src[(yy.min(bh - 1)) * bw + xx.min(bw - 1)];
            let top = p(xi, yi) + (p(xi + 1, yi) - p(xi, yi)) * fx;
            let bot = p(xi, yi + 1) + (p(xi + 1, yi + 1) - p(xi, yi + 1)) * fx;
            top + (bot - top) * fy
        };
        let offs: Vec<(f64, f64)> = (0..taps)
            .map(|k| {
                let f = k as f64 / (taps - 1) as f64 - 0.5;
                (m[0] * f, m[1] * f)
            })
            .collect();
        // Away from the box's border every pixel's taps have the same
        // whole-pixel offsets and bilinear weights: precomputed once.
        let whole: Vec<(isize, isize, f32, f32)> = offs
            .iter()
            .map(|&(dx, dy)| {
                let (ix, iy) = (dx.floor(), dy.floor());
                (ix as isize, iy as isize, (dx - ix) as f32, (dy - iy) as f32)
            })
            .collect();
        let reach = |pick: fn(&(isize, isize, f32, f32)) -> isize| {
            let lo = whole.iter().map(pick).min().unwrap_or(0);
            let hi = whole.iter().map(pick).max().unwrap_or(0);
            (lo, hi)
        };
        let ((dx_lo, dx_hi), (dy_lo, dy_hi)) = (reach(|t| t.0), reach(|t| t.1));
        // Pixels x in x_inner with x + dx_lo >= 0 and x + dx_hi + 1 <= bw - 1.
        let x_inner = (-dx_lo).max(0)..=(bw as isize - 2 - dx_hi);
        let y_inner = (-dy_lo).max(0)..=(bh as isize - 2 - dy_hi);
        let taps_px: Vec<(isize, f32, f32)> = whole
            .iter()
            .map(|&(ix, iy, fx, fy)| (iy * bw as isize + ix, fx, fy))
            .collect();
        for y in 0..bh {
            let row_inner = y_inner.contains(&(y as isize));
            for x in 0..bw {
                let mut acc = 0.0;
                if row_inner && x_inner.contains(&(x as isize)) {
                    let here = (y * bw + x) as isize;
                    for &(offset, fx, fy) in &taps_px {
                        let i = (here + offset) as usize;
                        let (p00, p10) = (src[i], src[i + 1]);
                        let (p01, p11) = (src[i + bw], src[i + bw + 1]);
                        let top = p00 + (p10 - p00) * fx;
                        let bot = p01 + (p11 - p01) * fx;
                        acc += top + (bot - top) * fy;
                    }
                } else {
                    for &(dx, dy) in &offs {
                        acc += sample(x as f64 + dx, y as f64 + dy);
                    }
                }
                rad[(v0 + y) * self.w + u0 + x] = acc / taps as f32;
            }
        }
    }

    #[inline(never)]
    pub(super) fn sensor(
        &self,
        rad: &mut [f32],
        dirty: &[bool],
        sky_grid: &[f32],
        veil_grid: &[f32],
        scene: &FrameScene,
    ) -> GrayImage {
        let (streak, glow, seed) = (
            scene.glare_streak.as_ref(),
            scene.glare_glow.as_ref(),
            scene.noise_seed,
        );
        let (w, h) = (self.w, self.h);
        let l = &self.look;
        let gain = (255.0 * l.gain) as f32;
        let noisy = l.read_noise_dn > 0.0 || l.shot_noise_dn > 0.0;
        // Noise sigma at the whole-DN level below the signal (computed, not
        // looked up, so the loop below vectorises).
        let read_var = l.read_noise_dn.powi(2) as f32;
        let shot = l.shot_noise_dn as f32;
        let glare = l.glare > 0.0;
        let mut out = vec![0u8; w * h];
        let mut state = seed ^ 0x9e37_79b9_7f4a_7c15;
        let mut next = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            state.wrapping_mul(0x2545_f491_4f6c_dd1d)
        };
        let mask = self.gauss.len() - 1;
        let mut veil_row = vec![0f32; self.gw];
        let mut sky = vec![0f32; w];
        let mut grid_row = vec![0f32; self.gw];
        for v in 0..h {
            // Rows with objects are finished in place (`rad` is scratch).
            let row = if dirty[v] {
                &mut rad[v * w..(v + 1) * w]
            } else {
                sky_row(sky_grid, self.gw, v, &mut grid_row, &mut sky);
                &mut sky[..]
            };
            // Vignetting: 1 - k r^2 (0.6 + 0.4 r^2), r relative to the corner.
            let dv2 = (v as f32 - self.cam.cy as f32).powi(2);
            let k = l.vignette as f32;
            for (r, du2) in row.iter_mut().zip(&self.du2) {
                let r2 = (du2 + dv2) * self.inv_corner2;
                *r *= (1.0 - k * r2 * (0.6 + 0.4 * r2)) * gain;
            }
            if glare {
                let (j, fy) = (v / GRID, (v % GRID) as f32 / GRID as f32);
                for (i, slot) in veil_row.iter_mut().enumerate() {
                    let a = veil_grid[j * self.gw + i];
                    *slot = a + (veil_grid[(j + 1) * self.gw + i] - a) * fy;
                }
                add_lerp_columns(&veil_row, gain, row);
            }
            if let Some(s) = streak {
                add_streak(row, v, s, gain);
            }
            if let Some(g) = glow {
                add_glow(row, v, g, gain);
            }
            let dst = &mut out[v * w..(v + 1) * w];
            if noisy {
                // Gaussian noise: a random run of the precomputed table,
                // taken as contiguous pieces up to the table's wrap.
                let mut start = next() as usize & mask;
                let (mut dst, mut row) = (&mut dst[..], &row[..]);
                while !row.is_empty() {
                    let n = row.len().min(self.gauss.len() - start);
                    let gauss = &self.gauss[start..start + n];
                    for ((o, &dn), &g) in dst[..n].iter_mut().zip(&row[..n]).zip(gauss) {
                        let q = dn.clamp(0.0, 255.0);
                        let sigma = (read_var + shot * floor_dn(q)).sqrt();
                        *o = dn_to_u8(q + g * sigma + 0.5);
                    }
                    (dst, row) = (&mut dst[n..], &row[n..]);
                    start = 0;
                }
            } else {
                for (o, &dn) in dst.iter_mut().zip(row.iter()) {
                    *o = dn_to_u8(dn + 0.5);
                }
            }
        }
        GrayImage::from_raw(w as u32, h as u32, out)
            .unwrap_or_else(|| GrayImage::new(w as u32, h as u32))
    }
}

/// The blur vector a frame can use: none when not finite (a drogue at an
/// unrepresentable position), and at most the image's diagonal long (a
/// longer streak is the same flat smear, and the blur's work grows with its
/// length).
pub(super) fn bounded_blur(m: [f64; 2], w: usize, h: usize) -> [f64; 2] {
    let len = m[0].hypot(m[1]);
    let diag = ((w * w + h * h) as f64).sqrt();
    if !len.is_finite() {
        [0.0, 0.0]
    } else if len > diag {
        [m[0] * diag / len, m[1] * diag / len]
    } else {
        m
    }
}
