//! What the review found, and the terminal summary it prints: detection
//! rate, accuracy against the truth by range, latency, the link, the run's
//! resources and the problems the log recorded.

use super::super::oversized::RECORD_LIMIT_BYTES;
use super::{Histogram, PlotPoint, RangeBin};
use std::collections::BTreeMap;
use std::fmt;
use std::path::PathBuf;

/// The run's resources, from its `/drogue/stats` records.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ResourceReview {
    /// `/drogue/stats` records read (one a second).
    pub samples: u64,
    /// Pipeline CPU (the process less the source and the log writer) over
    /// the whole run, % of one core.
    pub pipeline_cpu_pct: f64,
    /// The busiest one-second interval, % of one core.
    pub pipeline_cpu_max_pct: f64,
    /// The source's own CPU (simulator rendering, camera decoding), % of one core.
    pub source_cpu_pct: f64,
    /// The log writer's CPU (encoding, compression, writing), % of one core.
    pub log_writer_cpu_pct: f64,
    /// Largest resident memory of the process, bytes.
    pub peak_rss_bytes: u64,
    /// Deepest the log queue got, items.
    pub max_log_queue: u64,
    /// The log queue's depth at the last record, items.
    pub last_log_queue: u64,
    /// Deepest the link's event queue got, items.
    pub max_link_event_queue: u64,
}

/// Everything the review found.
#[derive(Debug, Default)]
pub struct ReviewReport {
    /// The log reviewed.
    pub log: PathBuf,
    /// Why reading stopped early (a cut-short log), if it did.
    pub cut: Option<String>,
    /// Why reading stopped at damage (a chunk CRC, a bad record), if it did.
    pub damaged: Option<String>,
    /// MCAP records above the record bound, skipped without being read
    /// (their frames or messages are missing from everything below), and
    /// their bytes.
    pub oversized_records: u64,
    /// Bytes of those records.
    pub oversized_bytes: u64,
    /// The log's MCAP metadata records (name, key/values), in file order.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Log time span of all messages, ns.
    pub first_ns: Option<u64>,
    /// End of that span, ns.
    pub last_ns: Option<u64>,
    /// Capture times of the first and last frame, ns.
    pub first_frame_ns: Option<u64>,
    /// Capture time of the last frame, ns.
    pub last_frame_ns: Option<u64>,
    /// Frames on `/camera/image`.
    pub frames: u64,
    /// Frames missing from `/camera/image` (gaps in the sequence numbers,
    /// counting only the frames the log's mode keeps).
    pub frames_lost: u64,
    /// `image_encoding = "crop"`: a full frame every this many (1 otherwise).
    pub full_frame_every: u64,
    /// Records on `/drogue/detection` (one per measured frame).
    pub measurements: u64,
    /// Of those, frames with a drogue detected.
    pub detected: u64,
    /// The others, by the reason their records give (`not_detected.reason`;
    /// `unknown` in logs written before records gave one).
    pub missed_by_reason: BTreeMap<String, u64>,
    /// Measurement time per frame, ms.
    pub processing_ms: Histogram,
    /// Capture to pose sent, ms (when the log has it).
    pub latency_ms: Histogram,
    /// The log is on the source's clock (`run --fast`): no latency in it.
    pub source_clock: bool,
    /// MAVLink messages sent, by name.
    pub mavlink_out: BTreeMap<String, u64>,
    /// MAVLink messages received, by name.
    pub mavlink_in: BTreeMap<String, u64>,
    /// HEARTBEATs received from the autopilot.
    pub heartbeats_in: u64,
    /// Times the autopilot's heartbeat stopped for more than 3 s.
    pub link_losses: u64,
    /// Longest time between two received heartbeats, seconds.
    pub longest_heartbeat_gap_s: f64,
    /// Warning events on `/log`.
    pub warnings: u64,
    /// Error events on `/log`.
    pub errors: u64,
    /// The first warnings and errors, quoted (`target: message`), and unreadable records.
    pub problems: Vec<String>,
    /// Items the log writer reported dropped (queue full + write errors).
    pub log_dropped: u64,
    /// Measured frames with a simulator truth to compare with.
    pub truth_frames: u64,
    /// Detection and accuracy against the truth, by range bin.
    pub by_range: Vec<RangeBin>,
    /// From `/drogue/stats` (logs of `run`).
    pub resources: Option<ResourceReview>,
    /// The files the review wrote (poses.csv, the plots).
    pub files_written: Vec<PathBuf>,
    /// Why the plots could not be drawn, if they could not.
    pub plot_error: Option<String>,
    #[doc(hidden)]
    pub(crate) series: Vec<PlotPoint>,
}

impl ReviewReport {
    /// First to last frame (all messages when the log has no frames), s.
    pub fn duration_s(&self) -> f64 {
        let span = if self.frames > 0 {
            (self.first_frame_ns, self.last_frame_ns)
        } else {
            (self.first_ns, self.last_ns)
        };
        match span {
            (Some(a), Some(b)) => b.saturating_sub(a) as f64 * 1e-9,
            _ => 0.0,
        }
    }
    /// Share of the measured frames with a drogue detected, 0..1.
    pub fn detection_rate(&self) -> f64 {
        if self.measurements == 0 {
            0.0
        } else {
            self.detected as f64 / self.measurements as f64
        }
    }
}

