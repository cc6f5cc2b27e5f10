//! The pipeline's counters (frames in, measured, detected, skipped, the
//! last range and latency) and its resource figures, sampled every second
//! into `/drogue/stats`. One set of counters: the status line, the stats
//! records and the end-of-run summary all read these.
//!
//! What a companion-computer user needs to know before flying: the CPU the
//! pipeline takes (the process's, less what the source spends making frames,
//! since a simulator's rendering is not a cost on a real camera), resident
//! memory, and the depth of the queues (a depth that keeps growing means a
//! stage falls behind). `review` reads these records back.

use crate::link::EventReceiver;
use crate::log::LogHandle;
use cpu_time::{ProcessTime, ThreadTime};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often a `/drogue/stats` record is written.
pub const STATS_PERIOD: Duration = Duration::from_secs(1);

/// Counters the pipeline's threads update as they go.
#[derive(Debug, Default)]
pub struct PipelineMeters {
    /// Items the source delivered (frames and unreadable ones).
    pub frames_in: AtomicU64,
    /// Frames not measured because the measurement was still busy.
    pub skipped: AtomicU64,
    /// Items the source could not deliver (reported and skipped).
    pub unreadable: AtomicU64,
    pub measured: AtomicU64,
    pub detected: AtomicU64,
    /// `--fast`: frames the link was not done with in time.
    pub link_handoff_timeouts: AtomicU64,
    /// Range of the last detection, metres, as f64 bits (0: none yet).
    last_range_bits: AtomicU64,
    /// Capture → send of the last pose, ms, as f64 bits (0: none yet).
    last_latency_bits: AtomicU64,
    /// Why the last frame measured had no drogue (`MissReason::code`);
    /// `None` when it had one.
    last_miss: Mutex<Option<&'static str>>,
    /// The frames without a drogue so far, by reason code.
    missed_by_reason: Mutex<BTreeMap<&'static str, u64>>,
    /// CPU time spent inside the source (rendering, decoding), ns.
    source_cpu_ns: AtomicU64,
    /// The measurement thread's own CPU time so far, ns.
    measure_cpu_ns: AtomicU64,
}

fn thread_cpu_ns() -> Option<u64> {
    ThreadTime::try_now()
        .ok()
        .map(|t| t.as_duration().as_nanos() as u64)
}

impl PipelineMeters {
    /// Runs `f` (the source producing a frame) and counts its CPU time as the
    /// source's.
    pub fn time_source<T>(&self, f: impl FnOnce() -> T) -> T {
        let before = thread_cpu_ns();
        let out = f();
        if let (Some(a), Some(b)) = (before, thread_cpu_ns()) {
            self.source_cpu_ns
                .fetch_add(b.saturating_sub(a), Ordering::Relaxed);
        }
        out
    }

    /// Called by the measurement thread after each frame, with the range of
    /// its detection (if any).
    pub fn frame_measured(&self, detected_range_m: Option<f64>) {
        self.measured.fetch_add(1, Ordering::Relaxed);
        if let Some(r) = detected_range_m {
            self.detected.fetch_add(1, Ordering::Relaxed);
            self.last_range_bits.store(r.to_bits(), Ordering::Relaxed);
        }
        if let Some(t) = thread_cpu_ns() {
            self.measure_cpu_ns.store(t, Ordering::Relaxed);
        }
    }

    /// Called by the measurement thread after each frame: why it had no
    /// drogue (`None`: it had one, or no reason is known).
    pub fn set_last_miss(&self, reason: Option<&'static str>) {
        if let Ok(mut last) = self.last_miss.lock() {
            *last = reason;
        }
        if let (Some(reason), Ok(mut counts)) = (reason, self.missed_by_reason.lock()) {
            *counts.entry(reason).or_default() += 1;
        }
    }

    /// The frames without a drogue so far, by reason code.
    pub fn missed_by_reason(&self) -> BTreeMap<String, u64> {
        self.missed_by_reason
            .lock()
            .map(|counts| counts.iter().map(|(r, n)| (r.to_string(), *n)).collect())
            .unwrap_or_default()
    }

