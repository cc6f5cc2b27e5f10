//! The second, independent candidate source: dark round shapes from their
//! edges, by Hough gradient voting (as OpenCV's `HOUGH_GRADIENT`, with the
//! edge's polarity).
//!
//! The coarse search needs the disc to stand out as a dark region at one of
//! a few global levels. Haze, glare and vignetting move the levels, and the
//! hose, the probe or a glare streak merge the disc with other regions or
//! split it. Its rim still has a dark-to-light edge all round: each edge
//! pixel of the decimated frame votes for the centres that lie against its
//! gradient (toward the dark side) at the distances a disc may have. A disc
//! gathers the votes of its whole rim at its centre, even with part of the
//! rim hidden; straight edges (hose, probe, cloud banks) spread theirs along
//! a line. Each peak's radius is the commonest distance of the edges that
//! voted for it. The verification decides, as for the coarse candidates.

use super::SATURATED_LEVEL;
use super::coarse::Decimated;

/// Smallest gradient that makes an edge pixel, gray levels per pixel of the
/// decimated frame, as a share of the detector's smallest rim contrast.
const MIN_GRADIENT_SHARE: f64 = 0.5;
/// Most votes an edge casts (decimated pixels along its gradient): discs
/// larger than this many decimated pixels are the coarse search's (they
/// are the near range, where the disc dominates the frame).
const MAX_VOTE_RADIUS: usize = 64;
/// Peaks closer than this (decimated pixels) are one peak.
const PEAK_SEPARATION: i64 = 4;
/// Two circles with centres within [`PEAK_SEPARATION`] are two when their
/// radii differ by more than this share of the smaller and more than
/// [`DISTINCT_RADIUS_PX`] decimated pixels: a radius is measured to a pixel
/// or two.
const DISTINCT_RADIUS_SHARE: f64 = 0.5;
const DISTINCT_RADIUS_PX: f64 = 2.0;
/// Edges within this distance (decimated pixels) of a circle's radius are
/// its rim: the three one-pixel bins [`EdgeVoter::radius_at`] sums.
const RIM_BINS_PX: f64 = 1.5;
/// A nested circle's centre lies within this many decimated pixels of the
/// smaller circle's it surrounds ([`EdgeVoter::nested`]): twice
/// [`PEAK_SEPARATION`] (the probe's tip lies anywhere inside the disc, and
/// its votes bury the disc's centre up to about that far).
const NESTED_REACH: f64 = 2.0 * PEAK_SEPARATION as f64;
/// Cells looked at per nested circle asked for: the others are weaker
/// than a circle's worth of votes more often than not, and each costs a
/// pass over the edges.
const NESTED_CELLS_PER_CIRCLE: usize = 4;
/// An edge whose light side keeps rising into saturation
/// ([`super::SATURATED_LEVEL`]) is the glare's own (its skirt, however
/// wide): a glare streak's two long edges are the strongest of the frame,
/// and their votes along lines bury a disc's that the streak cuts in two.
/// Like the rim passes' steps into saturation, they say nothing of the
/// disc. The rise is followed at most this many decimated pixels.
const MAX_SKIRT_PX: usize = 16;
const SKIRT_DIP: u8 = 4;

/// A peak needs votes from at least this share of its rim's circumference
/// (decimated pixels).
const MIN_RIM_SHARE: f64 = 0.35;
/// Edge pixels that voted for a peak lie within this angle of pointing
/// away from it (cosine), and their distances are binned by this many
/// decimated pixels.
const RADIAL_COS: f64 = 0.9;

/// A dark round shape found from its edges: centre and radius in
/// full-resolution pixels, and its votes per rim pixel.
#[derive(Clone, Debug)]
pub struct EdgeCircle {
    pub centre_px: [f64; 2],
    pub radius_px: f64,
    pub strength: f64,
}

/// A circle in the votes, decimated pixels: its centre and radius.
#[derive(Clone, Copy, Debug)]
struct Peak {
    centre: [f64; 2],
    radius: f64,
}

impl Peak {
    /// Whether `other` is this circle found again: centres within
    /// [`PEAK_SEPARATION`] of each other and radii within [`DISTINCT_RADIUS_PX`] or
    /// [`DISTINCT_RADIUS_SHARE`] of the smaller.
    fn one_circle_with(&self, other: &Peak) -> bool {
        let (small, large) = (self.radius.min(other.radius), self.radius.max(other.radius));
        let apart = (self.centre[0] - other.centre[0]).hypot(self.centre[1] - other.centre[1]);
        apart <= PEAK_SEPARATION as f64
            && (large - small <= DISTINCT_RADIUS_PX
                || large - small <= DISTINCT_RADIUS_SHARE * small)
    }
}

