//! `v4l:/dev/videoN` source: a V4L2 camera (Linux), built with the cargo
//! feature `v4l`. The configuration, the format conversions and the time and
//! sequence bookkeeping are plain Rust, compiled and tested in every build;
//! only the device access needs the feature (the `v4l` crate, whose bindings
//! are generated with libclang at build time).

pub mod clock;
pub mod convert;
#[cfg(feature = "v4l")]
mod device;
pub mod live;

use super::{FrameSource, SourceError};
pub use convert::PixelFormat;
use serde::{Deserialize, Serialize};

/// A camera control setting from the config: `"auto"`, `"driver"` (leave it
/// as the driver has it) or a value in the control's own units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "SettingText", into = "SettingText")]
pub enum ControlSetting {
    /// The camera's automatic mode (auto exposure, auto gain).
    Auto,
    /// Left as the driver has it: not set at all.
    Driver,
    /// A manual value, in the control's own units.
    Value(i32),
}

/// How a [`ControlSetting`] is written in TOML: a word or a number.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(untagged)]
enum SettingText {
    Number(i64),
    Word(String),
}

impl TryFrom<SettingText> for ControlSetting {
    type Error = String;
    fn try_from(t: SettingText) -> Result<Self, String> {
        match t {
            SettingText::Word(w) if w == "auto" => Ok(Self::Auto),
            SettingText::Word(w) if w == "driver" => Ok(Self::Driver),
            SettingText::Number(n) => i32::try_from(n)
                .map(Self::Value)
                .map_err(|_| format!("{n} is out of range for a V4L2 control")),
            SettingText::Word(w) => {
                Err(format!("`{w}`: expected \"auto\", \"driver\" or a number"))
            }
        }
    }
}

impl From<ControlSetting> for SettingText {
    fn from(s: ControlSetting) -> Self {
        match s {
            ControlSetting::Auto => Self::Word("auto".into()),
            ControlSetting::Driver => Self::Word("driver".into()),
            ControlSetting::Value(v) => Self::Number(i64::from(v)),
        }
    }
}

/// `[v4l]`: what to ask the camera for. The size must be granted exactly (it
/// is the calibration's); the rate and controls are what the driver grants,
/// logged when the camera opens.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct V4lConfig {
    /// Pixel formats in order of preference; the first one the camera offers is used.
    pub formats: Vec<PixelFormat>,
    /// Frame width, pixels (must match the calibration).
    pub width: u32,
    /// Frame height, pixels (must match the calibration).
    pub height: u32,
    /// Frames per second asked for.
    pub fps: f64,
    /// Exposure: auto, driver, or an absolute time in 100 us units
    /// (V4L2_CID_EXPOSURE_ABSOLUTE).
    pub exposure: ControlSetting,
    /// Gain: auto, driver, or a value in the driver's units (V4L2_CID_GAIN).
    pub gain: ControlSetting,
    /// Driver buffers (memory-mapped).
    pub buffers: u32,
    /// No frame for this long: the camera counts as lost and is reopened, ms.
    pub frame_timeout_ms: u64,
    /// Back-off between attempts to reopen a lost camera, from min doubling to max, ms.
    pub reopen_min_ms: u64,
    /// Longest back-off between reopen attempts, ms.
    pub reopen_max_ms: u64,
}

impl V4lConfig {
    /// The settings' own consistency (the camera decides the rest).
    pub fn validate(&self) -> Result<(), String> {
        let bad = |m: String| Err(format!("[v4l] {m}"));
        if self.formats.is_empty() {
            return bad("formats: give at least one of \"GREY\", \"YUYV\", \"MJPG\"".into());
        }
        if !(1..=16384).contains(&self.width) || !(1..=16384).contains(&self.height) {
            return bad(format!(
                "width/height {}x{}: must be 1..=16384",
                self.width, self.height
            ));
        }
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= 1000.0) {
            return bad(format!("fps {}: must be in (0, 1000]", self.fps));
        }
        if let ControlSetting::Value(v) = self.exposure
            && v < 1
        {
            return bad(format!("exposure {v}: must be >= 1 (units of 100 us)"));
        }
        if !(1..=32).contains(&self.buffers) {
            return bad(format!("buffers {}: must be 1..=32", self.buffers));
        }
        if !(1..=60_000).contains(&self.frame_timeout_ms) {
            return bad(format!(
                "frame_timeout_ms {}: must be 1..=60000",
                self.frame_timeout_ms
            ));
        }
        if self.reopen_min_ms == 0 || self.reopen_min_ms > self.reopen_max_ms {
            return bad(format!(
                "reopen_min_ms {} / reopen_max_ms {}: need 0 < min <= max",
                self.reopen_min_ms, self.reopen_max_ms
            ));
        }
        Ok(())
    }
}

/// Waits between attempts to reopen a lost camera: `min`, doubling up to `max`.
#[derive(Clone, Debug)]
pub struct Backoff {
    min: std::time::Duration,
    max: std::time::Duration,
    next: std::time::Duration,
}

impl Backoff {
    /// The back-off of the config, starting at `reopen_min_ms`.
    pub fn new(config: &V4lConfig) -> Self {
        let min = std::time::Duration::from_millis(config.reopen_min_ms);
        Self {
            min,
            max: std::time::Duration::from_millis(config.reopen_max_ms),
            next: min,
        }
    }
    /// The wait before the next attempt, after a failed one.
    pub fn failed(&mut self) -> std::time::Duration {
        let wait = self.next;
        self.next = (wait * 2).min(self.max);
        wait
    }
    /// The camera works again: the next loss starts from `min`.
    pub fn reset(&mut self) {
        self.next = self.min;
    }
}

