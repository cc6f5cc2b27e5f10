//! Reading image files into 8-bit gray frames.
//!
//! Frames are sized by the calibration: when the camera is known, an image
//! whose header gives another size is refused before a single pixel is
//! decoded, so a small file claiming a huge image (a "bomb") never makes the
//! process allocate more than a few frames' worth. Without a camera the
//! header may claim at most [`crate::camera::MAX_SIDE_PX`] a side and the
//! decoder at most [`UNSIZED_ALLOC_LIMIT`] bytes. A JPEG that ends before its
//! end-of-image marker is unreadable (the decoder would fill the missing part
//! with grey and the detector would run on it).

use crate::camera::{CameraModel, MAX_SIDE_PX};
use image::{DynamicImage, GrayImage, ImageFormat, ImageReader, Limits};
use std::io::{Cursor, Read};
use std::path::Path;

/// File endings `process` and the `dir:` source read (case-insensitive).
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "pgm", "bmp", "pnm"];

/// Most bytes a decoder may allocate for an image of unknown expected size.
pub const UNSIZED_ALLOC_LIMIT: u64 = 48 << 20;

/// Whether a path has one of [`IMAGE_EXTENSIONS`].
pub fn is_image_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// Decoder memory for an image of `w` x `h`: the widest pixel the formats
/// give (16-bit RGBA, 8 bytes), plus the gray copy and some slack.
fn alloc_limit(w: u32, h: u32) -> u64 {
    u64::from(w) * u64::from(h) * 9 + (1 << 20)
}

/// The words between the two sizes of a size-mismatch error: callers that
/// must tell a frame of another size (a setup error) from an unreadable one
/// look for them with [`is_size_mismatch`].
const SIZE_MISMATCH: &str = ", the camera file's calibration is ";

/// Whether an error of this module says the frame is not the camera file's
/// size (rather than unreadable).
pub fn is_size_mismatch(error: &str) -> bool {
    error.contains(SIZE_MISMATCH)
}

/// Reads an image file as 8-bit gray: 16-bit samples are scaled to 8 bits,
/// colour becomes luma, alpha is dropped. `expected`: the camera's frame
/// size; another size is refused from the header.
pub fn read_gray8(path: &Path, expected: Option<(u32, u32)>) -> Result<GrayImage, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    // An image file is never larger than its decoded pixels plus headers;
    // a bigger file is not read into memory whole.
    let (w, h) = expected.unwrap_or((MAX_SIDE_PX, MAX_SIDE_PX));
    let most = expected.map_or(UNSIZED_ALLOC_LIMIT, |_| alloc_limit(w, h));
    let mut bytes = Vec::new();
    file.take(most + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > most {
        return Err(format!(
            "file larger than {most} bytes, more than any {w}x{h} image needs"
        ));
    }
    decode_gray8(&bytes, None, expected)
}

/// Decodes an image held in memory (`format`: `None` guesses it from the
/// bytes), checking the header against `expected` first.
pub fn decode_gray8(
    bytes: &[u8],
    format: Option<ImageFormat>,
    expected: Option<(u32, u32)>,
) -> Result<GrayImage, String> {
    let reader = |bytes| -> Result<ImageReader<Cursor<&[u8]>>, String> {
        match format {
            Some(f) => Ok(ImageReader::with_format(Cursor::new(bytes), f)),
            None => ImageReader::new(Cursor::new(bytes))
                .with_guessed_format()
                .map_err(|e| e.to_string()),
        }
    };
    let mut limits = Limits::default();
    limits.max_alloc = Some(expected.map_or(UNSIZED_ALLOC_LIMIT, |(w, h)| alloc_limit(w, h)));
    // The header alone first: the size, and nothing allocated for pixels.
    let mut head = reader(bytes)?;
    let format = head.format();
    head.limits(limits.clone());
    let (w, h) = head.into_dimensions().map_err(|e| e.to_string())?;
    match expected {
        Some((ew, eh)) if (w, h) != (ew, eh) => {
            return Err(format!("image is {w}x{h}{SIZE_MISMATCH}{ew}x{eh}"));
        }
        None if w > MAX_SIDE_PX || h > MAX_SIDE_PX => {
            return Err(format!(
                "image is {w}x{h}, larger than {MAX_SIDE_PX} pixels a side"
            ));
        }
        _ => {}
    }
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    if format == Some(ImageFormat::Jpeg) && !jpeg_is_complete(bytes) {
        return Err("JPEG ends early (no end-of-image marker)".into());
    }
    let mut r = reader(bytes)?;
    r.limits(limits);
    let img = r.decode().map_err(|e| e.to_string())?;
    Ok(to_gray8(img))
}

/// Whether a JPEG ends with its end-of-image marker (FF D9), allowing the
/// zero padding some cameras append.
fn jpeg_is_complete(bytes: &[u8]) -> bool {
    let end = bytes.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
    bytes[..end].ends_with(&[0xFF, 0xD9])
}

/// A frame whose size is not the calibration's: refused (the intrinsics
/// would give wrong poses, and a larger frame costs more than budgeted).
pub fn check_frame_size(image: &GrayImage, camera: &CameraModel) -> Result<(), String> {
    if image.dimensions() == (camera.width, camera.height) {
        Ok(())
    } else {
        Err(format!(
            "frame is {}x{}{SIZE_MISMATCH}{}x{}",
            image.width(),
            image.height(),
            camera.width,
            camera.height
        ))
    }
}

/// Any decoded image as 8-bit gray (16-bit rounded to 8, colour to luma).
pub fn to_gray8(img: DynamicImage) -> GrayImage {
    match img {
        DynamicImage::ImageLuma8(g) => g,
        other => other.to_luma8(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encode(img: &GrayImage, format: ImageFormat) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        img.write_to(&mut out, format).unwrap();
        out.into_inner()
    }

    fn gradient(w: u32, h: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| image::Luma([((x * 7 + y * 3) % 256) as u8]))
    }

    #[test]
    fn the_header_size_is_checked_against_the_camera() {
        let png = encode(&gradient(64, 48), ImageFormat::Png);
        assert_eq!(
            decode_gray8(&png, None, Some((64, 48)))
                .unwrap()
                .dimensions(),
            (64, 48)
        );
        let e = decode_gray8(&png, None, Some((640, 480))).unwrap_err();
        assert!(e.contains("64x48") && e.contains("640x480"), "{e}");
    }

    #[test]
    fn a_truncated_jpeg_is_unreadable() {
        let jpeg = encode(&gradient(64, 48), ImageFormat::Jpeg);
        assert!(decode_gray8(&jpeg, None, Some((64, 48))).is_ok());
        // The image crate itself would decode the cut file (grey fill).
        let cut = &jpeg[..jpeg.len() * 2 / 3];
        assert!(image::load_from_memory(cut).is_ok());
        let e = decode_gray8(cut, None, Some((64, 48))).unwrap_err();
        assert!(e.contains("ends early"), "{e}");
        let mut padded = jpeg.clone();
        padded.extend_from_slice(&[0, 0, 0]);
        assert!(decode_gray8(&padded, None, Some((64, 48))).is_ok());
    }
}