/// Scratch for the voting, reused between frames.
#[derive(Clone, Default)]
pub struct EdgeVoter {
    /// Edge pixels: position and unit gradient (toward the light side).
    edges: Vec<([i32; 2], [f32; 2])>,
    /// Votes per centre, in the padded frame of [`Self::vote`].
    votes: Vec<u16>,
    /// Row length of `votes`.
    stride: usize,
    histogram: Vec<u32>,
    /// The radii voted for by the last [`EdgeVoter::find`], decimated pixels.
    radii: (usize, usize),
}

impl EdgeVoter {
    /// Up to `max_peaks` dark round shapes of radius `min_radius_px` to
    /// `max_radius_px` (full-resolution pixels), strongest first.
    pub fn find(
        &mut self,
        img: &Decimated,
        min_contrast_gray: f64,
        min_radius_px: f64,
        max_radius_px: f64,
        max_peaks: usize,
    ) -> Vec<EdgeCircle> {
        let (w, h) = (img.width, img.height);
        if w < 3 || h < 3 || max_peaks == 0 {
            return Vec::new();
        }
        let f = img.factor.max(1) as f64;
        let r_min = ((min_radius_px / f).floor() as usize).max(1);
        let r_max = ((max_radius_px / f).ceil() as usize)
            .min(MAX_VOTE_RADIUS)
            .max(r_min);
        self.collect_edges(img, MIN_GRADIENT_SHARE * min_contrast_gray);
        self.vote(w, h, r_min, r_max);
        self.radii = (r_min, r_max);
        tracing::trace!(edges = self.edges.len(), r_min, r_max, "edge pixels voting");
        let peaks = self.peaks(w, h, r_min, max_peaks);
        peaks
            .into_iter()
            .filter_map(|(x, y, votes)| {
                let r = self.radius_at([x as f64, y as f64], r_min, r_max)?;
                let circumference = std::f64::consts::TAU * r;
                let strength = f64::from(votes) / circumference;
                (strength >= MIN_RIM_SHARE).then(|| EdgeCircle {
                    centre_px: img.to_full(x as f64, y as f64),
                    radius_px: r * f,
                    strength,
                })
            })
            .collect()
    }

    /// Up to `max_more` further circles of the last [`Self::find`]'s votes,
    /// strongest first, each around one of `found` (its circles), once
    /// their rims are taken out with their votes. A circle nearly
    /// concentric with a stronger one (the disc around the probe's tip,
    /// whose votes run on through its centre) makes no peak of its own
    /// beside it; with the stronger rim's votes gone, it does. The circles
    /// are the strongest local maxima of the votes (summed over 3x3) within
    /// [`NESTED_REACH`] of a circle found, larger than it and not a circle
    /// already found.
    pub fn nested(
        &mut self,
        img: &Decimated,
        found: &[EdgeCircle],
        max_more: usize,
    ) -> Vec<EdgeCircle> {
        let (w, h) = (img.width, img.height);
        if w < 3 || h < 3 || max_more == 0 || self.votes.is_empty() {
            return Vec::new();
        }
        let (r_min, r_max) = self.radii;
        let f = img.factor.max(1) as f64;
        let found_here: Vec<Peak> = found
            .iter()
            .map(|c| Peak {
                centre: img.to_decimated(c.centre_px),
                radius: c.radius_px / f,
            })
            .collect();
        for p in &found_here {
            self.take_rim(p.centre, p.radius, r_min, r_max);
        }
        let mut known = found_here.clone();
        let floor = (MIN_RIM_SHARE * std::f64::consts::TAU * r_min as f64).ceil() as u32;
        // Only near the circles found: a nested circle's centre is within
        // [`NESTED_REACH`] of the smaller one's.
        let mut cells: Vec<(usize, usize, u32)> = Vec::new();
        for k in &found_here {
            for cell in self.maxima_near(k.centre, w, h, floor) {
                if !cells.contains(&cell) {
                    cells.push(cell);
                }
            }
        }
        // Strongest first, the earlier in raster order among equals.
        cells.sort_by_key(|p| (std::cmp::Reverse(p.2), p.1, p.0));
        let mut more = Vec::with_capacity(max_more);
        // A radius costs a pass over the edges: the strongest few cells
        // are looked at.
        for (x, y, votes) in cells.into_iter().take(NESTED_CELLS_PER_CIRCLE * max_more) {
            if more.len() == max_more {
                break;
            }
            let centre = [x as f64, y as f64];
            let Some(radius) = self.radius_at(centre, r_min, r_max) else {
                continue;
            };
            let peak = Peak { centre, radius };
            // Around a smaller circle found (the disc around the tip), and
            // not a circle known already.
            let surrounds = |k: &Peak| {
                (k.centre[0] - x as f64).hypot(k.centre[1] - y as f64) <= NESTED_REACH
                    && radius > k.radius
                    && !k.one_circle_with(&peak)
            };
            if !found_here.iter().any(surrounds) || known.iter().any(|k| k.one_circle_with(&peak)) {
                continue;
            }
            known.push(peak);
            let strength = f64::from(votes) / (std::f64::consts::TAU * radius);
            if strength >= MIN_RIM_SHARE {
                more.push(EdgeCircle {
                    centre_px: img.to_full(x as f64, y as f64),
                    radius_px: radius * f,
                    strength,
                });
            }
        }
        more
    }

