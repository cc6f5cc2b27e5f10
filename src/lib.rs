//! drogue-vision: the drogue's pose from one camera, streamed to the autopilot.
//!
//! Data flow (see `ARCHITECTURE.md`): `source` yields [`frame::Frame`]s,
//! `pipeline` hands each to `measure`, which turns it into a
//! [`measure::Measurement`]; `link` streams it over MAVLink and `log` writes
//! everything to MCAP. `commands` are the binary's subcommands.

pub mod camera;
pub mod clock;
pub mod commands;
pub mod config;
pub mod frame;
pub mod image_io;
pub mod link;
pub mod log;
pub mod measure;
pub mod pipeline;
pub mod priority;
pub mod record;
pub mod source;
pub mod spatial;
/// Shared test fixtures; see the module docs for how the feature is enabled.
#[cfg(any(test, feature = "testing"))]
pub mod testing;
