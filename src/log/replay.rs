//! Replay: `/camera/image` back as [`Frame`]s, streaming (one record in
//! memory at a time), with the camera from `/camera/calibration`.

use super::{LogError, recover::message_reader, topics};
use crate::camera::CameraModel;
use crate::frame::{Frame, FrameOrigin};
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, CompressedImage, RawImage};
use image::GrayImage;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Frames of a log in file order. A cut-short log ends with one `Err` (after
/// every frame before the cut); a frame that cannot be decoded gives an `Err`
/// and the reader carries on with the next.
pub struct ReplayReader {
    path: PathBuf,
    messages: mcap::io::MessageReader<BufReader<File>>,
    camera: Option<CameraModel>,
    done: bool,
}

/// Opens a log for replay.
pub fn open(path: &Path) -> Result<ReplayReader, LogError> {
    Ok(ReplayReader {
        path: path.to_path_buf(),
        messages: message_reader(path)?,
        camera: None,
        done: false,
    })
}

impl ReplayReader {
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
            let m = message.map_err(|e| LogError::format(path, e))?;
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
        for message in self.messages.by_ref() {
            let m = match message {
                Ok(m) => m,
                Err(e) => {
                    self.done = true;
                    return Some(Err(LogError::format(&self.path, e)));
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
        self.done = true;
        None
    }
}