    /// The local maxima (x, y, sum) of the votes summed over 3x3, of at
    /// least `floor`, within [`NESTED_REACH`] of `c` (decimated pixels; not
    /// on the frame's border); plateaus keep every cell.
    fn maxima_near(&self, c: [f64; 2], w: usize, h: usize, floor: u32) -> Vec<(usize, usize, u32)> {
        let reach = NESTED_REACH.ceil() as i64;
        let clamp = |v: f64, hi: usize| (v.round() as i64).clamp(1, hi as i64 - 2) as usize;
        let (x0, x1) = (clamp(c[0] - reach as f64, w), clamp(c[0] + reach as f64, w));
        let (y0, y1) = (clamp(c[1] - reach as f64, h), clamp(c[1] + reach as f64, h));
        // The 3x3 sums of the window and a cell around it (0 off the frame's
        // inside), in a grid `gw` wide.
        let gw = x1 - x0 + 3;
        let mut sums = vec![0u32; gw * (y1 - y0 + 3)];
        for y in y0.saturating_sub(1).max(1)..=(y1 + 1).min(h - 2) {
            for x in x0.saturating_sub(1).max(1)..=(x1 + 1).min(w - 2) {
                let mut sum = 0u32;
                for yy in y - 1..=y + 1 {
                    let row = &self.votes[(yy + 1) * self.stride + x..][..3];
                    sum += row.iter().map(|&v| u32::from(v)).sum::<u32>();
                }
                sums[(y + 1 - y0) * gw + (x + 1 - x0)] = sum;
            }
        }
        let mut found = Vec::new();
        for y in y0..=y1 {
            for x in x0..=x1 {
                let at = |dx: usize, dy: usize| sums[(y + dy - y0) * gw + (x + dx - x0)];
                let s = at(1, 1);
                let around = [
                    at(0, 0),
                    at(1, 0),
                    at(2, 0),
                    at(0, 1),
                    at(2, 1),
                    at(0, 2),
                    at(1, 2),
                    at(2, 2),
                ];
                if s >= floor && around.iter().all(|&a| a <= s) {
                    found.push((x, y, s));
                }
            }
        }
        found
    }

    /// Takes the edges of the rim of radius `r` about `c` ([`on_rim`]) out,
    /// with their votes.
    fn take_rim(&mut self, c: [f64; 2], r: f64, r_min: usize, r_max: usize) {
        let mut edges = std::mem::take(&mut self.edges);
        edges.retain(|&edge| {
            let rim = on_rim(c, r, edge);
            if rim {
                cast_votes(&mut self.votes, self.stride, edge, r_min, r_max, false);
            }
            !rim
        });
        self.edges = edges;
    }