pub(super) fn percentiles(h: &Histogram) -> String {
    if h.count() == 0 {
        return "none in the log".into();
    }
    format!(
        "p50 {:.2}  p95 {:.2}  p99 {:.2}  max {:.2} ms ({} frames)",
        h.quantile(0.50),
        h.quantile(0.95),
        h.quantile(0.99),
        h.max(),
        h.count()
    )
}

impl fmt::Display for ReviewReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "log        {}", self.log.display())?;
        if let Some(c) = &self.cut {
            writeln!(
                f,
                "           CUT SHORT, read up to: {c} (drogue-vision recover fixes the file)"
            )?;
        }
        if let Some(d) = &self.damaged {
            writeln!(
                f,
                "           DAMAGED, read up to: {d} (drogue-vision recover salvages the rest \
                 and says what is lost)"
            )?;
        }
        if self.oversized_records > 0 {
            writeln!(
                f,
                "           SKIPPED: {} MCAP record(s) ({} bytes) above the {} MiB record \
                 bound, not read (what they held is missing below)",
                self.oversized_records,
                self.oversized_bytes,
                RECORD_LIMIT_BYTES >> 20
            )?;
        }
        for (name, values) in &self.metadata {
            writeln!(f, "metadata   {name}")?;
            for (k, v) in values {
                // Long values (the config as TOML) are in metadata.txt.
                match v.lines().count() {
                    0 | 1 => writeln!(f, "             {k}: {v}")?,
                    n => writeln!(f, "             {k}: {n} lines, in metadata.txt")?,
                }
            }
        }
        writeln!(f, "duration   {:.1} s", self.duration_s())?;
        let mode = if self.full_frame_every > 1 {
            format!(
                " (crop mode: full frames every {}th, crops on /camera/crop)",
                self.full_frame_every
            )
        } else {
            String::new()
        };
        writeln!(
            f,
            "frames     {} logged{mode}, {} lost or dropped before the log (sequence gaps), {} dropped by the log writer",
            self.frames, self.frames_lost, self.log_dropped
        )?;
        writeln!(
            f,
            "detection  {} of {} frames ({:.1} %)",
            self.detected,
            self.measurements,
            100.0 * self.detection_rate()
        )?;
        if !self.missed_by_reason.is_empty() {
            writeln!(
                f,
                "           not detected: {}",
                crate::measure::miss::counts_line(&self.missed_by_reason)
            )?;
        }
        writeln!(f, "processing {}", percentiles(&self.processing_ms))?;
        if self.source_clock {
            writeln!(
                f,
                "latency    not measured (run --fast: the log is on the source's clock)"
            )?;
        } else {
            writeln!(f, "latency    {}", percentiles(&self.latency_ms))?;
        }
        let sent: u64 = self.mavlink_out.values().sum();
        let sent_list: Vec<String> = self
            .mavlink_out
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        writeln!(
            f,
            "sent       {sent} MAVLink messages ({})",
            sent_list.join(", ")
        )?;
        writeln!(
            f,
            "link       {} autopilot heartbeats, lost {} times (> 3 s), longest gap {:.1} s, {} messages received",
            self.heartbeats_in,
            self.link_losses,
            self.longest_heartbeat_gap_s,
            self.mavlink_in.values().sum::<u64>()
        )?;
        if let Some(res) = &self.resources {
            writeln!(
                f,
                "resources  pipeline CPU {:.1} % of one core (busiest second {:.1} %), source {:.1} % and \
                 log writer {:.1} % besides; peak resident memory {:.1} MB",
                res.pipeline_cpu_pct,
                res.pipeline_cpu_max_pct,
                res.source_cpu_pct,
                res.log_writer_cpu_pct,
                res.peak_rss_bytes as f64 / 1e6
            )?;
            writeln!(
                f,
                "queues     log writer at most {} items ({} at the end), link events at most {} ({} samples)",
                res.max_log_queue, res.last_log_queue, res.max_link_event_queue, res.samples
            )?;
        }
        writeln!(
            f,
            "problems   {} errors, {} warnings",
            self.errors, self.warnings
        )?;
        for p in &self.problems {
            writeln!(f, "           {p}")?;
        }
        if self.truth_frames > 0 {
            writeln!(
                f,
                "against the simulator's truth ({} frames):",
                self.truth_frames
            )?;
            writeln!(
                f,
                "  range m      frames  detected  pos err mean/rms/max m     normal err mean/max deg"
            )?;
            for b in self.by_range.iter().filter(|b| b.frames > 0) {
                writeln!(f, "  {b}")?;
            }
        }
        for p in &self.files_written {
            writeln!(f, "wrote      {}", p.display())?;
        }
        if let Some(e) = &self.plot_error {
            writeln!(f, "plots      not drawn: {e}")?;
        }
        Ok(())
    }
}
