//! The `[log]` config section: what the log writes (image encoding, chunk
//! compression, rotation, sync, queue sizes) and the checks of its values.
//! The log's own, so the config file's top level only gathers it.

use super::LogError;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// How `/camera/image` stores the frames. `raw` and `png` are lossless and
/// keep every frame, so a replay reproduces the logged detections exactly;
/// `jpeg` and `crop` are the opt-in long-flight modes, which give that up
/// (README, "Size").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImageEncoding {
    /// `foxglove.RawImage`, mono8: cheapest on the CPU.
    Raw,
    /// `foxglove.CompressedImage`, PNG ([`png_gray`](super::png_gray): Average filter,
    /// Huffman-only deflate): under half the disk of raw on camera frames.
    Png,
    /// `foxglove.CompressedImage`, JPEG at `jpeg_quality`: lossy, every frame.
    Jpeg,
    /// PNG full frames every `full_frame_every`-th frame, and on every frame
    /// a PNG crop around the drogue on `/camera/crop` (`crop`).
    Crop,
}

impl ImageEncoding {
    /// The schema of `/camera/image`.
    pub fn is_compressed(self) -> bool {
        self != ImageEncoding::Raw
    }
}

/// Chunk compression of the MCAP file (the `mcap` crate's own codecs; every
/// MCAP reader reads all three).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChunkCompression {
    /// zstd: the usual choice of the mcap CLI, rosbag2 and Foxglove.
    Zstd,
    /// lz4: less CPU, less saving.
    Lz4,
    /// Uncompressed chunks.
    None,
}

impl ChunkCompression {
    /// The `mcap` crate's setting.
    pub fn to_mcap(self) -> Option<mcap::Compression> {
        match self {
            ChunkCompression::Zstd => Some(mcap::Compression::Zstd),
            ChunkCompression::Lz4 => Some(mcap::Compression::Lz4),
            ChunkCompression::None => None,
        }
    }
}

/// `[log]` in the config (every key documented in `config/default.toml`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogConfig {
    /// Log folder (the `run --log-dir` default).
    pub dir: PathBuf,
    /// File name prefix: `<prefix>_<UTC start>_<part>.mcap`.
    pub file_prefix: String,
    /// How frames are stored: PNG, JPEG, raw, or crops around the drogue.
    pub image_encoding: ImageEncoding,
    /// JPEG quality of `image_encoding = "jpeg"` (1..=100).
    pub jpeg_quality: u8,
    /// `image_encoding = "crop"`: a full frame on `/camera/image` every this
    /// many frames (by sequence number).
    pub full_frame_every: u32,
    /// `image_encoding = "crop"`: the crop's half-size over the canopy's
    /// projected radius (1 = just the canopy).
    pub crop_margin: f64,
    /// `[drogue] canopy_radius_m / inner_radius_m`, set by the caller with
    /// [`LogConfig::set_drogue`]: the crop mode scales the inner circle's
    /// ellipse by it to cover the canopy. Not a config key.
    #[serde(skip)]
    pub canopy_ratio: Option<f64>,
    /// Chunk compression.
    pub compression: ChunkCompression,
    /// Compression level (zstd 1..=19, lz4 0..=12; 0 is the codec's default).
    pub compression_level: u32,
    /// Start a new numbered file after this many MiB (0: never by size).
    pub rotate_size_mib: u64,
    /// Start a new numbered file after this many seconds (0: never by time).
    pub rotate_duration_s: u64,
    /// Items (frames, measurements, messages, events) the queue holds before
    /// dropping new ones.
    pub queue_len: usize,
    /// Close the chunk and `sync_data` at least this often, milliseconds (1..=1000).
    pub sync_interval_ms: u64,
    /// Target chunk size, KiB (a chunk also ends at every sync).
    pub chunk_size_kib: u64,
    /// After a write error, wait this long before opening a new file, seconds.
    pub retry_after_error_s: u64,
    /// Recover cut-short files found in the log folder at start-up.
    pub recover_on_start: bool,
    /// Keep a recovered file's cut-short original as `<name>.mcap.cut`.
    pub keep_cut_files: bool,
}

impl LogConfig {
    /// Tells the crop mode the drogue's size (`[drogue]`, metres).
    pub fn set_drogue(&mut self, inner_radius_m: f64, canopy_radius_m: f64) {
        self.canopy_ratio = Some(canopy_radius_m / inner_radius_m);
    }

    /// Checks the values a writer relies on.
    pub fn validate(&self) -> Result<(), LogError> {
        let bad = |m: String| Err(LogError::Config(m));
        if !(1..=100).contains(&self.jpeg_quality) {
            return bad(format!(
                "log.jpeg_quality must be 1..=100, got {}",
                self.jpeg_quality
            ));
        }
        if self.full_frame_every == 0 {
            return bad("log.full_frame_every must be at least 1".into());
        }
        if !(1.0..=4.0).contains(&self.crop_margin) {
            return bad(format!(
                "log.crop_margin must be 1..=4, got {}",
                self.crop_margin
            ));
        }
        if self.image_encoding == ImageEncoding::Crop
            && !self
                .canopy_ratio
                .is_some_and(|r| r.is_finite() && (1.0..=100.0).contains(&r))
        {
            return bad(format!(
                "image_encoding = \"crop\" needs the drogue's size (LogConfig::set_drogue), got a canopy/inner ratio of {:?}",
                self.canopy_ratio
            ));
        }
        if self.queue_len == 0 {
            return bad("log.queue_len must be at least 1".into());
        }
        if !(1..=1000).contains(&self.sync_interval_ms) {
            return bad(format!(
                "log.sync_interval_ms must be 1..=1000 (a crash may lose at most about a second), got {}",
                self.sync_interval_ms
            ));
        }
        let max_level = match self.compression {
            ChunkCompression::Zstd => 19,
            ChunkCompression::Lz4 => 12,
            ChunkCompression::None => u32::MAX,
        };
        if self.compression_level > max_level {
            return bad(format!(
                "log.compression_level must be 0..={max_level} for {:?} compression, got {}",
                self.compression, self.compression_level
            ));
        }
        if self.chunk_size_kib == 0 {
            return bad("log.chunk_size_kib must be at least 1".into());
        }
        if self.file_prefix.is_empty()
            || self
                .file_prefix
                .chars()
                .any(|c| !(c.is_ascii_alphanumeric() || c == '-' || c == '_'))
        {
            return bad(format!(
                "log.file_prefix must be non-empty ASCII letters, digits, '-' or '_', got {:?}",
                self.file_prefix
            ));
        }
        Ok(())
    }
}
