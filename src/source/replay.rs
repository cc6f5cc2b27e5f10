//! Replay: `/camera/image` back as [`Frame`]s, streaming (one record in
//! memory at a time), with the camera from `/camera/calibration`. The MCAP
//! reader of frames, here with the sources (the `mcap:` source and
//! `process` read through it); the log's own `reader` and `topics` below it
//! say how the file and its messages are read.
//!
//! A record above the record bound (top-level, or inside a chunk) is
//! skipped without being held in memory and the reading goes on
//! ([`crate::log::oversized`]); each skip is logged as a warning when it
//! happens, the total when the log ends, and [`ReplayReader::oversized`]
//! counts them for the summaries (`process`).

use crate::camera::CameraModel;
use crate::frame::{Frame, FrameOrigin};
use crate::log::oversized::{Oversized, RECORD_LIMIT_BYTES};
use crate::log::reader::{LogMessageReader, counted_message_reader, message_reader};
use crate::log::{LogError, topics};
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, CompressedImage, RawImage};
use image::GrayImage;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Frames of a log in file order. A cut-short log ends with one `Err` (after
/// every frame before the cut); a frame that cannot be decoded gives an `Err`
/// and the reader carries on with the next.
pub struct ReplayReader {
    path: PathBuf,
    messages: LogMessageReader,
    camera: Option<CameraModel>,
    done: bool,
    /// Records above the bound skipped so far, and how many were reported.
    oversized: Arc<Oversized>,
    oversized_reported: u64,
}

/// Opens a log for replay.
pub fn open(path: &Path) -> Result<ReplayReader, LogError> {
    let (messages, oversized) = counted_message_reader(path)?;
    Ok(ReplayReader {
        path: path.to_path_buf(),
        messages,
        camera: None,
        done: false,
        oversized,
        oversized_reported: 0,
    })
}

impl ReplayReader {
    /// Records above [`RECORD_LIMIT_BYTES`] skipped so far.
    pub fn oversized_skipped(&self) -> u64 {
        self.oversized.records()
    }

    /// The live count of the records above the bound skipped, to read
    /// after the frames were consumed (the reader itself may be gone).
    pub fn oversized(&self) -> Arc<Oversized> {
        Arc::clone(&self.oversized)
    }

    /// Warns of the records skipped since the last warning.
    fn report_oversized(&mut self) {
        let n = self.oversized.records();
        if n > self.oversized_reported {
            tracing::warn!(
                "{}: skipped {} MCAP record(s) above the {} MiB record bound, unread \
                 ({n} so far)",
                self.path.display(),
                n - self.oversized_reported,
                RECORD_LIMIT_BYTES >> 20
            );
            self.oversized_reported = n;
        }
    }

    /// At the end of the log: the total skipped, when any.
    fn finish(&mut self) {
        self.done = true;
        self.report_oversized();
        let n = self.oversized.records();
        if n > 0 {
            tracing::warn!(
                "{}: {n} MCAP record(s) ({} bytes) above the {} MiB record bound skipped \
                 in all",
                self.path.display(),
                self.oversized.bytes(),
                RECORD_LIMIT_BYTES >> 20
            );
        }
    }

    /// The camera of the latest `/camera/calibration` read so far (the writer
    /// logs it right after each frame; read one frame first, or use
    /// [`ReplayReader::first_camera`]).
    pub fn camera(&self) -> Option<&CameraModel> {
        self.camera.as_ref()
    }

    /// The camera of the log's first `/camera/calibration` (reads the file
    /// from the start again; streams until it finds it).
    pub fn first_camera(path: &Path) -> Result<CameraModel, LogError> {
        for message in message_reader(path)? {
            let m = message
                .map_err(|e| LogError::format(path, crate::log::reader::describe_read_error(&e)))?;
            if m.channel.topic == topics::CALIBRATION {
                let cal = CameraCalibration::decode(m.data.as_ref())
                    .map_err(|e| LogError::format(path, format!("/camera/calibration: {e}")))?;
                return topics::camera_from_calibration(&cal)
                    .map_err(|e| LogError::format(path, format!("/camera/calibration: {e}")));
            }
        }
        Err(LogError::format(path, "no /camera/calibration in the log"))
    }

    fn decode_frame(&self, m: &mcap::Message<'_>) -> Result<Frame, String> {
        let encoding = m.channel.message_encoding.as_str();
        let schema = m.channel.schema.as_ref().map(|s| s.name.as_str());
        if encoding != "protobuf" {
            return Err(format!("{}: message encoding {encoding}", topics::IMAGE));
        }
        let image = match schema {
            Some("foxglove.RawImage") => raw_to_gray(
                &RawImage::decode(m.data.as_ref()).map_err(|e| format!("RawImage: {e}"))?,
            )?,
            Some("foxglove.CompressedImage") => {
                let c = CompressedImage::decode(m.data.as_ref())
                    .map_err(|e| format!("CompressedImage: {e}"))?;
                // JPEG (the lossy long-flight mode) replays too, to
                // slightly different detections (README, "Size").
                let format = match c.format.as_str() {
                    "png" => image::ImageFormat::Png,
                    "jpeg" | "jpg" => image::ImageFormat::Jpeg,
                    other => {
                        return Err(format!(
                            "CompressedImage format {other:?}: replay reads png and jpeg"
                        ));
                    }
                };
                crate::image_io::decode_gray8(&c.data, Some(format), None)
                    .map_err(|e| format!("{}: {e}", c.format))?
            }
            other => return Err(format!("{}: schema {other:?}", topics::IMAGE)),
        };
        Ok(Frame {
            seq: u64::from(m.sequence),
            capture_time_ns: m.log_time,
            image,
            origin: FrameOrigin::Replay {
                path: self.path.clone(),
                seq: u64::from(m.sequence),
            },
        })
    }
}

fn raw_to_gray(r: &RawImage) -> Result<GrayImage, String> {
    if r.encoding != "mono8" {
        return Err(format!("RawImage encoding {:?}, not mono8", r.encoding));
    }
    let (w, h, step) = (r.width as usize, r.height as usize, r.step as usize);
    if w == 0 || h == 0 || step < w || r.data.len() < step * (h - 1) + w {
        return Err(format!(
            "RawImage {w}x{h} step {step} with {} bytes",
            r.data.len()
        ));
    }
    let pixels = if step == w {
        r.data[..w * h].to_vec()
    } else {
        (0..h)
            .flat_map(|row| &r.data[row * step..row * step + w])
            .copied()
            .collect()
    };
    GrayImage::from_raw(r.width, r.height, pixels).ok_or_else(|| "RawImage size".to_string())
}

impl Iterator for ReplayReader {
    type Item = Result<Frame, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        while let Some(message) = self.messages.next() {
            self.report_oversized();
            let m = match message {
                Ok(m) => m,
                Err(e) => {
                    self.finish();
                    return Some(Err(LogError::format(
                        &self.path,
                        crate::log::reader::describe_read_error(&e),
                    )));
                }
            };
            match m.channel.topic.as_str() {
                topics::IMAGE => {
                    return Some(
                        self.decode_frame(&m)
                            .map_err(|e| LogError::format(&self.path, e)),
                    );
                }
                topics::CALIBRATION => {
                    if let Ok(cal) = CameraCalibration::decode(m.data.as_ref())
                        && let Ok(cam) = topics::camera_from_calibration(&cal)
                    {
                        self.camera = Some(cam);
                    }
                }
                _ => {}
            }
        }
        self.finish();
        None
    }
}
