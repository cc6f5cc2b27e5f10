//! Configuration: TOML, with `config/default.toml` embedded in the binary.
//!
//! A user file names only what it changes; it is laid over the embedded
//! default, so every default lives in exactly one place (the default file, with
//! its comments). A key the default does not have is rejected by name.

use crate::link::LinkConfig;
use crate::log::LogConfig;
use crate::measure::detect::DetectConfig;
use crate::measure::fit::FitConfig;
use crate::measure::mount::MountConfig;
use crate::measure::track::TrackConfig;
use crate::measure::{DrogueConfig, MeasureConfig};
pub use crate::source::sim::SitlAnchor;
use crate::source::v4l::V4lConfig;
use drogue_sim::bounds::{self, Range};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Value;

/// Largest whole number a TOML file can hold (its integers are i64).
const ANY_U64: f64 = i64::MAX as f64;

/// The allowed range of every number of the config, by dotted key (array
/// keys: each element). `config/default.toml` writes the same range next to
/// each key (a test compares them), and a key without a range here is refused.
pub const RANGES: &[(&str, Range)] = &[
    ("drogue.inner_radius_m", Range::above(0.0, 10.0)),
    ("drogue.canopy_radius_m", Range::above(0.0, 20.0)),
    ("drogue.canopy_band_m", Range::closed(0.0, 20.0)),
    ("camera.exposure_ms", Range::closed(0.0, 1000.0)),
    ("mount.camera_position_body_m", Range::closed(-100.0, 100.0)),
    ("mount.camera_roll_deg", Range::closed(-360.0, 360.0)),
    ("mount.camera_pitch_deg", Range::closed(-360.0, 360.0)),
    ("mount.camera_yaw_deg", Range::closed(-360.0, 360.0)),
    ("mount.probe_tip_body_m", Range::closed(-100.0, 100.0)),
    ("detect.decimation", Range::closed(1.0, 16.0)),
    ("detect.threshold_fractions", Range::open(0.0, 1.0)),
    ("detect.max_candidates", Range::closed(1.0, 100.0)),
    ("detect.min_range_m", Range::closed(0.01, 10_000.0)),
    ("detect.max_range_m", Range::closed(0.01, 10_000.0)),
    ("detect.min_axis_ratio", Range::above(0.0, 1.0)),
    ("detect.min_contrast_gray", Range::closed(0.0, 255.0)),
    ("detect.rim_point_spacing_px", Range::closed(0.1, 100.0)),
    (
        "detect.tracked_rim_point_spacing_px",
        Range::closed(0.1, 100.0),
    ),
    ("detect.max_rim_points", Range::closed(5.0, 10_000.0)),
    (
        "detect.tracked_max_rim_points",
        Range::closed(5.0, 10_000.0),
    ),
    ("detect.rim_search_fraction", Range::closed(0.0, 1.0)),
    ("detect.rim_search_max_px", Range::closed(1.0, 1000.0)),
    ("detect.min_rim_points", Range::closed(5.0, 10_000.0)),
    ("detect.inlier_tolerance_px", Range::above(0.0, 100.0)),
    ("detect.canopy_weight", Range::closed(0.0, 1.0)),
    (
        "detect.canopy_required_from_px",
        Range::closed(0.0, 100_000.0),
    ),
    ("detect.min_canopy_fraction", Range::closed(0.0, 1.0)),
    ("detect.min_score", Range::closed(0.0, 1.0)),
    ("detect.min_fill", Range::closed(0.0, 1.0)),
    ("detect.accept_score", Range::closed(0.0, 1.0)),
    ("detect.seed", Range::closed(0.0, ANY_U64)),
    ("fit.algorithm1_subsets", Range::closed(1.0, 1000.0)),
    ("fit.algorithm1_subset_size", Range::closed(5.0, 100.0)),
    ("fit.algorithm1_cluster_threshold", Range::above(0.0, 1e6)),
    (
        "fit.algorithm1_inlier_threshold_px",
        Range::above(0.0, 1000.0),
    ),
    ("fit.ransac_iterations", Range::closed(1.0, 100_000.0)),
    ("fit.ransac_threshold_px", Range::above(0.0, 1000.0)),
    ("fit.ransac_consensus_fraction", Range::above(0.0, 1.0)),
    ("fit.adaptive_subsets", Range::closed(1.0, 1000.0)),
    ("fit.adaptive_min_subsets", Range::closed(1.0, 1000.0)),
    ("fit.adaptive_confidence", Range::open(0.0, 1.0)),
    ("fit.adaptive_subset_size", Range::closed(5.0, 100.0)),
    ("fit.adaptive_cluster_relative", Range::closed(0.0, 10.0)),
    ("fit.adaptive_cluster_px", Range::closed(0.0, 1000.0)),
    ("fit.adaptive_clusters_scored", Range::closed(1.0, 100.0)),
    (
        "fit.adaptive_initial_band_relative",
        Range::closed(0.0, 10.0),
    ),
    ("fit.adaptive_inlier_sigmas", Range::above(0.0, 100.0)),
    ("fit.adaptive_inlier_min_px", Range::above(0.0, 1000.0)),
    ("fit.adaptive_refine_rounds", Range::closed(1.0, 100.0)),
    ("fit.geometric_iterations", Range::closed(0.0, 1000.0)),
    ("track.max_gap_ms", Range::closed(0.0, 3_600_000.0)),
    ("track.canopy_min_difference", Range::closed(0.0, 1.0)),
    ("track.canopy_min_support", Range::closed(0.0, 1.0)),
    ("track.continuity_margin_deg", Range::closed(0.0, 90.0)),
    (
        "track.continuity_max_gap_ms",
        Range::closed(0.0, 3_600_000.0),
    ),
    ("track.continuity_max_speed_mps", Range::closed(0.0, 1000.0)),
    ("link.system_id", Range::closed(1.0, 255.0)),
    ("link.component_id", Range::closed(1.0, 255.0)),
    ("link.max_rate_hz", Range::closed(0.1, 10_000.0).or_zero()),
    ("link.max_age_ms", Range::closed(0.0, 60_000.0)),
    ("link.heartbeat_interval_ms", Range::closed(10.0, 60_000.0)),
    ("link.heartbeat_timeout_ms", Range::closed(10.0, 600_000.0)),
    (
        "link.timesync_interval_ms",
        Range::closed(10.0, 600_000.0).or_zero(),
    ),
    ("link.telemetry_tolerance_ms", Range::closed(1.0, 60_000.0)),
    ("link.reconnect_min_ms", Range::closed(1.0, 600_000.0)),
    ("link.reconnect_max_ms", Range::closed(1.0, 600_000.0)),
    ("link.write_timeout_ms", Range::closed(1.0, 60_000.0)),
    ("link.signing_link_id", Range::closed(0.0, 255.0)),
    ("link.event_queue", Range::closed(1.0, 1_000_000.0)),
    ("link.log_incoming_max_hz", Range::closed(1.0, 100_000.0)),
    ("link.target_relative_std_scale", Range::closed(1.0, 100.0)),
    (
        "link.target_relative_std_floor_m",
        Range::closed(0.0, 100.0),
    ),
    ("log.rotate_size_mib", Range::closed(0.0, 1_048_576.0)),
    ("log.rotate_duration_s", Range::closed(0.0, 604_800.0)),
    ("log.queue_len", Range::closed(1.0, 100_000.0)),
    ("log.sync_interval_ms", Range::closed(1.0, 1000.0)),
    ("log.chunk_size_kib", Range::closed(1.0, 65_536.0)),
    ("log.retry_after_error_s", Range::closed(1.0, 86_400.0)),
    ("log.compression_level", Range::closed(0.0, 19.0)),
    ("log.jpeg_quality", Range::closed(1.0, 100.0)),
    ("log.full_frame_every", Range::closed(1.0, 100_000.0)),
    ("log.crop_margin", Range::closed(1.0, 4.0)),
    ("run.vehicle_pose_timeout_s", Range::above(0.0, 86_400.0)),
    ("run.vehicle_pose_delay_ms", Range::closed(0.0, 10_000.0)),
    ("run.realtime_priority", Range::closed(0.0, 99.0)),
    ("v4l.width", Range::closed(1.0, 16_384.0)),
    ("v4l.height", Range::closed(1.0, 16_384.0)),
    ("v4l.fps", Range::above(0.0, 1000.0)),
    ("v4l.exposure", Range::closed(1.0, 1_000_000.0)),
    ("v4l.gain", Range::closed(0.0, 1_000_000.0)),
    ("v4l.buffers", Range::closed(1.0, 32.0)),
    ("v4l.frame_timeout_ms", Range::closed(1.0, 60_000.0)),
    ("v4l.reopen_min_ms", Range::closed(1.0, 600_000.0)),
    ("v4l.reopen_max_ms", Range::closed(1.0, 600_000.0)),
];