    /// Edge pixels: Sobel gradient (gray levels per pixel) of at least
    /// `min_gradient`, with its direction. Each row's gradients are worked
    /// out first, in integers (a loop the compiler turns into vector
    /// instructions), then the few pixels over the threshold are taken.
    fn collect_edges(&mut self, img: &Decimated, min_gradient: f64) {
        let (w, h) = (img.width, img.height);
        // The squared magnitude is a whole number (below 2^22): at least
        // the threshold is at least its ceiling. A threshold beyond `i32`
        // (or NaN) makes no edges, as the comparison in `f64` would. A
        // pixel without a gradient has no direction and is never an edge,
        // whatever the threshold (`min_contrast_gray` may be 0).
        let min2 = (min_gradient * 8.0).powi(2).ceil();
        let min2 = if min2 <= f64::from(i32::MAX) {
            min2.max(1.0) as i32
        } else {
            i32::MAX
        };
        self.edges.clear();
        let any_glare = img.any_at_least(SATURATED_LEVEL);
        let (mut gx_row, mut gy_row, mut m2_row) = (vec![0i32; w], vec![0i32; w], vec![0i32; w]);
        for y in 1..h - 1 {
            // The three rows, each cut to the window's columns: no bounds
            // test per pixel.
            let row = |y: usize| &img.pixels[y * w..(y + 1) * w];
            let (above, here, below) = (row(y - 1), row(y), row(y + 1));
            for x in 1..w - 1 {
                let p = |r: &[u8], x: usize| i32::from(r[x]);
                let gx = p(above, x + 1) + 2 * p(here, x + 1) + p(below, x + 1)
                    - p(above, x - 1)
                    - 2 * p(here, x - 1)
                    - p(below, x - 1);
                let gy = p(below, x - 1) + 2 * p(below, x) + p(below, x + 1)
                    - p(above, x - 1)
                    - 2 * p(above, x)
                    - p(above, x + 1);
                gx_row[x] = gx;
                gy_row[x] = gy;
                m2_row[x] = gx * gx + gy * gy;
            }
            for x in 1..w - 1 {
                if m2_row[x] < min2 {
                    continue;
                }
                let (gx, gy) = (f64::from(gx_row[x]), f64::from(gy_row[x]));
                let m = f64::from(m2_row[x]).sqrt();
                let dir = [gx / m, gy / m];
                if any_glare && Self::rises_into_glare(img, x, y, dir) {
                    continue;
                }
                self.edges
                    .push(([x as i32, y as i32], [dir[0] as f32, dir[1] as f32]));
            }
        }
    }

    /// Whether the level keeps rising from (x, y) along `dir` (toward the
    /// light side, unit length) until it saturates: a glare's skirt. A dip
    /// of up to [`SKIRT_DIP`] levels is the decimated frame's noise.
    fn rises_into_glare(img: &Decimated, x: usize, y: usize, dir: [f64; 2]) -> bool {
        let mut peak = img.pixels[y * img.width + x];
        for k in 1..=MAX_SKIRT_PX {
            // The nearest pixel: truncation of a non-negative coordinate
            // plus a half is its floor (no libm call; off the frame below
            // zero, as the floor would be).
            let u = x as f64 + k as f64 * dir[0] + 0.5;
            let v = y as f64 + k as f64 * dir[1] + 0.5;
            if !(u >= 0.0 && v >= 0.0) {
                return false;
            }
            let (u, v) = (u as usize, v as usize);
            if u >= img.width || v >= img.height {
                return false;
            }
            let p = img.pixels[v * img.width + u];
            if p >= SATURATED_LEVEL {
                return true;
            }
            if p.saturating_add(SKIRT_DIP) < peak {
                return false;
            }
            peak = peak.max(p);
        }
        false
    }

    /// Each edge votes for the centres r_min..=r_max pixels against its
    /// gradient. The votes lie in a frame padded by one pixel before and
    /// `r_max + 1` after each side (`self.stride` wide), so that no vote
    /// needs a bounds test: a ray that has left the frame never comes back,
    /// and its votes beyond the border fall in the padding, which the peak
    /// search does not read.
    fn vote(&mut self, w: usize, h: usize, r_min: usize, r_max: usize) {
        let stride = w + r_max + 2;
        self.stride = stride;
        self.votes.clear();
        self.votes.resize(stride * (h + r_max + 2), 0);
        for &edge in &self.edges {
            cast_votes(&mut self.votes, stride, edge, r_min, r_max, true);
        }
    }

    /// The votes for frame pixel (x, y).
    fn votes_at(&self, x: usize, y: usize) -> u16 {
        self.votes[(y + 1) * self.stride + x + 1]
    }

