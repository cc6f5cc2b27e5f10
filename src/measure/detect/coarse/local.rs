//! Local contrast normalisation of the decimated frame: each pixel's level
//! relative to its neighbourhood, `(p - mean) / (std + floor)` over a
//! square window, so that a disc darker than the canopy around it stands
//! out wherever it is. The global thresholds of the coarse search hang on
//! the frame's darkest and median levels: haze lifts a far disc toward the
//! sky's level while a nearer probe or a dark cloud keeps the darkest level
//! low, vignetting and a glare's halo move the levels across the frame, and
//! the disc then makes no region of its own at any global threshold. Its
//! level relative to its own neighbourhood does not move with them.
//!
//! The window is chosen per disc size (a few times the disc's radius, so
//! that the light canopy is most of it); [`window_sides`] gives the few
//! windows that cover the sizes searched.

use super::Decimated;

/// Normalised levels are stored as gray levels `ZERO + SCALE * n`
/// (clamped to 0..=255): the labelling of the coarse search then runs on
/// them unchanged. `n` from -4 to +4 standard deviations fits.
const ZERO: f64 = 128.0;
const SCALE: f64 = 32.0;

/// The window's side over the radius of the smallest disc it is for. The
/// windows are [`RADIUS_RATIO`] apart, so the largest disc of a window
/// has 4.5 radii of side: it fills a sixth of the window (a disc on a
/// uniform canopy then sits 2.3 standard deviations below the mean), and
/// the rest is the canopy (2.2 radii) and a little beyond.
const SIDE_RADII: f64 = 9.0;
/// Disc radii covered by one window: from `r` to `RADIUS_RATIO r`.
pub const RADIUS_RATIO: f64 = 2.0;

/// The gray level that a pixel `n` standard deviations from its
/// neighbourhood's mean is stored as.
pub fn normalised_level(n: f64) -> f64 {
    (ZERO + SCALE * n).clamp(0.0, 255.0)
}

/// The odd window sides (decimated pixels) for disc radii from
/// `min_radius` to `max_radius` (decimated pixels), smallest first, each
/// for radii `r..RADIUS_RATIO r`, and no wider than `limit` (the frame's
/// smaller side: a disc that large is most of the frame, and the global
/// thresholds find it). With the disc's radius from each side's.
pub fn window_sides(min_radius: f64, max_radius: f64, limit: usize) -> Vec<(usize, f64)> {
    let mut sides = Vec::new();
    let mut r = min_radius.max(1.0);
    while r <= max_radius && sides.len() < 16 {
        let side = 2 * (SIDE_RADII * r / 2.0).ceil() as usize + 1;
        if side > limit {
            break;
        }
        sides.push((side, r));
        r *= RADIUS_RATIO;
    }
    sides
}

/// Scratch and output of the normalisation.
#[derive(Clone, Default)]
pub struct LocalContrast {
    /// Summed-area tables of the levels and their squares, one row and
    /// column of zeros first.
    sums: Vec<u32>,
    squares: Vec<u64>,
    /// The prepared frame's levels.
    levels: Vec<u8>,
    /// The normalised frame (same size and factor as the input).
    pub normalised: Decimated,
}

impl LocalContrast {
    /// Takes the frame the next [`normalise`](Self::normalise) calls work
    /// on (its summed-area tables, once for every window).
    pub fn prepare(&mut self, img: &Decimated) {
        self.tables(img);
        self.levels.clone_from(&img.pixels);
        self.normalised.width = img.width;
        self.normalised.height = img.height;
        self.normalised.factor = img.factor;
    }

    /// Normalises the prepared frame over windows of `side` x `side`
    /// pixels (clipped at the frame's border), with `floor_gray` added to
    /// the standard deviation: a flat patch of sky, whose deviation is its
    /// noise, does not make every faint mottle stand out.
    #[inline(never)]
    pub fn normalise(&mut self, side: usize, floor_gray: f64) {
        let (w, h) = (self.normalised.width, self.normalised.height);
        self.normalised.pixels.clear();
        self.normalised.pixels.resize(w * h, 0);
        if w == 0 || h == 0 || self.levels.len() != w * h {
            return;
        }
        let stride = w + 1;
        let half = side / 2;
        let floor = floor_gray.max(f64::EPSILON);
        for y in 0..h {
            let (y0, y1) = (y.saturating_sub(half), (y + half + 1).min(h));
            for x in 0..w {
                let (x0, x1) = (x.saturating_sub(half), (x + half + 1).min(w));
                // The window's corners in the tables.
                let (a, b) = (y1 * stride + x1, y0 * stride + x1);
                let (c, d) = (y1 * stride + x0, y0 * stride + x0);
                let n = ((x1 - x0) * (y1 - y0)) as f64;
                let sum = f64::from(self.sums[a] + self.sums[d] - self.sums[b] - self.sums[c]);
                let sq =
                    (self.squares[a] + self.squares[d] - self.squares[b] - self.squares[c]) as f64;
                let mean = sum / n;
                let std = (sq / n - mean * mean).max(0.0).sqrt();
                let p = f64::from(self.levels[y * w + x]);
                self.normalised.pixels[y * w + x] =
                    normalised_level((p - mean) / (std + floor)).round() as u8;
            }
        }
    }

