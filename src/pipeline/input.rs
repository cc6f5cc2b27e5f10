//! Opening the input: the source of a `run --source` address or of
//! `process`'s input, its camera, and its first frame checked against the
//! camera before anything is written.

use crate::camera::CameraModel;
use crate::source::dir::{DirSource, FolderTiming};
use crate::source::mcap::McapSource;
use crate::source::sim::SimSource;
use crate::source::v4l::V4lConfig;
use crate::source::{FrameSource, SourceError, SourceItem, SourceSpec};
use std::path::Path;

/// Opens the source an address names; a folder's frames get `folder_timing`.
pub fn open_source(
    spec: &SourceSpec,
    v4l: &V4lConfig,
    folder_timing: FolderTiming,
) -> Result<Box<dyn FrameSource>, SourceError> {
    Ok(match spec {
        SourceSpec::Sim(name) => Box::new(SimSource::open(name)?),
        SourceSpec::Dir(path) => Box::new(DirSource::open(path, folder_timing)?),
        SourceSpec::Mcap(path) => Box::new(McapSource::open(path)?),
        SourceSpec::V4l(dev) => crate::source::v4l::open(dev, v4l)?,
    })
}

/// The camera: `given` (the user's `--camera` wins, even over a log's or a
/// scenario's own), else the source's own, else `configured` (`[camera]
/// file`; empty: none).
pub fn choose_camera(
    source: &dyn FrameSource,
    given: Option<&Path>,
    configured: &Path,
) -> Result<CameraModel, String> {
    if let Some(file) = given {
        return CameraModel::load(file).map_err(|e| e.to_string());
    }
    if let Some(c) = source.camera() {
        return Ok(c);
    }
    if configured.as_os_str().is_empty() {
        let why = source
            .no_camera_reason()
            .map_or_else(String::new, |r| format!(" ({r})"));
        return Err(format!(
            "this source has no camera of its own{why}: give --camera or [camera] file"
        ));
    }
    CameraModel::load(configured).map_err(|e| e.to_string())
}

/// Reads the source's first item and checks it against the camera, before
/// anything starts (link, log files): a calibration of another size is
/// refused. The item is handed back for the pipeline to process first.
pub fn first_item(
    source: &mut dyn FrameSource,
    camera: &CameraModel,
) -> Result<Option<SourceItem>, String> {
    source.expect_size(camera.width, camera.height);
    let first = source.next_frame();
    match &first {
        Some(Ok(c)) => camera.check_frame_size(c.frame.image.width(), c.frame.image.height())?,
        // A folder's images are refused by their headers.
        Some(Err(e)) if crate::image_io::is_size_mismatch(e) => return Err(e.clone()),
        _ => {}
    }
    Ok(first)
}
