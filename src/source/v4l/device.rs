//! The V4L2 camera itself, through the `v4l` crate (memory-mapped streaming).
//!
//! Nothing the driver says is trusted: sizes are checked by `convert`, and the
//! `v4l` crate's own `unwrap`/`expect`/`panic!` on unexpected driver answers
//! (a format or control it cannot represent, a failed STREAMOFF) are caught
//! at this boundary and become errors, so a misbehaving camera costs frames,
//! never the run. Losing and reopening the camera, time stamps and sequence
//! numbers are `live.rs`'s (tested there with a scripted camera).

use super::clock::{BUFFER_FLAG_ERROR, ClockOffset};
use super::convert::{BufferLayout, PixelFormat, payload, to_gray};
use super::live::{Camera, CameraOpener, RawBuffer};
use super::{ControlSetting, V4lConfig};
use crate::source::dir::unix_now_ns;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Duration;
use v4l::buffer::Type;
use v4l::control::{Control, Value};
use v4l::io::mmap::Stream;
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::video::capture::Parameters;
use v4l::{Device, Format, FourCC, Fraction};

// V4L2 control ids (linux/v4l2-controls.h).
const CID_AUTOGAIN: u32 = 0x0098_0912;
const CID_GAIN: u32 = 0x0098_0913;
const CID_EXPOSURE_AUTO: u32 = 0x009a_0901;
const CID_EXPOSURE_ABSOLUTE: u32 = 0x009a_0902;
// V4L2_CID_EXPOSURE_AUTO menu items.
const EXPOSURE_AUTO: i64 = 0;
const EXPOSURE_MANUAL: i64 = 1;
const EXPOSURE_APERTURE_PRIORITY: i64 = 3;
// V4L2_CAP_VIDEO_CAPTURE, V4L2_CAP_STREAMING.
const CAP_VIDEO_CAPTURE: u32 = 0x0000_0001;
const CAP_STREAMING: u32 = 0x0400_0000;

/// Runs `f`, turning a panic inside the `v4l` crate into an error.
fn guarded<T>(what: &str, f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(panic) => {
            let message = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            Err(format!(
                "{what}: the v4l crate failed on the driver's answer ({message})"
            ))
        }
    }
}

/// What the camera granted, for the log.
#[derive(Clone, Debug)]
struct Granted {
    layout: BufferLayout,
    fps: Option<f64>,
    exposure: String,
    /// The fixed exposure time, when the camera is in manual exposure and
    /// reads it back.
    exposure_time: Option<Duration>,
    gain: String,
    card: String,
    driver: String,
}

impl std::fmt::Display for Granted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let fps = self
            .fps
            .map_or_else(|| "unknown".to_string(), |r| format!("{r:.2}"));
        write!(
            f,
            "{} ({}): {} {}x{} (stride {} bytes), {fps} fps, exposure {}, gain {}",
            self.card,
            self.driver,
            self.layout.format,
            self.layout.width,
            self.layout.height,
            self.layout.stride_bytes,
            self.exposure,
            self.gain
        )
    }
}

/// An open, streaming camera.
pub struct OpenCamera {
    stream: Stream<'static>,
    // Kept open for the controls; the stream holds its own handle.
    _device: Device,
    granted: Granted,
}

/// A `timeval` field: `time_t` is i64 on 64-bit Linux, i32 on 32-bit ARM boards.
fn time_field<T: Into<i64>>(value: T) -> i64 {
    value.into()
}

impl Camera for OpenCamera {
    fn next_buffer(&mut self) -> Result<RawBuffer, String> {
        let layout = self.granted.layout;
        let stream = &mut self.stream;
        guarded("dequeue", || {
            let (buffer, meta) = CaptureStream::next(stream).map_err(|e| {
                if e.kind() == std::io::ErrorKind::TimedOut {
                    "no frame within frame_timeout_ms".to_string()
                } else {
                    e.to_string()
                }
            })?;
            let dequeued_unix_ns = unix_now_ns();
            let flags = u32::from(meta.flags);
            let image = if flags & BUFFER_FLAG_ERROR != 0 {
                Err("the driver marked the buffer as corrupt".into())
            } else {
                to_gray(&layout, payload(buffer, meta.bytesused)).map_err(|e| e.to_string())
            };
            Ok(RawBuffer {
                image,
                flags,
                seconds: time_field(meta.timestamp.sec),
                microseconds: time_field(meta.timestamp.usec),
                sequence: meta.sequence,
                dequeued_unix_ns,
            })
        })
    }
    fn description(&self) -> String {
        self.granted.to_string()
    }
    fn fps(&self) -> Option<f64> {
        self.granted.fps
    }
    fn exposure(&self) -> Option<Duration> {
        self.granted.exposure_time
    }
}

