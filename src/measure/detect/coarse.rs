//! Coarse candidate search on a decimated image: dark connected regions at a
//! few thresholds between the darkest level and the typical (median) level.
//! Several thresholds because the disc merges with the probe (which is a
//! little lighter) at a high threshold, and a shaded disc breaks up at a low
//! one; the full-resolution verification decides among them.

use image::GrayImage;

/// Block-mean decimation of a frame, reusing its buffer.
#[derive(Clone, Default)]
pub struct Decimated {
    pub width: usize,
    pub height: usize,
    pub factor: usize,
    pub pixels: Vec<u8>,
}

impl Decimated {
    /// Averages `factor` x `factor` blocks (partial blocks at the right and
    /// bottom edges are dropped).
    pub fn update(&mut self, image: &GrayImage, factor: usize) {
        let factor = factor.max(1);
        let (w, h) = (image.width() as usize, image.height() as usize);
        self.factor = factor;
        self.width = w / factor;
        self.height = h / factor;
        self.pixels.clear();
        self.pixels.resize(self.width * self.height, 0);
        if self.width == 0 || self.height == 0 {
            return;
        }
        let raw = image.as_raw();
        let mut sums = vec![0u32; self.width];
        let area = (factor * factor) as u32;
        for by in 0..self.height {
            sums.iter_mut().for_each(|s| *s = 0);
            for y in by * factor..(by + 1) * factor {
                let row = &raw[y * w..y * w + self.width * factor];
                if factor == 4 {
                    for (s, block) in sums.iter_mut().zip(row.chunks_exact(4)) {
                        *s += u32::from(block[0])
                            + u32::from(block[1])
                            + u32::from(block[2])
                            + u32::from(block[3]);
                    }
                } else {
                    for (s, block) in sums.iter_mut().zip(row.chunks_exact(factor)) {
                        *s += block.iter().map(|&p| u32::from(p)).sum::<u32>();
                    }
                }
            }
            let out = &mut self.pixels[by * self.width..(by + 1) * self.width];
            for (o, s) in out.iter_mut().zip(&sums) {
                *o = ((s + area / 2) / area) as u8;
            }
        }
    }

    /// Full-resolution pixel coordinates of a decimated pixel position.
    pub fn to_full(&self, x: f64, y: f64) -> [f64; 2] {
        let f = self.factor as f64;
        [(x + 0.5) * f - 0.5, (y + 0.5) * f - 0.5]
    }
}

/// A dark connected region of the decimated image, summarised by its moments.
#[derive(Clone, Debug)]
pub struct Blob {
    /// Centroid, full-resolution pixels.
    pub centre_px: [f64; 2],
    /// Semi-axes and angle of the moment-equivalent ellipse, full-res pixels.
    pub a_px: f64,
    pub b_px: f64,
    pub theta: f64,
    /// Number of decimated pixels.
    pub area: usize,
    /// One of its pixels (decimated index).
    start: usize,
    /// The region's deepest point (farthest from its border), full-res
    /// pixels, and that distance (the inscribed radius), full-res pixels.
    /// Unlike the centroid, it stays on the disc when a long hose or probe
    /// merges with it.
    pub core_px: [f64; 2],
    pub core_radius_px: f64,
    /// The point of the region's medial ridge best surrounded by light (a
    /// disc with a probe as wide as itself merged into it has no deepest
    /// point of its own, but its centre is still ringed by the light
    /// canopy), its inscribed radius, full-res pixels, and the light share
    /// of the ring around it (0 when the region has no ridge).
    pub ringed_px: [f64; 2],
    pub ringed_radius_px: f64,
    pub ringed_light: f64,
    /// The dark region at the highest threshold that holds this one (the
    /// regions of a lower threshold are parts of those of a higher one):
    /// blobs with the same `region` are one dark area of the frame, seen at
    /// several thresholds or broken into parts.
    pub region: u32,
    /// Number of decimated pixels of that highest-threshold region.
    pub region_area: usize,
    /// Index of the threshold (in the configured list) the blob was found at.
    pub level: usize,
}

/// The level below which `fraction` of the pixels lie.
fn percentile(pixels: &[u8], fraction: f64) -> u8 {
    let mut hist = [0usize; 256];
    for &p in pixels {
        hist[p as usize] += 1;
    }
    let target = (pixels.len() as f64 * fraction) as usize;
    let mut acc = 0;
    for (level, &count) in hist.iter().enumerate() {
        acc += count;
        if acc > target {
            return level as u8;
        }
    }
    255
}

