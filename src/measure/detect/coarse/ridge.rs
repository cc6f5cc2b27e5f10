//! A dark region's deepest point (the centre of its largest inscribed
//! circle, on the disc even when the hose or probe has merged with it) and
//! its ridge point best ringed by light, from a chamfer distance transform
//! over the region's box.

use super::{Blob, BlobFinder, Decimated, RING_SAMPLES};

/// One sample of the ring test at a given chamfer distance: the floors of
/// rho cos and rho sin, and whether either lies so close below an integer
/// that adding the pixel coordinate in f64 might round up to it (then the
/// sample is computed in f64, exactly as without the table).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RingStep {
    du: i64,
    dv: i64,
    near: bool,
}

/// Chamfer distances with a cached ring table (larger ones, of huge
/// regions, are computed each time).
const RING_CACHE: usize = 2048;

/// The ring test's offsets at chamfer distance `di`.
fn ring_steps<'a>(
    cache: &'a mut Vec<Option<[RingStep; RING_SAMPLES]>>,
    scratch: &'a mut [RingStep; RING_SAMPLES],
    di: u32,
) -> &'a [RingStep; RING_SAMPLES] {
    let compute = |steps: &mut [RingStep; RING_SAMPLES]| {
        let rho = f64::from(di) / 3.0 * 1.25 + 1.0;
        for (step, &(sn, cs)) in steps.iter_mut().zip(RING.iter()) {
            let (tu, tv) = (rho * cs, rho * sn);
            let (fu, fv) = (tu.floor(), tv.floor());
            // x + t rounds to at most half an ulp of x + t (far below
            // 1e-6 for any image size) and never below x + floor(t).
            let near = |t: f64, f: f64| f + 1.0 - t < 1e-6;
            *step = RingStep {
                du: fu as i64,
                dv: fv as i64,
                near: near(tu, fu) || near(tv, fv),
            };
        }
    };
    let index = di as usize;
    if index >= RING_CACHE {
        compute(scratch);
        return scratch;
    }
    if cache.len() <= index {
        cache.resize(index + 1, None);
    }
    cache[index].get_or_insert_with(|| {
        let mut steps = [RingStep::default(); RING_SAMPLES];
        compute(&mut steps);
        steps
    })
}

