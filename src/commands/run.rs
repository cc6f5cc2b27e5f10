//! `drogue-vision run`: the command line of the live pipeline
//! (`crate::pipeline::live`) and its end-of-run report.

use crate::config::{Config, VehiclePoseSource};
use crate::log::LogHandle;
use crate::pipeline::live::RunOptions;
pub use crate::pipeline::live::{RunError, RunSummary};
use std::path::PathBuf;

/// Arguments of `run` (see `drogue-vision run --help`).
#[derive(Clone, Debug, Default, clap::Args)]
#[command(
    after_help = "With no arguments: the simulated `approach` scenario, MAVLink to \
udpout:127.0.0.1:14550, MCAP to logs/. Ctrl-C (SIGINT) or SIGTERM ends the run cleanly. \
Exit status: 0 the run ended (source finished, --max-frames, or a signal); 2 bad arguments, \
config, camera or source; 1 a failure while running, including --vehicle-pose mavlink without \
a pose from the autopilot within [run] vehicle_pose_timeout_s."
)]
pub struct RunArgs {
    /// Config file laid over the embedded default.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Frame source: sim:SCENARIO_NAME_OR_FILE, dir:PATH, mcap:PATH, v4l:/dev/videoN.
    #[arg(long)]
    pub source: Option<String>,
    /// Camera file; overrides the source's own (mcap:, sim:), required for
    /// dir: and v4l: without `[camera] file`. Its size must be the frames'.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// MAVLink connection: udpout:HOST:PORT, udpin:HOST:PORT (= udp:), udpbcast:BCAST:PORT,
    /// tcpout:HOST:PORT (= tcp:), tcpin:HOST:PORT, serial:DEVICE:BAUD.
    #[arg(long)]
    pub mavlink: Option<String>,
    /// Folder of the MCAP log (default from the config: logs/).
    #[arg(long)]
    pub log_dir: Option<PathBuf>,
    /// Stop after this many frames.
    #[arg(long)]
    pub max_frames: Option<u64>,
    /// Run as fast as the pipeline goes instead of at the source's frame
    /// rate, on the source's clock: every detected frame's pose is still sent
    /// and the log spans the source's own time.
    #[arg(long)]
    pub fast: bool,
    /// Who flies a sim: source's receiver: `script` (the scenario) or
    /// `mavlink` (SITL closed loop: the autopilot's reported pose).
    /// Default from `[run] vehicle_pose`.
    #[arg(long, value_enum)]
    pub vehicle_pose: Option<VehiclePoseSource>,
}

impl RunArgs {
    fn options(&self) -> RunOptions {
        RunOptions {
            source: self.source.clone(),
            camera: self.camera.clone(),
            mavlink: self.mavlink.clone(),
            log_dir: self.log_dir.clone(),
            max_frames: self.max_frames,
            fast: self.fast,
            vehicle_pose: self.vehicle_pose,
        }
    }
}

/// Runs the pipeline until the source ends, `--max-frames`, or a signal.
pub fn run(
    args: &RunArgs,
    config: Config,
    log_layer_sink: impl FnOnce(&LogHandle),
) -> Result<RunSummary, RunError> {
    crate::pipeline::live::run(&args.options(), config, log_layer_sink)
}

/// The link's end-of-run line: what was sent, and the autopilot's
/// heartbeat as it was (never heard is not "0 losses"; a link that never
/// opened says so).
fn link_report(l: &crate::link::LinkStats) -> String {
    if !l.opened {
        return format!(
            "\nlink: never opened ({} failed attempts, see the warnings above); nothing sent",
            l.io_errors
        );
    }
    let sent: Vec<String> = l.sent.iter().map(|(k, v)| format!("{v} {k}")).collect();
    let sent = if sent.is_empty() {
        "nothing".to_string()
    } else {
        sent.join(", ")
    };
    let heartbeat = if l.autopilot_heard() {
        format!("{} autopilot heartbeat losses", l.heartbeat_losses)
    } else {
        "autopilot heartbeat never heard".to_string()
    };
    let rate_limited = if l.rate_limited > 0 {
        format!(
            " ({} over max_rate_hz on the source's clock)",
            l.rate_limited
        )
    } else {
        String::new()
    };
    format!(
        "\nlink: sent {sent}{rate_limited}; {} stale poses not sent; {heartbeat}, {} reconnects",
        l.stale, l.reconnects
    )
}

/// The end-of-run lines on stderr.
pub fn report(summary: &RunSummary) -> String {
    let s = summary;
    {
        let rate = if s.measured > 0 {
            100.0 * s.detected as f64 / s.measured as f64
        } else {
            0.0
        };
        let files: Vec<String> = s
            .log_files
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        let link_line = s.link.as_ref().map_or_else(String::new, link_report);
        let misses = if s.missed_by_reason.is_empty() {
            String::new()
        } else {
            format!(
                "\nnot detected: {}",
                crate::measure::miss::counts_line(&s.missed_by_reason)
            )
        };
        let mut held = if s.vehicle_pose_held > 0 {
            format!(
                ", {} rendered with a held autopilot pose (stale)",
                s.vehicle_pose_held
            )
        } else {
            String::new()
        };
        if s.link_handoff_timeouts > 0 {
            held.push_str(&format!(
                ", {} not handled by the link in time (--fast)",
                s.link_handoff_timeouts
            ));
        }
        let latency = if s.source_clock {
            "not measured with --fast (the run is on the source's clock)".to_string()
        } else if s.latency_ms.count() == 0 {
            "no pose sent".to_string()
        } else {
            format!(
                "p50 {:.2}  p95 {:.2}  p99 {:.2}  max {:.2} ms over {} poses",
                s.latency_ms.quantile(0.50),
                s.latency_ms.quantile(0.95),
                s.latency_ms.quantile(0.99),
                s.latency_ms.max(),
                s.latency_ms.count()
            )
        };
        let r = &s.resources;
        let resources_line = format!(
            "\ncapture → send: {latency}\nresources: pipeline CPU {:.1} % of one core (source {:.1} %, \
             log writer {:.1} % besides), peak resident memory {:.1} MB, log queue at most {} items",
            r.pipeline_cpu_pct,
            r.source_cpu_pct,
            r.log_writer_cpu_pct,
            r.peak_rss_bytes as f64 / 1e6,
            r.max_log_queue
        );
        format!(
            "run {}: {} frames, {} measured, {} detected ({rate:.1} %), {} skipped (measurement busy), \
             {} unreadable, source late {} times{held}{misses}{}{resources_line}\nlog: {}{}",
            if s.interrupted {
                "interrupted"
            } else {
                "ended"
            },
            s.frames,
            s.measured,
            s.detected,
            s.skipped,
            s.unreadable,
            s.source_late,
            link_line,
            files.join(", "),
            if s.log_dropped > 0 {
                format!(
                    " ({} items not logged: the writer fell behind or a write failed)",
                    s.log_dropped
                )
            } else {
                String::new()
            }
        )
    }
}
