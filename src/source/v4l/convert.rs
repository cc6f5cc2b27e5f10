//! V4L2 buffers to 8-bit gray frames. Pure functions, so that every format
//! and every malformed buffer is tested without a camera.

use image::GrayImage;
use serde::{Deserialize, Serialize};

/// The pixel formats the camera source can use, by their V4L2 four-character code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum PixelFormat {
    /// `GREY`: 8-bit monochrome, used as is.
    #[serde(rename = "GREY")]
    Grey,
    /// `YUYV`: packed 4:2:2 (Y0 U Y1 V); the Y samples are the gray frame.
    #[serde(rename = "YUYV")]
    Yuyv,
    /// `MJPG`: one JPEG per frame (most USB cameras at full size), decoded to luma.
    #[serde(rename = "MJPG")]
    Mjpeg,
}

impl PixelFormat {
    /// The V4L2 four-character code.
    pub fn fourcc(self) -> [u8; 4] {
        match self {
            Self::Grey => *b"GREY",
            Self::Yuyv => *b"YUYV",
            Self::Mjpeg => *b"MJPG",
        }
    }

    /// The format of a four-character code, when it is one we read.
    pub fn from_fourcc(code: [u8; 4]) -> Option<Self> {
        [Self::Grey, Self::Yuyv, Self::Mjpeg]
            .into_iter()
            .find(|f| f.fourcc() == code)
    }

    /// Bytes per pixel of an uncompressed format (`None` for MJPEG).
    fn bytes_per_pixel(self) -> Option<usize> {
        match self {
            Self::Grey => Some(1),
            Self::Yuyv => Some(2),
            Self::Mjpeg => None,
        }
    }
}

impl std::fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(std::str::from_utf8(&self.fourcc()).unwrap_or("????"))
    }
}

/// What the driver granted: the layout of every buffer of the stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BufferLayout {
    /// The stream's pixel format.
    pub format: PixelFormat,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Bytes from one row to the next (V4L2 `bytesperline`); 0: rows packed.
    pub stride_bytes: u32,
}

/// A buffer that does not make a frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConvertError {
    /// The layout has a zero width or height.
    #[error("{format} frame of {width}x{height}: empty size")]
    EmptySize {
        /// The stream's pixel format.
        format: PixelFormat,
        /// Frame width, pixels.
        width: u32,
        /// Frame height, pixels.
        height: u32,
    },
    /// The row stride is shorter than a row of pixels.
    #[error("{format} frame of {width}x{height}: row stride {stride} bytes is less than a row")]
    StrideTooSmall {
        /// The stream's pixel format.
        format: PixelFormat,
        /// Frame width, pixels.
        width: u32,
        /// Frame height, pixels.
        height: u32,
        /// Bytes from one row to the next.
        stride: u32,
    },
    /// The buffer holds fewer bytes than the frame's rows need.
    #[error("{format} frame of {width}x{height}: buffer holds {got} bytes, the frame needs {need}")]
    ShortBuffer {
        /// The stream's pixel format.
        format: PixelFormat,
        /// Frame width, pixels.
        width: u32,
        /// Frame height, pixels.
        height: u32,
        /// Bytes in the buffer.
        got: usize,
        /// Bytes the frame needs.
        need: usize,
    },
    /// The JPEG lacks its end-of-image marker (a frame cut short).
    #[error("MJPG frame is incomplete (no end-of-image marker): {got} bytes")]
    JpegIncomplete {
        /// Bytes in the buffer.
        got: usize,
    },
    /// The JPEG decoder refused the frame; holds its message.
    #[error("MJPG frame does not decode: {0}")]
    JpegDecode(String),
    /// The JPEG decodes to another size than the stream's.
    #[error("MJPG frame is {got_width}x{got_height}, the stream was set up for {width}x{height}")]
    JpegSize {
        /// The decoded width, pixels.
        got_width: u32,
        /// The decoded height, pixels.
        got_height: u32,
        /// The stream's width, pixels.
        width: u32,
        /// The stream's height, pixels.
        height: u32,
    },
}

