//! MCAP flight log. PLACEHOLDER: built by the log work (issue 5).

use serde::{Deserialize, Serialize};

/// `[log]` in the config.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogConfig {}