    /// Why the last frame measured had no drogue.
    pub fn last_miss(&self) -> Option<&'static str> {
        self.last_miss.lock().ok().and_then(|last| *last)
    }

    pub fn set_latency_ms(&self, ms: f64) {
        self.last_latency_bits
            .store(ms.to_bits(), Ordering::Relaxed);
    }

    /// Range of the last detection, metres.
    pub fn range_m(&self) -> Option<f64> {
        let r = f64::from_bits(self.last_range_bits.load(Ordering::Relaxed));
        (r > 0.0).then_some(r)
    }

    /// Capture → send of the last pose sent, ms.
    pub fn latency_ms(&self) -> Option<f64> {
        let l = f64::from_bits(self.last_latency_bits.load(Ordering::Relaxed));
        (l > 0.0).then_some(l)
    }

    /// A counter's value now.
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Ordering::Relaxed)
    }
}

/// Resident memory of this process, bytes (Linux `/proc`; None elsewhere).
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// One reading of the cumulative counters.
#[derive(Clone, Copy, Debug)]
struct Reading {
    wall: Instant,
    process_cpu_ns: u64,
    source_cpu_ns: u64,
    measure_cpu_ns: u64,
    log_writer_cpu_ns: u64,
}

impl Reading {
    fn now(meters: &PipelineMeters, log: &LogHandle) -> Self {
        Self {
            wall: Instant::now(),
            process_cpu_ns: ProcessTime::try_now().map_or(0, |t| t.as_duration().as_nanos() as u64),
            source_cpu_ns: meters.source_cpu_ns.load(Ordering::Relaxed),
            measure_cpu_ns: meters.measure_cpu_ns.load(Ordering::Relaxed),
            log_writer_cpu_ns: log.writer_cpu_ns(),
        }
    }
}

/// What the run's end summary reports of its resources.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ResourceSummary {
    /// Pipeline CPU (the process less the source and the log writer: capture,
    /// measurement, link) over the whole run, % of one core.
    pub pipeline_cpu_pct: f64,
    /// The source's CPU (simulator rendering, decoding), % of one core.
    pub source_cpu_pct: f64,
    /// The log writer's CPU (frame encoding, chunk compression, writing),
    /// % of one core.
    pub log_writer_cpu_pct: f64,
    pub peak_rss_bytes: u64,
    /// Deepest log queue seen in a sample.
    pub max_log_queue: u64,
}

fn pct(cpu_ns: u64, wall: Duration) -> f64 {
    if wall.is_zero() {
        0.0
    } else {
        100.0 * cpu_ns as f64 / wall.as_nanos() as f64
    }
}

/// Samples the meters every [`STATS_PERIOD`] on its own thread.
pub struct StatsThread {
    stop: Arc<(Mutex<bool>, Condvar)>,
    handle: Option<JoinHandle<ResourceSummary>>,
}

struct Sampler {
    meters: Arc<PipelineMeters>,
    log: LogHandle,
    link_events: EventReceiver,
    first: Reading,
    last: Reading,
    summary: ResourceSummary,
}

