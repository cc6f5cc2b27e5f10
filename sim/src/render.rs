//! The renderer: 8-bit gray frames of the scene as the camera sees it.
//!
//! Exact perspective per pixel: a precomputed table gives every pixel's
//! undistorted ray (the lens distortion), the ray is intersected with the
//! drogue plane and tested against the radii. Edges are anti-aliased from
//! the signed distance to each edge in pixels (the local pixel footprint in
//! the drogue plane); the inner circle's edge, which carries the truth, is
//! supersampled 4x4. Hose and probe are 3-D tubes (segment + tapering
//! radius) tested per pixel by their closest approach to the ray. Sky and
//! glare vary slowly and are evaluated on a coarse grid, bilinearly
//! interpolated. Motion blur is a box filter along the drogue's image motion
//! during the exposure, applied before the probe (which moves with the
//! camera). Then vignetting, exposure gain, shot + read noise, 8-bit.
//!
//! Optional extras for robustness tests, all off by default (a scene without
//! them renders bit-identically): flat [`Decal`]s behind everything (dark
//! distractor blobs and rectangles, canopy-less discs and rings, crescents),
//! a [`GlareStreak`] added at the sensor (saturating where it is strong), and
//! frames without the drogue (`FrameScene::without_drogue`).
//!
//! Speed (a 1280x960 frame in 4-7 ms of one core's time, the first of a
//! run about 10 ms; `benches/render.rs`):
//! tubes become fragments (pixel, depth, coverage, radiance) blended in
//! afterwards, and the probe's are kept between frames, since it is fixed
//! to the receiver; per drogue pixel the nearest strut is found by climbing
//! from the neighbouring pixel's; the blur's taps share their weights; the
//! sensor loop is branch-free so it vectorises. Each of these is checked
//! against the straightforward every-pixel path in `render/tests.rs`. The
//! per-frame stages are `#[inline(never)]` so profiles name them.

use crate::camera::SimCamera;
use crate::geometry::{M3, V3};
use image::GrayImage;

/// Sky grid spacing, pixels.
const GRID: usize = 16;

/// Pixel box (u0, v0, u1, v1), inclusive.
type PixelBox = (usize, usize, usize, usize);

/// A tube (hose, probe): axis segment a -> b in the camera frame, radii.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tube {
    pub a: V3,
    pub b: V3,
    pub radius_a: f64,
    pub radius_b: f64,
    pub radiance: f64,
}

impl Tube {
    /// Closest approach of the ray t * d (d = (x, y, 1), t = depth) to the
    /// tube's axis: (depth t, distance beyond the surface in metres,
    /// distance from the axis over the radius).
    #[inline]
    pub fn probe_ray(&self, d: &V3) -> Option<(f64, f64, f64)> {
        TubeAxis::new(self)?.probe_ray(d)
    }

    /// Whether the ray hits the tube nearer than `depth` (z, metres).
    pub fn occludes(&self, d: &V3, depth: f64) -> bool {
        matches!(self.probe_ray(d), Some((t, sd, _)) if sd < 0.0 && t < depth)
    }

    /// The part of the tube in front of the plane z = `near`.
    pub fn clipped(&self, near: f64) -> Option<Tube> {
        let (za, zb) = (self.a.z, self.b.z);
        if za < near && zb < near {
            return None;
        }
        let mut t = *self;
        if za < near || zb < near {
            let f = (near - za) / (zb - za);
            let p = self.a + (self.b - self.a) * f;
            let r = self.radius_a + (self.radius_b - self.radius_a) * f;
            if za < near {
                t.a = p;
                t.radius_a = r;
            } else {
                t.b = p;
                t.radius_b = r;
            }
        }
        Some(t)
    }
}

/// A tube's axis, precomputed for per-pixel tests.
#[derive(Clone, Copy, Debug)]
struct TubeAxis {
    a: V3,
    u: V3,
    len: f64,
    ua: f64,
    radius_a: f64,
    radius_slope: f64,
}

impl TubeAxis {
    fn new(t: &Tube) -> Option<TubeAxis> {
        let seg = t.b - t.a;
        let len = seg.norm();
        (len > 1e-12).then(|| {
            let u = seg / len;
            TubeAxis {
                a: t.a,
                u,
                len,
                ua: u.dot(&t.a),
                radius_a: t.radius_a,
                radius_slope: (t.radius_b - t.radius_a) / len,
            }
        })
    }

    #[inline]
    fn probe_ray(&self, d: &V3) -> Option<(f64, f64, f64)> {
        let (t, s, dist2) = self.closest(d)?;
        let dist = dist2.sqrt();
        let r = self.radius_at(s);
        Some((t, dist - r, dist / r.max(1e-9)))
    }

    /// Tube radius at axis position `s` (metres from `a`).
    #[inline]
    fn radius_at(&self, s: f64) -> f64 {
        self.radius_a + self.radius_slope * s
    }

