//! The subcommands of the `drogue-vision` binary, one module each.

pub mod process;
pub mod recover;
pub mod review;
pub mod run;
pub mod sim;
