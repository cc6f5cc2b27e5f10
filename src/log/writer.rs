//! The writer thread: drains the queue into MCAP files, closes a chunk and
//! syncs at least every `sync_interval_ms`, rotates by size and duration, and
//! survives write errors (reported, counted, retried with a new file).
//! Here: the thread's loop and how each queued item becomes records; the
//! files under it and the failure policy: `writer/files.rs`.

use super::crop::{self, Crop, Cropper};
use super::send_stamps::{ReadyRecord, SendStamps, stamp};
use super::storage::{self, Storage};
use super::topics;
use super::{Counters, ImageEncoding, Item, LogConfig, LogEvent, LogSummary, MeasurementItem};
use crate::camera::CameraModel;
use crate::frame::Frame;
use crate::link::LinkEvent;
use foxglove::messages::log::Level;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

mod files;

use files::OpenFile;

thread_local! {
    /// Set on the writer thread: its own tracing events must not come back
    /// through the queue (it writes them to `/log` itself).
    pub(crate) static ON_WRITER_THREAD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
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
            .map_or_else(|| "log".into(), |s| s.to_string_lossy().into_owned());
        self.exact_path = Some(path);
    }

    pub(crate) fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
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
        let stamped = record
            .json
            .get("latency_ns")
            .is_some_and(serde_json::Value::is_object);
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
            .and_then(serde_json::Value::as_u64)
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
}
