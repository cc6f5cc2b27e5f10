//! Coarse candidate search on a decimated image: dark connected regions at a
//! few thresholds between the darkest level and the typical (median) level.
//! Several thresholds because the disc merges with the probe (which is a
//! little lighter) at a high threshold, and a shaded disc breaks up at a low
//! one; the full-resolution verification decides among them.
//!
//! `decimate`: the block-mean frame the search runs on; this module: the
//! run-length labelling of its dark regions and their moments; `ridge`:
//! each kept region's deepest point and its point best ringed by light.

mod decimate;
mod local;
mod ridge;

pub use decimate::Decimated;
pub use local::{
    LocalContrast, MASK_THRESHOLD as LOCAL_MASK_THRESHOLD, RADIUS_RATIO as LOCAL_RADIUS_RATIO,
    window_sides,
};
use ridge::RingStep;

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
    /// `ridge::RING_CACHE`), computed when first needed.
    ring_cache: Vec<Option<[RingStep; RING_SAMPLES]>>,
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
        let levels: Vec<f64> = fractions.iter().map(|f| lo + f * (hi - lo)).collect();
        self.find_below(img, &levels, min_area, out);
    }

    /// Dark regions (pixels at or below each of `levels`, gray) of at
    /// least `min_area` decimated pixels; each blob's `level` is the index
    /// of its level in `levels`.
    pub fn find_below(
        &mut self,
        img: &Decimated,
        levels: &[f64],
        min_area: usize,
        out: &mut Vec<Blob>,
    ) {
        out.clear();
        if img.pixels.is_empty() {
            return;
        }
        // Highest threshold first: its regions hold those of the lower ones.
        let mut order: Vec<usize> = (0..levels.len()).collect();
        order.sort_by(|&i, &j| levels[j].total_cmp(&levels[i]));
        self.labels.resize_with(order.len(), Vec::new);
        self.label_widths.resize(order.len(), 0);
        self.runs.resize_with(order.len(), Vec::new);
        for (pass, &level) in order.iter().enumerate() {
            let first = out.len();
            self.label(img, levels[level], min_area, pass, out);
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma};

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
            let mut img = Decimated::default();
            (img.width, img.height, img.factor, img.pixels) = (w, h, 4, pixels);
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
    fn uniform_image_has_no_blobs() {
        let img = GrayImage::from_pixel(64, 64, Luma([100]));
        let mut dec = Decimated::default();
        dec.update(&img, 4);
        let mut blobs = Vec::new();
        BlobFinder::default().find(&dec, &[0.3, 0.5], 1, 10.0, &mut blobs);
        assert!(blobs.is_empty());
    }
}