/// Scratch for the labelling.
#[derive(Clone, Default)]
pub struct BlobFinder {
    labels: Vec<u32>,
    stack: Vec<u32>,
    distance: Vec<u32>,
    /// Per label: index into the output, and the deepest pixel.
    label_out: Vec<Option<usize>>,
    deepest: Vec<(u32, usize)>,
    ringed: Vec<(f64, u32, usize)>,
    /// Labels of the highest threshold, and the size of each of its regions.
    region_labels: Vec<u32>,
    region_areas: Vec<usize>,
}

/// Directions of the ring test around ridge points.
const RING_SAMPLES: usize = 24;

impl BlobFinder {
    /// Dark regions at each threshold fraction between the darkest level and
    /// the median level. Regions smaller than `min_area` decimated pixels are
    /// dropped. Returns nothing when the image has less than
    /// `min_contrast` gray levels between its darkest and median level.
    pub fn find(
        &mut self,
        img: &Decimated,
        fractions: &[f64],
        min_area: usize,
        min_contrast: f64,
        out: &mut Vec<Blob>,
    ) {
        out.clear();
        if img.pixels.is_empty() {
            return;
        }
        let lo = f64::from(*img.pixels.iter().min().unwrap_or(&0));
        let hi = f64::from(percentile(&img.pixels, 0.5));
        if hi - lo < min_contrast {
            return;
        }
        // Highest threshold first: its regions hold those of the lower ones.
        let mut order: Vec<usize> = (0..fractions.len()).collect();
        order.sort_by(|&i, &j| fractions[j].total_cmp(&fractions[i]));
        for (pass, &level) in order.iter().enumerate() {
            let threshold = lo + fractions[level] * (hi - lo);
            let first = out.len();
            self.label(img, threshold, min_area, out);
            if pass == 0 {
                self.region_labels.clone_from(&self.labels);
                self.region_areas.clear();
                self.region_areas.resize(self.label_out.len(), 0);
            }
            for b in &mut out[first..] {
                b.level = level;
                b.region = self.region_labels[b.start];
                if pass == 0 {
                    self.region_areas[b.region as usize] = b.area;
                }
                b.region_area = self.region_areas[b.region as usize];
            }
        }
    }

