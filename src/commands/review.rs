//! `drogue-vision review LOG.mcap [--out DIR]`: post-flight summary, CSV, plots.

use crate::log::LogError;
use crate::log::review::{ReviewReport, review};
use std::path::{Path, PathBuf};

/// Arguments of `review`.
#[derive(Clone, Debug, clap::Args)]
#[command(
    after_help = "Writes DIR/poses.csv, DIR/metadata.txt and PNG plots (position_body.png, \
position_camera.png, detections.png, latency.png; error_vs_time.png and \
error_vs_range.png when the log has /sim/truth). DIR appears only when complete. Exit \
status: 0 reviewed (a cut-short or damaged log is reviewed up to the problem and says \
so); 1 the outputs could not be written; 2 the log could not be read."
)]
pub struct ReviewArgs {
    /// The MCAP log to review.
    pub log: PathBuf,
    /// Output folder (default: LOG without .mcap, plus `.review`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The default output folder beside the log.
pub fn default_out(log: &Path) -> PathBuf {
    let mut s = log.with_extension("").into_os_string();
    s.push(".review");
    PathBuf::from(s)
}

/// `review`: the log's report, with poses.csv and the plots written to `--out`
/// (default: beside the log).
pub fn run(args: &ReviewArgs) -> Result<ReviewReport, LogError> {
    let out = args.out.clone().unwrap_or_else(|| default_out(&args.log));
    review(&args.log, &out)
}
