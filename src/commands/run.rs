//! `drogue-vision run`: the live pipeline. Source → measurement thread → link
//! (latest-wins) and log (every frame), with bounded queues so that nothing
//! waits on the log and the link always gets the newest measurement.

use crate::camera::CameraModel;
use crate::config::Config;
use crate::frame::Frame;
use crate::link::{Link, LinkHandle};
use crate::log::{FlightLog, LogHandle};
use crate::measure::Measurer;
use crate::measure::mount::Mount;
use crate::record::DetectionRecord;
use crate::source::dir::{DirSource, unix_now_ns};
use crate::source::mcap::McapSource;
use crate::source::sim::SimSource;
use crate::source::{FrameSource, SourceSpec};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Arguments of `run` (see `drogue-vision run --help`).
#[derive(Clone, Debug, Default, clap::Args)]
#[command(
    after_help = "With no arguments: the simulated `approach` scenario, MAVLink to \
udpout:127.0.0.1:14550, MCAP to logs/. Ctrl-C (SIGINT) or SIGTERM ends the run cleanly. \
Exit status: 0 the run ended (source finished, --max-frames, or a signal); 2 bad arguments, \
config, camera or source; 1 a failure while running."
)]
pub struct RunArgs {
    /// Config file laid over the embedded default.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Frame source: sim:SCENARIO_NAME_OR_FILE, dir:PATH, mcap:PATH, v4l:/dev/videoN.
    #[arg(long)]
    pub source: Option<String>,
    /// Camera file for sources that do not carry their own (dir:, v4l:).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// MAVLink connection: udpout:HOST:PORT, udpin:HOST:PORT, tcpout:HOST:PORT, serial:DEVICE:BAUD.
    #[arg(long)]
    pub mavlink: Option<String>,
    /// Folder of the MCAP log (default from the config: logs/).
    #[arg(long)]
    pub log_dir: Option<PathBuf>,
    /// Stop after this many frames.
    #[arg(long)]
    pub max_frames: Option<u64>,
    /// Run as fast as the pipeline goes instead of at the source's frame rate.
    #[arg(long)]
    pub fast: bool,
}

/// Why `run` stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Nothing was started: bad arguments, config, camera, source.
    #[error("{0}")]
    Setup(String),
    /// A failure while running.
    #[error("{0}")]
    Runtime(String),
}

/// What the run did, printed at the end.
#[derive(Clone, Debug, Default)]
pub struct RunSummary {
    pub frames: u64,
    pub measured: u64,
    pub detected: u64,
    /// Frames not measured because the measurement was still busy.
    pub skipped: u64,
    /// Frames the source could not deliver (reported and skipped).
    pub unreadable: u64,
    /// Times a paced source fell behind its frame rate and was re-anchored.
    pub source_late: u64,
    pub log_files: Vec<PathBuf>,
    /// Log items lost (queue full or write errors).
    pub log_dropped: u64,
    pub link: Option<crate::link::LinkStats>,
    pub interrupted: bool,
}

fn open_source(spec: &SourceSpec, config: &Config) -> Result<Box<dyn FrameSource>, RunError> {
    let setup = |e: crate::source::SourceError| RunError::Setup(e.to_string());
    Ok(match spec {
        SourceSpec::Sim(name) => Box::new(SimSource::open(name).map_err(setup)?),
        SourceSpec::Dir(path) => Box::new(DirSource::open(path).map_err(setup)?),
        SourceSpec::Mcap(path) => Box::new(McapSource::open(path).map_err(setup)?),
        SourceSpec::V4l(dev) => crate::source::v4l::open(dev, &config.v4l).map_err(setup)?,
    })
}

/// The camera: the source's own, else `--camera`, else `[camera] file`.
fn choose_camera(
    source: &dyn FrameSource,
    args: &RunArgs,
    config: &Config,
) -> Result<CameraModel, RunError> {
    if let Some(c) = source.camera() {
        return Ok(c);
    }
    let file = args
        .camera
        .clone()
        .or_else(|| {
            (!config.camera.file.as_os_str().is_empty()).then(|| config.camera.file.clone())
        })
        .ok_or_else(|| {
            RunError::Setup(
                "this source has no camera of its own: give --camera or [camera] file".into(),
            )
        })?;
    CameraModel::load(&file).map_err(|e| RunError::Setup(e.to_string()))
}