/// Opens `path` with the `[v4l]` settings, as often as the camera is lost.
pub struct V4lOpener {
    pub path: String,
    pub config: V4lConfig,
}

impl CameraOpener for V4lOpener {
    type Camera = OpenCamera;
    fn open(&mut self) -> Result<OpenCamera, String> {
        open_camera(&self.path, &self.config)
    }
    fn clock_offset(&self) -> Option<ClockOffset> {
        ClockOffset::measure()
    }
}

/// Opens the device, negotiates format, rate and controls, starts streaming.
fn open_camera(path: &str, config: &V4lConfig) -> Result<OpenCamera, String> {
    guarded("open", || {
        let device = Device::with_path(path).map_err(|e| {
            let hint = if e.kind() == std::io::ErrorKind::PermissionDenied {
                " (is the user in the `video` group?)"
            } else {
                ""
            };
            format!("cannot open {path}: {e}{hint}")
        })?;
        let caps = device
            .query_caps()
            .map_err(|e| format!("not a V4L2 device ({e})"))?;
        let flags = u32::from(caps.capabilities);
        if flags & CAP_VIDEO_CAPTURE == 0 || flags & CAP_STREAMING == 0 {
            return Err(format!(
                "{} ({}) is not a streaming video capture device (a metadata node? try the \
                 other /dev/video number of this camera)",
                caps.card, caps.driver
            ));
        }
        let layout = negotiate_format(&device, config)?;
        let fps = negotiate_rate(&device, config.fps);
        let (exposure, exposure_time) = set_exposure(&device, config.exposure);
        let gain = set_gain(&device, config.gain);
        let mut stream = Stream::with_buffers(&device, Type::VideoCapture, config.buffers)
            .map_err(|e| format!("buffers: {e}"))?;
        stream.set_timeout(Duration::from_millis(config.frame_timeout_ms));
        Ok(OpenCamera {
            stream,
            _device: device,
            granted: Granted {
                layout,
                fps,
                exposure,
                exposure_time,
                gain,
                card: caps.card,
                driver: caps.driver,
            },
        })
    })
}

/// The first preferred format the camera offers at exactly the size asked
/// for. Another size is refused, never used: the camera file is a
/// calibration at one size, and frames of another would give wrong poses.
/// (USB cameras often offer the full size only as MJPG: the preference list
/// then moves on to it.)
fn negotiate_format(device: &Device, config: &V4lConfig) -> Result<BufferLayout, String> {
    let offered: Vec<[u8; 4]> = device
        .enum_formats()
        .map_err(|e| format!("formats: {e}"))?
        .iter()
        .map(|d| d.fourcc.repr)
        .collect();
    let mut refused = Vec::new();
    for &wanted in &config.formats {
        if !offered.contains(&wanted.fourcc()) {
            continue;
        }
        let asked = Format::new(config.width, config.height, FourCC::new(&wanted.fourcc()));
        let granted = match device.set_format(&asked) {
            Ok(g) => g,
            Err(e) => {
                refused.push(format!("{wanted}: {e}"));
                continue;
            }
        };
        let granted_format = PixelFormat::from_fourcc(granted.fourcc.repr);
        if granted_format != Some(wanted)
            || (granted.width, granted.height) != (config.width, config.height)
        {
            refused.push(format!(
                "{wanted}: granted {} {}x{}",
                String::from_utf8_lossy(&granted.fourcc.repr),
                granted.width,
                granted.height
            ));
            continue;
        }
        return Ok(BufferLayout {
            format: wanted,
            width: granted.width,
            height: granted.height,
            stride_bytes: granted.stride,
        });
    }
    let names: Vec<String> = offered
        .iter()
        .map(|c| String::from_utf8_lossy(c).into_owned())
        .collect();
    Err(format!(
        "no format of [v4l] formats at {}x{} (asked: {}); the camera offers {}{}; \
         see `v4l2-ctl -d DEVICE --list-formats-ext`",
        config.width,
        config.height,
        config
            .formats
            .iter()
            .map(|f| f.to_string())
            .collect::<Vec<_>>()
            .join(", "),
        names.join(", "),
        if refused.is_empty() {
            String::new()
        } else {
            format!(" (refused: {})", refused.join("; "))
        }
    ))
}