/// The embedded default configuration.
pub const DEFAULT_TOML: &str = include_str!("../config/default.toml");

/// [`DEFAULT_TOML`] parsed once: every config is merged onto a copy (a
/// clone costs a fraction of parsing 20 kB of commented TOML again).
fn default_value() -> &'static Result<Value, String> {
    static DEFAULT: std::sync::LazyLock<Result<Value, String>> =
        std::sync::LazyLock::new(|| toml::from_str(DEFAULT_TOML).map_err(|e| e.to_string()));
    &DEFAULT
}

/// A configuration that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read or is not TOML.
    #[error("config {file}: {message}")]
    Read {
        /// The config file's name, as given.
        file: String,
        /// Why it could not be read or parsed.
        message: String,
    },
    /// A key the default config does not have (a typo, or a removed key).
    #[error("config {file}: unknown key `{key}`")]
    UnknownKey {
        /// The config file.
        file: String,
        /// The key, dotted (`section.key`).
        key: String,
    },
    /// A value of the wrong type or out of its range, or keys that
    /// contradict each other.
    #[error("config {file}: {message}")]
    Invalid {
        /// The config file.
        file: String,
        /// Which value is wrong, and why.
        message: String,
    },
}

/// `[camera]`: where the intrinsics come from.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    /// Camera YAML; empty: the source's own camera (the simulator's), or
    /// `--camera` on the command line.
    pub file: PathBuf,
    /// Exposure time, milliseconds; 0: not known (the source's own when it
    /// knows it: the simulator's scenario, a V4L2 camera's fixed exposure).
    pub exposure_ms: f64,
}