    /// The summed-area tables of `img` (exact: at most 255^2 per pixel in
    /// u64, 255 per pixel in u32 for up to 16 million pixels).
    fn tables(&mut self, img: &Decimated) {
        let (w, h) = (img.width, img.height);
        let stride = w + 1;
        self.sums.clear();
        self.sums.resize(stride * (h + 1), 0);
        self.squares.clear();
        self.squares.resize(stride * (h + 1), 0);
        for y in 0..h {
            let (mut row, mut row_sq) = (0u32, 0u64);
            for x in 0..w {
                let p = u32::from(img.pixels[y * w + x]);
                row += p;
                row_sq += u64::from(p * p);
                let i = (y + 1) * stride + x + 1;
                self.sums[i] = self.sums[i - stride] + row;
                self.squares[i] = self.squares[i - stride] + row_sq;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decimated(w: usize, h: usize, f: impl Fn(usize, usize) -> u8) -> Decimated {
        let mut d = Decimated::default();
        d.width = w;
        d.height = h;
        d.factor = 4;
        d.pixels = (0..w * h).map(|i| f(i % w, i / w)).collect();
        d
    }

    #[test]
    fn matches_a_direct_window_mean_and_deviation() {
        // A pseudo-random frame: every pixel against its window's mean and
        // standard deviation computed directly.
        let img = decimated(23, 17, |x, y| ((x * 37 + y * 91 + x * y * 13) % 251) as u8);
        let mut lc = LocalContrast::default();
        let (side, floor) = (7, 2.0);
        lc.prepare(&img);
        lc.normalise(side, floor);
        for y in 0..img.height {
            for x in 0..img.width {
                let mut values = Vec::new();
                for v in y.saturating_sub(3)..(y + 4).min(img.height) {
                    for u in x.saturating_sub(3)..(x + 4).min(img.width) {
                        values.push(f64::from(img.pixels[v * img.width + u]));
                    }
                }
                let n = values.len() as f64;
                let mean = values.iter().sum::<f64>() / n;
                let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
                let p = f64::from(img.pixels[y * img.width + x]);
                let expected = normalised_level((p - mean) / (std + floor)).round();
                assert_eq!(
                    f64::from(lc.normalised.pixels[y * img.width + x]),
                    expected,
                    "({x}, {y})"
                );
            }
        }
    }

    #[test]
    fn a_disc_stands_out_whatever_the_level_around_it() {
        // Two discs 40 levels darker than their surroundings, one in a dark
        // part of the frame and one in a light part (a strong vignetting or
        // haze gradient): a global threshold between the frame's darkest
        // and median levels takes the whole dark half with the first disc
        // and misses the second; normalised, both are equally dark.
        let img = decimated(80, 40, |x, y| {
            let base = if x < 40 { 70.0 } else { 200.0 };
            let disc = |cx: f64| (x as f64 - cx).hypot(y as f64 - 20.0) <= 4.0;
            (base - if disc(20.0) || disc(60.0) { 40.0 } else { 0.0 }) as u8
        });
        let mut lc = LocalContrast::default();
        lc.prepare(&img);
        lc.normalise(19, 2.0);
        let at = |x: usize, y: usize| lc.normalised.pixels[y * 80 + x];
        let dark = normalised_level(-1.5) as u8;
        assert!(at(20, 20) <= dark && at(60, 20) <= dark);
        assert_eq!(at(20, 20), at(60, 20));
        // Away from the discs (and from the step between the halves) the
        // frame is at its neighbourhood's mean.
        assert_eq!(at(5, 5), normalised_level(0.0) as u8);
        assert_eq!(at(75, 35), normalised_level(0.0) as u8);
    }

    #[test]
    fn windows_cover_the_disc_sizes_searched() {
        let sides = window_sides(2.0, 40.0, 300);
        let radii: Vec<f64> = sides.iter().map(|s| s.1).collect();
        assert_eq!(radii, vec![2.0, 4.0, 8.0, 16.0, 32.0]);
        // The 32's window (289) is wider than a 240 frame.
        assert_eq!(window_sides(2.0, 40.0, 240).len(), 4);
        for (side, r) in &sides {
            assert_eq!(side % 2, 1);
            assert!(*side as f64 >= SIDE_RADII * r);
        }
        // No window wider than the frame's smaller side.
        assert!(window_sides(2.0, 400.0, 100).iter().all(|s| s.0 <= 100));
        assert!(window_sides(2.0, 1.0, 100).is_empty());
    }
}
