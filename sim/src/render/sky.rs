//! Sky, clouds, sun glare and haze: slowly varying light, evaluated on a
//! coarse grid of rays and interpolated bilinearly to the pixels.

use super::{GRID, Renderer, clamp01};
use crate::geometry::V3;

/// One image row of the sky, bilinear from the coarse grid.
pub(super) fn sky_row(grid: &[f32], gw: usize, v: usize, tmp: &mut [f32], out: &mut [f32]) {
    let (j, fy) = (v / GRID, (v % GRID) as f32 / GRID as f32);
    let (g0, g1) = (
        &grid[j * gw..(j + 1) * gw],
        &grid[(j + 1) * gw..(j + 2) * gw],
    );
    for ((t, a), b) in tmp.iter_mut().zip(g0).zip(g1) {
        *t = a + (b - a) * fy;
    }
    lerp_columns(tmp, out);
}

/// Bilinear along a row: pixel u = i * GRID + k gets
/// `cells[i] + (cells[i + 1] - cells[i]) * k / GRID`. Done one grid cell at a
/// time (a fixed 16-wide loop the compiler vectorises) instead of looking up
/// each pixel's cell.
#[inline]
pub(super) fn lerp_columns(cells: &[f32], out: &mut [f32]) {
    const FX: [f32; GRID] = {
        let mut f = [0f32; GRID];
        let mut k = 0;
        while k < GRID {
            f[k] = k as f32 / GRID as f32;
            k += 1;
        }
        f
    };
    for (chunk, pair) in out.chunks_mut(GRID).zip(cells.windows(2)) {
        let (a, b) = (pair[0], pair[1]);
        for (o, fx) in chunk.iter_mut().zip(&FX) {
            *o = a + (b - a) * fx;
        }
    }
}

/// Like `lerp_columns`, adding `scale` times the interpolated value.
#[inline]
pub(super) fn add_lerp_columns(cells: &[f32], scale: f32, out: &mut [f32]) {
    let mut tmp = [0f32; GRID];
    for (chunk, pair) in out.chunks_mut(GRID).zip(cells.windows(2)) {
        lerp_columns(pair, &mut tmp[..chunk.len()]);
        for (o, t) in chunk.iter_mut().zip(&tmp) {
            *o += t * scale;
        }
    }
}

pub(super) fn hash2(ix: i32, iy: i32, seed: u32) -> f32 {
    let mut h = (ix as u32).wrapping_mul(0x8da6_b343)
        ^ (iy as u32).wrapping_mul(0xd816_3841)
        ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0x00ff_ffff) as f32 / 16_777_216.0
}

/// `x.floor()` inlined: without SSE4.1, `f64::floor` is a libm call.
#[inline]
pub(super) fn floor_f64(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

pub(super) fn value_noise(x: f64, y: f64, seed: u32) -> f32 {
    let (fx, fy) = (floor_f64(x), floor_f64(y));
    let (ix, iy) = (fx as i32, fy as i32);
    let (tx, ty) = ((x - fx) as f32, (y - fy) as f32);
    let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let a = hash2(ix, iy, seed);
    let b = hash2(ix + 1, iy, seed);
    let c = hash2(ix, iy + 1, seed);
    let d = hash2(ix + 1, iy + 1, seed);
    (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy
}

pub(super) fn fbm(x: f64, y: f64, seed: u32) -> f32 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut f = 1.0;
    for o in 0..5 {
        sum += amp * value_noise(x * f, y * f, seed.wrapping_add(o));
        amp *= 0.5;
        f *= 2.03;
    }
    sum / 0.96875
}

impl Renderer {
    pub(super) fn haze(&self, x: f64) -> f64 {
        x * (1.0 - self.look.haze) + self.look.haze_radiance * self.look.haze
    }

    pub(super) fn sky(&self, d_ned: &V3) -> (f32, f32) {
        let l = &self.look;
        let el = (-d_ned.z).clamp(-1.0, 1.0).asin();
        let az = d_ned.y.atan2(d_ned.x);
        let base = if el >= 0.0 {
            l.sky_horizon + (l.sky_zenith - l.sky_horizon) * (1.0 - (-el / 0.35).exp())
        } else {
            l.ground + (l.sky_horizon - l.ground) * (el / 0.04).exp()
        };
        let mut value = base;
        if l.cloud_cover > 0.0 {
            let c = fbm(az * 5.0, el * 9.0, l.cloud_seed) as f64;
            let lo = 1.0 - l.cloud_cover - 0.08;
            let x = clamp01((c - lo) / 0.22);
            let cov = x * x * (3.0 - 2.0 * x);
            // Clear sky needs no cloud shading (half the noise work).
            if cov > 0.0 {
                let shade = 0.88 + 0.12 * fbm(az * 17.0, el * 30.0, l.cloud_seed ^ 0x55) as f64;
                value = base + (l.cloud_radiance * shade - base) * cov;
            }
        }
        let mut veil = 0.0;
        if l.glare > 0.0 {
            let ang = d_ned.dot(&l.sun_ned).clamp(-1.0, 1.0).acos();
            veil = l.glare
                * (1.5 * (-(ang / 0.02).powi(2)).exp() + 0.12 / (1.0 + (ang / 0.08).powi(2)));
        }
        (value as f32, veil as f32)
    }
}