impl CameraConfig {
    /// [`Self::exposure_ms`] as a time; `None` when not known.
    pub fn exposure(&self) -> Option<Duration> {
        (self.exposure_ms > 0.0)
            .then(|| Duration::try_from_secs_f64(self.exposure_ms * 1e-3).ok())
            .flatten()
    }
}

/// `[run]`: the live pipeline's defaults.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// Frame source: `sim:NAME_OR_FILE`, `dir:PATH`, `mcap:PATH`, `v4l:/dev/videoN`.
    pub source: String,
    /// Where a `sim:` source's receiver pose comes from (SITL closed loop).
    pub vehicle_pose: VehiclePoseSource,
    /// `mavlink`: how long to wait for the autopilot's first pose, seconds.
    pub vehicle_pose_timeout_s: f64,
    /// `mavlink`: how the autopilot's local NED sits in the scenario's world.
    pub sitl_anchor: SitlAnchor,
    /// `mavlink`: frames are captured this long before they are rendered, so
    /// the autopilot's pose at the capture is interpolated, not extrapolated.
    pub vehicle_pose_delay_ms: u64,
    /// Real-time priority (SCHED_FIFO, 1-99) of the threads on the capture ->
    /// send path (capture, measurement, link); 0: normal scheduling. Needs
    /// CAP_SYS_NICE or an RLIMIT_RTPRIO that allows it.
    pub realtime_priority: u8,
}

/// `[run] vehicle_pose`: who flies the simulated receiver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum VehiclePoseSource {
    /// The scenario's scripted approach.
    Script,
    /// The autopilot on the MAVLink link (LOCAL_POSITION_NED + ATTITUDE).
    Mavlink,
}

