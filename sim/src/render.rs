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
//!
//! Here: the renderer, its ray tables and the order of the stages. The
//! stages: `scene` (what a frame shows), `sky`, `drogue` (and the decals),
//! `tube` (hose and probe), `sensor` (blur, streak, noise, 8-bit).

use crate::camera::SimCamera;
use crate::geometry::V3;
use image::GrayImage;

/// Sky grid spacing, pixels.
const GRID: usize = 16;

/// Pixel box (u0, v0, u1, v1), inclusive.
type PixelBox = (usize, usize, usize, usize);

mod drogue;
mod scene;
mod sensor;
mod sky;
mod tube;

pub use scene::{
    Collar, Decal, DecalShape, DrogueView, FrameScene, GlareGlow, GlareStreak, Look, Tube,
};
use sensor::{bounded_blur, inv_normal};
use sky::sky_row;
use tube::TubeLayer;

/// Renders frames of one camera: holds its per-pixel ray table, so build one
/// per lens and reuse it.
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

#[inline]
fn clamp01(x: f64) -> f64 {
    x.clamp(0.0, 1.0)
}

impl Renderer {
    /// A renderer for `cam` with the scene-wide `look`; computes every pixel's
    /// undistorted ray.
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

    /// The scene-wide look in use.
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
        let img = self.sensor(&mut rad, &dirty, &sky_grid, &veil_grid, scene);
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
}

#[cfg(test)]
mod tests;
