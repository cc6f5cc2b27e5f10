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

/// Levels of the dark mask ([`LocalContrast::dark_mask`]): the labelling
/// of the coarse search runs on it unchanged, with [`MASK_THRESHOLD`].
const MASK_DARK: u8 = 0;
const MASK_LIGHT: u8 = 255;
/// A mask pixel at or below this level is dark.
pub const MASK_THRESHOLD: f64 = 127.0;

/// The window's side over the radius of the smallest disc it is for. The
/// windows are [`RADIUS_RATIO`] apart, so the largest disc of a window
/// has 4.5 radii of side: it fills a sixth of the window (a disc on a
/// uniform canopy then sits 2.3 standard deviations below the mean), and
/// the rest is the canopy (2.2 radii) and a little beyond.
const SIDE_RADII: f64 = 9.0;
/// Disc radii covered by one window: from `r` to `RADIUS_RATIO r`.
pub const RADIUS_RATIO: f64 = 2.0;

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
    sums: Vec<u64>,
    squares: Vec<u64>,
    /// The prepared frame's levels.
    levels: Vec<u8>,
    /// The dark mask (same size and factor as the input).
    pub mask: Decimated,
}

impl LocalContrast {
    /// Takes the frame the next [`dark_mask`](Self::dark_mask) calls work
    /// on (its summed-area tables, once for every window).
    pub fn prepare(&mut self, img: &Decimated) {
        self.tables(img);
        self.levels.clone_from(&img.pixels);
        self.mask.width = img.width;
        self.mask.height = img.height;
        self.mask.factor = img.factor;
    }

    /// The pixels of the prepared frame that lie `sigmas` standard
    /// deviations or more below the mean of their `side` x `side`
    /// neighbourhood (clipped at the frame's border), with `floor_gray`
    /// added to the deviation: `(p - mean) / (std + floor) <= -sigmas`.
    /// The floor keeps a flat patch of sky, whose deviation is its noise,
    /// from making every faint mottle stand out. Written to `mask` as
    /// [`MASK_DARK`] and [`MASK_LIGHT`]; tested as `mean - p - sigmas floor
    /// >= sigmas std` on squares, with no root or division per pixel.
    #[inline(never)]
    pub fn dark_mask(&mut self, side: usize, floor_gray: f64, sigmas: f64) {
        let (w, h) = (self.mask.width, self.mask.height);
        self.mask.pixels.clear();
        self.mask.pixels.resize(w * h, MASK_LIGHT);
        if w == 0 || h == 0 || self.levels.len() != w * h {
            return;
        }
        let stride = w + 1;
        let half = side / 2;
        let offset = sigmas * floor_gray.max(0.0);
        let sigmas_sq = sigmas * sigmas;
        // Each row's window column sums (the tables' rows y1 less y0).
        let mut columns = vec![0.0f64; stride];
        let mut columns_sq = vec![0.0f64; stride];
        // 1 / the window's pixel count, per column span (the rows' span is
        // the same along a row).
        let mut inverse_width = vec![0.0f64; w];
        for (x, inv) in inverse_width.iter_mut().enumerate() {
            let (x0, x1) = (x.saturating_sub(half), (x + half + 1).min(w));
            *inv = 1.0 / (x1 - x0) as f64;
        }
        for y in 0..h {
            let (y0, y1) = (y.saturating_sub(half), (y + half + 1).min(h));
            let (top, bottom) = (y0 * stride, y1 * stride);
            for x in 0..stride {
                columns[x] = (self.sums[bottom + x] - self.sums[top + x]) as f64;
                columns_sq[x] = (self.squares[bottom + x] - self.squares[top + x]) as f64;
            }
            let inverse_height = 1.0 / (y1 - y0) as f64;
            let row = &self.levels[y * w..(y + 1) * w];
            let out = &mut self.mask.pixels[y * w..(y + 1) * w];
            let dark = |x0: usize, x1: usize, inverse_n: f64, p: u8| {
                let mean = (columns[x1] - columns[x0]) * inverse_n;
                let variance =
                    ((columns_sq[x1] - columns_sq[x0]) * inverse_n - mean * mean).max(0.0);
                let d = mean - f64::from(p) - offset;
                d >= 0.0 && d * d >= sigmas_sq * variance
            };
            // The frame's left and right borders clip the window; between
            // them (`half..w - half`) it is whole, and the loop has no
            // clipping to do.
            let (inner_start, inner_end) = (half.min(w), w.saturating_sub(half).max(half.min(w)));
            for x in (0..inner_start).chain(inner_end..w) {
                let (x0, x1) = (x.saturating_sub(half), (x + half + 1).min(w));
                if dark(x0, x1, inverse_width[x] * inverse_height, row[x]) {
                    out[x] = MASK_DARK;
                }
            }
            let inverse_n = inverse_height / (2 * half + 1) as f64;
            // Written whatever the answer: no branch, so the loop vectorises.
            let (lo, hi) = (&columns[..], &columns[2 * half + 1..]);
            let (lo_sq, hi_sq) = (&columns_sq[..], &columns_sq[2 * half + 1..]);
            let span = inner_start..inner_end;
            for ((((o, &p), (&a, &b)), &a_sq), &b_sq) in out[span.clone()]
                .iter_mut()
                .zip(&row[span.clone()])
                .zip(lo.iter().zip(hi))
                .zip(lo_sq)
                .zip(hi_sq)
            {
                let mean = (b - a) * inverse_n;
                let variance = ((b_sq - a_sq) * inverse_n - mean * mean).max(0.0);
                let d = mean - f64::from(p) - offset;
                let dark = d >= 0.0 && d * d >= sigmas_sq * variance;
                *o = if dark { MASK_DARK } else { MASK_LIGHT };
            }
        }
    }

