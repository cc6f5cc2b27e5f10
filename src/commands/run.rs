//! `drogue-vision run`: the live pipeline. Source → measurement thread → link
//! (latest-wins) and log (every frame), with bounded queues so that nothing
//! waits on the log and the link always gets the newest measurement.
//!
//! `--fast` (a simulation, a log or a folder as fast as the pipeline goes)
//! runs on the source's clock ([`crate::clock`]): the link measures a pose's
//! age and the log stamps every topic against the capture time of the newest
//! measured frame, and the measurement waits until the link is done with
//! each frame ([`LinkHandle::wait_handled`]) instead of handing over
//! latest-wins. So every detected frame's pose is sent (unless `max_rate_hz`,
//! kept on the source's clock, thins it), and the log spans the source's
//! first to last capture time. The log waits for room there instead of
//! dropping (nothing is live). Capture → send latency is not measured there
//! (the source's clock stands still while a frame is processed).

use super::run_stats::{PipelineMeters, ResourceSummary, StatsThread};
use super::run_status::{StatusReporter, Vitals};
use crate::camera::CameraModel;
use crate::clock::RunClock;
use crate::config::{Config, SitlAnchor, VehiclePoseSource};
use crate::frame::Frame;
use crate::link::{Link, LinkHandle, VehiclePose};
use crate::log::review::Histogram;
use crate::log::{FlightLog, LogHandle};
use crate::measure::Measurer;
use crate::measure::mount::Mount;
use crate::record::DetectionRecord;
use crate::source::dir::{DirSource, unix_now_ns};
use crate::source::mcap::McapSource;
use crate::source::sim::{AutopilotAnchor, SimSource};
use crate::source::{FrameSource, SourceItem, SourceSpec};
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
    /// Closed loop: frames rendered with a held pose (the autopilot's was stale).
    pub vehicle_pose_held: u64,
    pub interrupted: bool,
    /// CPU, memory and queues (the `/drogue/stats` figures).
    pub resources: ResourceSummary,
    /// Capture to first pose message sent, ms (empty with `--fast`).
    pub latency_ms: Histogram,
    /// `--fast`: the run was on the source's clock.
    pub source_clock: bool,
    /// `--fast`: frames the link was not done with within
    /// [`HANDOFF_TIMEOUT`] (their poses may not have been sent).
    pub link_handoff_timeouts: u64,
}

/// `--fast`: longest the measurement waits for the link to be done with a
/// frame (a transport write stuck that long is a fault the link reports).
const HANDOFF_TIMEOUT: Duration = Duration::from_secs(2);

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
            Frames::ClosedLoop(c) => &c.sim,
        }
    }
}

