//! `mcap:` source: the `/camera/image` frames of a flight log, for replay.

use super::replay::{self, ReplayReader};
use super::{Captured, FrameSource, SourceError, SourceItem};
use crate::camera::CameraModel;
use crate::measure::mount::MountConfig;
use std::path::Path;

/// Reads a log's frames back with their recorded capture times.
pub struct McapSource {
    path: std::path::PathBuf,
    reader: ReplayReader,
    /// The log's own camera (`/camera/calibration`), or why it has none (a
    /// log without one needs `--camera`).
    camera: Result<CameraModel, String>,
}

impl McapSource {
    pub fn open(path: &Path) -> Result<Self, SourceError> {
        let open_err = |e: crate::log::LogError| SourceError::Open {
            source_name: format!("mcap:{}", path.display()),
            message: e.to_string(),
        };
        Ok(Self {
            path: path.to_path_buf(),
            camera: ReplayReader::first_camera(path)
                .map_err(|e| format!("mcap:{}: {e}", path.display())),
            reader: replay::open(path).map_err(open_err)?,
        })
    }
}

impl McapSource {
    /// Records above the record bound skipped unread so far (frames they
    /// held are missing).
    pub fn oversized_records(&self) -> u64 {
        self.reader.oversized().records()
    }
}

impl FrameSource for McapSource {
    fn camera(&self) -> Option<CameraModel> {
        self.camera.as_ref().ok().cloned()
    }
    fn no_camera_reason(&self) -> Option<String> {
        self.camera.as_ref().err().cloned()
    }
    fn mount(&self) -> Option<MountConfig> {
        None
    }
    fn fps(&self) -> Option<f64> {
        None
    }
    fn recorded_timeline(&self) -> bool {
        true
    }
    fn provenance(&self) -> Vec<(String, String)> {
        vec![("replayed_log".to_string(), self.path.display().to_string())]
    }
    fn next_frame(&mut self) -> Option<SourceItem> {
        self.reader
            .next()
            .map(|r| r.map(Captured::from).map_err(|e| e.to_string()))
    }
}