/// Asks for `fps`; the granted rate (the driver's interval), when it says.
fn negotiate_rate(device: &Device, fps: f64) -> Option<f64> {
    let interval = Fraction::new(1000, (fps * 1000.0).round() as u32);
    let params = match device.set_params(&Parameters::new(interval)) {
        Ok(p) => Some(p),
        Err(e) => {
            tracing::warn!("camera frame rate not set ({e}): the driver's own rate is used");
            device.params().ok()
        }
    }?;
    let Fraction {
        numerator,
        denominator,
    } = params.interval;
    (numerator > 0 && denominator > 0).then(|| f64::from(denominator) / f64::from(numerator))
}

fn read_control(device: &Device, id: u32) -> Option<i64> {
    match device.control(id).ok()?.value {
        Value::Integer(v) => Some(v),
        Value::Boolean(b) => Some(i64::from(b)),
        _ => None,
    }
}

fn set_control(device: &Device, id: u32, value: i64) -> Result<(), String> {
    device
        .set_control(Control {
            id,
            value: Value::Integer(value),
        })
        .map_err(|e| e.to_string())
}

/// Applies the exposure setting; returns what the camera now has, for the
/// log, and its exposure time when that is fixed (manual mode, read back).
fn set_exposure(device: &Device, setting: ControlSetting) -> (String, Option<Duration>) {
    let result = match setting {
        ControlSetting::Driver => Ok(()),
        // Full auto where offered; UVC cameras mostly offer only aperture
        // priority (= auto exposure time at a fixed iris).
        ControlSetting::Auto => set_control(device, CID_EXPOSURE_AUTO, EXPOSURE_AUTO)
            .or_else(|_| set_control(device, CID_EXPOSURE_AUTO, EXPOSURE_APERTURE_PRIORITY)),
        ControlSetting::Value(v) => set_control(device, CID_EXPOSURE_AUTO, EXPOSURE_MANUAL)
            .and_then(|()| set_control(device, CID_EXPOSURE_ABSOLUTE, i64::from(v))),
    };
    if let Err(e) = result {
        tracing::warn!("camera exposure {setting:?} not set ({e}): left as the driver has it");
    }
    let manual = read_control(device, CID_EXPOSURE_AUTO);
    let mode = match manual {
        Some(EXPOSURE_MANUAL) => "manual",
        Some(_) => "auto",
        None => "mode unknown",
    };
    let absolute = read_control(device, CID_EXPOSURE_ABSOLUTE);
    // The control's unit is 100 us.
    let fixed = absolute
        .filter(|&v| manual == Some(EXPOSURE_MANUAL) && v > 0)
        .and_then(|v| u64::try_from(v).ok())
        .map(|v| Duration::from_micros(v.saturating_mul(100)));
    let text = match absolute {
        Some(v) => format!("{mode}, {v} x 100 us"),
        None => format!("{mode} (no absolute exposure control)"),
    };
    (text, fixed)
}

/// Applies the gain setting where the camera offers one.
fn set_gain(device: &Device, setting: ControlSetting) -> String {
    let result = match setting {
        ControlSetting::Driver => Ok(()),
        ControlSetting::Auto => set_control(device, CID_AUTOGAIN, 1),
        ControlSetting::Value(v) => {
            // Cameras without an auto-gain control accept the gain directly.
            let _ = set_control(device, CID_AUTOGAIN, 0);
            set_control(device, CID_GAIN, i64::from(v))
        }
    };
    if let Err(e) = result {
        tracing::warn!("camera gain {setting:?} not set ({e}): left as the driver has it");
    }
    let auto =
        read_control(device, CID_AUTOGAIN).map_or("", |a| if a != 0 { "auto, " } else { "" });
    match read_control(device, CID_GAIN) {
        Some(v) => format!("{auto}{v}"),
        None => format!("{auto}not offered"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn a_file_that_is_not_a_camera_is_refused() {
        let e = open_camera("/dev/null", &Config::embedded().v4l)
            .err()
            .expect("/dev/null is not a camera");
        assert!(e.contains("not a V4L2 device"), "{e}");
    }

    #[test]
    fn a_panic_in_the_crate_becomes_an_error() {
        let e = guarded("dequeue", || -> Result<(), String> {
            panic!("Invalid field order")
        })
        .unwrap_err();
        assert!(
            e.contains("dequeue") && e.contains("Invalid field order"),
            "{e}"
        );
    }
}