    /// Closest approach of the ray to the axis: (depth t, axis position s,
    /// squared distance), without the square root, so per-pixel callers can
    /// reject pixels clear of the tube cheaply.
    #[inline]
    fn closest(&self, d: &V3) -> Option<(f64, f64, f64)> {
        let dd = d.dot(d);
        let du = d.dot(&self.u);
        let da = d.dot(&self.a);
        let den = dd - du * du;
        let s = if den > 1e-14 {
            let t = (da - self.ua * du) / den;
            t * du - self.ua
        } else {
            0.0
        };
        let s = s.clamp(0.0, self.len);
        let t = (da + s * du) / dd;
        if t <= 0.0 {
            return None;
        }
        Some((t, s, (d * t - self.a - self.u * s).norm_squared()))
    }
}

/// One pixel a tube covers: its column and row, the depth of the
/// tube's axis along the pixel's ray, its coverage and radiance.
#[derive(Clone, Copy, Debug)]
struct TubeFragment {
    u: u32,
    v: u32,
    depth: f64,
    coverage: f32,
    radiance: f32,
}

/// A tube's fragments (kept for the next frame: the probe is fixed to the
/// receiver, so its fragments stay valid while its tube is unchanged).
#[derive(Clone, Debug, Default)]
struct TubeLayer {
    tube: Option<Tube>,
    fragments: Vec<TubeFragment>,
    /// Image rows holding any fragment.
    rows: Vec<usize>,
}

/// The drogue in the camera frame.
#[derive(Clone, Copy, Debug)]
pub struct DrogueView {
    pub centre: V3,
    /// Unit normal toward the camera.
    pub normal: V3,
    /// In-plane basis; struts are laid out from `e1`.
    pub e1: V3,
    pub e2: V3,
    pub inner_radius: f64,
    pub canopy_radius: f64,
    pub rim_width: f64,
    pub struts: u32,
    pub strut_width: f64,
    pub disc: f64,
    pub canopy: f64,
    pub rim: f64,
    pub strut: f64,
}

/// Everything one frame needs, in the camera frame.
#[derive(Clone, Debug)]
pub struct FrameScene {
    pub drogue: DrogueView,
    pub hose: Option<Tube>,
    pub probe: Option<Tube>,
    /// Camera -> NED rotation (for the sky).
    pub r_ned_cam: M3,
    /// Image motion of the drogue during the exposure, pixels.
    pub blur_px: [f64; 2],
    pub noise_seed: u64,
    /// Leave the drogue out (drogue-free frames); default false.
    pub without_drogue: bool,
    /// Flat shapes behind the drogue and the tubes, painted in order; empty
    /// by default.
    pub decals: Vec<Decal>,
    /// A sun-glare streak; `None` by default.
    pub glare_streak: Option<GlareStreak>,
}

/// Outline of a [`Decal`] in its plane, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DecalShape {
    /// A disc (a dark disc without a canopy, a blob, a balloon).
    Disc { radius: f64 },
    /// An annulus between two radii (a dark ring without a canopy).
    Ring { inner: f64, outer: f64 },
    /// A rectangle with half-sizes along `e1` and `e2`.
    Rect { half_1: f64, half_2: f64 },
    /// An irregular blob: radius `radius * (1 + wobble * w(phi))` with
    /// w a fixed mix of the 2nd and 3rd harmonics (|w| <= 1) turned by
    /// `phase` radians; `wobble` within 0..0.5.
    Blob {
        radius: f64,
        wobble: f64,
        phase: f64,
    },
}

/// A flat, uniformly bright shape in the camera frame (plane through
/// `centre` with unit normal `normal`, in-plane orthonormal axes `e1`, `e2`).
/// Decals are background: the drogue, hose and probe are drawn over them,
/// and they are neither blurred nor shaded, but hazed like every object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decal {
    pub centre: V3,
    pub normal: V3,
    pub e1: V3,
    pub e2: V3,
    pub shape: DecalShape,
    /// Relative radiance 0..1.
    pub radiance: f64,
}

impl Decal {
    /// A crescent: a dark disc of `radius` partly covered by a lighter disc
    /// of `cover_radius` whose centre is `offset` metres along `e1`. The
    /// crescent's outer arc is the dark disc's own circle, so its image is
    /// a fine ellipse arc. Paint the two in the returned order.
    #[allow(clippy::too_many_arguments)]
    pub fn crescent(
        centre: V3,
        normal: V3,
        e1: V3,
        e2: V3,
        radius: f64,
        dark: f64,
        cover_radius: f64,
        offset: f64,
        light: f64,
    ) -> [Decal; 2] {
        let disc = |centre: V3, radius: f64, radiance: f64| Decal {
            centre,
            normal,
            e1,
            e2,
            shape: DecalShape::Disc { radius },
            radiance,
        };
        [
            disc(centre, radius, dark),
            disc(centre + e1 * offset, cover_radius, light),
        ]
    }