/// The gray frame in a driver buffer (`data`: the bytes the driver filled).
pub fn to_gray(layout: &BufferLayout, data: &[u8]) -> Result<GrayImage, ConvertError> {
    let BufferLayout {
        format,
        width,
        height,
        stride_bytes,
    } = *layout;
    if width == 0 || height == 0 {
        return Err(ConvertError::EmptySize {
            format,
            width,
            height,
        });
    }
    let Some(bytes_per_pixel) = format.bytes_per_pixel() else {
        return decode_mjpeg(layout, data);
    };
    let (w, h) = (width as usize, height as usize);
    // Sizes come from the driver: computed with checks, never trusted to fit.
    let row_bytes = w.checked_mul(bytes_per_pixel);
    let stride = if stride_bytes == 0 {
        row_bytes
    } else {
        Some(stride_bytes as usize)
    };
    let (Some(row_bytes), Some(stride)) = (row_bytes, stride) else {
        return Err(ConvertError::EmptySize {
            format,
            width,
            height,
        });
    };
    if stride < row_bytes {
        return Err(ConvertError::StrideTooSmall {
            format,
            width,
            height,
            stride: stride_bytes,
        });
    }
    let need = stride
        .checked_mul(h - 1)
        .and_then(|n| n.checked_add(row_bytes))
        .unwrap_or(usize::MAX);
    if data.len() < need {
        return Err(ConvertError::ShortBuffer {
            format,
            width,
            height,
            got: data.len(),
            need,
        });
    }
    let mut gray = Vec::with_capacity(w * h);
    for row in 0..h {
        let start = row * stride;
        let pixels = &data[start..start + row_bytes];
        match format {
            PixelFormat::Grey => gray.extend_from_slice(pixels),
            // Y0 U Y1 V: luma is every even byte.
            _ => gray.extend(pixels.chunks_exact(2).map(|yu| yu[0])),
        }
    }
    GrayImage::from_raw(width, height, gray).ok_or(ConvertError::ShortBuffer {
        format,
        width,
        height,
        got: data.len(),
        need,
    })
}

/// Whether a JPEG payload ends with its end-of-image marker. Cameras pad a
/// frame with zeros after it; a frame cut short by the USB transfer has none
/// (and a lenient decoder would fill the missing rows with gray).
fn jpeg_complete(data: &[u8]) -> bool {
    let end = data.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
    data[..end].ends_with(&[0xFF, 0xD9])
}

/// An MJPG frame (one JPEG; the Huffman tables may be left out, as motion
/// JPEG allows) decoded to its luma plane: for a YCbCr JPEG the Y samples as
/// coded, the same quantity as GREY and YUYV give, without a colour round trip.
/// Decoded by zune-jpeg, the `image` crate's own JPEG decoder, asked for luma
/// output directly (`image`'s decode + `into_luma8` costs ~3.5x more).
fn decode_mjpeg(layout: &BufferLayout, data: &[u8]) -> Result<GrayImage, ConvertError> {
    use zune_core::bytestream::ZCursor;
    use zune_core::colorspace::ColorSpace;
    use zune_core::options::DecoderOptions;
    if !jpeg_complete(data) {
        return Err(ConvertError::JpegIncomplete { got: data.len() });
    }
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::Luma);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(data), options);
    let pixels = decoder
        .decode()
        .map_err(|e| ConvertError::JpegDecode(e.to_string()))?;
    let (w, h) = decoder
        .dimensions()
        .ok_or_else(|| ConvertError::JpegDecode("no frame header".into()))?;
    let (got_width, got_height) = (
        u32::try_from(w).unwrap_or(u32::MAX),
        u32::try_from(h).unwrap_or(u32::MAX),
    );
    if (got_width, got_height) != (layout.width, layout.height) {
        return Err(ConvertError::JpegSize {
            got_width,
            got_height,
            width: layout.width,
            height: layout.height,
        });
    }
    // The decoder may keep another colorspace than asked (e.g. CMYK input):
    // only one byte per pixel is a gray frame.
    let one_byte_per_pixel = w.checked_mul(h) == Some(pixels.len());
    one_byte_per_pixel
        .then(|| GrayImage::from_raw(got_width, got_height, pixels))
        .flatten()
        .ok_or_else(|| {
            ConvertError::JpegDecode(format!(
                "decoded to {:?}, not to one luma byte per pixel",
                decoder.output_colorspace()
            ))
        })
}