    fn label(&mut self, img: &Decimated, threshold: f64, min_area: usize, out: &mut Vec<Blob>) {
        let (w, h) = (img.width, img.height);
        self.labels.clear();
        self.labels.resize(w * h, 0);
        // Integer levels: p <= threshold exactly when p <= floor(threshold).
        let level = threshold.floor().clamp(-1.0, 255.0) as i32;
        let pixels = &img.pixels;
        let dark = |i: usize| i32::from(pixels[i]) <= level;
        let first_out = out.len();
        // Union of the kept regions' boxes: the distance transform runs there only.
        let mut region = [usize::MAX, usize::MAX, 0usize, 0usize];
        self.label_out.clear();
        self.label_out.push(None);
        let mut next = 1u32;
        for start in 0..w * h {
            if self.labels[start] != 0 || !dark(start) {
                continue;
            }
            self.labels[start] = next;
            self.stack.clear();
            self.stack.push(start as u32);
            let (mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy) =
                (0usize, 0.0, 0.0, 0.0, 0.0, 0.0);
            let mut bbox = [usize::MAX, usize::MAX, 0usize, 0usize];
            while let Some(i) = self.stack.pop() {
                let i = i as usize;
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                n += 1;
                sx += x;
                sy += y;
                sxx += x * x;
                sxy += x * y;
                syy += y * y;
                let (xi, yi) = (i % w, i / w);
                bbox = [
                    bbox[0].min(xi),
                    bbox[1].min(yi),
                    bbox[2].max(xi),
                    bbox[3].max(yi),
                ];
                // The 8 neighbours inside the image.
                let (x0, x1) = (xi.saturating_sub(1), (xi + 1).min(w - 1));
                let (y0, y1) = (yi.saturating_sub(1), (yi + 1).min(h - 1));
                for ny in y0..y1 + 1 {
                    for j in ny * w + x0..ny * w + x1 + 1 {
                        if self.labels[j] == 0 && dark(j) {
                            self.labels[j] = next;
                            self.stack.push(j as u32);
                        }
                    }
                }
            }
            next += 1;
            if n < min_area {
                self.label_out.push(None);
                continue;
            }
            self.label_out.push(Some(out.len()));
            region = [
                region[0].min(bbox[0].saturating_sub(1)),
                region[1].min(bbox[1].saturating_sub(1)),
                region[2].max((bbox[2] + 1).min(w - 1)),
                region[3].max((bbox[3] + 1).min(h - 1)),
            ];
            let nf = n as f64;
            let (mx, my) = (sx / nf, sy / nf);
            // Second central moments; a filled ellipse has variance a^2/4
            // along its major axis.
            let cxx = sxx / nf - mx * mx + 1.0 / 12.0;
            let cyy = syy / nf - my * my + 1.0 / 12.0;
            let cxy = sxy / nf - mx * my;
            let tr = cxx + cyy;
            let det = cxx * cyy - cxy * cxy;
            let disc = (tr * tr / 4.0 - det).max(0.0).sqrt();
            let (l1, l2) = (tr / 2.0 + disc, (tr / 2.0 - disc).max(1e-6));
            let theta = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
            let f = img.factor as f64;
            let (a, b) = (2.0 * l1.sqrt(), 2.0 * l2.sqrt());
            out.push(Blob {
                centre_px: img.to_full(mx, my),
                a_px: a * f,
                b_px: b * f,
                theta,
                area: n,
                start,
                region: 0,
                region_area: 0,
                level: 0,
                core_px: [0.0; 2],
                core_radius_px: 0.0,
                ringed_px: [0.0; 2],
                ringed_radius_px: 0.0,
                ringed_light: 0.0,
            });
        }
        if out.len() > first_out {
            self.deepest_points(img, region, first_out, out);
        }
    }

