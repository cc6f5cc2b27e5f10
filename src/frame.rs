//! One camera frame as it enters the measurement.

use image::GrayImage;
use std::path::PathBuf;

/// Where a frame came from: kept for logs, errors and replay.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameOrigin {
    /// Rendered by the simulator; carries the exact truth of that frame.
    Sim(Box<drogue_sim::FrameTruth>),
    /// Read from an image file.
    File(PathBuf),
    /// Read back from an MCAP log (`/camera/image`).
    Replay { path: PathBuf, seq: u64 },
    /// Captured by a live camera.
    Camera { device: String },
}

/// An 8-bit gray frame with its capture time.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Sequence number in its source, from 0.
    pub seq: u64,
    /// Capture time, nanoseconds since the Unix epoch (the MCAP log_time and the
    /// MAVLink time fields use this, never the processing time).
    pub capture_time_ns: u64,
    pub image: GrayImage,
    pub origin: FrameOrigin,
}

impl Frame {
    /// The simulator's truth for this frame, when it has one.
    pub fn truth(&self) -> Option<&drogue_sim::FrameTruth> {
        match &self.origin {
            FrameOrigin::Sim(truth) => Some(truth),
            _ => None,
        }
    }
}