/// The whole configuration.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// `[camera]`: where the intrinsics come from.
    pub camera: CameraConfig,
    /// `[drogue]`: the target's radii.
    pub drogue: DrogueConfig,
    /// `[mount]`: the camera and the probe tip on the receiver.
    pub mount: MountConfig,
    /// `[detect]`: finding the drogue's rim in a frame.
    pub detect: DetectConfig,
    /// `[fit]`: the robust ellipse fit.
    pub fit: FitConfig,
    /// `[track]`: prediction and continuity between frames.
    pub track: TrackConfig,
    /// `[link]`: the MAVLink connection and what is sent.
    pub link: LinkConfig,
    /// `[log]`: the MCAP flight log.
    pub log: LogConfig,
    /// `[run]`: the live pipeline's defaults.
    pub run: RunConfig,
    /// `[v4l]`: the V4L2 camera's format and controls.
    pub v4l: V4lConfig,
}

/// Finds keys of `user` that `default` does not have, as dotted paths.
fn unknown_keys(user: &Value, default: &Value, prefix: &str, out: &mut Vec<String>) {
    if let (Value::Table(u), Value::Table(d)) = (user, default) {
        for (k, v) in u {
            let path = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            match d.get(k) {
                None => out.push(path),
                Some(dv) => unknown_keys(v, dv, &path, out),
            }
        }
    }
}

