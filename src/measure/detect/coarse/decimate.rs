//! Block-mean decimation of a frame for the coarse search (the edge
//! source votes on it too).

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
    /// Whether any block averages `level` or more: a whole block that
    /// bright is a saturated area (a glare), where a single specular pixel
    /// averages out.
    pub fn any_at_least(&self, level: u8) -> bool {
        // The largest block, not the first one at `level`: a scan without
        // an early exit that the compiler vectorises.
        self.pixels.iter().fold(0u8, |m, &p| m.max(p)) >= level
    }

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

    /// Decimated pixel position of full-resolution pixel coordinates: the
    /// inverse of [`Self::to_full`].
    pub fn to_decimated(&self, full_px: [f64; 2]) -> [f64; 2] {
        let f = self.factor.max(1) as f64;
        [(full_px[0] + 0.5) / f - 0.5, (full_px[1] + 0.5) / f - 0.5]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    #[test]
    fn to_decimated_undoes_to_full() {
        let mut d = Decimated::default();
        d.update(&GrayImage::new(64, 48), 4);
        // A block's centre: decimated pixel (2, 3) is full-res 8..11, 12..15.
        assert_eq!(d.to_full(2.0, 3.0), [9.5, 13.5]);
        assert_eq!(d.to_decimated([9.5, 13.5]), [2.0, 3.0]);
        assert_eq!(d.to_decimated(d.to_full(7.25, 0.5)), [7.25, 0.5]);
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
}
