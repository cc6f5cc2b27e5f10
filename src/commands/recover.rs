//! `drogue-vision recover LOG.mcap [--out FIXED.mcap]`: rewrites a cut-short
//! log into a complete, indexed one.

use crate::log::LogError;
use crate::log::recover::{RecoverReport, recover};
use std::path::{Path, PathBuf};

/// Arguments of `recover`.
#[derive(Clone, Debug, clap::Args)]
#[command(
    after_help = "Copies every message up to the cut (all complete chunks) into a new \
file with its summary and index. The input is never changed. Exit status: 0 recovered; \
1 the output could not be written; 2 the input is not an MCAP log."
)]
pub struct RecoverArgs {
    /// The cut-short MCAP log.
    pub log: PathBuf,
    /// Output file (default: LOG with `.recovered.mcap`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The default output beside the log.
pub fn default_out(log: &Path) -> PathBuf {
    log.with_extension("recovered.mcap")
}

pub fn run(args: &RecoverArgs) -> Result<(PathBuf, RecoverReport), LogError> {
    let out = args.out.clone().unwrap_or_else(|| default_out(&args.log));
    if out == args.log {
        return Err(LogError::Config(
            "--out must differ from the input (the input is kept as it is)".into(),
        ));
    }
    let report = recover(&args.log, &out)?;
    Ok((out, report))
}