/// A stop request from SIGINT / SIGTERM.
fn watch_signals(rt: &tokio::runtime::Runtime, stop: Arc<AtomicBool>) {
    rt.spawn(async move {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let (Ok(mut int), Ok(mut term)) = (
                signal(SignalKind::interrupt()),
                signal(SignalKind::terminate()),
            ) else {
                tracing::warn!("cannot watch SIGINT/SIGTERM; stop with --max-frames");
                return;
            };
            tokio::select! {
                _ = int.recv() => tracing::info!("SIGINT: finishing the run"),
                _ = term.recv() => tracing::info!("SIGTERM: finishing the run"),
            }
        }
        #[cfg(not(unix))]
        {
            let _ = tokio::signal::ctrl_c().await;
        }
        stop.store(true, Ordering::SeqCst);
    });
}

/// The measurement thread: every frame it gets is measured, handed to the
/// link (latest-wins) and logged.
fn spawn_measurement(
    mut measurer: Measurer,
    mount: Mount,
    link: LinkHandle,
    log: LogHandle,
    counts: Arc<Mutex<RunSummary>>,
) -> (SyncSender<Arc<Frame>>, std::thread::JoinHandle<()>) {
    // Capacity 1: at most one frame waits; a newer one finding it full is
    // skipped for measurement (still logged), so latency never builds up.
    let (tx, rx) = sync_channel::<Arc<Frame>>(1);
    let handle = std::thread::spawn(move || {
        for frame in rx {
            let m = Arc::new(measurer.measure(&frame));
            let measured_ns = unix_now_ns();
            link.submit(Arc::clone(&m));
            let mut record =
                serde_json::to_value(DetectionRecord::from_measurement(frame.seq.to_string(), &m))
                    .unwrap_or_default();
            record["latency_ns"] = serde_json::json!({
                "captured": frame.capture_time_ns,
                "measured": measured_ns,
            });
            if let Ok(mut c) = counts.lock() {
                c.measured += 1;
                c.detected += u64::from(m.detection.is_some());
            }
            log.measurement(m, record, &mount);
        }
    });
    (tx, handle)
}