    /// The summed-area tables of `img`, exact in u64 for any frame the
    /// camera file allows (a 16384 x 16384 frame at `decimation = 1` sums
    /// to 6.8e10 levels and 1.7e13 squares; u32 would wrap).
    fn tables(&mut self, img: &Decimated) {
        let (w, h) = (img.width, img.height);
        let stride = w + 1;
        self.sums.clear();
        self.sums.resize(stride * (h + 1), 0);
        self.squares.clear();
        self.squares.resize(stride * (h + 1), 0);
        for y in 0..h {
            let (mut row, mut row_sq) = (0u64, 0u64);
            for x in 0..w {
                let p = u64::from(img.pixels[y * w + x]);
                row += p;
                row_sq += p * p;
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
        // standard deviation computed directly, `(p - mean) / (std +
        // floor) <= -sigmas`.
        let img = decimated(23, 17, |x, y| ((x * 37 + y * 91 + x * y * 13) % 251) as u8);
        let mut lc = LocalContrast::default();
        lc.prepare(&img);
        for (side, floor, sigmas) in [(7, 2.0, 1.0), (5, 0.0, 0.5), (11, 6.0, 1.5)] {
            lc.dark_mask(side, floor, sigmas);
            let half = side / 2;
            let mut dark = 0;
            for y in 0..img.height {
                for x in 0..img.width {
                    let mut values = Vec::new();
                    for v in y.saturating_sub(half)..(y + half + 1).min(img.height) {
                        for u in x.saturating_sub(half)..(x + half + 1).min(img.width) {
                            values.push(f64::from(img.pixels[v * img.width + u]));
                        }
                    }
                    let n = values.len() as f64;
                    let mean = values.iter().sum::<f64>() / n;
                    let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
                    let p = f64::from(img.pixels[y * img.width + x]);
                    let z = (p - mean) / (std + floor);
                    let got = lc.mask.pixels[y * img.width + x] == MASK_DARK;
                    dark += usize::from(got);
                    // Rounding may decide a pixel exactly at the level.
                    if (z + sigmas).abs() > 1e-9 {
                        assert_eq!(got, z <= -sigmas, "({x}, {y}) side {side}: z {z}");
                    }
                }
            }
            assert!(
                dark > 0,
                "side {side}: no dark pixel, the test shows nothing"
            );
        }
    }

    #[test]
    fn a_disc_stands_out_whatever_the_level_around_it() {
        // Two discs 40 levels darker than their surroundings, one in a dark
        // part of the frame and one in a light part (a strong vignetting or
        // haze gradient): a global threshold between the frame's darkest
        // and median levels takes the whole dark half with the first disc
        // and misses the second; against their neighbourhoods both are dark
        // and nothing else is.
        let img = decimated(80, 40, |x, y| {
            let base = if x < 40 { 70.0 } else { 200.0 };
            let disc = |cx: f64| (x as f64 - cx).hypot(y as f64 - 20.0) <= 4.0;
            (base - if disc(20.0) || disc(60.0) { 40.0 } else { 0.0 }) as u8
        });
        let mut lc = LocalContrast::default();
        lc.prepare(&img);
        lc.dark_mask(19, 2.0, 1.5);
        let at = |x: usize, y: usize| lc.mask.pixels[y * 80 + x];
        assert_eq!((at(20, 20), at(60, 20)), (MASK_DARK, MASK_DARK));
        // Away from the discs (and from the step between the halves) the
        // frame is at its neighbourhood's mean.
        assert_eq!((at(5, 5), at(75, 35)), (MASK_LIGHT, MASK_LIGHT));
        // The dark pixels are the two discs' (radius 4: 49 pixels each).
        let dark: usize = lc
            .mask
            .pixels
            .iter()
            .map(|&p| usize::from(p == MASK_DARK))
            .sum();
        assert!((80..=98).contains(&dark), "{dark} dark pixels");
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