    /// The strongest local maxima of the votes (summed over 3x3), at least
    /// [`PEAK_SEPARATION`] apart: (x, y, votes).
    fn peaks(
        &self,
        w: usize,
        h: usize,
        r_min: usize,
        max_peaks: usize,
    ) -> Vec<(usize, usize, u32)> {
        // The 3x3 sums as sums of three rows' sums of three (one pass over
        // the votes, not nine reads per cell).
        let mut rows = vec![0u32; w * h];
        for y in 0..h {
            let row = &self.votes[(y + 1) * self.stride..][..w + 2];
            for (sum, three) in rows[y * w + 1..(y + 1) * w - 1]
                .iter_mut()
                .zip(row[1..].windows(3))
            {
                *sum = three.iter().map(|&v| u32::from(v)).sum();
            }
        }
        let sum3 =
            |x: usize, y: usize| rows[(y - 1) * w + x] + rows[y * w + x] + rows[(y + 1) * w + x];
        // The weakest peak worth a look: a fraction of the smallest rim.
        let floor = (MIN_RIM_SHARE * std::f64::consts::TAU * r_min as f64).ceil() as u32;
        // Each cell's sum where it is a candidate (voted for, at least
        // `floor`), else 0 (a voted cell's sum is at least 1).
        let mut sums = vec![0u32; w * h];
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                if self.votes_at(x, y) == 0 {
                    continue;
                }
                let s = sum3(x, y);
                if s >= floor {
                    sums[y * w + x] = s;
                }
            }
        }
        // Each kept peak rules out at most the cells of its box, so the
        // peaks kept are among the strongest `box * max_peaks + 1` (the
        // earlier in raster order first among equals): only those are
        // scanned below.
        let box_cells = (2 * PEAK_SEPARATION + 1).pow(2) as usize;
        let found = strongest_in_raster_order(&sums, w, box_cells * max_peaks + 1);
        // Greedy: the strongest (the first in raster order among equals)
        // not near a kept one, until `max_peaks`. A scan per peak, not a
        // sort of every candidate: `max_peaks` is a handful.
        let near = |k: &(usize, usize, u32), p: &(usize, usize, u32)| {
            (k.0 as i64 - p.0 as i64).abs() <= PEAK_SEPARATION
                && (k.1 as i64 - p.1 as i64).abs() <= PEAK_SEPARATION
        };
        let mut kept: Vec<(usize, usize, u32)> = Vec::with_capacity(max_peaks);
        while kept.len() < max_peaks {
            let best = found
                .iter()
                .filter(|p| !kept.iter().any(|k| near(k, p)))
                .fold(None, |best: Option<&(usize, usize, u32)>, p| match best {
                    Some(b) if b.2 >= p.2 => Some(b),
                    _ => Some(p),
                });
            match best {
                Some(&p) => kept.push(p),
                None => break,
            }
        }
        kept
    }

    /// The commonest distance (decimated pixels) from `c` of the edges
    /// whose gradient points away from it, within r_min..=r_max.
    fn radius_at(&mut self, c: [f64; 2], r_min: usize, r_max: usize) -> Option<f64> {
        self.histogram.clear();
        self.histogram.resize(r_max + 2, 0);
        let [cx, cy] = c;
        for &([x, y], [gx, gy]) in &self.edges {
            let (dx, dy) = (f64::from(x) - cx, f64::from(y) - cy);
            // No libm call, as `hypot` makes: the offsets are small.
            let d = (dx * dx + dy * dy).sqrt();
            if d < r_min as f64 - 0.5 || d > r_max as f64 + 0.5 {
                continue;
            }
            if (dx * f64::from(gx) + dy * f64::from(gy)) < RADIAL_COS * d {
                continue;
            }
            self.histogram[(d.round() as usize).min(r_max + 1)] += 1;
        }
        // Counts per unit circumference, smoothed over three bins.
        let density = |r: usize| {
            let n: u32 = self.histogram[r.saturating_sub(1)..=(r + 1).min(r_max + 1)]
                .iter()
                .sum();
            f64::from(n) / r.max(1) as f64
        };
        (r_min..=r_max)
            .max_by(|&a, &b| density(a).total_cmp(&density(b)))
            .filter(|&r| self.histogram[r] > 0 || density(r) > 0.0)
            .map(|r| r as f64)
    }
}

/// Below where `f32` stops counting every integer (2^23), so that a
/// coordinate clamped to it converts to `i32` exactly, and above any cell
/// of the padded frame: frames are at most
/// [`MAX_SIDE_PX`](crate::camera::MAX_SIDE_PX) a side (the assertion
/// below holds it at compile time).
const CELL_LIMIT: f32 = 8_388_608.0;
const _: () =
    assert!((crate::camera::MAX_SIDE_PX as usize + 2 * MAX_VOTE_RADIUS + 4) < CELL_LIMIT as usize);

