//! MCAP flight log (ARCHITECTURE.md section 7).
//!
//! The caller hands frames, measurements, MAVLink traffic and tracing events to a
//! cheap, cloneable [`LogHandle`]; a dedicated writer thread behind a bounded
//! queue encodes them (Foxglove protobuf schemas, JSON for our own records) and
//! writes them with the plain `mcap` crate. The caller never waits for the disk:
//! a full queue drops the item and counts it; a write error is reported and the
//! writer retries with a new file later.
//!
//! Every message's log time is the frame's capture time when it comes from
//! a frame, else "now" on the run's clock ([`LogHandle::set_clock`]): the
//! wall clock, or with `run --fast` the source's, so that every topic of a
//! fast replay uses the source's capture time base and the log spans the
//! run's real length ([`crate::clock`]).
//!
//! `/camera/image` is PNG by default ([`png_gray`]); the opt-in long-flight
//! modes are JPEG ([`topics::jpeg`]) and full frames at a lower rate with a
//! crop around the drogue on every frame (`crop`).
//!
//! Also here: the `[log]` config ([`LogConfig`]), the message reader every
//! reader of a log uses ([`reader`]), start-up recovery and `recover`
//! ([`recover`]) and the post-flight review ([`review`]). Replay of
//! `/camera/image` is a frame source: `crate::source::replay`.

mod config;
pub(crate) mod crop;
mod error;
mod layer;
pub mod metadata;
pub mod oversized;
pub mod png_gray;
pub mod reader;
pub mod recover;
pub mod review;
mod send_stamps;
pub(crate) mod storage;
pub mod topics;
mod writer;

pub use config::{ChunkCompression, ImageEncoding, LogConfig};
pub(crate) use error::error_chain;
pub use error::{LogError, check_mcap_input};

use crate::camera::CameraModel;
use crate::frame::Frame;
use crate::link::LinkEvent;
use crate::measure::Measurement;
use crate::measure::mount::Mount;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

pub use layer::LogLayer;
pub use storage::{FileStorage, Storage, StorageFile};
pub use topics::MountTransforms;

/// What a finished log wrote.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LogSummary {
    /// Files written by this run, in order (several when rotated).
    pub files: Vec<PathBuf>,
    /// Cut-short files of an earlier run recovered at start-up.
    pub recovered: Vec<PathBuf>,
    /// Messages written, all topics.
    pub messages: u64,
    /// Frames written to `/camera/image`.
    pub frames: u64,
    /// Crops written to `/camera/crop` (`image_encoding = "crop"`).
    pub crops: u64,
    /// Items dropped because the queue was full (the writer fell behind).
    pub dropped_queue_full: u64,
    /// Items lost because no file could be written (write errors, disk full).
    pub dropped_write_error: u64,
    /// Write, sync or open errors reported.
    pub write_errors: u64,
}

/// One tracing event for `/log`.
#[derive(Clone, Debug)]
pub(crate) struct LogEvent {
    pub time_ns: u64,
    pub level: foxglove::messages::log::Level,
    pub message: String,
    pub name: String,
    pub file: String,
    pub line: u32,
}

/// A measured frame with what its topics need besides the measurement.
pub(crate) struct MeasurementItem {
    pub measurement: Arc<Measurement>,
    pub detection_json: serde_json::Value,
    pub mount: MountTransforms,
}

/// What the queue carries to the writer thread.
pub(crate) enum Item {
    /// A frame, with the simulator's truth of it when there is one.
    Frame(Arc<Frame>, Option<Box<drogue_sim::FrameTruth>>),
    Measurement(Box<MeasurementItem>),
    Link(Box<LinkEvent>),
    Log(Box<LogEvent>),
    /// A `/drogue/stats` record (the run's resource figures).
    Stats(Box<serde_json::Value>),
    /// An MCAP metadata record, written to this file and every later part.
    Metadata(Box<mcap::records::Metadata>),
    /// Flush, write the summary, close, and reply.
    Finish(mpsc::Sender<LogSummary>),
}

/// Counters shared by the handles and the writer thread.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    pub dropped_queue_full: AtomicU64,
    /// Items in the queue now (pushed, not yet taken by the writer).
    pub queued: AtomicU64,
    /// The clock of the log times not taken from a frame.
    pub clock: std::sync::RwLock<crate::clock::RunClock>,
    /// The writer thread's own CPU time so far, ns (encoding, compression,
    /// writing), so that a run can say what its log costs.
    pub writer_cpu_ns: AtomicU64,
}

impl Counters {
    /// Now on the log's clock.
    pub fn now_ns(&self) -> u64 {
        self.clock
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .now_ns()
    }
}

