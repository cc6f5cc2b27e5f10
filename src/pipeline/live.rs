//! `run`'s pipeline: source → measurement thread → link (latest-wins) and log
//! (every frame), with bounded queues so that nothing waits on the log and
//! the link always gets the newest measurement. Threads: this one captures
//! (source, pacing), one measures ([`MeasureStage`]), one passes the link's
//! events to the log, one samples `/drogue/stats`, one draws the status line;
//! the link runs on its own tokio worker.
//!
//! `--fast` (a simulation, a log or a folder as fast as the pipeline goes)
//! runs on the source's clock ([`crate::clock`]): the link measures a pose's
//! age and the log stamps every topic against the capture time of the newest
//! measured frame, and the measurement waits until the link is done with
//! each frame ([`crate::link::LinkHandle::wait_handled`]) instead of handing over
//! latest-wins. So every detected frame's pose is sent (unless `max_rate_hz`,
//! kept on the source's clock, thins it), and the log spans the source's
//! first to last capture time. The log waits for room there instead of
//! dropping (nothing is live). Capture → send latency is not measured there
//! (the source's clock stands still while a frame is processed).

use super::closed_loop::{ClosedLoop, wait_for_autopilot_pose};
use super::input::{choose_camera, first_item, open_source};
use super::meters::{PipelineMeters, ResourceSummary, StatsThread};
use super::pacing::Pacer;
use super::provenance::{RunProvenance, run_metadata};
use super::signals::{realtime_if_asked, watch_signals};
use super::stage::MeasureStage;
use super::status::StatusReporter;
use super::threads::{spawn_event_logger, spawn_measurement, wait_until_handed_to_link};
use crate::clock::RunClock;
use crate::config::{Config, VehiclePoseSource};
use crate::link::{Link, LinkStats};
use crate::log::review::Histogram;
use crate::log::{FlightLog, LogHandle};
use crate::measure::Measurer;
use crate::measure::mount::Mount;
use crate::source::dir::FolderTiming;
use crate::source::sim::SimSource;
use crate::source::{Captured, FrameSource, SourceSpec};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::TrySendError;
use std::time::Duration;

/// What `run` was asked for (the command line over the config).
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Source address; `None`: `[run] source`.
    pub source: Option<String>,
    /// Camera file that overrides the source's own.
    pub camera: Option<PathBuf>,
    /// MAVLink address; `None`: `[link] connection`.
    pub mavlink: Option<String>,
    /// Log folder; `None`: `[log] dir`.
    pub log_dir: Option<PathBuf>,
    pub max_frames: Option<u64>,
    /// On the source's clock, as fast as the pipeline goes.
    pub fast: bool,
    /// `None`: `[run] vehicle_pose`.
    pub vehicle_pose: Option<VehiclePoseSource>,
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

/// What the run did.
#[derive(Clone, Debug, Default)]
pub struct RunSummary {
    /// Frames the source delivered.
    pub frames: u64,
    /// Frames measured.
    pub measured: u64,
    /// Frames with a drogue detected.
    pub detected: u64,
    /// The measured frames without one, by the reason their records give.
    pub missed_by_reason: std::collections::BTreeMap<String, u64>,
    /// Frames not measured because the measurement was still busy.
    pub skipped: u64,
    /// Frames the source could not deliver (reported and skipped).
    pub unreadable: u64,
    /// Times a paced source fell behind its frame rate and was re-anchored.
    pub source_late: u64,
    /// The MCAP files written (more than one after rotation).
    pub log_files: Vec<PathBuf>,
    /// Log items lost (queue full or write errors).
    pub log_dropped: u64,
    /// The link's counters at the end (`None`: no link was started).
    pub link: Option<LinkStats>,
    /// Closed loop: frames rendered with a held pose (the autopilot's was stale).
    pub vehicle_pose_held: u64,
    /// The run was stopped by a signal (Ctrl-C, SIGTERM), not by the source's end.
    pub interrupted: bool,
    /// CPU, memory and queues (the `/drogue/stats` figures).
    pub resources: ResourceSummary,
    /// Capture to first pose message sent, ms (empty with `--fast`).
    pub latency_ms: Histogram,
    /// `--fast`: the run was on the source's clock.
    pub source_clock: bool,
    /// `--fast`: frames the link was not done with in time (their poses may
    /// not have been sent).
    pub link_handoff_timeouts: u64,
}