    /// Radius of a circle about `centre` that holds the whole shape, metres.
    fn bounding_radius(&self) -> f64 {
        match self.shape {
            DecalShape::Disc { radius } => radius,
            DecalShape::Ring { outer, .. } => outer,
            DecalShape::Rect { half_1, half_2 } => half_1.hypot(half_2),
            DecalShape::Blob { radius, wobble, .. } => radius * (1.0 + wobble.abs()),
        }
    }

    /// Signed distance (metres, negative inside) of the in-plane point
    /// (x, y) to the outline (for `Blob` the radial distance, close enough
    /// for anti-aliasing).
    fn signed_distance(&self, x: f64, y: f64) -> f64 {
        match self.shape {
            DecalShape::Disc { radius } => x.hypot(y) - radius,
            DecalShape::Ring { inner, outer } => {
                let rho = x.hypot(y);
                (rho - outer).max(inner - rho)
            }
            DecalShape::Rect { half_1, half_2 } => {
                let (qx, qy) = (x.abs() - half_1, y.abs() - half_2);
                qx.max(0.0).hypot(qy.max(0.0)) + qx.max(qy).min(0.0)
            }
            DecalShape::Blob {
                radius,
                wobble,
                phase,
            } => {
                let phi = y.atan2(x);
                let w = 0.6 * (2.0 * phi + phase).sin() + 0.4 * (3.0 * phi + 2.0 * phase).sin();
                x.hypot(y) - radius * (1.0 + wobble * w)
            }
        }
    }
}

/// A sun-glare streak: a straight band of light added at the sensor (after
/// vignetting, before noise), Gaussian across with full width at half
/// maximum `width_px`, running across the whole frame. With a `strength`
/// near 1 or more it saturates the pixels it crosses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlareStreak {
    /// A point of the band's centre line, pixels.
    pub through_px: [f64; 2],
    /// Direction of the centre line from +u toward +v, radians.
    pub angle_rad: f64,
    /// Full width at half maximum, pixels (> 0).
    pub width_px: f64,
    /// Radiance added on the centre line (relative, like the scene's).
    pub strength: f64,
}

/// Scene-wide look (from the scenario).
#[derive(Clone, Debug)]
pub struct Look {
    pub sky_zenith: f64,
    pub sky_horizon: f64,
    pub ground: f64,
    pub cloud_cover: f64,
    pub cloud_radiance: f64,
    pub sun_ned: V3,
    pub glare: f64,
    pub haze: f64,
    pub haze_radiance: f64,
    pub gain: f64,
    pub read_noise_dn: f64,
    pub shot_noise_dn: f64,
    pub vignette: f64,
    pub cloud_seed: u32,
}

pub struct Renderer {
    cam: SimCamera,
    w: usize,
    h: usize,
    /// Undistorted normalised ray (x, y) of every pixel.
    rays: Vec<[f32; 2]>,
    /// (u - cx)^2 per column, and 1 / (corner radius)^2, for vignetting.
    du2: Vec<f32>,
    inv_corner2: f32,
    gw: usize,
    gh: usize,
    grid_rays: Vec<V3>,
    look: Look,
    gauss: Vec<f32>,
    rad: Vec<f32>,
    scratch: Vec<f32>,
    hose_layer: TubeLayer,
    probe_layer: TubeLayer,
}