/// Opens the camera at `device` (e.g. `/dev/video0`).
#[cfg(feature = "v4l")]
pub fn open(device: &str, config: &V4lConfig) -> Result<Box<dyn FrameSource>, SourceError> {
    let open_err = |message: String| SourceError::Open {
        source_name: format!("v4l:{device}"),
        message,
    };
    config.validate().map_err(open_err)?;
    let opener = device::V4lOpener {
        path: device.to_string(),
        config: config.clone(),
    };
    let source = live::LiveSource::open(device, opener, Backoff::new(config)).map_err(open_err)?;
    Ok(Box::new(source))
}

/// Without the `v4l` feature there is no camera support: says how to get it.
#[cfg(not(feature = "v4l"))]
pub fn open(device: &str, config: &V4lConfig) -> Result<Box<dyn FrameSource>, SourceError> {
    config.validate().map_err(|message| SourceError::Open {
        source_name: format!("v4l:{device}"),
        message,
    })?;
    Err(SourceError::Open {
        source_name: format!("v4l:{device}"),
        message: NO_FEATURE_MESSAGE.into(),
    })
}

/// The error of a build without the feature.
#[cfg(not(feature = "v4l"))]
const NO_FEATURE_MESSAGE: &str = "this build has no V4L2 camera support; build it with \
`cargo build --release --features v4l` (or `cargo install --path . --features v4l`), \
which needs libclang (Debian/Ubuntu: apt-get install libclang-dev)";

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn default_config_is_valid() {
        let c = Config::embedded();
        c.v4l.validate().unwrap();
        assert_eq!(
            c.v4l.formats,
            [PixelFormat::Grey, PixelFormat::Yuyv, PixelFormat::Mjpeg]
        );
    }

    #[test]
    fn control_settings_read_words_and_numbers() {
        let c = Config::from_toml_str("[v4l]\nexposure = 50\ngain = \"auto\"\n", "u.toml").unwrap();
        assert_eq!(c.v4l.exposure, ControlSetting::Value(50));
        assert_eq!(c.v4l.gain, ControlSetting::Auto);
        let c = Config::from_toml_str("[v4l]\nexposure = \"driver\"\n", "u.toml").unwrap();
        assert_eq!(c.v4l.exposure, ControlSetting::Driver);
        for bad in [
            "exposure = \"bright\"",
            "exposure = 1e3",
            "gain = 99999999999",
            "formats = [\"NV12\"]",
        ] {
            let e = Config::from_toml_str(&format!("[v4l]\n{bad}\n"), "u.toml").unwrap_err();
            assert!(e.to_string().contains("u.toml"), "{bad}: {e}");
        }
    }

    #[test]
    fn inconsistent_settings_are_named() {
        let base = Config::embedded().v4l;
        let cases: [(&str, V4lConfig); 6] = [
            (
                "formats",
                V4lConfig {
                    formats: vec![],
                    ..base.clone()
                },
            ),
            (
                "width",
                V4lConfig {
                    width: 0,
                    ..base.clone()
                },
            ),
            (
                "fps",
                V4lConfig {
                    fps: f64::NAN,
                    ..base.clone()
                },
            ),
            (
                "exposure",
                V4lConfig {
                    exposure: ControlSetting::Value(0),
                    ..base.clone()
                },
            ),
            (
                "buffers",
                V4lConfig {
                    buffers: 0,
                    ..base.clone()
                },
            ),
            (
                "reopen_min_ms",
                V4lConfig {
                    reopen_min_ms: 9_000,
                    ..base.clone()
                },
            ),
        ];
        for (key, c) in cases {
            let e = c.validate().unwrap_err();
            assert!(e.contains(key), "{key}: {e}");
        }
    }

    #[test]
    fn reopen_backoff_doubles_to_its_cap_and_resets() {
        let config = V4lConfig {
            reopen_min_ms: 200,
            reopen_max_ms: 1000,
            ..Config::embedded().v4l
        };
        let mut b = Backoff::new(&config);
        let ms: Vec<u128> = (0..5).map(|_| b.failed().as_millis()).collect();
        assert_eq!(ms, [200, 400, 800, 1000, 1000]);
        b.reset();
        assert_eq!(b.failed().as_millis(), 200);
    }

    #[cfg(not(feature = "v4l"))]
    #[test]
    fn without_the_feature_the_error_says_how_to_build() {
        let Err(e) = open("/dev/video0", &Config::embedded().v4l) else {
            panic!("a build without the v4l feature opened a camera");
        };
        let e = e.to_string();
        assert!(e.contains("v4l:/dev/video0"), "{e}");
        assert!(e.contains("--features v4l"), "{e}");
    }

    #[cfg(feature = "v4l")]
    #[test]
    fn a_missing_device_is_a_clear_error() {
        let Err(e) = open("/dev/video-does-not-exist", &Config::embedded().v4l) else {
            panic!("opened a device that does not exist");
        };
        let e = e.to_string();
        assert!(e.contains("v4l:/dev/video-does-not-exist"), "{e}");
        assert!(e.contains("No such file"), "{e}");
    }
}