/// Where the run's frames come from: any source, or the simulator flown by
/// the autopilot (SITL closed loop).
enum Frames {
    Source(Box<dyn FrameSource>),
    ClosedLoop(Box<ClosedLoop>),
}

impl Frames {
    fn source(&self) -> &dyn FrameSource {
        match self {
            Frames::Source(s) => s.as_ref(),
            Frames::ClosedLoop(c) => c.sim(),
        }
    }
}

/// Opens the frames for `vehicle_pose`: the closed loop needs a `sim:`
/// source on the wall clock.
fn open_frames(
    spec: &SourceSpec,
    vehicle_pose: VehiclePoseSource,
    fast: bool,
    config: &Config,
) -> Result<Frames, RunError> {
    let setup = |e: crate::source::SourceError| RunError::Setup(e.to_string());
    match (vehicle_pose, spec) {
        (VehiclePoseSource::Script, _) => Ok(Frames::Source(
            open_source(spec, &config.v4l, FolderTiming::ReadTime).map_err(setup)?,
        )),
        (VehiclePoseSource::Mavlink, SourceSpec::Sim(name)) => {
            if fast {
                return Err(RunError::Setup(
                    "--vehicle-pose mavlink runs on the wall clock (the autopilot's time): drop --fast"
                        .into(),
                ));
            }
            let timeout = config.run.vehicle_pose_timeout_s;
            if !(timeout.is_finite() && timeout > 0.0) {
                return Err(RunError::Setup(format!(
                    "[run] vehicle_pose_timeout_s = {timeout} must be > 0"
                )));
            }
            let (delay, max_age) = (config.run.vehicle_pose_delay_ms, config.link.max_age_ms);
            if max_age > 0 && delay >= max_age {
                return Err(RunError::Setup(format!(
                    "[run] vehicle_pose_delay_ms = {delay} must be below [link] max_age_ms = \
                     {max_age}: every frame would be too old to send"
                )));
            }
            let sim = SimSource::open(name).map_err(setup)?;
            Ok(Frames::ClosedLoop(Box::new(ClosedLoop::new(
                sim,
                config.run.sitl_anchor,
            ))))
        }
        (VehiclePoseSource::Mavlink, _) => Err(RunError::Setup(
            "--vehicle-pose mavlink needs a simulated source (--source sim:SCENARIO)".into(),
        )),
    }
}

/// The camera file the run used, for the log's metadata.
fn camera_file_used(source: &dyn FrameSource, opts: &RunOptions, config: &Config) -> String {
    if opts.camera.is_none() && source.camera().is_some() {
        return "(the source's own camera, in /camera/calibration)".into();
    }
    opts.camera
        .clone()
        .unwrap_or_else(|| config.camera.file.clone())
        .display()
        .to_string()
}

