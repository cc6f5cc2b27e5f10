//! The subcommands of the `drogue-vision` binary, one module each.

pub mod process;
pub mod recover;
pub mod review;
pub mod run;
pub mod run_stats;
pub mod run_status;
pub mod sim;
