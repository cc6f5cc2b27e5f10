//! The subcommands of the `drogue-vision` binary, one module each.

pub mod process;
pub mod sim;
