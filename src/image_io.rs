//! Reading image files into 8-bit gray frames.

use image::{DynamicImage, GrayImage, ImageReader, Limits};
use std::path::Path;

/// File endings `process` and the `dir:` source read (case-insensitive).
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "pgm", "bmp", "pnm"];

/// Whether a path has one of [`IMAGE_EXTENSIONS`].
pub fn is_image_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// Reads an image file as 8-bit gray: 16-bit samples are scaled to 8 bits,
/// colour becomes luma, alpha is dropped.
/// Decoding is bounded so that a hostile header cannot exhaust memory.
pub fn read_gray8(path: &Path) -> Result<GrayImage, String> {
    let mut reader = ImageReader::open(path)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let mut limits = Limits::default();
    limits.max_image_width = Some(32_768);
    limits.max_image_height = Some(32_768);
    limits.max_alloc = Some(512 * 1024 * 1024);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| e.to_string())?;
    Ok(to_gray8(img))
}

/// Any decoded image as 8-bit gray (16-bit rounded to 8, colour to luma).
pub fn to_gray8(img: DynamicImage) -> GrayImage {
    match img {
        DynamicImage::ImageLuma8(g) => g,
        other => other.to_luma8(),
    }
}
