//! Hose and probe: 3-D tubes turned into per-pixel fragments (coverage,
//! depth, radiance) by each pixel's closest approach to the tube's axis,
//! then blended into the frame behind or in front of the drogue. Kept apart
//! from the rest because the probe's fragments are cached between frames.

use super::{DrogueView, PixelBox, Renderer, Tube, clamp01};
use crate::geometry::V3;

/// A tube's axis, precomputed for per-pixel tests.
#[derive(Clone, Copy, Debug)]
pub(super) struct TubeAxis {
    pub(super) a: V3,
    pub(super) u: V3,
    pub(super) len: f64,
    pub(super) ua: f64,
    pub(super) radius_a: f64,
    pub(super) radius_slope: f64,
}

impl TubeAxis {
    pub(super) fn new(t: &Tube) -> Option<TubeAxis> {
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
    pub(super) fn probe_ray(&self, d: &V3) -> Option<(f64, f64, f64)> {
        let (t, s, dist2) = self.closest(d)?;
        let dist = dist2.sqrt();
        let r = self.radius_at(s);
        Some((t, dist - r, dist / r.max(1e-9)))
    }

    /// Tube radius at axis position `s` (metres from `a`).
    #[inline]
    pub(super) fn radius_at(&self, s: f64) -> f64 {
        self.radius_a + self.radius_slope * s
    }

    /// Closest approach of the ray to the axis: (depth t, axis position s,
    /// squared distance), without the square root, so per-pixel callers can
    /// reject pixels clear of the tube cheaply.
    #[inline]
    pub(super) fn closest(&self, d: &V3) -> Option<(f64, f64, f64)> {
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
pub(super) struct TubeFragment {
    pub(super) u: u32,
    pub(super) v: u32,
    pub(super) depth: f64,
    pub(super) coverage: f32,
    pub(super) radiance: f32,
}

/// A tube's fragments (kept for the next frame: the probe is fixed to the
/// receiver, so its fragments stay valid while its tube is unchanged).
#[derive(Clone, Debug, Default)]
pub(super) struct TubeLayer {
    pub(super) tube: Option<Tube>,
    pub(super) fragments: Vec<TubeFragment>,
    /// Image rows holding any fragment.
    pub(super) rows: Vec<usize>,
}

impl Renderer {
    /// Per image row, the pixel span (u0, u1) that may show the tube: the
    /// axis projected at a few points, each with its radius in pixels, and
    /// the band between consecutive points.
    pub(super) fn tube_spans(&self, tube: &Tube) -> Vec<(usize, usize, usize)> {
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
    pub(super) fn rasterise_tube(&self, layer: &mut TubeLayer, tube: Option<Tube>) {
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
                let base = tube.radiance_at(s, axis.len);
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
    pub(super) fn composite_tube(
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
}