impl BlobFinder {
    /// Fills in the blob's deepest point and its best-ringed ridge point
    /// (`core_*`, `ringed_*`). Chamfer (3-4) distance of each of its pixels
    /// to the nearest pixel outside it (or the image border), over its box
    /// and a pixel around it, kept with a ring of zeros so the passes need
    /// no bounds checks. The nearest outside pixel of a region is always
    /// one of its light 8-neighbours, so its own box is all it takes.
    #[inline(never)]
    pub fn describe_core(&mut self, img: &Decimated, blob: &mut Blob) {
        let (w, h) = (img.width, img.height);
        let Some(labels) = self.labels.get(blob.pass) else {
            return;
        };
        if labels.len() != w * h || w == 0 || h == 0 {
            return;
        }
        let label = blob.label;
        let [bx0, by0, bx1, by1] = blob.bbox;
        let (rx0, ry0) = (bx0.saturating_sub(1), by0.saturating_sub(1));
        let (rx1, ry1) = ((bx1 + 1).min(w - 1), (by1 + 1).min(h - 1));
        let pw = rx1 - rx0 + 3;
        let ph = ry1 - ry0 + 3;
        // Padded index of decimated pixel (x, y).
        let pad = |x: usize, y: usize| (y + 1 - ry0) * pw + (x + 1 - rx0);
        let d = &mut self.distance;
        d.clear();
        d.resize(pw * ph, 0);
        let inf = u32::MAX / 2;
        // Only the region's own runs are visited: the rest of its box
        // stays zero (outside the region), as the passes leave it.
        let Some(all_runs) = self.runs.get(blob.pass) else {
            return;
        };
        let runs = &mut self.blob_runs;
        runs.clear();
        runs.extend(all_runs.iter().filter(|r| r.label == label).map(|r| {
            let (y, x0, x1) = (r.y as usize, r.x0 as usize, r.x1 as usize);
            (pad(x0, y), x1 - x0, y, x0)
        }));
        for &(start, len, _, _) in runs.iter() {
            d[start..start + len].fill(inf);
        }
        // Forward pass in raster order (runs are in raster order), then
        // backward.
        for &(start, len, _, _) in runs.iter() {
            for i in start..start + len {
                d[i] = d[i]
                    .min(d[i - 1] + 3)
                    .min(d[i - pw] + 3)
                    .min(d[i - pw - 1] + 4)
                    .min(d[i - pw + 1] + 4);
            }
        }
        for &(start, len, _, _) in runs.iter().rev() {
            for i in (start..start + len).rev() {
                d[i] = d[i]
                    .min(d[i + 1] + 3)
                    .min(d[i + pw] + 3)
                    .min(d[i + pw + 1] + 4)
                    .min(d[i + pw - 1] + 4);
            }
        }
        // The deepest pixel (the first in raster order on ties).
        let mut deepest = (0u32, blob.start);
        for &(start, len, y, x0) in runs.iter() {
            for k in 0..len {
                let di = d[start + k];
                if di > deepest.0 {
                    deepest = (di, y * w + x0 + k);
                }
            }
        }
        // Ridge points (a local maximum of the distance across the region in
        // at least one direction) and the light share of a ring just
        // outside their inscribed circle. Not on the image's outermost
        // rows and columns.
        let mut ringed = (0.0f64, 0u32, 0usize);
        let mut ring_scratch = [RingStep::default(); RING_SAMPLES];
        for &(start, len, y, x0) in runs.iter() {
            if y == 0 || y + 1 >= h {
                continue;
            }
            for k in 0..len {
                let x = x0 + k;
                if x == 0 || x + 1 >= w {
                    continue;
                }
                let i = y * w + x;
                let pi = start + k;
                let di = d[pi];
                if di < 6 {
                    continue;
                }
                // Only the thick parts: the disc is among its region's
                // thickest (thin hose ends are ringed by light too).
                if 2 * di < deepest.0 {
                    continue;
                }
                let ridge = [(1, pw), (pw, 1), (pw + 1, pw - 1), (pw - 1, pw + 1)]
                    .iter()
                    .any(|&(a, b)| {
                        di >= d[pi - a]
                            && di >= d[pi + b]
                            && di >= d[pi + a]
                            && di >= d[pi - b]
                            && (di > d[pi - a] || di > d[pi + a])
                    });
                if !ridge {
                    continue;
                }
                let rho = f64::from(di) / 3.0 * 1.25 + 1.0;
                let (mut seen, mut light) = (0usize, 0usize);
                let steps = ring_steps(&mut self.ring_cache, &mut ring_scratch, di);
                for (step, &(sn, cs)) in steps.iter().zip(RING.iter()) {
                    // The sample pixel (floor of x + rho cos, y + rho sin):
                    // the precomputed integer offsets, but for offsets just
                    // below an integer, where the sum's rounding may reach
                    // it: there the float sum, as is.
                    let (u, v) = if step.near {
                        let (u, v) = (x as f64 + rho * cs, y as f64 + rho * sn);
                        (u.floor() as i64, v.floor() as i64)
                    } else {
                        (x as i64 + step.du, y as i64 + step.dv)
                    };
                    if u < 0 || v < 0 || u >= w as i64 || v >= h as i64 {
                        continue;
                    }
                    seen += 1;
                    if labels[v as usize * w + u as usize] == 0 {
                        light += 1;
                    }
                }
                // Outside the image counts as not light: the image border
                // cuts probes and clouds, and is no evidence of a canopy.
                if seen * 5 < RING_SAMPLES * 4 {
                    continue;
                }
                let share = light as f64 / RING_SAMPLES as f64;
                if share > ringed.0 || (share == ringed.0 && di > ringed.1) {
                    ringed = (share, di, i);
                }
            }
        }
        let f = img.factor as f64;
        let (share, dist, i) = ringed;
        blob.ringed_light = share;
        blob.ringed_px = img.to_full((i % w) as f64, (i / w) as f64);
        blob.ringed_radius_px = ((f64::from(dist) / 3.0) - 0.5).max(0.5) * f;
        let (dist, i) = deepest;
        blob.core_px = img.to_full((i % w) as f64, (i / w) as f64);
        // Chamfer units are 3 per pixel; the distance counts to the
        // centre of the first outside pixel, half a pixel too far.
        blob.core_radius_px = ((f64::from(dist) / 3.0) - 0.5).max(0.5) * f;
    }
}

/// Unit directions (sin, cos) of the ring test around ridge points.
static RING: std::sync::LazyLock<[(f64, f64); RING_SAMPLES]> = std::sync::LazyLock::new(|| {
    std::array::from_fn(|k| (std::f64::consts::TAU * k as f64 / RING_SAMPLES as f64).sin_cos())
});

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma};

    #[test]
    fn core_stays_on_a_disc_with_a_hose_merged_into_it() {
        // A disc of radius 40 with a long bar (a hose) leaving it to the
        // right: the centroid moves onto the bar, the core must not.
        let mut img = GrayImage::from_pixel(640, 320, Luma([180]));
        let (cx, cy, r) = (160.0, 160.0, 40.0);
        for (x, y, p) in img.enumerate_pixels_mut() {
            let (dx, dy) = (x as f64 - cx, y as f64 - cy);
            if dx * dx + dy * dy <= r * r || (dx > 0.0 && dy.abs() <= 12.0) {
                *p = Luma([30]);
            }
        }
        let mut dec = Decimated::default();
        dec.update(&img, 4);
        let mut finder = BlobFinder::default();
        let mut blobs = Vec::new();
        finder.find(&dec, &[0.5], 2, 10.0, &mut blobs);
        assert_eq!(blobs.len(), 1);
        let mut b = blobs[0].clone();
        assert!(b.centre_px[0] > cx + 40.0, "{b:?}");
        finder.describe_core(&dec, &mut b);
        let off = (b.core_px[0] - cx).hypot(b.core_px[1] - cy);
        assert!(off <= 4.0, "core {:?}", b.core_px);
        // Two decimated pixels: the block size and the chamfer metric.
        assert!((b.core_radius_px - r).abs() <= 8.0, "{}", b.core_radius_px);
        // The disc's centre is ringed by light on all sides but the hose's.
        let off = (b.ringed_px[0] - cx).hypot(b.ringed_px[1] - cy);
        assert!(off <= 8.0 && b.ringed_light >= 0.75, "{b:?}");
    }
}