    /// Chamfer (3-4) distance of every dark pixel to the nearest non-dark
    /// pixel or the image border, and each region's deepest pixel.
    /// `region`: [x0, y0, x1, y1] (inclusive) holding the regions and a
    /// pixel around them.
    fn deepest_points(
        &mut self,
        img: &Decimated,
        region: [usize; 4],
        first_out: usize,
        out: &mut [Blob],
    ) {
        let (w, h) = (img.width, img.height);
        let [rx0, ry0, rx1, ry1] = region;
        let d = &mut self.distance;
        d.clear();
        d.resize(w * h, 0);
        let labels = &self.labels;
        let inf = u32::MAX / 2;
        for y in ry0..=ry1 {
            for i in y * w + rx0..=y * w + rx1 {
                if labels[i] != 0 {
                    d[i] = inf;
                }
            }
        }
        let at = |d: &Vec<u32>, x: i64, y: i64| -> u32 {
            if x < rx0 as i64 || y < ry0 as i64 || x > rx1 as i64 || y > ry1 as i64 {
                0
            } else {
                d[y as usize * w + x as usize]
            }
        };
        for y in ry0 as i64..=ry1 as i64 {
            for x in rx0 as i64..=rx1 as i64 {
                let i = y as usize * w + x as usize;
                if d[i] == 0 {
                    continue;
                }
                let v = d[i]
                    .min(at(d, x - 1, y) + 3)
                    .min(at(d, x, y - 1) + 3)
                    .min(at(d, x - 1, y - 1) + 4)
                    .min(at(d, x + 1, y - 1) + 4);
                d[i] = v;
            }
        }
        for y in (ry0 as i64..=ry1 as i64).rev() {
            for x in (rx0 as i64..=rx1 as i64).rev() {
                let i = y as usize * w + x as usize;
                if d[i] == 0 {
                    continue;
                }
                let v = d[i]
                    .min(at(d, x + 1, y) + 3)
                    .min(at(d, x, y + 1) + 3)
                    .min(at(d, x + 1, y + 1) + 4)
                    .min(at(d, x - 1, y + 1) + 4);
                d[i] = v;
            }
        }
        self.deepest.clear();
        self.deepest.resize(out.len() - first_out, (0, 0));
        for y in ry0..ry1 + 1 {
            for i in y * w + rx0..y * w + rx1 + 1 {
                if let Some(Some(o)) = self.label_out.get(labels[i] as usize) {
                    let slot = &mut self.deepest[o - first_out];
                    if d[i] > slot.0 {
                        *slot = (d[i], i);
                    }
                }
            }
        }
        // Ridge points (a local maximum of the distance across the region in
        // at least one direction) and the light share of a ring just
        // outside their inscribed circle.
        self.ringed.clear();
        self.ringed.resize(out.len() - first_out, (0.0, 0, 0));
        let ring: Vec<(f64, f64)> = (0..RING_SAMPLES)
            .map(|k| (std::f64::consts::TAU * k as f64 / RING_SAMPLES as f64).sin_cos())
            .collect();
        for y in ry0.max(1)..=ry1.min(h.saturating_sub(2)) {
            for x in rx0.max(1)..=rx1.min(w.saturating_sub(2)) {
                let i = y * w + x;
                let di = d[i];
                if di < 6 {
                    continue;
                }
                let Some(Some(o)) = self.label_out.get(labels[i] as usize) else {
                    continue;
                };
                // Only the thick parts: the disc is among its region's
                // thickest (thin hose ends are ringed by light too).
                if 2 * di < self.deepest[o - first_out].0 {
                    continue;
                }
                let ridge =
                    [(1, w), (w, 1), (w + 1, w - 1), (w - 1, w + 1)]
                        .iter()
                        .any(|&(a, b)| {
                            di >= d[i - a]
                                && di >= d[i + b]
                                && di >= d[i + a]
                                && di >= d[i - b]
                                && (di > d[i - a] || di > d[i + a])
                        });
                if !ridge {
                    continue;
                }
                let rho = f64::from(di) / 3.0 * 1.25 + 1.0;
                let (mut seen, mut light) = (0usize, 0usize);
                for &(sn, cs) in &ring {
                    let (u, v) = (x as f64 + rho * cs, y as f64 + rho * sn);
                    if u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
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
                let slot = &mut self.ringed[o - first_out];
                if share > slot.0 || (share == slot.0 && di > slot.1) {
                    *slot = (share, di, i);
                }
            }
        }
        let f = img.factor as f64;
        for (blob, &(share, dist, i)) in out[first_out..].iter_mut().zip(&self.ringed) {
            blob.ringed_light = share;
            blob.ringed_px = img.to_full((i % w) as f64, (i / w) as f64);
            blob.ringed_radius_px = ((f64::from(dist) / 3.0) - 0.5).max(0.5) * f;
        }
        for (blob, &(dist, i)) in out[first_out..].iter_mut().zip(&self.deepest) {
            blob.core_px = img.to_full((i % w) as f64, (i / w) as f64);
            // Chamfer units are 3 per pixel; the distance counts to the
            // centre of the first outside pixel, half a pixel too far.
            blob.core_radius_px = ((f64::from(dist) / 3.0) - 0.5).max(0.5) * f;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    #[test]
    fn finds_a_dark_disc_with_its_size_and_centre() {
        let mut img = GrayImage::from_pixel(320, 240, Luma([180]));
        let (cx, cy, r) = (150.0, 100.0, 30.0);
        for (x, y, p) in img.enumerate_pixels_mut() {
            if (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2) <= r * r {
                *p = Luma([30]);
            }
        }
        let mut dec = Decimated::default();
        dec.update(&img, 4);
        assert_eq!((dec.width, dec.height), (80, 60));
        let mut blobs = Vec::new();
        BlobFinder::default().find(&dec, &[0.5], 2, 10.0, &mut blobs);
        assert_eq!(blobs.len(), 1);
        let b = &blobs[0];
        assert!((b.centre_px[0] - cx).abs() < 1.5 && (b.centre_px[1] - cy).abs() < 1.5);
        assert!(
            (b.a_px - r).abs() < 3.0 && (b.b_px - r).abs() < 3.0,
            "{b:?}"
        );
    }

    #[test]
    fn uniform_image_has_no_blobs() {
        let img = GrayImage::from_pixel(64, 64, Luma([100]));
        let mut dec = Decimated::default();
        dec.update(&img, 4);
        let mut blobs = Vec::new();
        BlobFinder::default().find(&dec, &[0.3, 0.5], 1, 10.0, &mut blobs);
        assert!(blobs.is_empty());
    }
}
