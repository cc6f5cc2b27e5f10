//! What `run` says while it runs: on a terminal, one status line redrawn
//! about once a second (frames, detected, why the last frame missed while
//! it does, range, latency, link state, log size); otherwise (systemd, a pipe) a plain `tracing` line every 10 s.
//! Colours only on a terminal, and never with `NO_COLOR` set
//! (<https://no-color.org>).
//!
//! The figures come from counters the pipeline keeps anyway
//! (`PipelineMeters`): nothing here is on the frame path.

use super::meters::PipelineMeters;
use crate::link::LinkHandle;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

/// Redraw period on a terminal.
const TERMINAL_PERIOD: Duration = Duration::from_secs(1);
/// Log-line period without a terminal.
const PLAIN_PERIOD: Duration = Duration::from_secs(10);

/// Whether stderr may carry colours: a terminal, and `NO_COLOR` unset or empty.
pub fn colour_allowed() -> bool {
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

/// Bytes of this run's MCAP files so far: the `.mcap` files of `dir`
/// written since `since` (leftovers recovered at start-up excluded).
// The log writer names its files `.mcap`: only ours are counted.
#[allow(clippy::case_sensitive_file_extension_comparisons)]
fn log_bytes(dir: &PathBuf, since: SystemTime) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .filter(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.ends_with(".mcap") && !name.contains("recovered")
        })
        .filter_map(|e| e.metadata().ok())
        .filter(|m| m.modified().is_ok_and(|t| t >= since))
        .map(|m| m.len())
        .sum()
}

/// One status text; `colour` wraps the link state in green, yellow or red.
fn status_text(vitals: &PipelineMeters, link: &LinkHandle, log_bytes: u64, colour: bool) -> String {
    let frames = vitals.frames_in.load(Ordering::Relaxed);
    let measured = vitals.measured.load(Ordering::Relaxed);
    let detected = vitals.detected.load(Ordering::Relaxed);
    let pct = if measured > 0 {
        100.0 * detected as f64 / measured as f64
    } else {
        0.0
    };
    let range = vitals
        .range_m()
        .map_or("range -".to_string(), |r| format!("range {r:.2} m"));
    // Why the last frame had no drogue, while the misses go on.
    let miss = vitals
        .last_miss()
        .map_or(String::new(), |why| format!(", last miss {why}"));
    let latency = vitals
        .latency_ms()
        .map_or("latency -".to_string(), |l| format!("latency {l:.1} ms"));
    let stats = link.stats();
    let state = stats.state();
    let state = if colour {
        let code = match (stats.connected, stats.autopilot_heard()) {
            (true, true) if stats.last_heartbeat_age_s < 3.0 => "32", // green
            (true, _) => "33",                                        // yellow
            (false, _) => "31",                                       // red
        };
        format!("\x1b[{code}m{state}\x1b[0m")
    } else {
        state
    };
    format!(
        "frames {frames}, detected {detected} ({pct:.1} %){miss}, {range}, {latency}, link {state}, log {:.1} MB",
        log_bytes as f64 / 1e6
    )
}

/// The reporting thread; [`StatusReporter::finish`] stops it and clears the
/// line.
pub struct StatusReporter {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    terminal: bool,
}

impl StatusReporter {
    /// Starts the thread: on a terminal it redraws the status line in place
    /// every second; elsewhere it logs the line every 10 s.
    pub fn spawn(vitals: Arc<PipelineMeters>, link: LinkHandle, log_dir: PathBuf) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let colour = colour_allowed();
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = Arc::clone(&stop);
        let since = SystemTime::now() - Duration::from_secs(1);
        let handle = std::thread::Builder::new()
            .name("status".into())
            .spawn(move || {
                let period = if terminal {
                    TERMINAL_PERIOD
                } else {
                    PLAIN_PERIOD
                };
                let mut next = Instant::now() + period;
                while !stop_flag.load(Ordering::SeqCst) {
                    std::thread::sleep(Duration::from_millis(100));
                    if Instant::now() < next {
                        continue;
                    }
                    next += period;
                    let text = status_text(&vitals, &link, log_bytes(&log_dir, since), colour);
                    if terminal {
                        // \r and erase-line: redraw in place; a log line
                        // printed meanwhile erases it first (see main.rs).
                        let mut err = std::io::stderr().lock();
                        let _ = write!(err, "\r\x1b[2K{text}");
                        let _ = err.flush();
                    } else {
                        tracing::info!("status: {text}");
                    }
                }
            })
            .ok();
        Self {
            stop,
            handle,
            terminal,
        }
    }

    /// Stops the thread; on a terminal the status line is erased.
    pub fn finish(self) {}
}

impl Drop for StatusReporter {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
        if self.terminal {
            let mut err = std::io::stderr().lock();
            let _ = write!(err, "\r\x1b[2K");
            let _ = err.flush();
        }
    }
}

/// The `tracing` writer for stderr: on a terminal each event first erases
/// the status line (`\r`, erase line), so log lines never run into it; the
/// next redraw puts it back under them.
#[derive(Clone, Copy)]
pub struct StderrWriter {
    terminal: bool,
}

impl StderrWriter {
    /// A writer that erases the status line first when stderr is a terminal.
    pub fn new() -> Self {
        Self {
            terminal: std::io::stderr().is_terminal(),
        }
    }
}

impl Default for StderrWriter {
    fn default() -> Self {
        Self::new()
    }
}

/// One event's writer (see [`StderrWriter`]).
pub struct EventWriter {
    erase_first: bool,
}

impl Write for EventWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let mut err = std::io::stderr().lock();
        if std::mem::take(&mut self.erase_first) {
            err.write_all(b"\r\x1b[2K")?;
        }
        err.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for StderrWriter {
    type Writer = EventWriter;

    fn make_writer(&'a self) -> Self::Writer {
        EventWriter {
            erase_first: self.terminal,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_text_has_every_figure_and_colour_only_when_asked() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let cfg = crate::config::Config::embedded().link;
        let link =
            crate::link::Link::start(&cfg, Some("serial:/nonexistent/tty:57600"), rt.handle())
                .unwrap();
        let v = PipelineMeters::default();
        v.frames_in.store(30, Ordering::Relaxed);
        v.measured.store(5, Ordering::Relaxed);
        for _ in 0..15 {
            v.frame_measured(Some(12.345));
        }
        v.set_latency_ms(4.26);
        let plain = status_text(&v, &link, 2_500_000, false);
        assert_eq!(
            plain,
            "frames 30, detected 15 (75.0 %), range 12.35 m, latency 4.3 ms, link never opened, log 2.5 MB"
        );
        v.set_last_miss(Some("blurred"));
        assert!(
            status_text(&v, &link, 0, false).contains("detected 15 (75.0 %), last miss blurred,"),
            "{}",
            status_text(&v, &link, 0, false)
        );
        v.set_last_miss(None);
        let coloured = status_text(&v, &link, 0, true);
        assert!(
            coloured.contains("\x1b[31mnever opened\x1b[0m"),
            "{coloured}"
        );
        link.shutdown();
    }
}
