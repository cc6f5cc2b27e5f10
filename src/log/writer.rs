//! The writer thread: drains the queue into MCAP files, closes a chunk and
//! syncs at least every `sync_interval_ms`, rotates by size and duration, and
//! survives write errors (reported, counted, retried with a new file).

use super::crop::{self, Crop, Cropper};
use super::send_stamps::{ReadyRecord, SendStamps, stamp};
use super::storage::{self, Storage, StorageFile};
use super::topics::{self, ChannelSpec};
use super::{
    Counters, ImageEncoding, Item, LogConfig, LogError, LogEvent, LogSummary, MeasurementItem,
};
use crate::camera::CameraModel;
use crate::frame::Frame;
use crate::link::LinkEvent;
use foxglove::messages::log::Level;
use mcap::records::MessageHeader;
use std::collections::HashMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// Record overhead per message (opcode, length, header, index entry): for
/// the size estimate that drives rotation.
const MESSAGE_OVERHEAD_BYTES: u64 = 40;
/// Reports kept for `/log` while no file is open (the first ones matter).
const MAX_PENDING_REPORTS: usize = 20;
/// Queue-full drops are reported at most this often.
const DROP_REPORT_INTERVAL: Duration = Duration::from_secs(5);

thread_local! {
    /// Set on the writer thread: its own tracing events must not come back
    /// through the queue (it writes them to `/log` itself).
    pub(crate) static ON_WRITER_THREAD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// One open MCAP file.
struct OpenFile {
    path: PathBuf,
    mcap: mcap::Writer<Box<dyn storage::WriteSeek>>,
    sync: Box<dyn FnMut() -> std::io::Result<()> + Send>,
    channels: HashMap<&'static str, u16>,
    opened: Instant,
    bytes: u64,
    /// Written since the last sync.
    dirty: bool,
}

pub(crate) struct Writer {
    cfg: LogConfig,
    dir: PathBuf,
    base: String,
    camera: CameraModel,
    storage: Box<dyn Storage>,
    counters: Arc<Counters>,
    file: Option<OpenFile>,
    next_part: u32,
    /// After an error: no new file before this.
    retry_at: Option<Instant>,
    summary: LogSummary,
    buf: Vec<u8>,
    /// Reports made while no file was open, for `/log` of the next file.
    pending_reports: Vec<LogEvent>,
    /// Queue-full drops already reported, and when.
    reported_dropped: u64,
    last_drop_report: Option<Instant>,
    /// Detection records waiting for their send stamp.
    send_stamps: SendStamps,
    /// The first file's exact path (`process --log OUT.mcap`); later parts
    /// are `<stem>_<part>.mcap` beside it.
    exact_path: Option<PathBuf>,
    /// Metadata records for every file of the run.
    metadata: Vec<mcap::records::Metadata>,
    /// PNG encoder buffers, reused frame to frame.
    png: super::png_gray::GrayPngEncoder,
    /// `image_encoding = "crop"`: frames waiting for their crop.
    cropper: Option<Cropper>,
}

impl Writer {
    pub(crate) fn new(
        cfg: LogConfig,
        dir: PathBuf,
        base: String,
        camera: CameraModel,
        storage: Box<dyn Storage>,
        counters: Arc<Counters>,
        recovered: Vec<PathBuf>,
    ) -> Self {
        let cropper = (cfg.image_encoding == ImageEncoding::Crop).then(|| {
            // validate() has checked the ratio is there.
            let scale = cfg.canopy_ratio.unwrap_or(1.0) * cfg.crop_margin;
            Cropper::new(scale, camera.clone())
        });
        Self {
            cropper,
            cfg,
            dir,
            base,
            camera,
            storage,
            counters,
            file: None,
            next_part: 0,
            retry_at: None,
            summary: LogSummary {
                recovered,
                ..Default::default()
            },
            buf: Vec::with_capacity(2 << 20),
            pending_reports: Vec::new(),
            reported_dropped: 0,
            last_drop_report: None,
            send_stamps: SendStamps::default(),
            exact_path: None,
            metadata: Vec::new(),
            png: Default::default(),
        }
    }

    /// Writes the first file to exactly `path`.
    pub(crate) fn set_exact_path(&mut self, path: PathBuf) {
        self.base = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "log".into());
        self.exact_path = Some(path);
    }

    pub(crate) fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
    }

    /// The next file's path.
    fn next_path(&self) -> PathBuf {
        match &self.exact_path {
            Some(p) if self.next_part == 0 => p.clone(),
            _ => storage::part_path(&self.dir, &self.base, self.next_part),
        }
    }

    /// Opens part 000; its failure stops the start-up (a bad log folder).
    pub(crate) fn open_first(&mut self) -> Result<(), LogError> {
        let path = self.next_path();
        let file = self.open(&path).map_err(|e| LogError::io(&path, e))?;
        self.file = Some(file);
        Ok(())
    }

    fn open(&mut self, path: &std::path::Path) -> Result<OpenFile, String> {
        let StorageFile { writer, sync } = self
            .storage
            .create(path)
            .map_err(|e| super::error_chain(&e))?;
        let options = mcap::WriteOptions::new()
            .compression(self.cfg.compression.to_mcap())
            .compression_level(self.cfg.compression_level)
            // Compress on this (background) thread only: the pipeline's
            // cores are not the log's.
            .compression_threads(0)
            .profile("")
            .library(concat!("drogue-vision ", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(self.cfg.chunk_size_kib.saturating_mul(1024)));
        let mcap = match mcap::Writer::with_options(writer, options).and_then(|mut m| {
            for record in &self.metadata {
                m.write_metadata(record)?;
            }
            Ok(m)
        }) {
            Ok(m) => m,
            Err(e) => {
                // Not even the header fits: leave no empty file behind.
                let _ = self.storage.remove(path);
                return Err(super::error_chain(&e));
            }
        };
        self.next_part += 1;
        self.summary.files.push(path.to_path_buf());
        Ok(OpenFile {
            path: path.to_path_buf(),
            mcap,
            sync,
            channels: HashMap::new(),
            opened: Instant::now(),
            bytes: 0,
            dirty: true,
        })
    }

    pub(crate) fn run(mut self, rx: Receiver<Item>) -> LogSummary {
        ON_WRITER_THREAD.with(|f| f.set(true));
        let interval = Duration::from_millis(self.cfg.sync_interval_ms);
        let mut next_sync = Instant::now() + interval;
        loop {
            let wake = self
                .send_stamps
                .next_deadline()
                .map_or(next_sync, |d| d.min(next_sync));
            let timeout = wake.saturating_duration_since(Instant::now());
            let item = match rx.recv_timeout(timeout) {
                Ok(item) => {
                    self.counters
                        .queued
                        .fetch_sub(1, std::sync::atomic::Ordering::Relaxed);
                    Some(item)
                }
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => break,
            };
            let expired = self.send_stamps.expired(Instant::now());
            self.write_detections(expired);
            match item {
                Some(Item::Finish(reply)) => {
                    self.drain_crops();
                    let held = self.send_stamps.drain();
                    self.write_detections(held);
                    self.close();
                    let _ = reply.send(self.summary.clone());
                    return self.summary;
                }
                Some(item) => {
                    self.handle(item);
                    self.rotate_if_due();
                }
                None => {}
            }
            if let Ok(t) = cpu_time::ThreadTime::try_now() {
                let ns = u64::try_from(t.as_duration().as_nanos()).unwrap_or(u64::MAX);
                self.counters
                    .writer_cpu_ns
                    .store(ns, std::sync::atomic::Ordering::Relaxed);
            }
            if Instant::now() >= next_sync {
                self.sync();
                self.rotate_if_due();
                self.report_drops();
                next_sync = Instant::now() + interval;
            }
        }
        // Every handle is gone without finish(): still close the file cleanly.
        self.drain_crops();
        let held = self.send_stamps.drain();
        self.write_detections(held);
        self.close();
        self.summary
    }

    fn handle(&mut self, item: Item) {
        match item {
            Item::Frame(frame, truth) => self.frame(&frame, truth.as_deref()),
            Item::Measurement(m) => self.measurement(*m),
            Item::Link(e) => self.link(&e),
            Item::Log(e) => self.write_log_event(&e),
            Item::Stats(record) => self.stats(&record),
            Item::Metadata(record) => self.write_metadata(*record),
            Item::Finish(_) => {}
        }
    }

    fn frame(&mut self, frame: &Arc<Frame>, truth: Option<&drogue_sim::FrameTruth>) {
        let t = frame.capture_time_ns;
        let seq = frame.seq;
        let mut buf = std::mem::take(&mut self.buf);
        // The crop mode keeps only every full_frame_every-th full frame.
        let full =
            self.cropper.is_none() || seq.is_multiple_of(u64::from(self.cfg.full_frame_every));
        let encoded = if full {
            topics::image(
                frame,
                self.cfg.image_encoding,
                self.cfg.jpeg_quality,
                &mut self.png,
                &mut buf,
            )
            .map(Some)
        } else {
            Ok(None)
        };
        match encoded {
            Ok(Some(())) => {
                if self.write(topics::IMAGE, seq, t, t, &buf) {
                    self.summary.frames += 1;
                }
            }
            Ok(None) => {}
            Err(e) => self.report(Level::Error, format!("frame {seq}: {e}")),
        }
        let cal = topics::calibration(&self.camera, t);
        self.write_proto(topics::CALIBRATION, seq, t, &cal, &mut buf);
        if let Some(truth) = truth {
            self.write_json(topics::SIM_TRUTH, seq, t, t, truth, &mut buf);
        }
        self.buf = buf;
        if let Some(cropper) = self.cropper.as_mut() {
            let crops = cropper.frame(Arc::clone(frame));
            self.write_crops(crops);
        }
    }

    /// `/camera/crop` (PNG) and `/camera/crop_info` of each crop.
    fn write_crops(&mut self, crops: Vec<Crop>) {
        let mut pixels = Vec::new();
        for c in crops {
            let (seq, t) = (c.frame.seq, c.frame.capture_time_ns);
            crop::crop_pixels(&c.frame, &c.rect, &mut pixels);
            let mut data = Vec::new();
            let mut buf = std::mem::take(&mut self.buf);
            let encoded = self
                .png
                .encode(&pixels, c.rect.width, c.rect.height, &mut data)
                .and_then(|()| topics::compressed(t, data, "png", &mut buf));
            match encoded {
                Ok(()) => {
                    if self.write(topics::CROP, seq, t, t, &buf) {
                        self.summary.crops += 1;
                    }
                    let (width, height) = c.frame.image.dimensions();
                    let info = serde_json::json!({
                        "seq": seq,
                        "x": c.rect.x,
                        "y": c.rect.y,
                        "width": c.rect.width,
                        "height": c.rect.height,
                        "image_width": width,
                        "image_height": height,
                        "around": c.basis,
                    });
                    self.write_json(topics::CROP_INFO, seq, t, t, &info, &mut buf);
                }
                Err(e) => self.report(Level::Error, format!("crop of frame {seq}: {e}")),
            }
            self.buf = buf;
        }
    }

    /// Crops of the frames still waiting (at the end).
    fn drain_crops(&mut self) {
        if let Some(cropper) = self.cropper.as_mut() {
            let crops = cropper.drain();
            self.write_crops(crops);
        }
    }

    fn measurement(&mut self, item: MeasurementItem) {
        let m = &item.measurement;
        let (seq, t) = (m.seq, m.capture_time_ns);
        if let Some(cropper) = self.cropper.as_mut() {
            let ellipse = m.detection.as_ref().map(|d| &d.ellipse_px);
            let crops = cropper.measurement(seq, t, ellipse);
            self.write_crops(crops);
        }
        let mut buf = std::mem::take(&mut self.buf);
        let ann = topics::annotations(m, &self.camera);
        self.write_proto(topics::ANNOTATIONS, seq, t, &ann, &mut buf);
        self.buf = buf;
        let record = ReadyRecord {
            seq,
            capture_time_ns: t,
            json: item.detection_json,
        };
        // Records with latency stamps (from `run`) of detected frames wait
        // for their pose to be sent; the rest are complete now.
        let stamped = record.json.get("latency_ns").is_some_and(|v| v.is_object());
        let ready = match (stamped, m.detection.is_some()) {
            (true, true) => self.send_stamps.hold(record, Instant::now()),
            // No detection, no pose message.
            (true, false) => vec![stamp(record, None)],
            (false, _) => vec![record],
        };
        self.write_detections(ready);
        let mut buf = std::mem::take(&mut self.buf);
        if let Some(d) = &m.detection {
            self.write_proto(topics::POSE, seq, t, &topics::pose(d, t), &mut buf);
        }
        let tf = topics::transforms(m, &item.mount);
        self.write_proto(topics::TF, seq, t, &tf, &mut buf);
        self.buf = buf;
    }

    /// `/drogue/detection` records, with `latency_ns.logged` stamped now.
    fn write_detections(&mut self, records: Vec<ReadyRecord>) {
        let mut buf = std::mem::take(&mut self.buf);
        for mut r in records {
            if let Some(latency) = r.json.get_mut("latency_ns").and_then(|v| v.as_object_mut()) {
                latency.insert("logged".into(), storage::now_ns().into());
            }
            let t = r.capture_time_ns;
            self.write_json(topics::DETECTION, r.seq, t, t, &r.json, &mut buf);
        }
        self.buf = buf;
    }

    /// Writes a metadata record now and into every later part.
    fn write_metadata(&mut self, record: mcap::records::Metadata) {
        if self.ensure_file()
            && let Some(file) = self.file.as_mut()
            && let Err(e) = file.mcap.write_metadata(&record)
        {
            let path = file.path.display().to_string();
            self.fail(format!(
                "writing metadata to {path}: {}",
                super::error_chain(&e)
            ));
        }
        self.metadata.push(record);
    }

    fn stats(&mut self, record: &serde_json::Value) {
        let t = record
            .get("time_ns")
            .and_then(|v| v.as_u64())
            .unwrap_or_else(|| self.counters.now_ns());
        let mut buf = std::mem::take(&mut self.buf);
        self.write_json(topics::STATS, 0, t, t, record, &mut buf);
        self.buf = buf;
    }

    fn link(&mut self, e: &LinkEvent) {
        let topic = if e.outgoing {
            topics::MAVLINK_OUT
        } else {
            topics::MAVLINK_IN
        };
        // Derived from a frame: stamped with its capture time (Foxglove lines
        // it up with the image); the send time is the publish time.
        let log_time = e.capture_time_ns.unwrap_or(e.time_ns);
        let mut buf = std::mem::take(&mut self.buf);
        self.write_json(topic, 0, log_time, e.time_ns, e, &mut buf);
        self.buf = buf;
        if let (true, Some(capture)) = (e.outgoing, e.capture_time_ns) {
            let ready = self.send_stamps.sent(capture, e.time_ns);
            self.write_detections(ready);
        }
    }

    fn write_log_event(&mut self, e: &LogEvent) {
        let mut buf = std::mem::take(&mut self.buf);
        let msg = topics::log_message(e);
        self.write_proto(topics::LOG, 0, e.time_ns, &msg, &mut buf);
        self.buf = buf;
    }

    fn write_proto<T: foxglove::Encode>(
        &mut self,
        topic: &'static str,
        seq: u64,
        time_ns: u64,
        msg: &T,
        buf: &mut Vec<u8>,
    ) {
        match topics::encode(msg, buf) {
            Ok(()) => {
                self.write(topic, seq, time_ns, time_ns, buf);
            }
            Err(e) => self.report(Level::Error, format!("{topic}: encoding: {e}")),
        }
    }

    fn write_json<T: serde::Serialize>(
        &mut self,
        topic: &'static str,
        seq: u64,
        log_time: u64,
        publish_time: u64,
        value: &T,
        buf: &mut Vec<u8>,
    ) {
        buf.clear();
        match serde_json::to_writer(&mut *buf, value) {
            Ok(()) => {
                self.write(topic, seq, log_time, publish_time, buf);
            }
            Err(e) => self.report(Level::Error, format!("{topic}: JSON: {e}")),
        }
    }

    /// Writes one message; on failure reports, abandons the file and drops.
    fn write(
        &mut self,
        topic: &'static str,
        seq: u64,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> bool {
        if !self.ensure_file() {
            self.summary.dropped_write_error += 1;
            return false;
        }
        let image = self.cfg.image_encoding;
        let Some(file) = self.file.as_mut() else {
            return false;
        };
        let result = (|| -> Result<(), String> {
            let channel_id = match file.channels.get(topic) {
                Some(&id) => id,
                None => {
                    let ChannelSpec {
                        schema,
                        message_encoding,
                    } = topics::channel_spec(topic, image)?;
                    let schema_id = file
                        .mcap
                        .add_schema(&schema.name, &schema.encoding, &schema.data)
                        .map_err(|e| super::error_chain(&e))?;
                    let id = file
                        .mcap
                        .add_channel(schema_id, topic, message_encoding, &Default::default())
                        .map_err(|e| super::error_chain(&e))?;
                    file.channels.insert(topic, id);
                    id
                }
            };
            let header = MessageHeader {
                channel_id,
                // Frame-derived topics carry the frame's sequence number
                // (replay restores Frame::seq from it).
                sequence: u32::try_from(seq).unwrap_or(u32::MAX),
                log_time,
                publish_time,
            };
            file.mcap
                .write_to_known_channel(&header, data)
                .map_err(|e| super::error_chain(&e))
        })();
        match result {
            Ok(()) => {
                file.bytes += data.len() as u64 + MESSAGE_OVERHEAD_BYTES;
                file.dirty = true;
                self.summary.messages += 1;
                true
            }
            Err(e) => {
                let path = file.path.display().to_string();
                self.fail(format!("writing {topic} to {path}: {e}"));
                self.summary.dropped_write_error += 1;
                false
            }
        }
    }

    /// A file to write to: the open one, or a new part once the retry time
    /// after an error has passed.
    fn ensure_file(&mut self) -> bool {
        if self.file.is_some() {
            return true;
        }
        if self.retry_at.is_some_and(|t| Instant::now() < t) {
            return false;
        }
        let path = self.next_path();
        match self.open(&path) {
            Ok(f) => {
                self.file = Some(f);
                self.retry_at = None;
                // What went wrong while no file was open goes to /log now.
                for event in std::mem::take(&mut self.pending_reports) {
                    self.write_log_event(&event);
                }
                self.file.is_some()
            }
            Err(e) => {
                // The part number is not used up by a failed open.
                self.fail(format!("opening {}: {e}", path.display()));
                false
            }
        }
    }

    /// A write, sync or open error: report it, abandon the file (what reached
    /// the disk stays readable and recoverable), retry later.
    fn fail(&mut self, message: String) {
        self.summary.write_errors += 1;
        if let Some(file) = self.file.take() {
            let (path, empty) = (file.path.clone(), file.bytes == 0);
            // Dropping the mcap writer tries to finish the file; after an I/O
            // error that fails quietly, which is fine: the file is recovered
            // at the next start-up.
            drop(file);
            if empty {
                // Not one message got in (a retry on a disk still full):
                // leave no empty file behind, and reuse its part number.
                let _ = self.storage.remove(&path);
                if self.summary.files.last() == Some(&path) {
                    self.summary.files.pop();
                    self.next_part -= 1;
                }
            }
        }
        self.retry_at = Some(Instant::now() + Duration::from_secs(self.cfg.retry_after_error_s));
        self.report(
            Level::Error,
            format!(
                "{message}; logging paused, retrying with a new file in {} s",
                self.cfg.retry_after_error_s
            ),
        );
    }

    /// Reports on the terminal (tracing) and, if a file is open, in `/log`.
    fn report(&mut self, level: Level, message: String) {
        match level {
            Level::Error | Level::Fatal => {
                tracing::error!(target: "drogue_vision::log", "{message}")
            }
            Level::Warning => tracing::warn!(target: "drogue_vision::log", "{message}"),
            _ => tracing::info!(target: "drogue_vision::log", "{message}"),
        }
        let event = LogEvent {
            time_ns: self.counters.now_ns(),
            level,
            message,
            name: "drogue_vision::log".into(),
            file: file!().into(),
            line: line!(),
        };
        if self.file.is_some() {
            self.write_log_event(&event);
        } else if self.pending_reports.len() < MAX_PENDING_REPORTS {
            self.pending_reports.push(event);
        }
    }

    /// Reports items dropped on a full queue since the last report (at most
    /// every DROP_REPORT_INTERVAL, so a slow disk does not flood `/log`).
    fn report_drops(&mut self) {
        let dropped = self
            .counters
            .dropped_queue_full
            .load(std::sync::atomic::Ordering::Relaxed);
        let due = self
            .last_drop_report
            .is_none_or(|t| t.elapsed() >= DROP_REPORT_INTERVAL);
        if dropped > self.reported_dropped && due {
            self.report(
                Level::Warning,
                format!(
                    "log queue full, the writer is behind: {} items dropped ({} in all)",
                    dropped - self.reported_dropped,
                    dropped
                ),
            );
            self.reported_dropped = dropped;
            self.last_drop_report = Some(Instant::now());
        }
    }

    /// Closes the chunk and makes the file durable.
    fn sync(&mut self) {
        let Some(file) = self.file.as_mut() else {
            return;
        };
        if !file.dirty {
            return;
        }
        let result = file
            .mcap
            .flush()
            .map_err(|e| super::error_chain(&e))
            .and_then(|()| (file.sync)().map_err(|e| super::error_chain(&e)));
        match result {
            Ok(()) => file.dirty = false,
            Err(e) => {
                let path = file.path.display().to_string();
                self.fail(format!("syncing {path}: {e}"));
            }
        }
    }

    fn rotate_if_due(&mut self) {
        let Some(file) = self.file.as_ref() else {
            return;
        };
        let by_size = self.cfg.rotate_size_mib > 0
            && file.bytes >= self.cfg.rotate_size_mib.saturating_mul(1 << 20);
        let by_time = self.cfg.rotate_duration_s > 0
            && file.opened.elapsed() >= Duration::from_secs(self.cfg.rotate_duration_s);
        if by_size || by_time {
            self.close();
            // The next item opens the next part.
        }
    }

    /// Writes the summary and index, syncs, closes.
    fn close(&mut self) {
        let Some(mut file) = self.file.take() else {
            return;
        };
        let dropped = self
            .counters
            .dropped_queue_full
            .load(std::sync::atomic::Ordering::Relaxed);
        if dropped > 0 || self.summary.dropped_write_error > 0 {
            self.file = Some(file);
            self.report(
                Level::Warning,
                format!(
                    "log items dropped so far: {dropped} (queue full), {} (write errors)",
                    self.summary.dropped_write_error
                ),
            );
            let Some(f) = self.file.take() else {
                return;
            };
            file = f;
        }
        let OpenFile {
            path,
            mut mcap,
            mut sync,
            ..
        } = file;
        let result = mcap
            .finish()
            .map(|_| ())
            .map_err(|e| super::error_chain(&e));
        // finish() leaves the footer in the write buffer: flush, then sync.
        let mut inner = mcap.into_inner();
        let result = result
            .and_then(|()| inner.flush().map_err(|e| super::error_chain(&e)))
            .and_then(|()| sync().map_err(|e| super::error_chain(&e)));
        if let Err(e) = result {
            self.fail(format!("closing {}: {e}", path.display()));
        }
    }
}
