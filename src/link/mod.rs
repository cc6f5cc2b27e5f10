//! MAVLink link to the autopilot. PLACEHOLDER: built by the link work (issue 4).

use serde::{Deserialize, Serialize};

/// `[link]` in the config.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkConfig {}
