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
use crate::source::v4l::V4lConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use toml::Value;

/// The embedded default configuration.
pub const DEFAULT_TOML: &str = include_str!("../config/default.toml");

/// A configuration that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("config {file}: {message}")]
    Read { file: String, message: String },
    #[error("config {file}: unknown key `{key}`")]
    UnknownKey { file: String, key: String },
    #[error("config {file}: {message}")]
    Invalid { file: String, message: String },
}

/// `[camera]`: where the intrinsics come from.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    /// Camera YAML; empty: the source's own camera (the simulator's), or
    /// `--camera` on the command line.
    pub file: PathBuf,
}

/// `[drogue]`: the target's known geometry.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DrogueConfig {
    /// Radius of the dark inner circle, metres.
    pub inner_radius_m: f64,
    /// Radius of the canopy's outer rim, metres (resolves the ambiguity).
    pub canopy_radius_m: f64,
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

/// `[run] sitl_anchor`: the autopilot's local NED in the scenario's world.
/// Both are placed at the autopilot's first pose (a translation and a yaw);
/// they differ in whether that placement then moves with the tanker.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SitlAnchor {
    /// Moves with the tanker: a vehicle holding its position keeps station
    /// behind the drogue (multicopter SITL).
    Tanker,
    /// Fixed in the world: the vehicle itself must fly the tanker's speed
    /// and course (fixed-wing SITL, scenario `[tanker] airspeed_mps`).
    World,
}

/// The whole configuration.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub camera: CameraConfig,
    pub drogue: DrogueConfig,
    pub mount: MountConfig,
    pub detect: DetectConfig,
    pub fit: FitConfig,
    pub track: TrackConfig,
    pub link: LinkConfig,
    pub log: LogConfig,
    pub run: RunConfig,
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
        let mut merged: Value =
            toml::from_str(DEFAULT_TOML).map_err(|e| read_err(format!("embedded default: {e}")))?;
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
        merged
            .try_into()
            .map_err(|e: toml::de::Error| ConfigError::Invalid {
                file: file.to_string(),
                message: e.to_string(),
            })
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

    #[test]
    fn wrong_types_are_reported() {
        let e =
            Config::from_toml_str("[drogue]\ninner_radius_m = \"big\"\n", "u.toml").unwrap_err();
        assert!(e.to_string().contains("u.toml"), "{e}");
        let e = Config::from_toml_str("not toml = = =", "u.toml").unwrap_err();
        assert!(e.to_string().contains("u.toml"), "{e}");
    }
}