/// The bytes of a dequeued buffer that hold the frame: `bytesused` as the
/// driver reports it, bounded by the buffer; a driver that leaves it at 0
/// (allowed for fixed-size formats) means the whole buffer.
pub fn payload(buffer: &[u8], bytes_used: u32) -> &[u8] {
    match bytes_used as usize {
        0 => buffer,
        n => &buffer[..n.min(buffer.len())],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageEncoder, Luma};

    /// A test pattern whose every pixel is known: a gradient with a dark disc.
    fn pattern(width: u32, height: u32) -> GrayImage {
        GrayImage::from_fn(width, height, |x, y| {
            let (dx, dy) = (
                x as f64 - width as f64 / 2.0,
                y as f64 - height as f64 / 2.0,
            );
            if dx * dx + dy * dy < (height as f64 / 4.0).powi(2) {
                Luma([20])
            } else {
                Luma([(100 + (x * 3 + y) % 120) as u8])
            }
        })
    }

    fn layout(format: PixelFormat, width: u32, height: u32, stride: u32) -> BufferLayout {
        BufferLayout {
            format,
            width,
            height,
            stride_bytes: stride,
        }
    }

    /// The YUYV buffer of `gray`: Y from the image, U/V set to values that
    /// must not leak into the result, `pad` bytes of padding per row.
    fn yuyv_of(gray: &GrayImage, pad: usize) -> Vec<u8> {
        let mut out = Vec::new();
        for row in gray.rows() {
            for (i, p) in row.enumerate() {
                out.push(p[0]);
                out.push(if i % 2 == 0 { 0x55 } else { 0xAA });
            }
            out.extend(std::iter::repeat_n(0xEE, pad));
        }
        out
    }

    fn jpeg_of(gray: &GrayImage, quality: u8) -> Vec<u8> {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
            .write_image(
                gray.as_raw(),
                gray.width(),
                gray.height(),
                image::ExtendedColorType::L8,
            )
            .unwrap();
        out
    }

    /// The gray image as a colour (YCbCr, chroma-subsampled) JPEG, as
    /// cameras send it: R = G = B, so its luma is the gray value.
    fn colour_jpeg_of(gray: &GrayImage, quality: u8) -> Vec<u8> {
        let rgb: Vec<u8> = gray.as_raw().iter().flat_map(|&y| [y, y, y]).collect();
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
            .write_image(
                &rgb,
                gray.width(),
                gray.height(),
                image::ExtendedColorType::Rgb8,
            )
            .unwrap();
        out
    }

    fn mean_abs_error(a: &GrayImage, b: &GrayImage) -> f64 {
        a.as_raw()
            .iter()
            .zip(b.as_raw())
            .map(|(&x, &y)| (x as f64 - y as f64).abs())
            .sum::<f64>()
            / a.as_raw().len() as f64
    }

    #[test]
    fn grey_packed_and_padded_rows() {
        let truth = pattern(64, 48);
        let packed = truth.as_raw().clone();
        let got = to_gray(&layout(PixelFormat::Grey, 64, 48, 0), &packed).unwrap();
        assert_eq!(got, truth);
        let got = to_gray(&layout(PixelFormat::Grey, 64, 48, 64), &packed).unwrap();
        assert_eq!(got, truth);
        // Rows padded to 80 bytes; the padding must not appear in the frame.
        let mut padded = Vec::new();
        for row in truth.as_raw().chunks(64) {
            padded.extend_from_slice(row);
            padded.extend_from_slice(&[0xFF; 16]);
        }
        let got = to_gray(&layout(PixelFormat::Grey, 64, 48, 80), &padded).unwrap();
        assert_eq!(got, truth);
        // The last row's padding may be missing from the buffer.
        padded.truncate(padded.len() - 16);
        let got = to_gray(&layout(PixelFormat::Grey, 64, 48, 80), &padded).unwrap();
        assert_eq!(got, truth);
    }

    #[test]
    fn yuyv_takes_luma_only() {
        let truth = pattern(64, 48);
        let got = to_gray(&layout(PixelFormat::Yuyv, 64, 48, 0), &yuyv_of(&truth, 0)).unwrap();
        assert_eq!(got, truth);
        let got = to_gray(
            &layout(PixelFormat::Yuyv, 64, 48, 140),
            &yuyv_of(&truth, 12),
        )
        .unwrap();
        assert_eq!(got, truth);
    }

    #[test]
    fn short_buffers_and_bad_strides_are_errors() {
        let truth = pattern(64, 48);
        let grey = truth.as_raw();
        let e = to_gray(
            &layout(PixelFormat::Grey, 64, 48, 0),
            &grey[..grey.len() - 1],
        );
        assert_eq!(
            e,
            Err(ConvertError::ShortBuffer {
                format: PixelFormat::Grey,
                width: 64,
                height: 48,
                got: 64 * 48 - 1,
                need: 64 * 48
            })
        );
        // A GREY-sized buffer read as YUYV is half the size it must be.
        assert!(matches!(
            to_gray(&layout(PixelFormat::Yuyv, 64, 48, 0), grey),
            Err(ConvertError::ShortBuffer { need: 6144, .. })
        ));
        assert!(matches!(
            to_gray(&layout(PixelFormat::Yuyv, 64, 48, 100), &yuyv_of(&truth, 0)),
            Err(ConvertError::StrideTooSmall { stride: 100, .. })
        ));
        assert!(matches!(
            to_gray(&layout(PixelFormat::Grey, 0, 48, 0), grey),
            Err(ConvertError::EmptySize { .. })
        ));
        assert!(to_gray(&layout(PixelFormat::Grey, 64, 48, 0), &[]).is_err());
        // Sizes that overflow are errors, not panics.
        assert!(
            to_gray(
                &layout(PixelFormat::Yuyv, u32::MAX, u32::MAX, u32::MAX),
                grey
            )
            .is_err()
        );
        assert!(to_gray(&layout(PixelFormat::Grey, u32::MAX, 2, 0), grey).is_err());
    }

    #[test]
    fn mjpeg_decodes_to_luma_within_jpeg_loss() {
        let truth = pattern(160, 120);
        let jpeg = jpeg_of(&truth, 95);
        let got = to_gray(&layout(PixelFormat::Mjpeg, 160, 120, 0), &jpeg).unwrap();
        assert_eq!(got.dimensions(), truth.dimensions());
        let e = mean_abs_error(&got, &truth);
        assert!(e < 2.0, "mean |error| {e} gray levels");
        let colour = colour_jpeg_of(&truth, 95);
        let got_colour = to_gray(&layout(PixelFormat::Mjpeg, 160, 120, 0), &colour).unwrap();
        let e = mean_abs_error(&got_colour, &truth);
        assert!(e < 2.0, "colour JPEG: mean |error| {e} gray levels");
        // Zero padding after the end-of-image marker, as cameras send it.
        let mut padded = jpeg.clone();
        padded.extend_from_slice(&[0; 300]);
        let got2 = to_gray(&layout(PixelFormat::Mjpeg, 160, 120, 0), &padded).unwrap();
        assert_eq!(got2, got);
    }

    #[test]
    fn mjpeg_faults_are_errors() {
        let truth = pattern(160, 120);
        let jpeg = jpeg_of(&truth, 90);
        let l = layout(PixelFormat::Mjpeg, 160, 120, 0);
        // Cut short, as an interrupted USB transfer leaves it.
        for cut in [0, 2, 100, jpeg.len() / 2, jpeg.len() - 1] {
            assert!(
                matches!(
                    to_gray(&l, &jpeg[..cut]),
                    Err(ConvertError::JpegIncomplete { .. })
                ),
                "cut at {cut}"
            );
        }
        // Not a JPEG at all, ending like one.
        let mut junk = vec![0x42; 500];
        junk.extend_from_slice(&[0xFF, 0xD9]);
        assert!(matches!(
            to_gray(&l, &junk),
            Err(ConvertError::JpegDecode(_))
        ));
        // A corrupted header (start-of-frame marker destroyed).
        let sof = jpeg.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
        let mut broken = jpeg.clone();
        broken[sof + 1] = 0x00;
        broken[sof + 2] = 0x00;
        assert!(to_gray(&l, &broken).is_err());
        // Another size than the stream's.
        assert_eq!(
            to_gray(&layout(PixelFormat::Mjpeg, 320, 240, 0), &jpeg),
            Err(ConvertError::JpegSize {
                got_width: 160,
                got_height: 120,
                width: 320,
                height: 240
            })
        );
    }

    #[test]
    fn mjpeg_without_huffman_tables_decodes() {
        // Motion JPEG as UVC cameras send it: an AVI1 APP0 segment and no DHT
        // segment (the decoder supplies the standard tables, which is what
        // the image crate's encoder uses too, so the pixels must be equal).
        let truth = pattern(160, 120);
        let jpeg = jpeg_of(&truth, 90);
        let reference = to_gray(&layout(PixelFormat::Mjpeg, 160, 120, 0), &jpeg).unwrap();
        let mut mjpeg = vec![0xFF, 0xD8];
        mjpeg.extend_from_slice(&[0xFF, 0xE0, 0x00, 0x10]);
        mjpeg.extend_from_slice(b"AVI1\0");
        mjpeg.extend_from_slice(&[0; 9]);
        let mut i = 2;
        let mut dht_removed = 0;
        while i + 4 <= jpeg.len() && jpeg[i] == 0xFF {
            let marker = jpeg[i + 1];
            if marker == 0xDA {
                mjpeg.extend_from_slice(&jpeg[i..]);
                break;
            }
            let len = u16::from_be_bytes([jpeg[i + 2], jpeg[i + 3]]) as usize;
            if marker == 0xC4 {
                dht_removed += 1;
            } else if marker != 0xE0 {
                mjpeg.extend_from_slice(&jpeg[i..i + 2 + len]);
            }
            i += 2 + len;
        }
        assert!(dht_removed > 0, "the test JPEG must carry Huffman tables");
        let got = to_gray(&layout(PixelFormat::Mjpeg, 160, 120, 0), &mjpeg).unwrap();
        assert_eq!(got, reference);
    }

    #[test]
    fn payload_is_bounded_by_the_buffer() {
        let buf = [1u8, 2, 3, 4];
        assert_eq!(payload(&buf, 0), &buf);
        assert_eq!(payload(&buf, 2), &buf[..2]);
        assert_eq!(payload(&buf, 99), &buf);
    }

    #[test]
    fn fourcc_round_trip() {
        for f in [PixelFormat::Grey, PixelFormat::Yuyv, PixelFormat::Mjpeg] {
            assert_eq!(PixelFormat::from_fourcc(f.fourcc()), Some(f));
        }
        assert_eq!(PixelFormat::from_fourcc(*b"NV12"), None);
        assert_eq!(PixelFormat::Mjpeg.to_string(), "MJPG");
    }
}
