//! The run's metadata record (`drogue_vision.run`, see
//! [`crate::log::metadata`]): what a reviewer needs to know of how a log was
//! made, built from the whole config (hence here, above the log).

use crate::log::metadata::{git_hash, version};
use std::collections::BTreeMap;

/// What a run's metadata record says about where its frames came from.
#[derive(Clone, Debug, Default)]
pub struct RunProvenance {
    /// The `--source` spec (`sim:approach`, `v4l:/dev/video0`, ...).
    pub source: String,
    /// The source's own description: scenario name and seed of a simulated
    /// run, the replayed log, the camera device (see `FrameSource::provenance`).
    pub source_details: Vec<(String, String)>,
    /// The camera file used, or where the camera came from.
    pub camera_file: String,
    /// The MAVLink connection in use (`--mavlink` or `[link] connection`).
    pub mavlink: String,
    /// The clock of the log's times: `wall`, or `source` for `run --fast`
    /// (the source's capture time base, see [`crate::clock`]).
    pub clock: String,
}

/// The run's metadata record (`log::metadata::RUN_METADATA`): version, git hash, the
/// config as TOML (the signing passphrase left out), the camera file, the
/// mount, the source (with scenario and seed for simulated runs) and the
/// MAVLink connection with our system and component ids.
pub fn run_metadata(config: &crate::config::Config, p: &RunProvenance) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    m.insert("version".into(), version().into());
    m.insert("git_hash".into(), git_hash().into());
    let mut redacted = config.clone();
    if !redacted.link.signing_passphrase.is_empty() {
        redacted.link.signing_passphrase = "(set, not logged)".into();
    }
    m.insert("config_toml".into(), to_toml(&redacted));
    m.insert("mount_toml".into(), to_toml(&redacted.mount));
    m.insert("camera_file".into(), p.camera_file.clone());
    m.insert("source".into(), p.source.clone());
    for (k, v) in &p.source_details {
        m.insert(format!("source.{k}"), v.clone());
    }
    m.insert("mavlink.connection".into(), p.mavlink.clone());
    m.insert("clock".into(), p.clock.clone());
    m.insert(
        "mavlink.system_id".into(),
        config.link.system_id.to_string(),
    );
    m.insert(
        "mavlink.component_id".into(),
        config.link.component_id.to_string(),
    );
    m
}

/// TOML text of a config section (an error's text when it is not TOML).
fn to_toml<T: serde::Serialize>(v: &T) -> String {
    toml::to_string(v).unwrap_or_else(|e| format!("(not representable as TOML: {e})"))
}
