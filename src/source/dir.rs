//! `dir:` source: the images of a folder, in lexicographic order, with the
//! capture times of a [`FolderTiming`].

use super::{Captured, FrameSource, SourceError, SourceItem};
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

/// The capture times a folder's frames get (a folder records none).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FolderTiming {
    /// The time each image is read (`run --source dir:`).
    ReadTime,
    /// Frame `seq` at `seq` × this period, ns, from 0 (`process`): the same
    /// times on every run, for the tracker's prediction.
    Period(u64),
}

/// Reads a folder's images one by one, in lexicographic order.
pub struct DirSource {
    images: std::vec::IntoIter<PathBuf>,
    seq: u64,
    timing: FolderTiming,
    /// Image files in the folder, and other files (not read).
    images_total: usize,
    others: usize,
    /// The camera's frame size, once known.
    expected: Option<(u32, u32)>,
}

impl DirSource {
    pub fn open(dir: &Path, timing: FolderTiming) -> Result<Self, SourceError> {
        let (images, others) = list_images(dir)?;
        Ok(Self {
            images_total: images.len(),
            images: images.into_iter(),
            seq: 0,
            timing,
            others,
            expected: None,
        })
    }

    /// One image file, as a folder holding only it (`process IMAGE`).
    pub fn one_image(path: &Path, timing: FolderTiming) -> Self {
        Self {
            images_total: 1,
            images: vec![path.to_path_buf()].into_iter(),
            seq: 0,
            timing,
            others: 0,
            expected: None,
        }
    }

    /// The folder's image files (each one item).
    pub fn images(&self) -> usize {
        self.images_total
    }

    /// Files in the folder that are not images (not read).
    pub fn other_files(&self) -> usize {
        self.others
    }

    /// The next image's path, before [`FrameSource::next_frame`] reads it.
    pub fn peek_path(&self) -> Option<&Path> {
        self.images.as_slice().first().map(PathBuf::as_path)
    }
}

/// Now, nanoseconds since the Unix epoch.
pub fn unix_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
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
        let capture_time_ns = match self.timing {
            FolderTiming::ReadTime => unix_now_ns(),
            FolderTiming::Period(ns) => seq.saturating_mul(ns),
        };
        Some(
            read_gray8(&path, self.expected)
                .map(|image| Frame {
                    seq,
                    capture_time_ns,
                    image,
                    origin: FrameOrigin::File(path.clone()),
                })
                .map(Captured::from)
                .map_err(|e| format!("{}: {e}", path.display())),
        )
    }
}
