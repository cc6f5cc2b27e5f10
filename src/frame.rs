//! One camera frame as it enters the measurement: pixels, capture time and
//! where it came from; nothing of the simulator (its truth travels beside the
//! frame, see [`crate::source::Captured`]).

use image::GrayImage;
use std::path::PathBuf;

/// Where a frame came from: kept for logs, errors and replay.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameOrigin {
    /// Rendered by the simulator (its exact truth travels beside the frame,
    /// in [`crate::source::Captured`]: the measurement never sees it).
    Sim,
    /// Read from an image file.
    File(PathBuf),
    /// Read back from an MCAP log (`/camera/image`).
    Replay {
        /// The log file.
        path: PathBuf,
        /// The frame's sequence number in the log.
        seq: u64,
    },
    /// Captured by a live camera.
    Camera {
        /// The device, e.g. `/dev/video0`.
        device: String,
    },
}

/// An 8-bit gray frame with its capture time.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Sequence number in its source, from 0.
    pub seq: u64,
    /// Capture time, nanoseconds since the Unix epoch (the MCAP log_time and the
    /// MAVLink time fields use this, never the processing time).
    pub capture_time_ns: u64,
    /// The pixels, 8-bit gray.
    pub image: GrayImage,
    /// Where the frame came from.
    pub origin: FrameOrigin,
}
