//! MAVLink link to the autopilot. PLACEHOLDER: built by the link work (issue 4).

use serde::{Deserialize, Serialize};

/// `[link]` in the config.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkConfig {}

/// One MAVLink message sent or received, decoded, for the log (`/mavlink/out`,
/// `/mavlink/in`). Defined here by the log work so it compiles; the link work
/// owns it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkEvent {
    /// When it was sent or received, ns since the Unix epoch.
    pub time_ns: u64,
    pub outgoing: bool,
    /// Message name, e.g. `LANDING_TARGET`.
    pub name: String,
    /// Capture time of the frame it carries, for pose messages.
    pub capture_time_ns: Option<u64>,
    /// The decoded fields.
    pub fields: serde_json::Value,
}