/// One edge's votes for the centres `r_min..=r_max` pixels against its
/// gradient, in the padded frame of [`EdgeVoter::vote`]: added, or taken
/// back (`add` false). The cells' columns and rows are worked out first,
/// all radii at once (a loop the compiler turns into vector
/// instructions), then counted: the same cells as one radius at a time,
/// in fewer instructions.
fn cast_votes(
    votes: &mut [u16],
    stride: usize,
    ([x, y], [gx, gy]): ([i32; 2], [f32; 2]),
    r_min: usize,
    r_max: usize,
    add: bool,
) {
    // The padded cell of a coordinate: rounding half away from zero, as
    // `f32::round`, without its libm call; at or below -0.5 the padding's
    // first cell (a clamp and a comparison, not a branch: the same cell).
    let cell = |v: f32| {
        let t = v + 0.5;
        // SAFETY: `max` then `min` keep it in [0, CELL_LIMIT] and finite
        // (a NaN, which no edge direction is, becomes 0, where `clamp`
        // would keep it), so within `i32`: the unchecked conversion is
        // exact, as `as` would be, and converts four lanes at once where
        // `as` (saturating) goes one by one. The upper end is never
        // reached (CELL_LIMIT).
        #[allow(clippy::manual_clamp)] // `clamp` keeps a NaN: see above.
        let whole: i32 = unsafe { t.max(0.0).min(CELL_LIMIT).to_int_unchecked() };
        whole + i32::from(t > 0.0)
    };
    let (x, y) = (x as f32, y as f32);
    let n = (r_max + 1).saturating_sub(r_min).min(MAX_VOTE_RADIUS + 1);
    let mut columns = [0i32; MAX_VOTE_RADIUS + 1];
    let mut rows = [0i32; MAX_VOTE_RADIUS + 1];
    // The radius in f32 (exact for these small integers), from a 32-bit
    // count: a 64-bit one does not convert in vector instructions.
    let first = r_min as i32;
    for (k, (column, row)) in (0i32..).zip(columns[..n].iter_mut().zip(&mut rows[..n])) {
        let r = (first + k) as f32;
        *column = cell(x - gx * r);
        *row = cell(y - gy * r);
    }
    for (&column, &row) in columns[..n].iter().zip(&rows[..n]) {
        let v = &mut votes[row as usize * stride + column as usize];
        *v = if add {
            v.saturating_add(1)
        } else {
            v.saturating_sub(1)
        };
    }
}

/// Whether an edge is on the rim of the circle of radius `r` about `c`:
/// within [`RIM_BINS_PX`] of it, its gradient pointing away from the centre
/// (as [`EdgeVoter::radius_at`] counts it for that radius).
fn on_rim(c: [f64; 2], r: f64, ([x, y], [gx, gy]): ([i32; 2], [f32; 2])) -> bool {
    let (dx, dy) = (f64::from(x) - c[0], f64::from(y) - c[1]);
    let d = (dx * dx + dy * dy).sqrt();
    (d - r).abs() <= RIM_BINS_PX && dx * f64::from(gx) + dy * f64::from(gy) >= RADIAL_COS * d
}

