//! The writer's files: opening one (channels, metadata), writing a record
//! to it, syncing, rotating by size and duration, closing; and what the
//! writer does when that fails (report, count, retry with a new file after
//! a pause). Apart from the per-item encoding in `writer.rs`, so the failure
//! policy is in one place.

use super::super::storage::{self, StorageFile};
use super::super::topics::{self, ChannelSpec};
use super::super::{LogError, LogEvent};
use super::Writer;
use foxglove::messages::log::Level;
use mcap::records::MessageHeader;
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Record overhead per message (opcode, length, header, index entry): for
/// the size estimate that drives rotation.
pub(super) const MESSAGE_OVERHEAD_BYTES: u64 = 40;
/// Reports kept for `/log` while no file is open (the first ones matter).
pub(super) const MAX_PENDING_REPORTS: usize = 20;
/// Queue-full drops are reported at most this often.
pub(super) const DROP_REPORT_INTERVAL: Duration = Duration::from_secs(5);

/// One open MCAP file.
pub(super) struct OpenFile {
    pub(super) path: PathBuf,
    pub(super) mcap: mcap::Writer<Box<dyn storage::WriteSeek>>,
    pub(super) sync: Box<dyn FnMut() -> std::io::Result<()> + Send>,
    pub(super) channels: HashMap<&'static str, u16>,
    pub(super) opened: Instant,
    pub(super) bytes: u64,
    /// Written since the last sync.
    pub(super) dirty: bool,
}

impl Writer {
    /// The next file's path.
    pub(super) fn next_path(&self) -> PathBuf {
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

    pub(super) fn open(&mut self, path: &std::path::Path) -> Result<OpenFile, String> {
        let StorageFile { writer, sync } = self
            .storage
            .create(path)
            .map_err(|e| super::super::error_chain(&e))?;
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
                return Err(super::super::error_chain(&e));
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

    pub(super) fn write_proto<T: foxglove::Encode>(
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

    pub(super) fn write_json<T: serde::Serialize>(
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
    pub(super) fn write(
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
                        .map_err(|e| super::super::error_chain(&e))?;
                    let id = file
                        .mcap
                        .add_channel(schema_id, topic, message_encoding, &Default::default())
                        .map_err(|e| super::super::error_chain(&e))?;
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
                .map_err(|e| super::super::error_chain(&e))
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
    pub(super) fn ensure_file(&mut self) -> bool {
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
    pub(super) fn fail(&mut self, message: String) {
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
    pub(super) fn report(&mut self, level: Level, message: String) {
        match level {
            Level::Error | Level::Fatal => {
                tracing::error!(target: "drogue_vision::log", "{message}");
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
    pub(super) fn report_drops(&mut self) {
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
    pub(super) fn sync(&mut self) {
        let Some(file) = self.file.as_mut() else {
            return;
        };
        if !file.dirty {
            return;
        }
        let result = file
            .mcap
            .flush()
            .map_err(|e| super::super::error_chain(&e))
            .and_then(|()| (file.sync)().map_err(|e| super::super::error_chain(&e)));
        match result {
            Ok(()) => file.dirty = false,
            Err(e) => {
                let path = file.path.display().to_string();
                self.fail(format!("syncing {path}: {e}"));
            }
        }
    }

    pub(super) fn rotate_if_due(&mut self) {
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
    pub(super) fn close(&mut self) {
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
            .map_err(|e| super::super::error_chain(&e));
        // finish() leaves the footer in the write buffer: flush, then sync.
        let mut inner = mcap.into_inner();
        let result = result
            .and_then(|()| inner.flush().map_err(|e| super::super::error_chain(&e)))
            .and_then(|()| sync().map_err(|e| super::super::error_chain(&e)));
        if let Err(e) = result {
            self.fail(format!("closing {}: {e}", path.display()));
        }
    }
}