/// Lays `user` over `base`, table by table.
fn merge(base: &mut Value, user: Value) {
    match (base, user) {
        (Value::Table(b), Value::Table(u)) => {
            for (k, v) in u {
                match b.get_mut(&k) {
                    Some(bv) => merge(bv, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (b, u) => *b = u,
    }
}

impl Config {
    /// The embedded default.
    pub fn embedded() -> Self {
        // The default file is part of the binary and covered by tests; failing
        // here is a build defect, not bad input.
        Self::from_toml_str("", "(embedded default)")
            .unwrap_or_else(|e| panic!("embedded config/default.toml is invalid: {e}"))
    }

    /// The default with `text` (a user's TOML) laid over it.
    pub fn from_toml_str(text: &str, file: &str) -> Result<Self, ConfigError> {
        let read_err = |message: String| ConfigError::Read {
            file: file.to_string(),
            message,
        };
        let mut merged = default_value()
            .clone()
            .map_err(|e| read_err(format!("embedded default: {e}")))?;
        let user: Value = toml::from_str(text).map_err(|e| read_err(e.to_string()))?;
        let mut unknown = Vec::new();
        unknown_keys(&user, &merged, "", &mut unknown);
        if let Some(key) = unknown.into_iter().next() {
            return Err(ConfigError::UnknownKey {
                file: file.to_string(),
                key,
            });
        }
        merge(&mut merged, user);
        let invalid = |message: String| ConfigError::Invalid {
            file: file.to_string(),
            message,
        };
        let config: Config = merged
            .clone()
            .try_into()
            .map_err(|e: toml::de::Error| invalid(e.to_string()))?;
        bounds::check(&merged, RANGES).map_err(|v| invalid(v.to_string()))?;
        config.check_together().map_err(invalid)?;
        Ok(config)
    }

    /// The rules that tie keys together, and the sections' own checks, once
    /// every number is within its range.
    fn check_together(&self) -> Result<(), String> {
        let d = &self.detect;
        let rules = [
            (
                self.drogue.canopy_radius_m > self.drogue.inner_radius_m,
                "[drogue] canopy_radius_m must exceed inner_radius_m",
            ),
            (
                self.drogue.canopy_band_m
                    < self.drogue.canopy_radius_m - self.drogue.inner_radius_m,
                "[drogue] canopy_band_m must be narrower than the canopy (canopy_radius_m - inner_radius_m)",
            ),
            (
                d.min_range_m < d.max_range_m,
                "[detect] min_range_m must be below max_range_m",
            ),
            (
                (1..=16).contains(&d.threshold_fractions.len()),
                "[detect] threshold_fractions must hold 1 to 16 fractions",
            ),
            (
                d.min_rim_points <= d.max_rim_points.min(d.tracked_max_rim_points),
                "[detect] min_rim_points must not exceed max_rim_points nor tracked_max_rim_points",
            ),
            (
                d.min_score <= d.accept_score,
                "[detect] min_score must not exceed accept_score",
            ),
            (
                self.fit.adaptive_min_subsets <= self.fit.adaptive_subsets,
                "[fit] adaptive_min_subsets must not exceed adaptive_subsets",
            ),
            (
                self.link.heartbeat_interval_ms < self.link.heartbeat_timeout_ms,
                "[link] heartbeat_interval_ms must be below heartbeat_timeout_ms",
            ),
            (
                self.link.reconnect_min_ms <= self.link.reconnect_max_ms,
                "[link] reconnect_min_ms must not exceed reconnect_max_ms",
            ),
        ];
        if let Some((_, message)) = rules.iter().find(|(ok, _)| !ok) {
            return Err((*message).to_string());
        }
        self.fit.validate().map_err(|e| format!("[fit] {e}"))?;
        self.track_check()?;
        let mut log = self.log.clone();
        log.set_drogue(self.drogue.inner_radius_m, self.drogue.canopy_radius_m);
        log.validate().map_err(|e| e.to_string())?;
        self.v4l.validate()?;
        crate::measure::mount::Mount::from_config(&self.mount)
            .map_err(|e| format!("[mount] {e}"))?;
        Ok(())
    }

    /// `[track]` is checked by its tracker; the same check, at load.
    fn track_check(&self) -> Result<(), String> {
        crate::measure::track::Tracker::new(&self.track)
            .map(|_| ())
            .map_err(|e| format!("[track] {e}"))
    }

    /// The sections the measurement reads ([`crate::measure::Measurer::new`]).
    pub fn measure(&self) -> MeasureConfig {
        MeasureConfig {
            drogue: self.drogue.clone(),
            mount: self.mount.clone(),
            detect: self.detect.clone(),
            fit: self.fit.clone(),
            track: self.track.clone(),
            exposure: self.camera.exposure(),
        }
    }

    /// Reads a user config file; `None`: the embedded default.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        match path {
            None => Ok(Self::embedded()),
            Some(p) => {
                let file = p.display().to_string();
                let text = std::fs::read_to_string(p).map_err(|e| ConfigError::Read {
                    file: file.clone(),
                    message: e.to_string(),
                })?;
                Self::from_toml_str(&text, &file)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_default_parses() {
        let c = Config::embedded();
        assert!(c.drogue.inner_radius_m > 0.0);
    }

    #[test]
    fn user_values_override_defaults() {
        let c = Config::from_toml_str("[drogue]\ninner_radius_m = 0.2\n", "u.toml").expect("ok");
        assert_eq!(c.drogue.inner_radius_m, 0.2);
        assert_eq!(
            c.drogue.canopy_radius_m,
            Config::embedded().drogue.canopy_radius_m
        );
    }

    #[test]
    fn unknown_keys_are_named() {
        let e = Config::from_toml_str("[drogue]\nradius = 0.2\n", "u.toml").unwrap_err();
        assert_eq!(e.to_string(), "config u.toml: unknown key `drogue.radius`");
        let e = Config::from_toml_str("[nope]\n", "u.toml").unwrap_err();
        assert!(e.to_string().contains("`nope`"));
    }

    /// Every number of the default has a range, and the default file writes
    /// that range on the line above its key.
    #[test]
    fn every_number_has_its_range_written_in_the_default_file() {
        let default: Value = toml::from_str(DEFAULT_TOML).unwrap();
        bounds::walk_numbers(&default, "", &mut |key, _| {
            assert!(
                bounds::range_of(RANGES, key).is_some(),
                "{key} has no range"
            );
        });
        let lines: Vec<&str> = DEFAULT_TOML.lines().collect();
        for (key, range) in RANGES {
            let (section, name) = key.split_once('.').unwrap();
            let start = lines
                .iter()
                .position(|l| *l == format!("[{section}]"))
                .unwrap_or_else(|| panic!("no [{section}]"));
            let at = lines[start..]
                .iter()
                .position(|l| l.starts_with(&format!("{name} =")))
                .unwrap_or_else(|| panic!("{key} not in the default file"))
                + start;
            assert_eq!(lines[at - 1], format!("# Range: {range}"), "{key}");
        }
    }

    fn refused(text: &str) -> String {
        Config::from_toml_str(text, "r.toml")
            .unwrap_err()
            .to_string()
    }

    /// The reproducers (issue 16): each is refused naming the file,
    /// the key and the allowed range.
    #[test]
    fn the_reproducers_are_refused_with_key_and_range() {
        let cases = [
            (
                "[link]\nmax_rate_hz = 1e-300\n",
                "[link] max_rate_hz",
                "0 or [0.1, 10000]",
            ),
            (
                "[run]\nvehicle_pose_timeout_s = 1e300\n",
                "[run] vehicle_pose_timeout_s",
                "(0, 86400]",
            ),
            (
                "[log]\nretry_after_error_s = 9223372036854775807\n",
                "[log] retry_after_error_s",
                "[1, 86400]",
            ),
            (
                "[fit]\nadaptive_subsets = 0\n",
                "[fit] adaptive_subsets",
                "[1, 1000]",
            ),
            (
                "[fit]\nadaptive_confidence = nan\n",
                "[fit] adaptive_confidence",
                "(0, 1)",
            ),
            (
                "[detect]\nmax_candidates = 0\n",
                "[detect] max_candidates",
                "[1, 100]",
            ),
            (
                "[detect]\nmin_range_m = inf\n",
                "[detect] min_range_m",
                "[0.01, 10000]",
            ),
            (
                "[mount]\ncamera_position_body_m = [0.0, -inf, 0.0]\n",
                "[mount] camera_position_body_m",
                "[-100, 100]",
            ),
        ];
        for (text, key, range) in cases {
            let e = refused(text);
            assert!(e.starts_with("config r.toml: "), "{e}");
            assert!(e.contains(key) && e.contains(range), "{text}: {e}");
        }
        let e = refused("[detect]\nthreshold_fractions = []\n");
        assert!(
            e.contains("threshold_fractions") && e.contains("1 to 16"),
            "{e}"
        );
        let e = refused("[detect]\nmin_range_m = 50.0\nmax_range_m = 40.0\n");
        assert!(e.contains("min_range_m"), "{e}");
    }

    /// Random values, finite or not, for every number of the config: the
    /// load answers (never panics), and what it accepts is in range.
    #[test]
    fn random_values_for_every_number_are_accepted_in_range_or_refused() {
        use proptest::prelude::*;
        use proptest::test_runner::{Config as PropConfig, TestRunner};
        let default: Value = toml::from_str(DEFAULT_TOML).unwrap();
        let mut keys = Vec::new();
        bounds::walk_numbers(&default, "", &mut |key, _| {
            if !keys.iter().any(|k| k == key) {
                keys.push(key.to_string());
            }
        });
        let value = prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(0.0),
            Just(-1.0),
            Just(1e300),
            Just(1e-300),
            -2000.0..2000.0f64,
            -1e7..1e7f64,
            any::<f64>(),
        ];
        let mut runner = TestRunner::new(PropConfig::with_cases(512));
        let started = std::time::Instant::now();
        runner
            .run(&(0..keys.len(), value, any::<bool>()), |(i, x, as_int)| {
                let key = &keys[i];
                let (section, name) = key.split_once('.').unwrap();
                let is_array = default[section][name].is_array();
                let number = if as_int && x.is_finite() && x.abs() < 9e18 {
                    format!("{}", x.trunc() as i64)
                } else {
                    Value::Float(x).to_string()
                };
                let number = if is_array {
                    let n = default[section][name].as_array().unwrap().len();
                    format!("[{}]", vec![number; n].join(", "))
                } else {
                    number
                };
                let text = format!("[{section}]\n{name} = {number}\n");
                match Config::from_toml_str(&text, "p.toml") {
                    Ok(_) => {
                        let r = bounds::range_of(RANGES, key).unwrap();
                        let v: f64 = number
                            .trim_matches(['[', ']'])
                            .split(',')
                            .next()
                            .unwrap()
                            .trim()
                            .parse()
                            .unwrap();
                        prop_assert!(r.contains(v), "{text} accepted");
                    }
                    Err(e) => {
                        let e = e.to_string();
                        prop_assert!(e.starts_with("config p.toml:"), "{e}");
                    }
                }
                Ok(())
            })
            .unwrap();
        assert!(started.elapsed().as_secs() < 60);
    }

    #[test]
    fn wrong_types_are_reported() {
        let e =
            Config::from_toml_str("[drogue]\ninner_radius_m = \"big\"\n", "u.toml").unwrap_err();
        assert!(e.to_string().contains("u.toml"), "{e}");
        let e = Config::from_toml_str("not toml = = =", "u.toml").unwrap_err();
        assert!(e.to_string().contains("u.toml"), "{e}");
    }
}
