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
    /// Scratch: column sums of one block row.
    column_sums: Vec<u16>,
}

impl Decimated {
    /// Averages `factor` x `factor` blocks (partial blocks at the right and
    /// bottom edges are dropped).
    #[inline(never)]
    pub fn update(&mut self, image: &GrayImage, factor: usize) {
        // u16 column sums hold up to 257 rows of 255.
        let factor = factor.clamp(1, 256);
        let (w, h) = (image.width() as usize, image.height() as usize);
        self.factor = factor;
        self.width = w / factor;
        self.height = h / factor;
        // Every pixel is written below: no need to zero a buffer of the
        // right size.
        if self.pixels.len() != self.width * self.height {
            self.pixels.clear();
            self.pixels.resize(self.width * self.height, 0);
        }
        if self.width == 0 || self.height == 0 {
            return;
        }
        let raw = image.as_raw();
        // Column sums of a block row first (u16: at most 16 x 255), a loop
        // the compiler vectorises, then the sums of `factor` columns.
        let used = self.width * factor;
        self.column_sums.clear();
        self.column_sums.resize(used, 0);
        let area = (factor * factor) as u32;
        if factor == 4 {
            self.update_by_4(raw, w);
            return;
        }
        for by in 0..self.height {
            let top = by * factor;
            let first = &raw[top * w..top * w + used];
            for (s, &p) in self.column_sums.iter_mut().zip(first) {
                *s = u16::from(p);
            }
            for y in top + 1..top + factor {
                let row = &raw[y * w..y * w + used];
                for (s, &p) in self.column_sums.iter_mut().zip(row) {
                    *s += u16::from(p);
                }
            }
            let out = &mut self.pixels[by * self.width..(by + 1) * self.width];
            if factor == 4 {
                // The default, unrolled: a rounded division by 16.
                for (o, b) in out.iter_mut().zip(self.column_sums.chunks_exact(4)) {
                    let s = u32::from(b[0]) + u32::from(b[1]) + u32::from(b[2]) + u32::from(b[3]);
                    *o = ((s + 8) >> 4) as u8;
                }
            } else {
                for (o, block) in out.iter_mut().zip(self.column_sums.chunks_exact(factor)) {
                    let s: u32 = block.iter().map(|&v| u32::from(v)).sum();
                    *o = ((s + area / 2) / area) as u8;
                }
            }
        }
    }

    /// The default factor 4, eight columns (two blocks) at a time in a u64:
    /// the sums of pixel pairs of the four rows in u16 lanes (at most
    /// 8 x 255), then of lane pairs in u32 lanes (a block's sum), with a
    /// rounded division by 16. The same means as the general loop.
    fn update_by_4(&mut self, raw: &[u8], w: usize) {
        const BYTES: u64 = 0x00ff_00ff_00ff_00ff;
        const HALVES: u64 = 0x0000_ffff_0000_ffff;
        let used = self.width * 4;
        let pairs = |chunk: &[u8]| {
            let mut bytes = [0u8; 8];
            bytes.copy_from_slice(chunk);
            let v = u64::from_le_bytes(bytes);
            (v & BYTES) + ((v >> 8) & BYTES)
        };
        for (by, out) in self.pixels.chunks_exact_mut(self.width).enumerate() {
            let row = |k: usize| {
                let y = by * 4 + k;
                raw.get(y * w..y * w + used).unwrap_or(&[])
            };
            let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
            let chunks = r0
                .chunks_exact(8)
                .zip(r1.chunks_exact(8))
                .zip(r2.chunks_exact(8).zip(r3.chunks_exact(8)));
            let mut outs = out.chunks_exact_mut(2);
            for (o, ((a, b), (c, d))) in (&mut outs).zip(chunks) {
                let lanes = pairs(a) + pairs(b) + pairs(c) + pairs(d);
                let sums = (lanes & HALVES) + ((lanes >> 16) & HALVES);
                let means = (sums + 0x0000_0008_0000_0008) >> 4;
                o[0] = means as u8;
                o[1] = (means >> 32) as u8;
            }
            // An odd last block.
            if let Some(last) = outs.into_remainder().first_mut() {
                let x = used - 4;
                let mut t = 0u32;
                for r in [r0, r1, r2, r3] {
                    if let Some(block) = r.get(x..x + 4) {
                        t += block.iter().map(|&p| u32::from(p)).sum::<u32>();
                    }
                }
                *last = ((t + 8) >> 4) as u8;
            }
        }
    }