/// Opens the frames for `vehicle_pose`: the closed loop needs a `sim:`
/// source on the wall clock.
fn open_frames(
    spec: &SourceSpec,
    vehicle_pose: VehiclePoseSource,
    args: &RunArgs,
    config: &Config,
) -> Result<Frames, RunError> {
    match (vehicle_pose, spec) {
        (VehiclePoseSource::Script, _) => Ok(Frames::Source(open_source(spec, config)?)),
        (VehiclePoseSource::Mavlink, SourceSpec::Sim(name)) => {
            if args.fast {
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
            let sim = SimSource::open(name).map_err(|e| RunError::Setup(e.to_string()))?;
            Ok(Frames::ClosedLoop(Box::new(ClosedLoop {
                sim,
                mode: config.run.sitl_anchor,
                anchor: None,
                held: None,
                stale: false,
                held_frames: 0,
                dropped: 0,
            })))
        }
        (VehiclePoseSource::Mavlink, _) => Err(RunError::Setup(
            "--vehicle-pose mavlink needs a simulated source (--source sim:SCENARIO)".into(),
        )),
    }
}

/// SITL closed loop (`--vehicle-pose mavlink`): each frame is rendered with
/// the receiver at the pose the autopilot reports on the link
/// (LOCAL_POSITION_NED + ATTITUDE) for the frame's capture time, while the
/// drogue flies its own trajectory. The autopilot's local NED is placed in
/// the scenario's world at its first pose ([`AutopilotAnchor`]).
struct ClosedLoop {
    sim: SimSource,
    mode: SitlAnchor,
    anchor: Option<AutopilotAnchor>,
    /// The last pose used: held while the autopilot's is stale.
    held: Option<VehiclePose>,
    stale: bool,
    held_frames: u64,
    /// Frames dropped because the rendering fell behind.
    dropped: u64,
}

impl ClosedLoop {
    /// The next frame on the wall clock, captured `delay_ns` before it is
    /// rendered, from the autopilot's pose at the capture (or the last one
    /// while it is stale). Frames the run is too late for are dropped, as a
    /// camera drops them: the scenario's clock stays on the autopilot's.
    fn next_frame(
        &mut self,
        link: &LinkHandle,
        pacer: &mut Pacer,
        delay_ns: u64,
    ) -> Option<SourceItem> {
        let due_ns = loop {
            match pacer.wait_until_due_or_drop(self.sim.next_frame_time_ns()) {
                Some(due) => break due,
                None => {
                    self.sim.skip_frame()?;
                    self.dropped += 1;
                    pacer.late += 1;
                    if self.dropped.is_power_of_two() {
                        tracing::warn!(
                            dropped = self.dropped,
                            "closed loop: rendering behind the frame rate, frames dropped"
                        );
                    }
                }
            }
        };
        let capture_time_ns = due_ns.saturating_sub(delay_ns);
        let pose = match (link.vehicle_pose_at(capture_time_ns), self.held) {
            (Some(p), _) => {
                if self.stale {
                    self.stale = false;
                    tracing::info!("closed loop: the autopilot's pose is back");
                }
                p
            }
            (None, Some(held)) => {
                if !self.stale {
                    self.stale = true;
                    tracing::warn!(
                        "closed loop: the autopilot's pose is stale (no LOCAL_POSITION_NED + \
                         ATTITUDE near the capture time): holding the last one"
                    );
                }
                self.held_frames += 1;
                held
            }
            (None, None) => {
                return Some(Err(
                    "closed loop: no pose from the autopilot for this frame".into(),
                ));
            }
        };
        self.held = Some(pose);
        if self.anchor.is_none() {
            self.anchor = self.anchor_at(&pose);
        }
        let Some(anchor) = &self.anchor else {
            return Some(Err(
                "closed loop: the autopilot's first pose cannot be placed in the scenario".into(),
            ));
        };
        self.sim.next_frame_from_autopilot(
            anchor,
            pose.position_ned_m,
            pose.q_ned_body,
            capture_time_ns,
        )
    }

    /// Places the autopilot's local NED in the scenario's world at its first
    /// pose, and says so (tracing, MCAP `/log`): it holds for the whole run.
    fn anchor_at(&self, pose: &VehiclePose) -> Option<AutopilotAnchor> {
        let anchor = AutopilotAnchor::new(
            self.sim.simulator().scenario(),
            self.mode,
            pose.position_ned_m,
            pose.q_ned_body,
        )?;
        tracing::info!(
            mode = ?self.mode,
            yaw_world_autopilot_deg = anchor.yaw_world_autopilot_rad.to_degrees(),
            origin_autopilot_m = ?anchor.origin_autopilot_m,
            origin_world_m = ?anchor.origin_world_m,
            velocity_world_mps = ?anchor.velocity_world_mps,
            "closed loop: the autopilot's local NED placed in the scenario's world \
             (world = R_yaw (p - origin_autopilot) + origin_world + velocity t); \
             /sim/truth NED fields are in the autopilot's frame"
        );
        Some(anchor)
    }
}

/// Waits until the autopilot's pose is on the link (the link keeps
/// heartbeating meanwhile), then `delay` more, so that the first frame's
/// capture time (`delay` before it is rendered) comes after the first
/// report. `Ok(false)`: a signal ended the wait.
fn wait_for_autopilot_pose(
    link: &LinkHandle,
    timeout_s: f64,
    delay: Duration,
    stop: &AtomicBool,
) -> Result<bool, RunError> {
    let deadline = Instant::now() + Duration::from_secs_f64(timeout_s);
    let mut said = false;
    loop {
        if link.vehicle_pose_at(unix_now_ns()).is_some() {
            if said {
                tracing::info!("closed loop: the autopilot's pose arrived");
            }
            std::thread::sleep(delay);
            return Ok(!stop.load(Ordering::SeqCst));
        }
        if stop.load(Ordering::SeqCst) {
            return Ok(false);
        }
        if Instant::now() > deadline {
            return Err(RunError::Runtime(format!(
                "no pose from the autopilot within {timeout_s} s: stream LOCAL_POSITION_NED and \
                 ATTITUDE on the MAVLink link (see README, SITL docking)"
            )));
        }
        if !said {
            said = true;
            tracing::info!(
                "waiting for the autopilot's pose (LOCAL_POSITION_NED + ATTITUDE on the link)"
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Replays a source's timeline on the wall clock: a frame's capture time
/// becomes the run's start plus its time on the timeline (exact, so truth
/// and messages line up). A source that falls more than [`MAX_SOURCE_LAG`]
/// behind (a simulator on a busy machine) is re-anchored, like a camera
/// dropping frames; otherwise its frames would all arrive stale.
struct Pacer {
    started: Instant,
    started_ns: u64,
    lag: Duration,
    first_ns: Option<u64>,
    /// Times the source fell behind and was re-anchored.
    late: u64,
}

const MAX_SOURCE_LAG: Duration = Duration::from_millis(100);

impl Pacer {
    fn start() -> Self {
        Self {
            started: Instant::now(),
            started_ns: unix_now_ns(),
            lag: Duration::ZERO,
            first_ns: None,
            late: 0,
        }
    }

    /// Sleeps until the frame at `timeline_ns` (the source's clock) is due;
    /// returns its capture time, ns since the Unix epoch.
    fn wait_until_due(&mut self, timeline_ns: u64, seq: u64) -> u64 {
        let first = *self.first_ns.get_or_insert(timeline_ns);
        let offset = Duration::from_nanos(timeline_ns.saturating_sub(first));
        let now = Instant::now();
        let due = self.started + offset + self.lag;
        if now > due + MAX_SOURCE_LAG {
            self.lag += now - due;
            self.late += 1;
            tracing::warn!(seq, "source behind its frame rate: timeline moved on");
        } else if let Some(wait) = due.checked_duration_since(now) {
            std::thread::sleep(wait);
        }
        self.started_ns + (offset + self.lag).as_nanos() as u64
    }

    /// Like [`Pacer::wait_until_due`] but the timeline never moves: `None`
    /// when the frame is more than [`MAX_SOURCE_LAG`] late (the caller drops
    /// it). For the closed loop, whose scenario clock must stay on the
    /// autopilot's (wall) clock.
    fn wait_until_due_or_drop(&mut self, timeline_ns: u64) -> Option<u64> {
        let first = *self.first_ns.get_or_insert(timeline_ns);
        let offset = Duration::from_nanos(timeline_ns.saturating_sub(first));
        let now = Instant::now();
        let due = self.started + offset;
        if now > due + MAX_SOURCE_LAG {
            return None;
        }
        if let Some(wait) = due.checked_duration_since(now) {
            std::thread::sleep(wait);
        }
        Some(self.started_ns + offset.as_nanos() as u64)
    }
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

/// The camera: `--camera` (the user's word wins, even over a log's or a
/// scenario's own), else the source's own, else `[camera] file`.
fn choose_camera(
    source: &dyn FrameSource,
    args: &RunArgs,
    config: &Config,
) -> Result<CameraModel, RunError> {
    if let Some(file) = &args.camera {
        return CameraModel::load(file).map_err(|e| RunError::Setup(e.to_string()));
    }
    if let Some(c) = source.camera() {
        return Ok(c);
    }
    let file = (!config.camera.file.as_os_str().is_empty())
        .then(|| config.camera.file.clone())
        .ok_or_else(|| {
            RunError::Setup(
                "this source has no camera of its own: give --camera or [camera] file".into(),
            )
        })?;
    CameraModel::load(&file).map_err(|e| RunError::Setup(e.to_string()))
}

/// The camera file [`choose_camera`] used, for the log's metadata.
fn camera_file_used(source: &dyn FrameSource, args: &RunArgs, config: &Config) -> String {
    if source.camera().is_some() {
        return "(the source's own camera, in /camera/calibration)".into();
    }
    args.camera
        .clone()
        .unwrap_or_else(|| config.camera.file.clone())
        .display()
        .to_string()
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

/// Makes the calling thread real-time (`[run] realtime_priority`, 0: off).
/// A refusal is a warning: the run goes on at normal priority.
fn realtime_if_asked(thread: &str, priority: u8) {
    if priority == 0 {
        return;
    }
    match crate::priority::make_this_thread_realtime(priority) {
        Ok(()) => tracing::info!("{thread} thread: SCHED_FIFO priority {priority}"),
        Err(e) => tracing::warn!("{thread} thread stays at normal priority: {e}"),
    }
}

/// The measurement thread: every frame it gets is measured, handed to the
/// link (latest-wins) and logged, and counted in `counts` (the run's summary
/// and its resource meters).
fn spawn_measurement(
    mut measurer: Measurer,
    mount: Mount,
    (link, clock): (LinkHandle, RunClock),
    log: LogHandle,
    counts: (Arc<Mutex<RunSummary>>, Arc<PipelineMeters>, Arc<Vitals>),
    handed_to_link: Option<std::sync::mpsc::Sender<u64>>,
    realtime_priority: u8,
) -> (SyncSender<Arc<Frame>>, std::thread::JoinHandle<()>) {
    let (counts, meters, vitals) = counts;
    // Capacity 1: at most one frame waits; a newer one finding it full is
    // skipped for measurement (still logged), so latency never builds up.
    let (tx, rx) = sync_channel::<Arc<Frame>>(1);
    let handle = std::thread::spawn(move || {
        realtime_if_asked("measurement", realtime_priority);
        let source_clock = clock.is_source();
        let mut handoff_timeouts = 0u64;
        for frame in rx {
            let m = Arc::new(measurer.measure(&frame));
            let measured_ns = unix_now_ns();
            // --fast: the source's clock reaches this frame as it goes to the
            // link, which is then waited for (module docs).
            clock.advance_to(frame.capture_time_ns);
            link.submit(Arc::clone(&m));
            let timed_out =
                source_clock && !link.wait_handled(frame.capture_time_ns, HANDOFF_TIMEOUT);
            if timed_out {
                handoff_timeouts += 1;
                if handoff_timeouts.is_power_of_two() {
                    tracing::warn!(
                        seq = frame.seq,
                        timeouts = handoff_timeouts,
                        "--fast: the link was not done with a frame within {HANDOFF_TIMEOUT:?}"
                    );
                }
            }
            if let Some(done) = &handed_to_link {
                let _ = done.send(frame.seq);
            }
            let mut record =
                serde_json::to_value(DetectionRecord::from_measurement(frame.seq.to_string(), &m))
                    .unwrap_or_default();
            // Latency stamps are wall-clock times from the capture on: not
            // on the source's clock.
            if !source_clock {
                record["latency_ns"] = serde_json::json!({
                    "captured": frame.capture_time_ns,
                    "measured": measured_ns,
                });
            }
            if let Ok(mut c) = counts.lock() {
                c.measured += 1;
                c.detected += u64::from(m.detection.is_some());
                c.link_handoff_timeouts += u64::from(timed_out);
            }
            vitals.measured.fetch_add(1, Ordering::Relaxed);
            if let Some(d) = &m.detection {
                vitals.detected.fetch_add(1, Ordering::Relaxed);
                vitals.set_range_m(d.position_body_m.norm());
            }
            log.measurement(m, record, &mount);
            meters.frame_measured();
        }
    });
    (tx, handle)
}

/// Longest a rendering source waits for the measurement of its last frame.
const MAX_YIELD: Duration = Duration::from_millis(20);

/// Waits (at most [`MAX_YIELD`]) until frame `seq` has been handed to the link.
fn wait_until_handed_to_link(handed: &std::sync::mpsc::Receiver<u64>, seq: u64) {
    let deadline = Instant::now() + MAX_YIELD;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match handed.recv_timeout(left) {
            Ok(done) if done >= seq => return,
            Ok(_) => {}
            Err(_) => return,
        }
    }
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
    let vehicle_pose = args.vehicle_pose.unwrap_or(config.run.vehicle_pose);
    let priority = config.run.realtime_priority;
    if priority > 99 {
        return Err(RunError::Setup(format!(
            "[run] realtime_priority = {priority}: 0 (off) or 1-99"
        )));
    }
    let mut frames_in = open_frames(&spec, vehicle_pose, args, &config)?;
    let camera = choose_camera(frames_in.source(), args, &config)?;
    if let Frames::Source(s) = &mut frames_in {
        s.expect_size(camera.width, camera.height);
    }
    // The first frame is read before anything starts (link, log files): a
    // calibration of another size is refused with exit status 2.
    let mut first_item = match &mut frames_in {
        Frames::Source(source) => source.next_frame(),
        Frames::ClosedLoop(_) => None,
    };
    match &first_item {
        Some(Ok(first)) => camera
            .check_frame_size(first.image.width(), first.image.height())
            .map_err(RunError::Setup)?,
        // A folder's images are refused by their headers.
        Some(Err(e)) if crate::image_io::is_size_mismatch(e) => {
            return Err(RunError::Setup(e.clone()));
        }
        _ => {}
    }
    // --fast runs on the source's clock (module docs); a camera's frames come
    // in real time whatever --fast says.
    let live = frames_in.source().live();
    if args.fast && live {
        tracing::warn!("--fast has no effect on a live camera: the run is on the wall clock");
    }
    let clock = if args.fast && !live {
        RunClock::source(match &first_item {
            Some(Ok(first)) => first.capture_time_ns,
            _ => 0,
        })
    } else {
        RunClock::wall()
    };
    let mut config = config;
    if let Some(m) = frames_in.source().mount() {
        config.mount = m;
    }
    let mount = Mount::from_config(&config.mount).map_err(RunError::Setup)?;
    let measurer =
        Measurer::new(camera.clone(), &config).map_err(|e| RunError::Setup(e.to_string()))?;

    // The link's thread is on the latency path too (it writes each pose).
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .on_thread_start(move || realtime_if_asked("link", priority))
        .enable_all()
        .build()
        .map_err(|e| RunError::Setup(format!("tokio runtime: {e}")))?;
    let link = Link::start_with_clock(
        &config.link,
        args.mavlink.as_deref(),
        rt.handle(),
        clock.clone(),
    )
    .map_err(|e| RunError::Setup(e.to_string()))?;
    let log_dir = args
        .log_dir
        .clone()
        .unwrap_or_else(|| config.log.dir.clone());
    let mut log_config = config.log.clone();
    log_config.set_drogue(config.drogue.inner_radius_m, config.drogue.canopy_radius_m);
    let log = FlightLog::start(&log_config, &log_dir, &camera)
        .map_err(|e| RunError::Setup(e.to_string()))?;
    log.set_clock(clock.clone());
    // --fast: nothing is live, so the log waits for room rather than drop.
    log.set_waiting(clock.is_source());
    log_layer_sink(&log);
    log.metadata(
        crate::log::metadata::RUN_METADATA,
        crate::log::metadata::run_metadata(
            &config,
            &crate::log::metadata::RunProvenance {
                source: spec_text.clone(),
                source_details: frames_in.source().provenance(),
                camera_file: camera_file_used(frames_in.source(), args, &config),
                mavlink: args
                    .mavlink
                    .clone()
                    .unwrap_or_else(|| config.link.connection.clone()),
                clock: if clock.is_source() { "source" } else { "wall" }.into(),
            },
        ),
    );
    tracing::info!(
        source = %spec_text,
        mavlink = %args.mavlink.as_deref().unwrap_or(&config.link.connection),
        camera = %camera.name,
        vehicle_pose = ?vehicle_pose,
        "run started"
    );

    let stop = Arc::new(AtomicBool::new(false));
    watch_signals(&rt, Arc::clone(&stop));

    // Link events (sent and received messages) go to the log; the capture →
    // send latency of each frame's first pose message is counted on the way.
    let events = link.events();
    let event_log = log.clone();
    let vitals = Arc::new(Vitals::default());
    let event_vitals = Arc::clone(&vitals);
    // Received messages wait while the log's queue is half full: camera
    // frames and measurements are never dropped for them (counted in the
    // link stats as unlogged_incoming).
    let busy_depth = (config.log.queue_len as u64).div_ceil(2);
    let events_done = Arc::new(AtomicBool::new(false));
    let events_done_flag = Arc::clone(&events_done);
    // (On the source's clock a send's time is its frame's capture time: no
    // latency to measure.)
    let measure_latency = !clock.is_source();
    let event_thread = std::thread::spawn(move || {
        let mut latency_ms = Histogram::default();
        let mut last_sent_capture = None;
        loop {
            match events.recv_timeout(Duration::from_millis(100)) {
                Some(ev) => {
                    if let (true, true, Some(captured)) =
                        (measure_latency, ev.outgoing, ev.capture_time_ns)
                        && last_sent_capture != Some(captured)
                    {
                        last_sent_capture = Some(captured);
                        let ms = ev.time_ns.saturating_sub(captured) as f64 * 1e-6;
                        latency_ms.add(ms);
                        event_vitals.set_latency_ms(ms.max(1e-6));
                    }
                    if !ev.outgoing && event_log.queue_depth() >= busy_depth {
                        events.skip_incoming();
                        continue;
                    }
                    event_log.mavlink(ev);
                }
                None if events_done_flag.load(Ordering::SeqCst) => break,
                None => {}
            }
        }
        latency_ms
    });

    let meters = Arc::new(PipelineMeters::default());
    let stats_thread = StatsThread::spawn(Arc::clone(&meters), log.clone(), link.events());
    let counts = Arc::new(Mutex::new(RunSummary::default()));
    // A source that renders its frames (the simulator) waits until the
    // measurement has handed the frame to the link before making the next:
    // on a small companion computer it would otherwise take a core from the
    // measurement right when latency matters, which a camera never does.
    let (handed_tx, handed_rx) = std::sync::mpsc::channel::<u64>();
    let yield_to_measurement = frames_in.source().renders_frames();
    let (frame_tx, measure_thread) = spawn_measurement(
        measurer,
        mount,
        (link.clone(), clock.clone()),
        log.clone(),
        (
            Arc::clone(&counts),
            Arc::clone(&meters),
            Arc::clone(&vitals),
        ),
        yield_to_measurement.then_some(handed_tx),
        config.run.realtime_priority,
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
            failure = Some(e);
            false
        }),
        Frames::Source(_) => true,
    };
    let paced = frames_in.source().recorded_timeline() && !args.fast;
    let status = StatusReporter::spawn(Arc::clone(&vitals), link.clone(), log_dir.clone());
    // This thread takes each frame from the source (a camera's dequeue, the
    // pacer's wake-up at a frame's due time) and hands it on.
    realtime_if_asked("capture", priority);
    let mut pacer = Pacer::start();
    let max_frames = args.max_frames.unwrap_or(u64::MAX);
    let (mut frames, mut skipped, mut unreadable) = (0u64, 0u64, 0u64);
    while go && frames < max_frames && !stop.load(Ordering::SeqCst) {
        // The source's own CPU (rendering, decoding) is counted apart from
        // the pipeline's.
        let item = meters.time_source(|| match &mut frames_in {
            Frames::Source(_) if first_item.is_some() => first_item.take(),
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
        vitals.frames.fetch_add(1, Ordering::Relaxed);
        let checked =
            item.and_then(|f| crate::image_io::check_frame_size(&f.image, &camera).map(|()| f));
        let mut frame = match checked {
            Ok(f) => f,
            Err(e) => {
                unreadable += 1;
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
        log.frame(Arc::clone(&frame));
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
                skipped += 1;
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
        Frames::ClosedLoop(cl) => cl.held_frames,
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

    let mut summary = counts.lock().map(|c| c.clone()).unwrap_or_default();
    summary.frames = frames;
    summary.skipped = skipped;
    summary.unreadable = unreadable;
    summary.source_late = late;
    summary.vehicle_pose_held = vehicle_pose_held;
    summary.interrupted = stop.load(Ordering::SeqCst);
    summary.log_files = log_summary.files;
    summary.link = Some(link_stats);
    summary.resources = resources;
    summary.latency_ms = latency_ms;
    summary.source_clock = clock.is_source();
    summary.log_dropped = log_summary.dropped_queue_full + log_summary.dropped_write_error;
    if skipped > 0 {
        tracing::warn!("{skipped} frames were not measured (measurement busy)");
    }
    if let Some(e) = failure {
        return Err(e);
    }
    Ok(summary)
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
        let link_line = self.link.as_ref().map_or_else(String::new, link_report);
        let mut held = if self.vehicle_pose_held > 0 {
            format!(
                ", {} rendered with a held autopilot pose (stale)",
                self.vehicle_pose_held
            )
        } else {
            String::new()
        };
        if self.link_handoff_timeouts > 0 {
            held.push_str(&format!(
                ", {} not handled by the link in time (--fast)",
                self.link_handoff_timeouts
            ));
        }
        let latency = if self.source_clock {
            "not measured with --fast (the run is on the source's clock)".to_string()
        } else if self.latency_ms.count() == 0 {
            "no pose sent".to_string()
        } else {
            format!(
                "p50 {:.2}  p95 {:.2}  p99 {:.2}  max {:.2} ms over {} poses",
                self.latency_ms.quantile(0.50),
                self.latency_ms.quantile(0.95),
                self.latency_ms.quantile(0.99),
                self.latency_ms.max(),
                self.latency_ms.count()
            )
        };
        let r = &self.resources;
        let resources_line = format!(
            "\ncapture → send: {latency}\nresources: pipeline CPU {:.1} % of one core (source {:.1} % \
             besides), peak resident memory {:.1} MB, log queue at most {} items",
            r.pipeline_cpu_pct,
            r.source_cpu_pct,
            r.peak_rss_bytes as f64 / 1e6,
            r.max_log_queue
        );
        format!(
            "run {}: {} frames, {} measured, {} detected ({rate:.1} %), {} skipped (measurement busy), \
             {} unreadable, source late {} times{held}{}{resources_line}\nlog: {}",
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