/// Runs the pipeline until the source ends, `--max-frames`, or a signal.
pub fn run(
    args: &RunArgs,
    config: Config,
    log_layer_sink: impl FnOnce(&LogHandle),
) -> Result<RunSummary, RunError> {
    let spec_text = args
        .source
        .clone()
        .unwrap_or_else(|| config.run.source.clone());
    let spec: SourceSpec = spec_text
        .parse()
        .map_err(|e: crate::source::SourceError| RunError::Setup(e.to_string()))?;
    let mut source = open_source(&spec, &config)?;
    let camera = choose_camera(source.as_ref(), args, &config)?;
    let mut config = config;
    if let Some(m) = source.mount() {
        config.mount = m;
    }
    let mount = Mount::from_config(&config.mount).map_err(RunError::Setup)?;
    let measurer =
        Measurer::new(camera.clone(), &config).map_err(|e| RunError::Setup(e.to_string()))?;

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| RunError::Setup(format!("tokio runtime: {e}")))?;
    let link = Link::start(&config.link, args.mavlink.as_deref(), rt.handle())
        .map_err(|e| RunError::Setup(e.to_string()))?;
    let log_dir = args
        .log_dir
        .clone()
        .unwrap_or_else(|| config.log.dir.clone());
    let log = FlightLog::start(&config.log, &log_dir, &camera)
        .map_err(|e| RunError::Setup(e.to_string()))?;
    log_layer_sink(&log);
    tracing::info!(
        source = %spec_text,
        mavlink = %args.mavlink.as_deref().unwrap_or(&config.link.connection),
        camera = %camera.name,
        "run started"
    );

    let stop = Arc::new(AtomicBool::new(false));
    watch_signals(&rt, Arc::clone(&stop));

    // Link events (sent and received messages) go to the log.
    let events = link.events();
    let event_log = log.clone();
    let events_done = Arc::new(AtomicBool::new(false));
    let events_done_flag = Arc::clone(&events_done);
    let event_thread = std::thread::spawn(move || {
        loop {
            match events.recv_timeout(Duration::from_millis(100)) {
                Some(ev) => event_log.mavlink(ev),
                None if events_done_flag.load(Ordering::SeqCst) => break,
                None => {}
            }
        }
    });

    let counts = Arc::new(Mutex::new(RunSummary::default()));
    let (frame_tx, measure_thread) = spawn_measurement(
        measurer,
        mount,
        link.clone(),
        log.clone(),
        Arc::clone(&counts),
    );

    // Sources with a timeline (sim, log) are replayed at its pace unless
    // --fast, on the wall clock: a frame's capture time becomes the run's
    // start plus its time on the source's timeline (exact, so truth and
    // messages line up). A source that falls more than MAX_SOURCE_LAG behind
    // (a simulator on a busy machine) is re-anchored, like a camera dropping
    // frames; otherwise its frames would all arrive stale.
    const MAX_SOURCE_LAG: Duration = Duration::from_millis(100);
    let paced = source.recorded_timeline() && !args.fast;
    let started = Instant::now();
    let started_ns = unix_now_ns();
    let mut lag = Duration::ZERO;
    let mut first_capture_ns: Option<u64> = None;
    let max_frames = args.max_frames.unwrap_or(u64::MAX);
    let (mut frames, mut skipped, mut unreadable, mut late) = (0u64, 0u64, 0u64, 0u64);
    while frames < max_frames && !stop.load(Ordering::SeqCst) {
        let Some(item) = source.next_frame() else {
            break;
        };
        frames += 1;
        let mut frame = match item {
            Ok(f) => f,
            Err(e) => {
                unreadable += 1;
                tracing::warn!("frame skipped: {e}");
                continue;
            }
        };
        if paced {
            let first = *first_capture_ns.get_or_insert(frame.capture_time_ns);
            let offset = Duration::from_nanos(frame.capture_time_ns.saturating_sub(first));
            let now = Instant::now();
            let due = started + offset + lag;
            if now > due + MAX_SOURCE_LAG {
                lag += now - due;
                late += 1;
                tracing::warn!(
                    seq = frame.seq,
                    "source behind its frame rate: timeline moved on"
                );
            } else if let Some(wait) = due.checked_duration_since(now) {
                std::thread::sleep(wait);
            }
            frame.capture_time_ns = started_ns + (offset + lag).as_nanos() as u64;
        }
        let frame = Arc::new(frame);
        log.frame(Arc::clone(&frame));
        // Offline and fast sources wait for the measurement; a live one never
        // does (a frame that finds the measurement busy is skipped).
        if !paced {
            if frame_tx.send(frame).is_err() {
                return Err(RunError::Runtime("measurement thread ended".into()));
            }
            continue;
        }
        match frame_tx.try_send(frame) {
            Ok(()) => {}
            Err(TrySendError::Full(f)) => {
                skipped += 1;
                tracing::debug!(seq = f.seq, "measurement busy: frame skipped");
            }
            Err(TrySendError::Disconnected(_)) => {
                return Err(RunError::Runtime("measurement thread ended".into()));
            }
        }
    }
    drop(frame_tx);
    let _ = measure_thread.join();
    link.shutdown();
    events_done.store(true, Ordering::SeqCst);
    let _ = event_thread.join();
    let link_stats = link.stats();
    tracing::info!(
        frames,
        skipped,
        unreadable,
        late,
        interrupted = stop.load(Ordering::SeqCst),
        "run finished"
    );
    let log_summary = log.finish().map_err(|e| RunError::Runtime(e.to_string()))?;
    rt.shutdown_timeout(Duration::from_secs(1));

    let mut summary = counts.lock().map(|c| c.clone()).unwrap_or_default();
    summary.frames = frames;
    summary.skipped = skipped;
    summary.unreadable = unreadable;
    summary.source_late = late;
    summary.interrupted = stop.load(Ordering::SeqCst);
    summary.log_files = log_summary.files;
    summary.link = Some(link_stats);
    summary.log_dropped = log_summary.dropped_queue_full + log_summary.dropped_write_error;
    if skipped > 0 {
        tracing::warn!("{skipped} frames were not measured (measurement busy)");
    }
    Ok(summary)
}

impl RunSummary {
    /// The end-of-run lines on stderr.
    pub fn report(&self) -> String {
        let rate = if self.measured > 0 {
            100.0 * self.detected as f64 / self.measured as f64
        } else {
            0.0
        };
        let files: Vec<String> = self
            .log_files
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        let link_line = self.link.as_ref().map_or_else(String::new, |l| {
            let sent: Vec<String> = l.sent.iter().map(|(k, v)| format!("{v} {k}")).collect();
            format!(
                "\nlink: sent {}; {} stale poses not sent; {} autopilot heartbeat losses, {} reconnects",
                sent.join(", "),
                l.stale,
                l.heartbeat_losses,
                l.reconnects
            )
        });
        format!(
            "run {}: {} frames, {} measured, {} detected ({rate:.1} %), {} skipped (measurement busy), \
             {} unreadable, source late {} times{}\nlog: {}",
            if self.interrupted {
                "interrupted"
            } else {
                "ended"
            },
            self.frames,
            self.measured,
            self.detected,
            self.skipped,
            self.unreadable,
            self.source_late,
            link_line,
            files.join(", ")
        )
    }
}