struct Shared {
    tx: SyncSender<Item>,
    /// Wait for room instead of dropping (offline `process --log`: nothing
    /// is live, and nothing may be lost).
    blocking: std::sync::atomic::AtomicBool,
    counters: Arc<Counters>,
    thread: Mutex<Option<JoinHandle<LogSummary>>>,
}

/// The caller's side of the log: cheap to clone, never blocks.
#[derive(Clone)]
pub struct LogHandle {
    shared: Arc<Shared>,
}

/// Starts flight logs.
pub struct FlightLog;

impl FlightLog {
    /// Opens a new file (named by start time) in `dir` and starts the writer
    /// thread. Recovers leftovers of an interrupted run found in `dir` first.
    pub fn start(cfg: &LogConfig, dir: &Path, camera: &CameraModel) -> Result<LogHandle, LogError> {
        cfg.validate()?;
        std::fs::create_dir_all(dir).map_err(|e| LogError::io(dir, e))?;
        Self::start_with_storage(cfg, dir, camera, Box::new(FileStorage))
    }

    /// An offline log written to exactly `path` (`process --log OUT.mcap`):
    /// no recovery of other files, no rotation, and a handle that waits for
    /// room in the queue instead of dropping, since nothing here is live.
    pub fn start_file(
        cfg: &LogConfig,
        path: &Path,
        camera: &CameraModel,
    ) -> Result<LogHandle, LogError> {
        let mut cfg = cfg.clone();
        cfg.rotate_size_mib = 0;
        cfg.rotate_duration_s = 0;
        cfg.recover_on_start = false;
        cfg.validate()?;
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| LogError::io(parent, e))?;
        }
        let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut w = writer::Writer::new(
            cfg.clone(),
            dir,
            String::new(),
            camera.clone(),
            Box::new(FileStorage),
            Arc::new(Counters::default()),
            Vec::new(),
        );
        w.set_exact_path(path.to_path_buf());
        Self::spawn(&cfg, w, true)
    }

    /// [`FlightLog::start`] writing through `storage` (tests inject failing
    /// storage here: disk full, I/O errors).
    pub fn start_with_storage(
        cfg: &LogConfig,
        dir: &Path,
        camera: &CameraModel,
        storage: Box<dyn Storage>,
    ) -> Result<LogHandle, LogError> {
        cfg.validate()?;
        let recovered = if cfg.recover_on_start {
            recover::recover_dir(dir, cfg.keep_cut_files)?
        } else {
            Vec::new()
        };
        let base = storage::run_base_name(dir, &cfg.file_prefix, storage::now_ns());
        let w = writer::Writer::new(
            cfg.clone(),
            dir.to_path_buf(),
            base,
            camera.clone(),
            storage,
            Arc::new(Counters::default()),
            recovered,
        );
        Self::spawn(cfg, w, false)
    }

    /// Opens the writer's first file (so a bad folder shows at start-up, not
    /// later) and starts its thread.
    fn spawn(
        cfg: &LogConfig,
        mut w: writer::Writer,
        blocking: bool,
    ) -> Result<LogHandle, LogError> {
        w.open_first()?;
        let counters = w.counters();
        let (tx, rx) = mpsc::sync_channel(cfg.queue_len);
        let thread = std::thread::Builder::new()
            .name("mcap-log".into())
            .spawn(move || {
                crate::priority::make_this_thread_background("log writer");
                w.run(rx)
            })
            .map_err(|e| LogError::Writer(format!("cannot start the writer thread: {e}")))?;
        Ok(LogHandle {
            shared: Arc::new(Shared {
                tx,
                blocking: blocking.into(),
                counters,
                thread: Mutex::new(Some(thread)),
            }),
        })
    }
}

