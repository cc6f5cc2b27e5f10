//! The drogue and the decals: flat shapes in their own planes, drawn pixel
//! by pixel over their bounding box, each pixel's ray meeting the plane,
//! edges anti-aliased by their distance in pixels. The inner circle's edge,
//! which carries the truth, is supersampled.

use super::{Decal, DrogueView, PixelBox, Renderer, clamp01};
use crate::geometry::V3;

/// Index of the strut direction (cos, sin) nearest in angle to the
/// in-plane point (x, y), i.e. with the largest x cos + y sin. Around the
/// circle of evenly spaced struts that is unimodal, so climbing from
/// `start` (the neighbouring pixel's strut) takes a step or two instead of
/// a look at every strut. `dirs` must not be empty.
#[inline]
pub(super) fn nearest_strut(dirs: &[(f64, f64)], x: f64, y: f64, start: usize) -> usize {
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

impl Renderer {
    /// A decal over its box: each pixel's ray meets the decal's plane, the
    /// outline's signed distance there is turned into pixels by its change
    /// to the next pixel in u and v, and gives the coverage.
    #[inline(never)]
    pub(super) fn draw_decal(&self, rad: &mut [f32], d: &Decal, b: PixelBox) {
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
    pub(super) fn draw_drogue(&self, rad: &mut [f32], d: &DrogueView, b: PixelBox) {
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
                let mut val = d.canopy_radiance(rho, x);
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
}
