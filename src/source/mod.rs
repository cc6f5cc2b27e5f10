//! Frame sources for `run`: the simulator, a folder of images, an MCAP log,
//! a V4L2 camera.

pub(crate) mod dir;
pub(crate) mod mcap;
pub mod replay;
pub mod sim;
pub mod v4l;

use crate::camera::CameraModel;
use crate::frame::Frame;
use crate::measure::mount::MountConfig;
use std::path::PathBuf;
use std::time::Duration;

/// A source address as given on the command line or in `[run] source`.
#[derive(Clone, Debug, PartialEq)]
pub enum SourceSpec {
    /// `sim:NAME_OR_FILE`: a built-in scenario or a scenario file.
    Sim(String),
    /// `dir:PATH`: the images of a folder, in lexicographic order.
    Dir(PathBuf),
    /// `mcap:PATH`: the `/camera/image` frames of a log.
    Mcap(PathBuf),
    /// `v4l:/dev/videoN`: a V4L2 camera.
    V4l(String),
}

/// A source address that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// Not of the form `KIND:WHAT` with a known kind; holds the address.
    #[error("source `{0}`: expected sim:NAME_OR_FILE, dir:PATH, mcap:PATH or v4l:/dev/videoN")]
    BadAddress(String),
    /// The source could not be opened.
    #[error("source {source_name}: {message}")]
    Open {
        /// The source as given (a scenario, folder, log or device).
        source_name: String,
        /// Why it could not be opened.
        message: String,
    },
}

impl std::str::FromStr for SourceSpec {
    type Err = SourceError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || SourceError::BadAddress(s.to_string());
        let (kind, rest) = s.split_once(':').ok_or_else(bad)?;
        if rest.is_empty() {
            return Err(bad());
        }
        match kind {
            "sim" => Ok(Self::Sim(rest.to_string())),
            "dir" => Ok(Self::Dir(PathBuf::from(rest))),
            "mcap" => Ok(Self::Mcap(PathBuf::from(rest))),
            "v4l" => Ok(Self::V4l(rest.to_string())),
            _ => Err(bad()),
        }
    }
}

/// A frame as a source delivers it. The simulator's exact truth of the frame
/// travels beside it, for the log (`/sim/truth`) and tests; the measurement
/// gets the frame alone.
#[derive(Clone, Debug)]
pub struct Captured {
    /// The frame, all the measurement sees.
    pub frame: Frame,
    /// The simulator's exact truth of the frame; `None` from other sources.
    pub truth: Option<Box<drogue_sim::FrameTruth>>,
}

impl From<Frame> for Captured {
    /// A frame without truth (every source but the simulator).
    fn from(frame: Frame) -> Self {
        Self { frame, truth: None }
    }
}

/// One item a source yields: a frame, or a frame it could not read (reported
/// and skipped by the pipeline).
pub type SourceItem = Result<Captured, String>;

/// What every source offers the pipeline.
pub trait FrameSource: Send {
    /// The camera of this source, when it knows it (the simulator, a log).
    fn camera(&self) -> Option<CameraModel>;
    /// Why [`FrameSource::camera`] is `None` where a camera was expected
    /// (a log without a readable `/camera/calibration`), for the error.
    fn no_camera_reason(&self) -> Option<String> {
        None
    }
    /// The camera mount of this source, when it knows it (the simulator).
    fn mount(&self) -> Option<MountConfig>;
    /// Nominal frame rate, when known (for pacing and staleness).
    fn fps(&self) -> Option<f64>;
    /// The exposure time, when the source knows it (the simulator's
    /// scenario, a camera in manual exposure): it overrides `[camera]
    /// exposure_ms`, from which a tracked frame's motion blur is predicted.
    fn exposure(&self) -> Option<Duration> {
        None
    }
    /// Whether the frames' capture times form a timeline to replay at its
    /// own pace (the simulator, a log); a folder of images has none.
    fn recorded_timeline(&self) -> bool {
        false
    }
    /// Whether making a frame costs this process real CPU (the simulator's
    /// rendering). `run` then waits for a frame's measurement before asking
    /// for the next one, so the source never competes with the pipeline for
    /// a core, as a camera never would.
    fn renders_frames(&self) -> bool {
        false
    }
    /// Whether frames come in real time whatever the pipeline does (a
    /// camera): such a source must not wait for the measurement; a frame
    /// that finds it busy is skipped for measurement (and still logged),
    /// or else the driver's buffers fill and the latency grows.
    fn live(&self) -> bool {
        false
    }
    /// What the flight log's metadata records about this source (key,
    /// value): the scenario and seed of a simulation, the replayed log.
    fn provenance(&self) -> Vec<(String, String)> {
        Vec::new()
    }

    /// The camera's frame size, once the camera is chosen: a source that
    /// decodes files refuses other sizes from their headers (see
    /// [`crate::image_io`]). The others' frames are checked by the caller.
    fn expect_size(&mut self, _width: u32, _height: u32) {}
    /// The next frame; `None` at the end of the source.
    fn next_frame(&mut self) -> Option<SourceItem>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_addresses() {
        assert_eq!(
            "sim:approach".parse::<SourceSpec>().ok(),
            Some(SourceSpec::Sim("approach".into()))
        );
        assert_eq!(
            "dir:/tmp/x".parse::<SourceSpec>().ok(),
            Some(SourceSpec::Dir("/tmp/x".into()))
        );
        assert_eq!(
            "mcap:a.mcap".parse::<SourceSpec>().ok(),
            Some(SourceSpec::Mcap("a.mcap".into()))
        );
        assert_eq!(
            "v4l:/dev/video0".parse::<SourceSpec>().ok(),
            Some(SourceSpec::V4l("/dev/video0".into()))
        );
        for bad in ["approach", "sim:", "usb:/dev/x", ""] {
            assert!(bad.parse::<SourceSpec>().is_err(), "{bad}");
        }
    }
}