/// Runs the pipeline until the source ends, `max_frames`, or a signal.
/// `log_layer_sink` gets the log as soon as it exists (the `/log` topic).
pub fn run(
    opts: &RunOptions,
    config: Config,
    log_layer_sink: impl FnOnce(&LogHandle),
) -> Result<RunSummary, RunError> {
    let setup = RunError::Setup;
    let spec_text = opts
        .source
        .clone()
        .unwrap_or_else(|| config.run.source.clone());
    let spec: SourceSpec = spec_text
        .parse()
        .map_err(|e: crate::source::SourceError| setup(e.to_string()))?;
    let vehicle_pose = opts.vehicle_pose.unwrap_or(config.run.vehicle_pose);
    let priority = config.run.realtime_priority;
    if priority > 99 {
        return Err(setup(format!(
            "[run] realtime_priority = {priority}: 0 (off) or 1-99"
        )));
    }
    let mut frames_in = open_frames(&spec, vehicle_pose, opts.fast, &config)?;
    let camera = choose_camera(
        frames_in.source(),
        opts.camera.as_deref(),
        &config.camera.file,
    )
    .map_err(setup)?;
    // The first frame is read before anything starts (link, log files): a
    // calibration of another size is refused with exit status 2.
    let mut first = match &mut frames_in {
        Frames::Source(source) => first_item(source.as_mut(), &camera).map_err(setup)?,
        Frames::ClosedLoop(_) => None,
    };
    // --fast runs on the source's clock (module docs); a camera's frames come
    // in real time whatever --fast says.
    let live = frames_in.source().live();
    if opts.fast && live {
        tracing::warn!("--fast has no effect on a live camera: the run is on the wall clock");
    }
    let clock = if opts.fast && !live {
        RunClock::source(match &first {
            Some(Ok(c)) => c.frame.capture_time_ns,
            _ => 0,
        })
    } else {
        RunClock::wall()
    };
    let mut config = config;
    if let Some(m) = frames_in.source().mount() {
        config.mount = m;
    }
    if let Some(e) = frames_in.source().exposure() {
        config.camera.exposure_ms = e.as_secs_f64() * 1e3;
    }
    let mount = Mount::from_config(&config.mount).map_err(setup)?;
    let measurer =
        Measurer::new(camera.clone(), &config.measure()).map_err(|e| setup(e.to_string()))?;

    // The link's thread is on the latency path too (it writes each pose).
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .on_thread_start(move || realtime_if_asked("link", priority))
        .enable_all()
        .build()
        .map_err(|e| setup(format!("tokio runtime: {e}")))?;
    let link = Link::start_with_clock(
        &config.link,
        opts.mavlink.as_deref(),
        rt.handle(),
        clock.clone(),
    )
    .map_err(|e| setup(e.to_string()))?;
    let log_dir = opts
        .log_dir
        .clone()
        .unwrap_or_else(|| config.log.dir.clone());
    let mut log_config = config.log.clone();
    log_config.set_drogue(config.drogue.inner_radius_m, config.drogue.canopy_radius_m);
    let log = FlightLog::start(&log_config, &log_dir, &camera).map_err(|e| setup(e.to_string()))?;
    log.set_clock(clock.clone());
    // --fast: nothing is live, so the log waits for room rather than drop.
    log.set_waiting(clock.is_source());
    log_layer_sink(&log);
    log.metadata(
        crate::log::metadata::RUN_METADATA,
        run_metadata(
            &config,
            &RunProvenance {
                source: spec_text.clone(),
                source_details: frames_in.source().provenance(),
                camera_file: camera_file_used(frames_in.source(), opts, &config),
                mavlink: opts
                    .mavlink
                    .clone()
                    .unwrap_or_else(|| config.link.connection.clone()),
                clock: if clock.is_source() { "source" } else { "wall" }.into(),
            },
        ),
    );
    tracing::info!(
        source = %spec_text,
        mavlink = %opts.mavlink.as_deref().unwrap_or(&config.link.connection),
        camera = %camera.name,
        vehicle_pose = ?vehicle_pose,
        "run started"
    );

    let stop = Arc::new(AtomicBool::new(false));
    watch_signals(&rt, Arc::clone(&stop));

    let meters = Arc::new(PipelineMeters::default());
    let events_done = Arc::new(AtomicBool::new(false));
    // (On the source's clock a send's time is its frame's capture time: no
    // latency to measure.)
    let event_thread = spawn_event_logger(
        &link,
        log.clone(),
        Arc::clone(&meters),
        (config.log.queue_len as u64).div_ceil(2),
        !clock.is_source(),
        Arc::clone(&events_done),
    );
    let stats_thread = StatsThread::spawn(Arc::clone(&meters), log.clone(), link.events());
    // A source that renders its frames (the simulator) waits until the
    // measurement has handed the frame to the link before making the next:
    // on a small companion computer it would otherwise take a core from the
    // measurement right when latency matters, which a camera never does.
    let (handed_tx, handed_rx) = std::sync::mpsc::channel::<u64>();
    let yield_to_measurement = frames_in.source().renders_frames();
    let stage = MeasureStage::new(
        measurer,
        mount,
        Some(link.clone()),
        Some(log.clone()),
        clock.clone(),
    );
    let (frame_tx, measure_thread) = spawn_measurement(
        stage,
        Arc::clone(&meters),
        yield_to_measurement.then_some(handed_tx),
        priority,
    );

    // Sources with a timeline (sim, log) are replayed at its pace unless
    // --fast (see Pacer). The closed loop first waits for the autopilot.
    let mut failure = None;
    let go = match &frames_in {
        Frames::ClosedLoop(_) => wait_for_autopilot_pose(
            &link,
            config.run.vehicle_pose_timeout_s,
            Duration::from_millis(config.run.vehicle_pose_delay_ms),
            &stop,
        )
        .unwrap_or_else(|e| {
            tracing::error!("{e}");
            failure = Some(RunError::Runtime(e));
            false
        }),
        Frames::Source(_) => true,
    };
    let paced = frames_in.source().recorded_timeline() && !opts.fast;
    let status = StatusReporter::spawn(Arc::clone(&meters), link.clone(), log_dir.clone());
    // This thread takes each frame from the source (a camera's dequeue, the
    // pacer's wake-up at a frame's due time) and hands it on.
    realtime_if_asked("capture", priority);
    let mut pacer = Pacer::start();
    let max_frames = opts.max_frames.unwrap_or(u64::MAX);
    let mut frames = 0u64;
    while go && frames < max_frames && !stop.load(Ordering::SeqCst) {
        // The source's own CPU (rendering, decoding) is counted apart from
        // the pipeline's.
        let item = meters.time_source(|| match &mut frames_in {
            Frames::Source(_) if first.is_some() => first.take(),
            Frames::Source(source) => source.next_frame(),
            // Rendered [run] vehicle_pose_delay_ms after its capture, from
            // the autopilot's pose at the capture.
            Frames::ClosedLoop(cl) => {
                let delay_ns = config.run.vehicle_pose_delay_ms.saturating_mul(1_000_000);
                cl.next_frame(&link, &mut pacer, delay_ns)
            }
        });
        let Some(item) = item else {
            break;
        };
        frames += 1;
        meters.frames_in.fetch_add(1, Ordering::Relaxed);
        let checked = item
            .and_then(|c| crate::image_io::check_frame_size(&c.frame.image, &camera).map(|()| c));
        let Captured { mut frame, truth } = match checked {
            Ok(c) => c,
            Err(e) => {
                meters.unreadable.fetch_add(1, Ordering::Relaxed);
                tracing::warn!("frame skipped: {e}");
                continue;
            }
        };
        // (Only when the source's first item was unreadable.)
        clock.start_at(frame.capture_time_ns);
        if paced && matches!(frames_in, Frames::Source(_)) {
            frame.capture_time_ns = pacer.wait_until_due(frame.capture_time_ns, frame.seq);
        }
        let frame = Arc::new(frame);
        log.frame_with_truth(Arc::clone(&frame), truth);
        // Offline and fast sources wait for the measurement; a live one (a
        // paced timeline, a camera) never does: a frame that finds the
        // measurement busy is skipped.
        if !paced && !live {
            if frame_tx.send(frame).is_err() {
                return Err(RunError::Runtime("measurement thread ended".into()));
            }
            continue;
        }
        let seq = frame.seq;
        match frame_tx.try_send(frame) {
            Ok(()) if yield_to_measurement => wait_until_handed_to_link(&handed_rx, seq),
            Ok(()) => {}
            Err(TrySendError::Full(f)) => {
                meters.skipped.fetch_add(1, Ordering::Relaxed);
                tracing::debug!(seq = f.seq, "measurement busy: frame skipped");
            }
            Err(TrySendError::Disconnected(_)) => {
                return Err(RunError::Runtime("measurement thread ended".into()));
            }
        }
    }
    let late = pacer.late;
    let vehicle_pose_held = match &frames_in {
        Frames::ClosedLoop(cl) => cl.held_frames(),
        Frames::Source(_) => 0,
    };
    drop(frame_tx);
    let _ = measure_thread.join();
    status.finish();
    link.shutdown();
    events_done.store(true, Ordering::SeqCst);
    let latency_ms = event_thread.join().unwrap_or_default();
    let resources = stats_thread.finish();
    let link_stats = link.stats();
    let get = PipelineMeters::get;
    let (skipped, unreadable) = (get(&meters.skipped), get(&meters.unreadable));
    tracing::info!(
        frames,
        skipped,
        unreadable,
        late,
        vehicle_pose_held,
        interrupted = stop.load(Ordering::SeqCst),
        "run finished"
    );
    let log_summary = log.finish().map_err(|e| RunError::Runtime(e.to_string()))?;
    rt.shutdown_timeout(Duration::from_secs(1));
    if skipped > 0 {
        tracing::warn!("{skipped} frames were not measured (measurement busy)");
    }
    if let Some(e) = failure {
        return Err(e);
    }
    Ok(RunSummary {
        frames,
        measured: get(&meters.measured),
        detected: get(&meters.detected),
        missed_by_reason: meters.missed_by_reason(),
        skipped,
        unreadable,
        source_late: late,
        log_files: log_summary.files,
        log_dropped: log_summary.dropped_queue_full + log_summary.dropped_write_error,
        link: Some(link_stats),
        vehicle_pose_held,
        interrupted: stop.load(Ordering::SeqCst),
        resources,
        latency_ms,
        source_clock: clock.is_source(),
        link_handoff_timeouts: get(&meters.link_handoff_timeouts),
    })
}
