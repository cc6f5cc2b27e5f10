//! `drogue-vision recover LOG.mcap [--out FIXED.mcap]`: rewrites a cut-short
//! or damaged log into a complete, indexed one ([`crate::log::recover`]).

use crate::log::LogError;
use crate::log::recover::{RecoverReport, recover};
use std::path::{Path, PathBuf};

/// Arguments of `recover`.
#[derive(Clone, Debug, clap::Args)]
#[command(
    after_help = "Copies every message the input still holds (every complete chunk; \
the readable records of a chunk whose CRC fails, reported as DAMAGED and recorded in \
the copy's metadata) into a new zstd-compressed file with its summary and index. The \
input is never changed; the output appears only when complete. Exit status: 0 \
recovered; 1 the output could not be written, or it would hold fewer messages than the \
input yields (refused, nothing written); 2 the input is missing or not an MCAP log."
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

/// `recover`: copies what the log still holds into `--out` (default: beside
/// it); the file written and what was found.
pub fn run(args: &RecoverArgs) -> Result<(PathBuf, RecoverReport), LogError> {
    let out = args.out.clone().unwrap_or_else(|| default_out(&args.log));
    let report = recover(&args.log, &out)?;
    Ok((out, report))
}
