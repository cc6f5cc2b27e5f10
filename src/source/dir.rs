//! `dir:` source: the images of a folder, in lexicographic order.

use super::{FrameSource, SourceError, SourceItem};
use crate::camera::CameraModel;
use crate::frame::{Frame, FrameOrigin};
use crate::image_io::{is_image_path, read_gray8};
use crate::measure::mount::MountConfig;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// The image files of a folder, sorted, and how many other files it holds.
pub fn list_images(dir: &Path) -> Result<(Vec<PathBuf>, usize), SourceError> {
    let open_err = |e: std::io::Error| SourceError::Open {
        source_name: dir.display().to_string(),
        message: e.to_string(),
    };
    let mut images = Vec::new();
    let mut others = 0;
    for entry in std::fs::read_dir(dir).map_err(open_err)? {
        let path = entry.map_err(open_err)?.path();
        if !path.is_file() {
            continue;
        }
        if is_image_path(&path) {
            images.push(path);
        } else {
            others += 1;
        }
    }
    images.sort();
    Ok((images, others))
}

/// Reads a folder's images one by one; capture time = the time of reading.
pub struct DirSource {
    images: std::vec::IntoIter<PathBuf>,
    seq: u64,
    /// The camera's frame size, once known.
    expected: Option<(u32, u32)>,
}

impl DirSource {
    pub fn open(dir: &Path) -> Result<Self, SourceError> {
        let (images, _) = list_images(dir)?;
        Ok(Self {
            images: images.into_iter(),
            seq: 0,
            expected: None,
        })
    }
}

/// Now, nanoseconds since the Unix epoch.
pub fn unix_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

impl FrameSource for DirSource {
    fn camera(&self) -> Option<CameraModel> {
        None
    }
    fn mount(&self) -> Option<MountConfig> {
        None
    }
    fn fps(&self) -> Option<f64> {
        None
    }
    fn expect_size(&mut self, width: u32, height: u32) {
        self.expected = Some((width, height));
    }
    fn next_frame(&mut self) -> Option<SourceItem> {
        let path = self.images.next()?;
        let seq = self.seq;
        self.seq += 1;
        Some(
            read_gray8(&path, self.expected)
                .map(|image| Frame {
                    seq,
                    capture_time_ns: unix_now_ns(),
                    image,
                    origin: FrameOrigin::File(path.clone()),
                })
                .map_err(|e| format!("{}: {e}", path.display())),
        )
    }
}