    /// Whether a box [x0, y0, x1, y1] (inclusive, decimated pixels) touches
    /// the image's outermost rows or columns.
    pub fn touches_border(&self, bbox: [usize; 4]) -> bool {
        let [x0, y0, x1, y1] = bbox;
        x0 == 0 || y0 == 0 || x1 + 1 >= self.width || y1 + 1 >= self.height
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
    /// Its first pixel in raster order (decimated index).
    start: usize,
    /// Its label in the label image of pass `pass`, and its bounding box
    /// [x0, y0, x1, y1] (inclusive, decimated pixels).
    label: u32,
    pass: usize,
    bbox: [usize; 4],
    /// The region's deepest point (farthest from its border), full-res
    /// pixels, and that distance (the inscribed radius), full-res pixels.
    /// This and `ringed_*` are filled in by [`BlobFinder::describe_core`],
    /// only for the blobs that get that far.
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

impl Blob {
    /// Whether the region's moments can describe a whole disc: not cut by
    /// the frame's border (the receiver's own probe always is) and no more
    /// elongated than the most tilted disc. A disc merged with the hose or
    /// probe is neither, and is still tried, after these.
    pub fn whole_and_round(&self, img: &Decimated, min_axis_ratio: f64) -> bool {
        !img.touches_border(self.bbox) && self.b_px >= min_axis_ratio * self.a_px
    }
}

/// The darkest level and the level below which `fraction` of the pixels
/// lie, from one histogram.
fn darkest_and_percentile(pixels: &[u8], fraction: f64) -> (u8, u8) {
    // Four interleaved histograms: runs of one level (a uniform sky) would
    // otherwise make every increment wait for the one before.
    let mut hists = [[0u32; 256]; 4];
    let mut quads = pixels.chunks_exact(4);
    for q in &mut quads {
        for (hist, &p) in hists.iter_mut().zip(q) {
            hist[p as usize] += 1;
        }
    }
    for &p in quads.remainder() {
        hists[0][p as usize] += 1;
    }
    let hist: [usize; 256] =
        std::array::from_fn(|level| hists.iter().map(|h| h[level] as usize).sum());
    let darkest = hist.iter().position(|&c| c > 0).unwrap_or(0) as u8;
    let target = (pixels.len() as f64 * fraction) as usize;
    let mut acc = 0;
    for (level, &count) in hist.iter().enumerate() {
        acc += count;
        if acc > target {
            return (darkest, level as u8);
        }
    }
    (darkest, 255)
}

/// Scratch for the labelling.
#[derive(Clone, Default)]
pub struct BlobFinder {
    /// The label image of each pass (highest threshold first), and its
    /// width: only the runs of the previous frame are cleared in it.
    labels: Vec<Vec<u32>>,
    label_widths: Vec<usize>,
    /// The dark runs of each pass, in raster order, with their labels.
    runs: Vec<Vec<Run>>,
    moments: Vec<RegionMoments>,
    /// Chamfer distances over a blob's box, with a ring of zeros.
    distance: Vec<u32>,
    /// A blob's runs: (padded index of the first pixel, length, y, x0).
    blob_runs: Vec<(usize, usize, usize, usize)>,
    /// Size of each region of the highest threshold.
    region_areas: Vec<usize>,
    /// The ring test's offsets for each chamfer distance (below
    /// [`RING_CACHE`]), computed when first needed.
    ring_cache: Vec<Option<[RingStep; RING_SAMPLES]>>,
}

/// One sample of the ring test at a given chamfer distance: the floors of
/// rho cos and rho sin, and whether either lies so close below an integer
/// that adding the pixel coordinate in f64 might round up to it (then the
/// sample is computed in f64, exactly as without the table).
#[derive(Clone, Copy, Debug, Default)]
struct RingStep {
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

/// A run of dark pixels `x0..x1` of row `y`, a node of the union-find.
#[derive(Clone, Copy, Debug)]
struct Run {
    y: u32,
    x0: u32,
    x1: u32,
    parent: u32,
    /// The region's label (1, 2, ... in raster order), once known.
    label: u32,
}

fn find_root(runs: &mut [Run], mut r: usize) -> usize {
    while runs[r].parent as usize != r {
        // Path halving.
        let grandparent = runs[runs[r].parent as usize].parent;
        runs[r].parent = grandparent;
        r = grandparent as usize;
    }
    r
}

/// Joins two runs' sets; the root with the lower index (the earlier run)
/// stays the root.
fn union(runs: &mut [Run], a: usize, b: usize) {
    let (ra, rb) = (find_root(runs, a), find_root(runs, b));
    if ra != rb {
        let (keep, join) = (ra.min(rb), ra.max(rb));
        runs[join].parent = keep as u32;
    }
}

/// Integer moments of a region (exact), its first pixel and bounding box.
#[derive(Clone, Copy, Debug, Default)]
struct RegionMoments {
    n: usize,
    sx: u64,
    sy: u64,
    sxx: u64,
    sxy: u64,
    syy: u64,
    /// Index of its first pixel in raster order.
    start: usize,
    /// [x0, y0, x1, y1], inclusive.
    bbox: [usize; 4],
}

impl RegionMoments {
    fn add_run(&mut self, run: &Run) {
        let (x0, x1, y) = (u64::from(run.x0), u64::from(run.x1), u64::from(run.y));
        let n = x1 - x0;
        // Sums of x and x^2 over x0..x1 from the closed forms of 0..k.
        let s1 = |k: u64| k * k.saturating_sub(1) / 2;
        let s2 = |k: u64| k.saturating_sub(1) * k * (2 * k).saturating_sub(1) / 6;
        let sx = s1(x1) - s1(x0);
        self.n += n as usize;
        self.sx += sx;
        self.sy += y * n;
        self.sxx += s2(x1) - s2(x0);
        self.sxy += y * sx;
        self.syy += y * y * n;
        self.bbox = [
            self.bbox[0].min(run.x0 as usize),
            self.bbox[1].min(run.y as usize),
            self.bbox[2].max(run.x1 as usize - 1),
            self.bbox[3].max(run.y as usize),
        ];
    }
}

/// Directions of the ring test around ridge points.
const RING_SAMPLES: usize = 24;

impl BlobFinder {
    /// Dark regions at each threshold fraction between the darkest level and
    /// the median level. Regions smaller than `min_area` decimated pixels are
    /// dropped. Returns nothing when the image has less than
    /// `min_contrast` gray levels between its darkest and median level.
    #[inline(never)]
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
        let (darkest, median) = darkest_and_percentile(&img.pixels, 0.5);
        let (lo, hi) = (f64::from(darkest), f64::from(median));
        if hi - lo < min_contrast {
            return;
        }
        // Highest threshold first: its regions hold those of the lower ones.
        let mut order: Vec<usize> = (0..fractions.len()).collect();
        order.sort_by(|&i, &j| fractions[j].total_cmp(&fractions[i]));
        self.labels.resize_with(order.len(), Vec::new);
        self.label_widths.resize(order.len(), 0);
        self.runs.resize_with(order.len(), Vec::new);
        for (pass, &level) in order.iter().enumerate() {
            let threshold = lo + fractions[level] * (hi - lo);
            let first = out.len();
            self.label(img, threshold, min_area, pass, out);
            if pass == 0 {
                self.region_areas.clear();
                self.region_areas.resize(self.moments.len(), 0);
            }
            for b in &mut out[first..] {
                b.level = level;
                b.region = self.labels[0][b.start];
                if pass == 0 {
                    self.region_areas[b.region as usize] = b.area;
                }
                b.region_area = self.region_areas[b.region as usize];
            }
        }
    }

    /// Labels the 8-connected dark regions (pixels <= `threshold`) in
    /// raster order of their first pixel, and summarises those of at least
    /// `min_area` pixels. Works on runs of dark pixels per row, joined
    /// across rows by union-find: far fewer steps than a pixel flood fill,
    /// and the moments of a run have closed forms.
    fn label(
        &mut self,
        img: &Decimated,
        threshold: f64,
        min_area: usize,
        pass: usize,
        out: &mut Vec<Blob>,
    ) {
        let (w, h) = (img.width, img.height);
        // Integer levels: p <= threshold exactly when p <= floor(threshold).
        let level = threshold.floor().clamp(-1.0, 255.0) as i32;
        // The label image is all zeros but for the previous runs of this
        // pass (when it has the same size): clear those, not the whole image.
        let labels = &mut self.labels[pass];
        if labels.len() == w * h && self.label_widths[pass] == w {
            for run in &self.runs[pass] {
                let row = run.y as usize * w;
                labels[row + run.x0 as usize..row + run.x1 as usize].fill(0);
            }
        } else {
            labels.clear();
            labels.resize(w * h, 0);
            self.label_widths[pass] = w;
        }
        self.find_runs(img, level, pass);
        let runs = &mut self.runs[pass];

        // Components numbered in raster order of their first run, which
        // holds their first pixel.
        self.moments.clear();
        self.moments.push(RegionMoments::default());
        for r in 0..runs.len() {
            let root = find_root(runs, r);
            let label = if runs[root].label == 0 {
                let label = self.moments.len() as u32;
                runs[root].label = label;
                let first = &runs[r];
                self.moments.push(RegionMoments {
                    start: first.y as usize * w + first.x0 as usize,
                    bbox: [usize::MAX, usize::MAX, 0, 0],
                    ..RegionMoments::default()
                });
                label
            } else {
                runs[root].label
            };
            runs[r].label = label;
            self.moments[label as usize].add_run(&runs[r]);
        }

        let labels = &mut self.labels[pass];
        for run in runs.iter() {
            let row = run.y as usize * w;
            labels[row + run.x0 as usize..row + run.x1 as usize].fill(run.label);
        }

        for (label, m) in self.moments.iter().enumerate().skip(1) {
            if m.n < min_area {
                continue;
            }
            // Exact integer sums (as f64 they are exact below 2^53).
            let n = m.n;
            let nf = n as f64;
            let (sx, sy) = (m.sx as f64, m.sy as f64);
            let (sxx, sxy, syy) = (m.sxx as f64, m.sxy as f64, m.syy as f64);
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
                start: m.start,
                label: label as u32,
                pass,
                bbox: m.bbox,
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
    }

    /// The runs of dark pixels (<= `level`) of each row, in raster order,
    /// each joined (union-find) to the 8-connected runs of the row above.
    fn find_runs(&mut self, img: &Decimated, level: i32, pass: usize) {
        let w = img.width;
        let runs = &mut self.runs[pass];
        runs.clear();
        let mut above = 0..0;
        for (y, row) in img.pixels.chunks_exact(w).enumerate() {
            let first = runs.len();
            let mut x = 0;
            while x < w {
                // Skip light pixels, 16 at a time while a whole block is light.
                // (The block's minimum: no early exit, so it vectorises.)
                while x + 16 <= w
                    && i32::from(row[x..x + 16].iter().fold(u8::MAX, |m, &p| m.min(p))) > level
                {
                    x += 16;
                }
                while x < w && i32::from(row[x]) > level {
                    x += 1;
                }
                if x == w {
                    break;
                }
                let x0 = x;
                // Dark pixels, 16 at a time while a whole block is dark.
                while x + 16 <= w
                    && i32::from(row[x..x + 16].iter().fold(0, |m: u8, &p| m.max(p))) <= level
                {
                    x += 16;
                }
                while x < w && i32::from(row[x]) <= level {
                    x += 1;
                }
                let index = runs.len();
                runs.push(Run {
                    y: y as u32,
                    x0: x0 as u32,
                    x1: x as u32,
                    parent: index as u32,
                    label: 0,
                });
            }
            // 8-connected: [x0, x1) and [u0, u1) touch when x0 <= u1 and u0 <= x1.
            let current = first..runs.len();
            let mut j = above.start;
            for i in current.clone() {
                while j < above.end && runs[j].x1 < runs[i].x0 {
                    j += 1;
                }
                let mut k = j;
                while k < above.end && runs[k].x0 <= runs[i].x1 {
                    union(runs, i, k);
                    k += 1;
                }
            }
            above = current;
        }
    }

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

    /// The regions by a plain 8-connected pixel flood fill: (first pixel,
    /// area, centroid), in raster order of their first pixel.
    fn flood_fill_regions(img: &Decimated, level: i32) -> Vec<(usize, usize, [f64; 2])> {
        let (w, h) = (img.width, img.height);
        let dark = |i: usize| i32::from(img.pixels[i]) <= level;
        let mut seen = vec![false; w * h];
        let mut regions = Vec::new();
        for start in 0..w * h {
            if seen[start] || !dark(start) {
                continue;
            }
            seen[start] = true;
            let mut stack = vec![start];
            let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
            while let Some(i) = stack.pop() {
                let (x, y) = (i % w, i / w);
                n += 1;
                sx += x as f64;
                sy += y as f64;
                for ny in y.saturating_sub(1)..(y + 2).min(h) {
                    for nx in x.saturating_sub(1)..(x + 2).min(w) {
                        let j = ny * w + nx;
                        if !seen[j] && dark(j) {
                            seen[j] = true;
                            stack.push(j);
                        }
                    }
                }
            }
            regions.push((start, n, img.to_full(sx / n as f64, sy / n as f64)));
        }
        regions
    }

    #[test]
    fn run_labelling_matches_a_pixel_flood_fill() {
        use rand::{Rng, SeedableRng};
        // Smoothed noise: regions with holes, spirals of U-shapes that
        // join rows below, and single pixels touching only diagonally.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for trial in 0..20 {
            let (w, h) = (37 + trial, 29 + 2 * trial);
            let noise: Vec<f64> = (0..w * h).map(|_| rng.random_range(0.0..255.0)).collect();
            let smooth = trial % 3;
            let pixels: Vec<u8> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as i64, (i / w) as i64);
                    let (mut sum, mut count) = (0.0, 0.0);
                    for dy in -(smooth as i64)..=smooth as i64 {
                        for dx in -(smooth as i64)..=smooth as i64 {
                            let (u, v) = (x + dx, y + dy);
                            if u >= 0 && v >= 0 && u < w as i64 && v < h as i64 {
                                sum += noise[v as usize * w + u as usize];
                                count += 1.0;
                            }
                        }
                    }
                    (sum / count) as u8
                })
                .collect();
            let img = Decimated {
                width: w,
                height: h,
                factor: 4,
                pixels,
                column_sums: Vec::new(),
            };
            let lo = f64::from(*img.pixels.iter().min().unwrap());
            let mut sorted = img.pixels.clone();
            sorted.sort_unstable();
            let hi = f64::from(sorted[sorted.len() / 2]);
            assert_eq!(
                darkest_and_percentile(&img.pixels, 0.5),
                (lo as u8, hi as u8),
                "trial {trial}"
            );
            for fraction in [0.3, 0.6, 0.9] {
                let threshold = lo + fraction * (hi - lo);
                let mut blobs = Vec::new();
                BlobFinder::default().find(&img, &[fraction], 1, 0.0, &mut blobs);
                let expected = flood_fill_regions(&img, threshold.floor() as i32);
                assert_eq!(blobs.len(), expected.len(), "trial {trial} at {fraction}");
                for (b, (start, n, centre)) in blobs.iter().zip(&expected) {
                    assert_eq!((b.start, b.area), (*start, *n));
                    assert!((b.centre_px[0] - centre[0]).abs() < 1e-9);
                    assert!((b.centre_px[1] - centre[1]).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn a_reused_finder_labels_as_a_new_one() {
        // The label images are cleared run by run between frames: a finder
        // that has seen other frames (and other sizes) finds the same blobs,
        // cores and ringed points as a fresh one.
        let disc = |w: u32, h: u32, cx: f64, cy: f64, r: f64| {
            GrayImage::from_fn(w, h, |x, y| {
                let d = (x as f64 - cx).hypot(y as f64 - cy);
                Luma([
                    if d <= r || (x as f64 > cx && (y as f64 - cy).abs() < 6.0) {
                        30
                    } else {
                        180
                    },
                ])
            })
        };
        let frames = [
            disc(320, 240, 150.0, 100.0, 30.0),
            disc(320, 240, 90.0, 160.0, 45.0),
            disc(240, 320, 100.0, 200.0, 25.0),
            disc(320, 240, 200.0, 60.0, 20.0),
        ];
        let mut reused = BlobFinder::default();
        for (k, img) in frames.iter().enumerate() {
            let mut dec = Decimated::default();
            dec.update(img, 4);
            let (mut a, mut b) = (Vec::new(), Vec::new());
            let mut fresh = BlobFinder::default();
            fresh.find(&dec, &[0.15, 0.3, 0.5], 2, 10.0, &mut a);
            reused.find(&dec, &[0.15, 0.3, 0.5], 2, 10.0, &mut b);
            assert!(!a.is_empty(), "frame {k}");
            assert_eq!(a.len(), b.len(), "frame {k}");
            for (x, y) in a.iter_mut().zip(b.iter_mut()) {
                fresh.describe_core(&dec, x);
                reused.describe_core(&dec, y);
                assert_eq!(format!("{x:?}"), format!("{y:?}"), "frame {k}");
            }
        }
    }

    #[test]
    fn decimation_is_the_rounded_block_mean() {
        // Widths of an even and an odd number of 4-blocks, and of fewer
        // than two.
        for (w, h, factor) in [
            (67, 45, 1usize),
            (67, 45, 3),
            (67, 45, 4),
            (71, 45, 4),
            (7, 9, 4),
            (3, 9, 4),
            (67, 45, 16),
        ] {
            let img = GrayImage::from_fn(w, h, |x, y| Luma([((x * 37 + y * 91) % 256) as u8]));
            let mut dec = Decimated::default();
            dec.update(&img, factor);
            assert_eq!(
                (dec.width, dec.height),
                (w as usize / factor, h as usize / factor)
            );
            for by in 0..dec.height {
                for bx in 0..dec.width {
                    let mut sum = 0u32;
                    for y in by * factor..(by + 1) * factor {
                        for x in bx * factor..(bx + 1) * factor {
                            sum += u32::from(img.get_pixel(x as u32, y as u32)[0]);
                        }
                    }
                    let area = (factor * factor) as f64;
                    let mean = (f64::from(sum) / area + 0.5).floor() as u8;
                    assert_eq!(
                        dec.pixels[by * dec.width + bx],
                        mean,
                        "{factor} at {bx},{by}"
                    );
                }
            }
        }
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