/// One image row of the sky, bilinear from the coarse grid.
fn sky_row(grid: &[f32], gw: usize, v: usize, tmp: &mut [f32], out: &mut [f32]) {
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
fn lerp_columns(cells: &[f32], out: &mut [f32]) {
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
fn add_lerp_columns(cells: &[f32], scale: f32, out: &mut [f32]) {
    let mut tmp = [0f32; GRID];
    for (chunk, pair) in out.chunks_mut(GRID).zip(cells.windows(2)) {
        lerp_columns(pair, &mut tmp[..chunk.len()]);
        for (o, t) in chunk.iter_mut().zip(&tmp) {
            *o += t * scale;
        }
    }
}

fn hash2(ix: i32, iy: i32, seed: u32) -> f32 {
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
fn floor_f64(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

fn value_noise(x: f64, y: f64, seed: u32) -> f32 {
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

fn fbm(x: f64, y: f64, seed: u32) -> f32 {
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

/// Inverse normal CDF (Acklam's rational approximation, |error| < 1.2e-9).
fn inv_normal(p: f64) -> f64 {
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

/// Index of the strut direction (cos, sin) nearest in angle to the
/// in-plane point (x, y), i.e. with the largest x cos + y sin. Around the
/// circle of evenly spaced struts that is unimodal, so climbing from
/// `start` (the neighbouring pixel's strut) takes a step or two instead of
/// a look at every strut. `dirs` must not be empty.
#[inline]
fn nearest_strut(dirs: &[(f64, f64)], x: f64, y: f64, start: usize) -> usize {
    let n = dirs.len();
    let along = |k: usize| x * dirs[k].0 + y * dirs[k].1;
    let (mut k, mut best) = (start, along(start));
    loop {
        let next = if k + 1 == n { 0 } else { k + 1 };
        let prev = if k == 0 { n - 1 } else { k - 1 };
        let (a_next, a_prev) = (along(next), along(prev));
        if a_next > best {
            (k, best) = (next, a_next);
        } else if a_prev > best {
            (k, best) = (prev, a_prev);
        } else {
            return k;
        }
    }
}

/// Adds the glare streak's light to image row `v` (gain applied).
fn add_streak(row: &mut [f32], v: usize, s: &GlareStreak, gain: f32) {
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

/// 2^23: adding it to a float in [0, 2^23) leaves the float's integer
/// part (rounded to nearest) in the low mantissa bits.
const F32_INT_MAGIC: f32 = 8_388_608.0;

/// `floor(x)` for 0 <= x < 2^23 (a digital number), without a float to int
/// cast: Rust's saturating `as` casts are scalar code, this vectorises.
/// Bit-identical to `x as i32 as f32` on that range.
#[inline]
fn floor_dn(x: f32) -> f32 {
    let nearest = (x + F32_INT_MAGIC) - F32_INT_MAGIC;
    if nearest > x { nearest - 1.0 } else { nearest }
}

/// `x.clamp(0.0, 255.0) as i32 as u8` (truncation, NaN to 0), vectorisable.
#[inline]
fn dn_to_u8(x: f32) -> u8 {
    (floor_dn(x.clamp(0.0, 255.0)) + F32_INT_MAGIC).to_bits() as u8
}

#[inline]
fn clamp01(x: f64) -> f64 {
    x.clamp(0.0, 1.0)
}

impl Renderer {
    pub fn new(cam: &SimCamera, look: Look) -> Renderer {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let pinhole = |u: f64, v: f64| ((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy);
        let ray_of = |u: f64, v: f64| -> (f64, f64) {
            let (xd, yd) = pinhole(u, v);
            cam.undistort_normalized(xd, yd).unwrap_or((xd, yd))
        };
        let mut rays = Vec::with_capacity(w * h);
        let r_corner2 =
            (cam.cx.max(w as f64 - cam.cx)).powi(2) + (cam.cy.max(h as f64 - cam.cy)).powi(2);
        for v in 0..h {
            for u in 0..w {
                let (x, y) = ray_of(u as f64, v as f64);
                rays.push([x as f32, y as f32]);
            }
        }
        let gw = w.div_ceil(GRID) + 1;
        let gh = h.div_ceil(GRID) + 1;
        let mut grid_rays = Vec::with_capacity(gw * gh);
        for j in 0..gh {
            for i in 0..gw {
                let (x, y) = ray_of((i * GRID) as f64, (j * GRID) as f64);
                grid_rays.push(V3::new(x, y, 1.0).normalize());
            }
        }
        // 2^16 normal quantiles in a fixed pseudo-random order.
        let n = 1usize << 16;
        let mut gauss: Vec<f32> = (0..n)
            .map(|i| inv_normal((i as f64 + 0.5) / n as f64) as f32)
            .collect();
        let mut st = 0x2545_f491_4f6c_dd1du64;
        for i in (1..n).rev() {
            st ^= st << 13;
            st ^= st >> 7;
            st ^= st << 17;
            gauss.swap(i, (st % (i as u64 + 1)) as usize);
        }
        Renderer {
            cam: cam.clone(),
            w,
            h,
            rays,
            du2: (0..w).map(|u| (u as f32 - cam.cx as f32).powi(2)).collect(),
            inv_corner2: (1.0 / r_corner2) as f32,
            gw,
            gh,
            grid_rays,
            look,
            gauss,
            rad: vec![0.0; w * h],
            scratch: Vec::new(),
            hose_layer: TubeLayer::default(),
            probe_layer: TubeLayer::default(),
        }
    }

    /// Changes the scene-wide look (haze, exposure, noise, sky ...) while
    /// keeping the camera's ray table: cheaper than a new renderer.
    pub fn set_look(&mut self, look: Look) {
        self.look = look;
    }

    pub fn look(&self) -> &Look {
        &self.look
    }

    #[inline]
    fn ray(&self, u: usize, v: usize) -> V3 {
        let r = self.rays[v * self.w + u];
        V3::new(r[0] as f64, r[1] as f64, 1.0)
    }

    /// Ray steps to the next pixel in u and v (the local lens Jacobian).
    #[inline]
    fn ray_steps(&self, u: usize, v: usize) -> (V3, V3) {
        let (u0, u1) = if u + 1 < self.w {
            (u, u + 1)
        } else {
            (u - 1, u)
        };
        let (v0, v1) = if v + 1 < self.h {
            (v, v + 1)
        } else {
            (v - 1, v)
        };
        (
            self.ray(u1, v) - self.ray(u0, v),
            self.ray(u, v1) - self.ray(u, v0),
        )
    }

    fn haze(&self, x: f64) -> f64 {
        x * (1.0 - self.look.haze) + self.look.haze_radiance * self.look.haze
    }

    fn sky(&self, d_ned: &V3) -> (f32, f32) {
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

    /// Renders one frame.
    pub fn render(&mut self, scene: &FrameScene) -> GrayImage {
        let (w, h) = (self.w, self.h);
        // 1. Sky on the coarse grid (bilinear to the pixels, row by row).
        let mut sky_grid = vec![0f32; self.gw * self.gh];
        let mut veil_grid = vec![0f32; self.gw * self.gh];
        for (k, r) in self.grid_rays.iter().enumerate() {
            let (s, v) = self.sky(&(scene.r_ned_cam * r));
            sky_grid[k] = s;
            veil_grid[k] = v;
        }
        // 2. Rows the objects touch get a full radiance row; the others go
        // straight from the sky to the sensor.
        let mut hose_layer = std::mem::take(&mut self.hose_layer);
        let mut probe_layer = std::mem::take(&mut self.probe_layer);
        self.rasterise_tube(&mut hose_layer, scene.hose.and_then(|t| t.clipped(0.05)));
        // The probe is fixed to the receiver: it rasterises once per run.
        let probe = scene.probe.and_then(|t| t.clipped(0.05));
        if probe_layer.tube != probe || probe.is_none() {
            self.rasterise_tube(&mut probe_layer, probe);
        }
        let bbox = if scene.without_drogue {
            None
        } else {
            self.drogue_bbox(&scene.drogue)
        };
        let decal_boxes: Vec<(&Decal, PixelBox)> = scene
            .decals
            .iter()
            .filter_map(|d| {
                Some((
                    d,
                    self.disc_bbox(&d.centre, &d.e1, &d.e2, d.bounding_radius())?,
                ))
            })
            .collect();
        let m = bounded_blur(scene.blur_px, w, h);
        let blur_len = (m[0] * m[0] + m[1] * m[1]).sqrt();
        let mut dirty = vec![false; h];
        for &v in hose_layer.rows.iter().chain(&probe_layer.rows) {
            dirty[v] = true;
        }
        for (_, b) in &decal_boxes {
            for d in &mut dirty[b.1..=b.3] {
                *d = true;
            }
        }
        if let Some(b) = bbox {
            let pad = (blur_len / 2.0).ceil() as usize + 2;
            for d in &mut dirty[b.1.saturating_sub(pad)..=(b.3 + pad).min(h - 1)] {
                *d = true;
            }
        }
        let mut rad = std::mem::take(&mut self.rad);
        let mut grid_row = vec![0f32; self.gw];
        for v in (0..h).filter(|v| dirty[*v]) {
            sky_row(
                &sky_grid,
                self.gw,
                v,
                &mut grid_row,
                &mut rad[v * w..(v + 1) * w],
            );
        }
        for (decal, b) in &decal_boxes {
            self.draw_decal(&mut rad, decal, *b);
        }
        self.composite_tube(&mut rad, &hose_layer, None);
        if let Some(b) = bbox {
            self.draw_drogue(&mut rad, &scene.drogue, b);
            if blur_len >= 0.3 {
                self.blur(&mut rad, b, m);
            }
        }
        self.composite_tube(&mut rad, &probe_layer, bbox.map(|b| (&scene.drogue, b)));
        // 3. Sensor: vignette, glare veil, gain, noise, 8 bits.
        let img = self.sensor(
            &mut rad,
            &dirty,
            &sky_grid,
            &veil_grid,
            scene.glare_streak.as_ref(),
            scene.noise_seed,
        );
        self.rad = rad;
        self.hose_layer = hose_layer;
        self.probe_layer = probe_layer;
        img
    }

    /// Pixel bounding box (u0, v0, u1, v1), inclusive, of the canopy.
    fn drogue_bbox(&self, d: &DrogueView) -> Option<PixelBox> {
        self.disc_bbox(&d.centre, &d.e1, &d.e2, d.canopy_radius * 1.02)
    }

    /// Pixel bounding box (u0, v0, u1, v1), inclusive, of the circle of
    /// radius `r` about `centre` in the plane spanned by `e1`, `e2`; the
    /// whole frame when it comes near the camera plane or beyond the lens
    /// model's range, `None` when it is out of the frame.
    fn disc_bbox(&self, centre: &V3, e1: &V3, e2: &V3, r: f64) -> Option<PixelBox> {
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        if !(r.is_finite() && centre.iter().all(|x| x.is_finite())) {
            return None;
        }
        for k in 0..72 {
            let a = k as f64 * std::f64::consts::TAU / 72.0;
            let p = centre + (e1 * a.cos() + e2 * a.sin()) * r;
            if p.z < 0.02 {
                return Some((0, 0, self.w - 1, self.h - 1));
            }
            // Beyond the lens model's range: fall back to the whole frame.
            let (x, y) = (p.x / p.z, p.y / p.z);
            if x.abs() > 2.0 || y.abs() > 2.0 {
                return Some((0, 0, self.w - 1, self.h - 1));
            }
            let q = self.cam.project_px(&p)?;
            u0 = u0.min(q[0]);
            v0 = v0.min(q[1]);
            u1 = u1.max(q[0]);
            v1 = v1.max(q[1]);
        }
        let m = 3.0;
        if u1 < -m || v1 < -m || u0 > self.w as f64 + m || v0 > self.h as f64 + m {
            return None;
        }
        let cl = |x: f64, hi: usize| (x.max(0.0) as usize).min(hi - 1);
        Some((
            cl(u0 - m, self.w),
            cl(v0 - m, self.h),
            cl(u1 + m + 1.0, self.w),
            cl(v1 + m + 1.0, self.h),
        ))
    }

    /// A decal over its box: each pixel's ray meets the decal's plane, the
    /// outline's signed distance there is turned into pixels by its change
    /// to the next pixel in u and v, and gives the coverage.
    #[inline(never)]
    fn draw_decal(&self, rad: &mut [f32], d: &Decal, b: PixelBox) {
        let nc = d.normal.dot(&d.centre);
        let distance_at = |u: usize, v: usize| -> Option<f64> {
            let ray = self.ray(u, v);
            let nd = d.normal.dot(&ray);
            if nd.abs() < 1e-12 {
                return None;
            }
            let t = nc / nd;
            if t <= 0.0 {
                return None;
            }
            let p = ray * t - d.centre;
            Some(d.signed_distance(p.dot(&d.e1), p.dot(&d.e2)))
        };
        let value = self.haze(d.radiance) as f32;
        for v in b.1..=b.3 {
            let (vn, sv) = if v + 1 < self.h {
                (v + 1, 1.0)
            } else {
                (v - 1, -1.0)
            };
            for u in b.0..=b.2 {
                let (un, su) = if u + 1 < self.w {
                    (u + 1, 1.0)
                } else {
                    (u - 1, -1.0)
                };
                let (Some(sd), Some(sd_u), Some(sd_v)) =
                    (distance_at(u, v), distance_at(un, v), distance_at(u, vn))
                else {
                    continue;
                };
                let per_px = ((sd_u - sd) * su).hypot((sd_v - sd) * sv).max(1e-12);
                let cov = clamp01(0.5 - sd / per_px) as f32;
                if cov > 0.0 {
                    let o = &mut rad[v * self.w + u];
                    *o += (value - *o) * cov;
                }
            }
        }
    }

    /// The drogue, pixel by pixel over its box: each pixel's ray meets the
    /// drogue plane at in-plane (x, y); edges are anti-aliased by their
    /// distance in pixels (metres over the pixel footprint |grad rho|).
    #[inline(never)]
    fn draw_drogue(&self, rad: &mut [f32], d: &DrogueView, b: PixelBox) {
        let nc = d.normal.dot(&d.centre);
        if nc >= 0.0 {
            return;
        }
        let strut_dirs: Vec<(f64, f64)> = (0..d.struts)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / d.struts as f64;
                (a.cos(), a.sin())
            })
            .collect();
        let half_strut = d.strut_width * 0.5;
        let disc = self.haze(d.disc) as f32;
        let (n, e1, e2) = (d.normal, d.e1, d.e2);
        // The plane point of ray (rx, ry, 1) at depth t is t * ray - centre:
        // in-plane x = t * (e1 . ray) - e1 . centre (and y with e2).
        let (e1_c, e2_c) = (e1.dot(&d.centre), e2.dot(&d.centre));
        let reject = d.canopy_radius * 1.03;
        let rim_inner = d.canopy_radius - d.rim_width;
        let inv_canopy_span = 1.0 / (d.canopy_radius - d.inner_radius);
        let r_in2 = d.inner_radius * d.inner_radius;
        for v in b.1..=b.3 {
            // The nearest strut of the previous pixel in the row.
            let mut strut = 0;
            for u in b.0..=b.2 {
                let ray = self.ray(u, v);
                let nd = n.x * ray.x + n.y * ray.y + n.z;
                if nd >= -1e-12 {
                    continue;
                }
                let t = nc / nd;
                let (a1, a2) = (
                    e1.x * ray.x + e1.y * ray.y + e1.z,
                    e2.x * ray.x + e2.y * ray.y + e2.z,
                );
                let (x, y) = (t * a1 - e1_c, t * a2 - e2_c);
                let rho2 = x * x + y * y;
                if rho2 > reject * reject {
                    continue;
                }
                let rho = rho2.sqrt();
                // Pixel footprint |grad rho| (metres per pixel), from the ray
                // steps su, sv (z = 0): d(plane point)/du = t (su - ray
                // (n . su) / nd), projected on the radial direction.
                let (su, sv) = self.ray_steps(u, v);
                let (x_r, y_r) = if rho > 1e-9 { (x, y) } else { (1.0, 0.0) };
                let radial_ray = x_r * a1 + y_r * a2;
                let grad = |s: &V3| {
                    let radial_s =
                        x_r * (e1.x * s.x + e1.y * s.y) + y_r * (e2.x * s.x + e2.y * s.y);
                    radial_s - radial_ray * (n.x * s.x + n.y * s.y) / nd
                };
                let (gu, gv) = (grad(&su), grad(&sv));
                let norm_r = if rho > 1e-9 { rho } else { 1.0 };
                let s = (t * (gu * gu + gv * gv).sqrt() / norm_r).max(1e-12);
                let inv_s = 1.0 / s;
                let alpha = clamp01(0.5 - (rho - d.canopy_radius) * inv_s);
                if alpha <= 0.0 {
                    continue;
                }
                // Inner circle: supersampled 4x4 near its edge; inside it,
                // nothing else shows.
                let edge = (rho - d.inner_radius) * inv_s;
                let o = &mut rad[v * self.w + u];
                if edge < -1.2 {
                    *o += (disc - *o) * alpha as f32;
                    continue;
                }
                // Canopy: radial shading toward the disc, side light.
                let radial_f = (rho - d.inner_radius) * inv_canopy_span;
                let mut val =
                    d.canopy * (0.82 + 0.18 * clamp01(radial_f)) * (1.0 + 0.06 * x / rho.max(1e-9));
                // Coverage falls with the distance to a strut, so the nearest
                // strut (on its own side of the centre) decides.
                let mut perp_min = f64::INFINITY;
                if !strut_dirs.is_empty() {
                    strut = nearest_strut(&strut_dirs, x, y, strut);
                    let (c, sn) = strut_dirs[strut];
                    if x * c + y * sn > 0.0 {
                        perp_min = (-x * sn + y * c).abs();
                    }
                }
                let strut_cov = clamp01(0.5 - (perp_min - half_strut) * inv_s);
                val += (d.strut - val) * strut_cov;
                let rim_cov = clamp01(0.5 + (rho - rim_inner) * inv_s);
                val += (d.rim - val) * rim_cov;
                let disc_cov = if edge < 1.2 {
                    let mut inside = 0;
                    for j in 0..4 {
                        for i in 0..4 {
                            let (du, dv) = ((i as f64 - 1.5) / 4.0, (j as f64 - 1.5) / 4.0);
                            let r2 = ray + su * du + sv * dv;
                            let t2 = nc / n.dot(&r2);
                            if (r2 * t2 - d.centre).norm_squared() < r_in2 {
                                inside += 1;
                            }
                        }
                    }
                    inside as f32 / 16.0
                } else {
                    0.0
                };
                let val = self.haze(val) as f32;
                let val = val + (disc - val) * disc_cov;
                *o += (val - *o) * alpha as f32;
            }
        }
    }

    /// Per image row, the pixel span (u0, u1) that may show the tube: the
    /// axis projected at a few points, each with its radius in pixels, and
    /// the band between consecutive points.
    fn tube_spans(&self, tube: &Tube) -> Vec<(usize, usize, usize)> {
        const N: usize = 24;
        let mut pts: Vec<(f64, f64, f64)> = Vec::with_capacity(N + 1);
        for k in 0..=N {
            let f = k as f64 / N as f64;
            let p = tube.a + (tube.b - tube.a) * f;
            let r = tube.radius_a + (tube.radius_b - tube.radius_a) * f;
            let (x, y) = (p.x / p.z, p.y / p.z);
            let q = if x.abs() > 1.5 || y.abs() > 1.5 {
                // Outside the lens model's range: pinhole, clamped far out.
                [
                    self.cam.fx * x.clamp(-3.0, 3.0) + self.cam.cx,
                    self.cam.fy * y.clamp(-3.0, 3.0) + self.cam.cy,
                ]
            } else {
                match self.cam.project_px(&p) {
                    Some(q) => q,
                    None => continue,
                }
            };
            pts.push((q[0], q[1], self.cam.fx * r / p.z * 1.2 + 3.0));
        }
        let mut spans = Vec::new();
        for v in 0..self.h {
            let vf = v as f64;
            let (mut lo, mut hi) = (f64::MAX, f64::MIN);
            for pair in pts.windows(2) {
                let ((u0, v0, r0), (u1, v1, r1)) = (pair[0], pair[1]);
                let rm = r0.max(r1);
                if vf < v0.min(v1) - rm || vf > v0.max(v1) + rm {
                    continue;
                }
                let (du, dv) = (u1 - u0, v1 - v0);
                let len = (du * du + dv * dv).sqrt();
                let (mut a, mut b) = (u0.min(u1) - rm, u0.max(u1) + rm);
                if dv.abs() > 1e-9 {
                    let f = ((vf - v0) / dv).clamp(0.0, 1.0);
                    let uc = u0 + du * f;
                    let half = rm * len / dv.abs() + rm;
                    a = a.max(uc - half);
                    b = b.min(uc + half);
                }
                lo = lo.min(a);
                hi = hi.max(b);
            }
            if hi >= 0.0 && lo <= (self.w - 1) as f64 && lo <= hi {
                spans.push((
                    v,
                    lo.max(0.0) as usize,
                    (hi.min((self.w - 1) as f64)) as usize,
                ));
            }
        }
        spans
    }

    /// The tube's fragments into `layer`.
    #[inline(never)]
    fn rasterise_tube(&self, layer: &mut TubeLayer, tube: Option<Tube>) {
        layer.tube = tube;
        layer.fragments.clear();
        layer.rows.clear();
        let Some(tube) = tube else {
            return;
        };
        let Some(axis) = TubeAxis::new(&tube) else {
            return;
        };
        let px = 1.0 / self.cam.fx;
        let base = tube.radiance;
        for (v, u0, u1) in self.tube_spans(&tube) {
            let first = layer.fragments.len();
            for u in u0..=u1 {
                let ray = self.ray(u, v);
                let Some((t, s, dist2)) = axis.closest(&ray) else {
                    continue;
                };
                // Coverage needs dist < r + t * px / 2; span pixels clear of
                // the tube are rejected here without the square root.
                let r = axis.radius_at(s);
                let reach = r + 0.5 * t * px;
                if reach > 0.0 && dist2 > reach * reach * (1.0 + 1e-9) {
                    continue;
                }
                let dist = dist2.sqrt();
                let (sd, k) = (dist - r, dist / r.max(1e-9));
                let cov = clamp01(0.5 - sd / (t * px));
                if cov <= 0.0 {
                    continue;
                }
                let k = k.min(1.0);
                let shade = base * (0.7 + 0.45 * (1.0 - k * k).sqrt())
                    + 0.25 * base * (-((k - 0.45) / 0.12).powi(2)).exp();
                layer.fragments.push(TubeFragment {
                    u: u as u32,
                    v: v as u32,
                    depth: t,
                    coverage: cov as f32,
                    radiance: self.haze(shade) as f32,
                });
            }
            if layer.fragments.len() > first {
                layer.rows.push(v);
            }
        }
    }

    /// Blends a tube's fragments into the frame; where `in_front_of` (the
    /// drogue) is nearer than the tube, it hides the tube.
    #[inline(never)]
    fn composite_tube(
        &self,
        rad: &mut [f32],
        layer: &TubeLayer,
        in_front_of: Option<(&DrogueView, PixelBox)>,
    ) {
        for f in &layer.fragments {
            let (u, v) = (f.u as usize, f.v as usize);
            // Only inside its box can the drogue be in front.
            if let Some((d, b)) = in_front_of
                && (b.0..=b.2).contains(&u)
                && (b.1..=b.3).contains(&v)
            {
                let ray = self.ray(u, v);
                let nd = d.normal.dot(&ray);
                if nd < 0.0 {
                    let tp = d.normal.dot(&d.centre) / nd;
                    if tp > 0.0 && tp < f.depth && (ray * tp - d.centre).norm() < d.canopy_radius {
                        continue;
                    }
                }
            }
            let o = &mut rad[v * self.w + u];
            *o += (f.radiance - *o) * f.coverage;
        }
    }

    /// Box blur along `m` (pixels, centred) within the box; `m` comes
    /// through [`bounded_blur`], so its taps are at most a few image sizes.
    #[inline(never)]
    fn blur(&mut self, rad: &mut [f32], b: PixelBox, m: [f64; 2]) {
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
    fn sensor(
        &self,
        rad: &mut [f32],
        dirty: &[bool],
        sky_grid: &[f32],
        veil_grid: &[f32],
        streak: Option<&GlareStreak>,
        seed: u64,
    ) -> GrayImage {
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
fn bounded_blur(m: [f64; 2], w: usize, h: usize) -> [f64; 2] {
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

#[cfg(test)]
mod tests;