impl Sampler {
    fn sample(&mut self) {
        let now = Reading::now(&self.meters, &self.log);
        let wall = now.wall.duration_since(self.last.wall);
        let d = |a: u64, b: u64| b.saturating_sub(a);
        let process = d(self.last.process_cpu_ns, now.process_cpu_ns);
        let source = d(self.last.source_cpu_ns, now.source_cpu_ns);
        let measure = d(self.last.measure_cpu_ns, now.measure_cpu_ns);
        let writer = d(self.last.log_writer_cpu_ns, now.log_writer_cpu_ns);
        let rss = resident_bytes();
        let log_queue = self.log.queue_depth();
        let m = &self.meters;
        let record = serde_json::json!({
            // On the log's clock (the source's with --fast), like every topic.
            "time_ns": self.log.now_ns(),
            "interval_s": wall.as_secs_f64(),
            "cpu_pct": {
                "process": pct(process, wall),
                "source": pct(source, wall),
                "pipeline": pct(process.saturating_sub(source + writer), wall),
                "measurement": pct(measure, wall),
                "log_writer": pct(writer, wall),
            },
            "cpu_s_total": {
                "process": now.process_cpu_ns as f64 * 1e-9,
                "source": now.source_cpu_ns as f64 * 1e-9,
                "measurement": now.measure_cpu_ns as f64 * 1e-9,
                "log_writer": now.log_writer_cpu_ns as f64 * 1e-9,
            },
            "rss_bytes": rss,
            "queues": {
                "log": log_queue,
                "log_dropped": self.log.dropped(),
                "link_events": self.link_events.len(),
                "link_events_dropped": self.link_events.dropped(),
            },
            "frames": {
                "in": m.frames_in.load(Ordering::Relaxed),
                "measured": m.measured.load(Ordering::Relaxed),
                "skipped": m.skipped.load(Ordering::Relaxed),
            },
        });
        self.log.stats(record);
        self.last = now;
        self.summary.peak_rss_bytes = self.summary.peak_rss_bytes.max(rss.unwrap_or(0));
        self.summary.max_log_queue = self.summary.max_log_queue.max(log_queue);
        let total_wall = now.wall.duration_since(self.first.wall);
        let process = d(self.first.process_cpu_ns, now.process_cpu_ns);
        let source = d(self.first.source_cpu_ns, now.source_cpu_ns);
        let writer = d(self.first.log_writer_cpu_ns, now.log_writer_cpu_ns);
        self.summary.pipeline_cpu_pct = pct(process.saturating_sub(source + writer), total_wall);
        self.summary.source_cpu_pct = pct(source, total_wall);
        self.summary.log_writer_cpu_pct = pct(writer, total_wall);
    }
}

impl StatsThread {
    pub fn spawn(meters: Arc<PipelineMeters>, log: LogHandle, link_events: EventReceiver) -> Self {
        let stop = Arc::new((Mutex::new(false), Condvar::new()));
        let stop_flag = Arc::clone(&stop);
        let first = Reading::now(&meters, &log);
        let mut sampler = Sampler {
            meters,
            log,
            link_events,
            first,
            last: first,
            summary: ResourceSummary::default(),
        };
        let handle = std::thread::Builder::new()
            .name("run-stats".into())
            .spawn(move || {
                let (lock, cvar) = &*stop_flag;
                let mut stopped = lock
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                loop {
                    let (guard, _) = cvar
                        .wait_timeout_while(stopped, STATS_PERIOD, |s| !*s)
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    stopped = guard;
                    // The last, partial interval is sampled too.
                    sampler.sample();
                    if *stopped {
                        return sampler.summary;
                    }
                }
            })
            .ok();
        if handle.is_none() {
            tracing::warn!("cannot start the statistics thread: no /drogue/stats in this log");
        }
        Self { stop, handle }
    }

    /// Takes a last sample and returns the run's figures.
    pub fn finish(mut self) -> ResourceSummary {
        let (lock, cvar) = &*self.stop;
        *lock
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = true;
        cvar.notify_all();
        self.handle
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resident_memory_is_read() {
        let rss = resident_bytes();
        if cfg!(target_os = "linux") {
            // A test binary's resident set: more than a page, less than the machine.
            let rss = rss.unwrap_or(0);
            assert!(rss > 4096 && rss < (64 << 30), "{rss}");
        }
    }

    #[test]
    fn source_time_counts_work_done_inside_only() {
        let meters = PipelineMeters::default();
        let spin = |ms: u64| {
            let t = Instant::now();
            let mut x = 0u64;
            while t.elapsed() < Duration::from_millis(ms) {
                x = std::hint::black_box(x.wrapping_add(1));
            }
            x
        };
        meters.time_source(|| spin(60));
        spin(60);
        let source_ms = meters.source_cpu_ns.load(Ordering::Relaxed) as f64 * 1e-6;
        // 60 ms of busy wall time inside is at most 60 ms of this thread's
        // CPU; the 60 ms outside must not be counted.
        assert!(source_ms > 5.0 && source_ms <= 75.0, "{source_ms}");
    }

    #[test]
    fn percent_of_one_core() {
        assert_eq!(pct(500_000_000, Duration::from_secs(1)), 50.0);
        assert_eq!(pct(1, Duration::ZERO), 0.0);
    }
}