impl LogHandle {
    /// Queues without waiting; a full queue drops the item and counts it.
    fn push(&self, item: Item) {
        let counters = &self.shared.counters;
        // Counted before the send: the writer may take the item at once.
        counters.queued.fetch_add(1, Ordering::Relaxed);
        let sent = if self.shared.blocking.load(Ordering::Relaxed) {
            self.shared.tx.send(item).is_ok()
        } else {
            match self.shared.tx.try_send(item) {
                Ok(()) => true,
                Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => false,
            }
        };
        if !sent {
            counters.queued.fetch_sub(1, Ordering::Relaxed);
            counters.dropped_queue_full.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Puts the log times not taken from a frame (`/log`, `/drogue/stats`
    /// without a time, the writer's own reports) on `clock` (default: the
    /// wall clock).
    pub fn set_clock(&self, clock: crate::clock::RunClock) {
        *self
            .shared
            .counters
            .clock
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = clock;
    }

    /// Wait for room in the queue instead of dropping (`run --fast`: nothing
    /// is live there, so nothing may be lost).
    pub fn set_waiting(&self, wait: bool) {
        self.shared.blocking.store(wait, Ordering::Relaxed);
    }

    /// Now on the log's clock (see [`LogHandle::set_clock`]).
    pub fn now_ns(&self) -> u64 {
        self.shared.counters.now_ns()
    }

    /// Items waiting in the queue for the writer now (for the run's
    /// statistics: a depth that keeps growing means the disk is too slow).
    pub fn queue_depth(&self) -> u64 {
        self.shared.counters.queued.load(Ordering::Relaxed)
    }

    /// CPU time the writer thread has used so far, ns (updated after each
    /// item it writes).
    pub fn writer_cpu_ns(&self) -> u64 {
        self.shared.counters.writer_cpu_ns.load(Ordering::Relaxed)
    }

    /// `/drogue/stats`: the run's resource figures (CPU, memory, queues);
    /// its `time_ns` field is the log time.
    pub fn stats(&self, record: serde_json::Value) {
        self.push(Item::Stats(Box::new(record)));
    }

    /// An MCAP metadata record (name, key/values) for this file and every
    /// later part of the run (`pipeline::provenance::run_metadata` builds the run's).
    /// Waits for room in the queue: it is sent once, at the start.
    pub fn metadata(&self, name: &str, values: std::collections::BTreeMap<String, String>) {
        let item = Item::Metadata(Box::new(mcap::records::Metadata {
            name: name.into(),
            metadata: values,
        }));
        let counters = &self.shared.counters;
        counters.queued.fetch_add(1, Ordering::Relaxed);
        if self.shared.tx.send(item).is_err() {
            counters.queued.fetch_sub(1, Ordering::Relaxed);
        }
    }

    /// Items dropped so far because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.shared
            .counters
            .dropped_queue_full
            .load(Ordering::Relaxed)
    }

    /// `/camera/image` and `/camera/calibration`.
    pub fn frame(&self, frame: Arc<Frame>) {
        self.push(Item::Frame(frame, None));
    }

    /// [`LogHandle::frame`] and `/sim/truth`, the simulator's truth of the
    /// frame, logged at the frame's capture time.
    pub fn frame_with_truth(&self, frame: Arc<Frame>, truth: Option<Box<drogue_sim::FrameTruth>>) {
        self.push(Item::Frame(frame, truth));
    }

    /// `/drogue/annotations`, `/drogue/detection` (the given JSON: the
    /// DetectionRecord plus the caller's timings/latency stamps),
    /// `/drogue/pose` (when detected), `/tf`.
    pub fn measurement(
        &self,
        m: Arc<Measurement>,
        detection_json: serde_json::Value,
        mount: &Mount,
    ) {
        self.measurement_with_transforms(m, detection_json, MountTransforms::from_mount(mount));
    }

    /// [`LogHandle::measurement`] with the mount given as plain transforms.
    pub fn measurement_with_transforms(
        &self,
        m: Arc<Measurement>,
        detection_json: serde_json::Value,
        mount: MountTransforms,
    ) {
        self.push(Item::Measurement(Box::new(MeasurementItem {
            measurement: m,
            detection_json,
            mount,
        })));
    }

    /// `/mavlink/out` (outgoing) or `/mavlink/in`.
    pub fn mavlink(&self, event: LinkEvent) {
        self.push(Item::Link(Box::new(event)));
    }

    /// A tracing Layer that writes events to `/log` (foxglove.Log).
    pub fn tracing_layer(&self) -> LogLayer {
        LogLayer::new(self.clone())
    }

    pub(crate) fn log_event(&self, event: LogEvent) {
        self.push(Item::Log(Box::new(event)));
    }

    /// Flushes, writes the summary/index, closes; returns paths written and
    /// counts. Waits for the queue to drain. Other clones of the handle stay
    /// usable but their items are dropped (and counted) from here on.
    pub fn finish(self) -> Result<LogSummary, LogError> {
        let (reply_tx, reply_rx) = mpsc::channel();
        let sent = self.shared.tx.send(Item::Finish(reply_tx)).is_ok();
        let reply = if sent { reply_rx.recv().ok() } else { None };
        let thread = self
            .shared
            .thread
            .lock()
            .map_err(|_| LogError::Writer("writer state poisoned".into()))?
            .take();
        let joined = match thread {
            Some(t) => Some(
                t.join()
                    .map_err(|_| LogError::Writer("the writer thread panicked".into()))?,
            ),
            None => None,
        };
        let mut summary = reply
            .or(joined)
            .ok_or_else(|| LogError::Writer("the log was already finished".into()))?;
        summary.dropped_queue_full = self.dropped();
        Ok(summary)
    }
}