/// The `n` cells (x, y, sum) of `sums` (a frame `w` wide; 0 where no
/// candidate) with the largest sums, the earlier in raster order first
/// among equals, in raster order: the sums' cutoff from a count of each
/// value (linear; a partial sort of the tens of thousands of voted cells
/// was a tenth of the edge source's work, and a list of them all a
/// twentieth).
fn strongest_in_raster_order(sums: &[u32], w: usize, n: usize) -> Vec<(usize, usize, u32)> {
    let cell = |i: usize, s: u32| (i % w, i / w, s);
    let candidates = sums.iter().filter(|&&s| s > 0);
    let (count, high) = candidates.fold((0usize, 0u32), |(c, hi), &s| (c + 1, hi.max(s)));
    if count <= n {
        return (sums.iter().enumerate())
            .filter(|(_, s)| **s > 0)
            .map(|(i, &s)| cell(i, s))
            .collect();
    }
    let mut counts = vec![0usize; high as usize + 1];
    for &s in sums {
        counts[s as usize] += 1;
    }
    // The cutoff: the value at which the strongest first reach `n`.
    let mut above = 0;
    let mut cutoff = 1;
    for v in (1..=high).rev() {
        let c = counts[v as usize];
        if above + c >= n {
            cutoff = v;
            break;
        }
        above += c;
    }
    let mut ties = n - above;
    let mut kept = Vec::with_capacity(n);
    for (i, &s) in sums.iter().enumerate() {
        let tie = s == cutoff && ties > 0;
        ties -= usize::from(tie);
        if s > cutoff || tie {
            kept.push(cell(i, s));
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::GrayImage;

    /// A dark disc (radius 60 px at (400, 300)) with a dark bar merged into
    /// it, on a light background; decimated by 4.
    fn scene(with_bar: bool) -> Decimated {
        let img = GrayImage::from_fn(800, 600, |x, y| {
            let (dx, dy) = (f64::from(x) - 400.0, f64::from(y) - 300.0);
            let disc = dx.hypot(dy) < 60.0;
            let bar = with_bar && (f64::from(y) - 300.0).abs() < 25.0 && x > 400;
            image::Luma([if disc || bar { 40 } else { 180 }])
        });
        let mut d = Decimated::default();
        d.update(&img, 4);
        d
    }

    /// The votes as cast one radius at a time, with `f32::round` (half
    /// away from zero) and a bounds test per vote: what `cast_votes`
    /// must give, cell for cell.
    fn votes_one_by_one(
        w: usize,
        h: usize,
        edges: &[([i32; 2], [f32; 2])],
        r_min: usize,
        r_max: usize,
    ) -> Vec<u16> {
        let stride = w + r_max + 2;
        let mut votes = vec![0u16; stride * (h + r_max + 2)];
        for &([x, y], [gx, gy]) in edges {
            for r in r_min..=r_max {
                let r = r as f32;
                let padded = |v: f32| {
                    let v = v.round();
                    if v <= -1.0 { 0 } else { v as usize + 1 }
                };
                let at = padded(y as f32 - gy * r) * stride + padded(x as f32 - gx * r);
                votes[at] += 1;
            }
        }
        votes
    }

    #[test]
    fn votes_land_where_rounding_each_one_puts_them() {
        // Edges all over a small frame, pointing every way (some at exact
        // half-pixel offsets), so that rays leave it through every side.
        let (w, h, r_min, r_max) = (40usize, 30usize, 1usize, 20usize);
        let mut edges = Vec::new();
        for k in 0..400 {
            let angle = k as f32 * 0.137;
            let dir = if k % 7 == 0 {
                [0.5f32, 0.0]
            } else {
                [angle.cos(), angle.sin()]
            };
            edges.push(([(k * 13 % w) as i32, (k * 7 % h) as i32], dir));
        }
        let mut voter = EdgeVoter {
            edges: edges.clone(),
            ..EdgeVoter::default()
        };
        voter.vote(w, h, r_min, r_max);
        assert_eq!(voter.votes, votes_one_by_one(w, h, &edges, r_min, r_max));
    }

    /// `min_contrast_gray` may be 0 (its range is [0, 255]): the flat
    /// pixels, without a gradient, must still make no edges, whose
    /// direction would be 0 / 0 and whose votes would be cast at NaN
    /// (the unchecked conversion in `cast_votes`).
    #[test]
    fn a_zero_contrast_threshold_makes_no_edges_without_a_direction() {
        let img = scene(true);
        let mut voter = EdgeVoter::default();
        let circles = voter.find(&img, 0.0, 12.0, 120.0, 3);
        assert!(!voter.edges.is_empty());
        assert!(
            voter
                .edges
                .iter()
                .all(|(_, [gx, gy])| gx.is_finite() && gy.is_finite()),
            "an edge without a direction"
        );
        let flat = img.pixels.len() - voter.edges.len();
        assert!(flat > 0, "the scene has flat pixels");
        assert!(circles.iter().all(|c| c.radius_px.is_finite()));
    }

    /// A configuration whose farthest range makes the smallest disc larger
    /// than the votes reach (`max_range_m` 0.7 at a focal length of 1280
    /// px: 274 px) votes at that radius alone: the radii's bounds once
    /// crossed, and `clamp` panicked.
    #[test]
    fn a_smallest_disc_beyond_the_votes_reach_is_voted_for_without_panic() {
        let circles = EdgeVoter::default().find(&scene(false), 12.0, 274.0, 480.0, 3);
        // The one radius voted for: 68 decimated pixels (by 4).
        assert!(circles.iter().all(|c| c.radius_px == 272.0), "{circles:?}");
    }

    #[test]
    fn finds_a_disc_with_its_radius_even_when_merged_with_a_bar() {
        for with_bar in [false, true] {
            let circles = EdgeVoter::default().find(&scene(with_bar), 12.0, 10.0, 200.0, 3);
            let c = &circles[0];
            let off = (c.centre_px[0] - 400.0).hypot(c.centre_px[1] - 300.0);
            assert!(off < 6.0, "{with_bar}: {c:?}");
            assert!((c.radius_px - 60.0).abs() < 8.0, "{with_bar}: {c:?}");
        }
    }

    /// A hazed disc (radius 60 px at (400, 300)) with the probe's darker
    /// tip (radius 16 px) at its centre; decimated by 4.
    fn tip_in_disc() -> Decimated {
        let img = GrayImage::from_fn(800, 600, |x, y| {
            let r = (f64::from(x) - 400.0).hypot(f64::from(y) - 300.0);
            image::Luma([if r < 16.0 {
                20
            } else if r < 60.0 {
                150
            } else {
                190
            }])
        });
        let mut d = Decimated::default();
        d.update(&img, 4);
        d
    }

    #[test]
    fn a_circle_nested_with_a_stronger_one_is_found_once_that_ones_rim_is_taken_out() {
        let img = tip_in_disc();
        let mut voter = EdgeVoter::default();
        let found = voter.find(&img, 12.0, 10.0, 200.0, 4);
        // Radii to a decimated pixel (4 px).
        let near = |c: &EdgeCircle, r: f64| {
            (c.centre_px[0] - 400.0).hypot(c.centre_px[1] - 300.0) < 6.0
                && (c.radius_px - r).abs() <= (0.15 * r).max(4.0)
        };
        // One peak for both: the tip's rim, whose votes bury the disc's.
        assert!(near(&found[0], 16.0), "{found:?}");
        assert!(!found.iter().any(|c| near(c, 60.0)), "{found:?}");
        let nested = voter.nested(&img, &found, 2);
        assert!(near(&nested[0], 60.0), "{nested:?}");
    }

    /// A dark disc (radius 40 px at (400, 300)) and a saturated glare
    /// streak 24 px wide with a soft skirt, at 30 degrees across the
    /// frame, `offset_px` from the disc's centre; decimated by 4.
    fn disc_beside_a_streak(offset_px: f64) -> Decimated {
        let img = GrayImage::from_fn(800, 600, |x, y| {
            let (u, v) = (f64::from(x), f64::from(y));
            let across = ((v - 300.0) * 0.866 - (u - 400.0) * 0.5 - offset_px).abs();
            let glare = if across < 12.0 {
                255.0
            } else {
                (255.0 - 12.0 * (across - 12.0)).max(0.0)
            };
            let disc = (u - 400.0).hypot(v - 300.0) < 40.0;
            let base: f64 = if disc { 40.0 } else { 170.0 };
            image::Luma([base.max(glare) as u8])
        });
        let mut d = Decimated::default();
        d.update(&img, 4);
        d
    }

    /// The streak's long edges, beside its saturated middle, cast no votes
    /// (far from any disc, no edge of the frame is left); the disc's rim
    /// beside the streak still votes, and the disc is found.
    #[test]
    fn a_glare_streaks_edges_do_not_vote_and_a_disc_beside_it_does() {
        let mut voter = EdgeVoter::default();
        voter.collect_edges(&disc_beside_a_streak(200.0), 6.0);
        let near_disc = |e: &&([i32; 2], [f32; 2])| {
            (f64::from(e.0[0]) - 100.0).hypot(f64::from(e.0[1]) - 75.0) < 14.0
        };
        // (Where the streak leaves the frame its rise is cut off: those
        // edges, within 2 pixels of the border, may stay.)
        let inside =
            |e: &&([i32; 2], [f32; 2])| (3..197).contains(&e.0[0]) && (3..147).contains(&e.0[1]);
        let far: Vec<_> = voter
            .edges
            .iter()
            .filter(|e| inside(e) && !near_disc(e))
            .collect();
        assert!(far.is_empty(), "{} edges, {far:?}", voter.edges.len());
        assert!(!voter.edges.is_empty());
        for offset_px in [200.0, 60.0, 30.0] {
            let found = voter.find(&disc_beside_a_streak(offset_px), 12.0, 10.0, 200.0, 2);
            let on_disc = |c: &EdgeCircle| {
                (c.centre_px[0] - 400.0).hypot(c.centre_px[1] - 300.0) < 6.0
                    && (c.radius_px - 40.0).abs() < 8.0
            };
            assert!(found.iter().any(on_disc), "{offset_px}: {found:?}");
        }
    }

    #[test]
    fn the_strongest_cells_are_kept_in_raster_order_earlier_first_among_equals() {
        // A frame 3 wide, two rows; 0 is no candidate.
        let sums = [5, 9, 7, 7, 7, 1, 0, 0, 0];
        assert_eq!(
            strongest_in_raster_order(&sums, 3, 3),
            vec![(1, 0, 9), (2, 0, 7), (0, 1, 7)]
        );
        assert_eq!(
            strongest_in_raster_order(&sums, 3, 5),
            vec![(0, 0, 5), (1, 0, 9), (2, 0, 7), (0, 1, 7), (1, 1, 7)]
        );
        let few = [0, 1, 0];
        assert_eq!(strongest_in_raster_order(&few, 3, 3), vec![(1, 0, 1)]);
    }

    #[test]
    fn a_uniform_frame_has_no_circles() {
        let img = GrayImage::from_pixel(320, 240, image::Luma([120]));
        let mut d = Decimated::default();
        d.update(&img, 4);
        assert!(
            EdgeVoter::default()
                .find(&d, 12.0, 10.0, 200.0, 3)
                .is_empty()
        );
    }
}
