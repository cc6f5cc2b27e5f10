//! Recovery of cut-short or damaged logs (a crash, a power cut, a full disk,
//! flipped bits): every message the input still holds is copied, streaming,
//! into a new complete, indexed MCAP file.
//!
//! The input is walked record by record here (not through the `mcap` crate's
//! message reader, which stops at the first problem), so that one damaged
//! chunk costs only that chunk:
//! - every chunk is decompressed (none, zstd, lz4) and its CRC checked;
//! - a chunk whose CRC fails, or that does not decompress, is *damaged*: its
//!   records are salvaged one by one where they parse, the rest are dropped
//!   and counted (the message index after the chunk says how many it held),
//!   and the damage is reported and recorded in the output as a
//!   `drogue_vision.recover` metadata record, so a copy never hides it;
//! - a record whose length runs past the end of the file is a cut, unless a
//!   valid chunk follows further on (a damaged length): then the bytes in
//!   between are skipped, counted and reported.
//!
//! The output is written to a temporary file beside it and renamed into
//! place only when complete; on any failure nothing is left behind. Before
//! the rename the output is read back with the `mcap` crate's own validating
//! reader and compared with what that reader gets from the input: recovery
//! refuses ([`LogError::Refused`]) to write fewer messages than the input
//! yields.

mod copy;
mod input;

use super::LogError;
use super::oversized::RECORD_LIMIT_BYTES;
use super::reader::{count_readable, is_complete};
use copy::{Copier, OUTPUT_OPTIONS, stream_chunk};
use input::{Input, Next, decompress, inner_records, read_up_to};
use mcap::records::{self, Record, op};
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::{BufReader, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Name of the metadata record that lists what a recovery found damaged.
pub const RECOVER_METADATA: &str = "drogue_vision.recover";

/// A chunk whose CRC failed or that did not decompress.
#[derive(Clone, Debug, PartialEq)]
pub struct DamagedChunk {
    /// Byte offset of the chunk record in the input.
    pub offset: u64,
    /// Log times the chunk header claims, ns.
    pub start_ns: u64,
    /// End of that span, ns.
    pub end_ns: u64,
    /// Why, in words: a CRC mismatch, a failed decompression, a broken record.
    pub reason: String,
    /// Messages copied from it (they parsed; their content is unverified).
    pub salvaged: u64,
    /// Messages its index lists that could not be read (None: no index).
    pub dropped: Option<u64>,
}

impl DamagedChunk {
    /// A chunk whose header was read: its offset and claimed times, and what
    /// was salvaged from it (`dropped` is filled in later from the index).
    fn from_header(
        offset: u64,
        header: &records::ChunkHeader,
        reason: String,
        salvaged: u64,
    ) -> Self {
        Self {
            offset,
            start_ns: header.message_start_time,
            end_ns: header.message_end_time,
            reason,
            salvaged,
            dropped: None,
        }
    }
}

/// What a recovery copied and what it found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecoverReport {
    /// Messages written to the output.
    pub messages: u64,
    /// Messages the `mcap` crate's validating reader reads from the input
    /// (the output has at least as many).
    pub readable_by_reader: u64,
    /// Why the input ended early (None: it was complete).
    pub cut: Option<String>,
    /// The chunks found damaged, in file order.
    pub damaged: Vec<DamagedChunk>,
    /// Bytes skipped between a damaged record and the next valid chunk.
    pub skipped_bytes: u64,
    /// Records that did not parse (outside damaged chunks too), dropped.
    pub unreadable_records: u64,
    /// Messages of channels whose channel record was lost, dropped.
    pub unknown_channel_messages: u64,
    /// Records above [`RECORD_LIMIT_BYTES`] (top-level, or inside a chunk),
    /// skipped and not held in memory.
    pub oversized_records: u64,
    /// Log time of the last message copied, ns.
    pub last_log_time_ns: Option<u64>,
}

impl RecoverReport {
    /// Messages known lost (damaged chunks' index counts, unknown channels,
    /// unparsable records).
    pub fn dropped(&self) -> u64 {
        self.damaged.iter().filter_map(|d| d.dropped).sum::<u64>() + self.unknown_channel_messages
    }
}

impl fmt::Display for RecoverReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} messages (the mcap reader reads {} from the input)",
            self.messages, self.readable_by_reader
        )?;
        match &self.cut {
            Some(c) => write!(f, "; the input was cut short: {c}")?,
            None => write!(f, "; the input was complete")?,
        }
        for d in &self.damaged {
            write!(
                f,
                "\nDAMAGED chunk at byte {} (log time {}..{} ns): {}; {} messages salvaged \
                 (content unverified), {} dropped",
                d.offset,
                d.start_ns,
                d.end_ns,
                d.reason,
                d.salvaged,
                d.dropped
                    .map_or_else(|| "an unknown number".into(), |n| n.to_string())
            )?;
        }
        if self.skipped_bytes > 0 {
            write!(
                f,
                "\nDAMAGED: {} unreadable bytes skipped",
                self.skipped_bytes
            )?;
        }
        if self.oversized_records > 0 {
            write!(
                f,
                "\nSKIPPED: {} records above the {} MiB record bound",
                self.oversized_records,
                RECORD_LIMIT_BYTES >> 20
            )?;
        }
        if self.unreadable_records > 0 || self.unknown_channel_messages > 0 {
            write!(
                f,
                "\nDAMAGED: {} records did not parse, {} messages of lost channels dropped",
                self.unreadable_records, self.unknown_channel_messages
            )?;
        }
        Ok(())
    }
}

/// Whether two paths name the same existing file (hard links, symlinks).
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Largest summary section read for its schemas and channels (they are a
/// few kB; the chunk indexes beside them grow with the log, about 150 bytes
/// a chunk).
const SUMMARY_LIMIT_BYTES: u64 = 64 << 20;

/// The schema and channel records (opcode, body) of the summary section of
/// the MCAP file `file` (`len` bytes), when it ends with a footer that
/// points to a summary whose CRC holds; none otherwise (a cut file, a
/// damaged summary).
fn summary_schemas_and_channels(file: &mut File, len: u64) -> Vec<(u8, Vec<u8>)> {
    // Footer record: opcode, length, summary start and offset start (u64
    // each), summary CRC (u32); then the closing magic.
    const FOOTER_FIELDS: u64 = 8 + 8 + 4;
    const TAIL: u64 = 1 + 8 + FOOTER_FIELDS + 8;
    let read_at = |file: &mut File, at: u64, n: u64| -> Option<Vec<u8>> {
        let mut buf = vec![0u8; usize::try_from(n).ok()?];
        file.seek(SeekFrom::Start(at)).ok()?;
        std::io::Read::read_exact(file, &mut buf).ok()?;
        Some(buf)
    };
    let Some(tail) = len.checked_sub(TAIL).and_then(|at| read_at(file, at, TAIL)) else {
        return Vec::new();
    };
    let u64_at = |b: &[u8], i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap_or([0; 8]));
    if tail[0] != op::FOOTER || &tail[tail.len() - 8..] != mcap::MAGIC {
        return Vec::new();
    }
    let (summary_start, offsets_start) = (u64_at(&tail, 9), u64_at(&tail, 17));
    let crc = u32::from_le_bytes(tail[25..29].try_into().unwrap_or([0; 4]));
    let footer_at = len - TAIL;
    let end = if offsets_start > 0 {
        offsets_start
    } else {
        footer_at
    };
    if summary_start == 0 || summary_start >= end || end > footer_at {
        return Vec::new();
    }
    // What is read (the summary, its offsets, up to the footer) is bounded,
    // whatever the footer claims.
    if footer_at - summary_start > SUMMARY_LIMIT_BYTES {
        return Vec::new();
    }
    let Some(summary) = read_at(file, summary_start, footer_at - summary_start) else {
        return Vec::new();
    };
    // The CRC runs from the summary's start to the footer's offset start.
    if crc != 0 {
        let mut h = crc32fast::Hasher::new();
        h.update(&summary);
        h.update(&tail[..25]);
        if h.finalize() != crc {
            return Vec::new();
        }
    }
    let mut records = Vec::new();
    let mut at = 0usize;
    let section = &summary[..usize::try_from(end - summary_start).unwrap_or(0)];
    while let Some(head) = section.get(at..at + 9) {
        let opcode = head[0];
        let Ok(n) = usize::try_from(u64_at(head, 1)) else {
            break;
        };
        let Some(body) = section.get(at + 9..(at + 9).saturating_add(n)) else {
            break;
        };
        if opcode == op::SCHEMA || opcode == op::CHANNEL {
            records.push((opcode, body.to_vec()));
        }
        at += 9 + n;
    }
    records
}

/// Copies every message `input` still holds into a new complete file
/// `output` (zstd chunks). Fails when `input` is missing or not an MCAP file
/// ([`LogError::Format`]), when `output` is the input or cannot be written
/// ([`LogError::Io`], [`LogError::Config`]), or when the copy would hold
/// fewer messages than the `mcap` crate reads from the input
/// ([`LogError::Refused`]). On failure no output file is left.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, LogError> {
    if input == output || same_file(input, output) {
        return Err(LogError::Config(format!(
            "the output {} is the input: recover never overwrites its input",
            output.display()
        )));
    }
    // A missing or foreign input is the input's fault (exit status 2).
    super::check_mcap_input(input)?;
    let file = File::open(input).map_err(|e| LogError::io(input, e))?;
    let len = file.metadata().map_err(|e| LogError::io(input, e))?.len();
    let mut src = Input {
        r: BufReader::with_capacity(1 << 20, file),
        pos: 0,
        len,
    };
    let mut magic = [0u8; 8];
    let got = read_up_to(&mut src.r, &mut magic).map_err(|e| LogError::io(input, e))?;
    if got < magic.len() || magic.as_slice() != mcap::MAGIC {
        return Err(LogError::format(input, "no MCAP magic at the start"));
    }
    src.pos = magic.len() as u64;

    let dir = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let tmp = tempfile::Builder::new()
        .prefix(".recovering-")
        .suffix(".mcap")
        .tempfile_in(dir)
        .map_err(|e| LogError::io(output, e))?;
    let handle = tmp
        .as_file()
        .try_clone()
        .map_err(|e| LogError::io(output, e))?;
    let options = OUTPUT_OPTIONS.clone();
    let out = mcap::Writer::with_options(BufWriter::with_capacity(1 << 20, handle), options)
        .map_err(|e| LogError::io(output, super::error_chain(&e)))?;
    let mut c = Copier {
        out,
        schemas: HashMap::new(),
        out_schema: HashMap::new(),
        channels: HashMap::new(),
        out_channel: HashMap::new(),
        report: RecoverReport::default(),
    };
    // A channel whose record a damaged chunk took with it is still known
    // from the summary, when the file has one: its messages in the other
    // chunks are kept.
    if let Ok(mut file) = File::open(input) {
        for (opcode, body) in summary_schemas_and_channels(&mut file, len) {
            c.record(opcode, &body)
                .map_err(|e| LogError::io(output, e))?;
        }
    }
    let out_err = |e: String| LogError::io(output, e);
    let mut footer_seen = false;
    // The damaged chunk whose message indexes are being counted.
    let mut counting: Option<usize> = None;
    loop {
        let next = src.next().map_err(|e| LogError::io(input, e))?;
        match next {
            Next::End => break,
            Next::Oversized => {
                c.report.oversized_records += 1;
                counting = None;
            }
            Next::LargeChunk {
                offset,
                header,
                end,
            } => {
                let (salvaged, problem) =
                    stream_chunk(&mut c, &header, &mut src.r).map_err(out_err)?;
                src.r
                    .seek(SeekFrom::Start(end))
                    .map_err(|e| LogError::io(input, e))?;
                src.pos = end;
                counting = None;
                if let Some(reason) = problem {
                    c.report
                        .damaged
                        .push(DamagedChunk::from_header(offset, &header, reason, salvaged));
                    counting = Some(c.report.damaged.len() - 1);
                }
            }
            Next::Short {
                offset,
                opcode,
                message,
            } => {
                let Some(at) = src.resync(offset + 1).map_err(|e| LogError::io(input, e))? else {
                    // The end of the file: a chunk the writer had begun
                    // gives up its complete records (no CRC to check yet:
                    // the writer writes it when the chunk closes).
                    let mut message = message;
                    if opcode == Some(op::CHUNK)
                        && let Some((_, _, plain)) = src
                            .partial_chunk(offset)
                            .map_err(|e| LogError::io(input, e))?
                    {
                        let mut n = 0;
                        for (o, b) in inner_records(&plain).0 {
                            if c.record(o, b).map_err(out_err)? {
                                n += 1;
                            }
                        }
                        message
                            .push_str(&format!("; {n} messages read from that unfinished chunk"));
                    }
                    c.report.cut = Some(message);
                    break;
                };
                c.report.skipped_bytes += at - offset;
                c.report.damaged.push(DamagedChunk {
                    offset,
                    start_ns: 0,
                    end_ns: 0,
                    reason: format!("{message}; the next valid chunk is at byte {at}"),
                    salvaged: 0,
                    dropped: None,
                });
                counting = None;
            }
            Next::Record {
                offset,
                opcode,
                body,
            } => match opcode {
                op::CHUNK => {
                    counting = None;
                    let Ok(Record::Chunk { header, data }) = mcap::parse_record(opcode, &body)
                    else {
                        c.report.unreadable_records += 1;
                        continue;
                    };
                    let (salvaged, problem) =
                        if header.uncompressed_size > RECORD_LIMIT_BYTES as u64 {
                            // It may hold records above the bound.
                            stream_chunk(&mut c, &header, &data[..]).map_err(out_err)?
                        } else {
                            let (plain, problem) = decompress(&header, &data);
                            let (records, _) = inner_records(&plain);
                            let mut salvaged = 0;
                            for (o, b) in records {
                                if c.record(o, b).map_err(out_err)? {
                                    salvaged += 1;
                                }
                            }
                            (salvaged, problem)
                        };
                    if let Some(reason) = problem {
                        c.report
                            .damaged
                            .push(DamagedChunk::from_header(offset, &header, reason, salvaged));
                        counting = Some(c.report.damaged.len() - 1);
                    }
                }
                op::MESSAGE_INDEX => {
                    if let Some(i) = counting
                        && let Ok(Record::MessageIndex(ix)) = mcap::parse_record(opcode, &body)
                    {
                        let d = &mut c.report.damaged[i];
                        d.dropped = Some(d.dropped.unwrap_or(0) + ix.records.len() as u64);
                    }
                }
                op::DATA_END | op::FOOTER => {
                    counting = None;
                    footer_seen |= opcode == op::FOOTER;
                    if opcode == op::DATA_END {
                        // The summary repeats schemas and channels: of use
                        // only where the data section lost them, so read on.
                    }
                }
                op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA | op::ATTACHMENT => {
                    counting = None;
                    if !footer_seen {
                        c.record(opcode, &body).map_err(out_err)?;
                    }
                }
                _ => {
                    counting = None;
                }
            },
        }
        if footer_seen {
            break;
        }
    }
    // Dropped = listed in the index but not salvaged.
    for d in &mut c.report.damaged {
        if let Some(n) = d.dropped {
            d.dropped = Some(n.saturating_sub(d.salvaged));
        }
    }
    if c.report.cut.is_none() && !footer_seen {
        c.report.cut = Some("the file ends without its footer (the writer never finished)".into());
    }
    if !c.report.damaged.is_empty()
        || c.report.skipped_bytes > 0
        || c.report.unreadable_records > 0
        || c.report.unknown_channel_messages > 0
        || c.report.oversized_records > 0
    {
        // The damage stays visible in the copy: review prints this record.
        let mut m = BTreeMap::new();
        m.insert("input".to_string(), input.display().to_string());
        m.insert("report".to_string(), c.report.to_string());
        c.out
            .write_metadata(&records::Metadata {
                name: RECOVER_METADATA.into(),
                metadata: m,
            })
            .map_err(|e| out_err(super::error_chain(&e)))?;
    }
    let mut report = c.report;
    let mut writer = c.out;
    writer
        .finish()
        .map_err(|e| out_err(super::error_chain(&e)))?;
    let mut inner = writer.into_inner();
    inner.flush().map_err(|e| LogError::io(output, e))?;
    inner
        .get_ref()
        .sync_all()
        .map_err(|e| LogError::io(output, e))?;
    drop(inner);

    // Read the copy back and compare with what the crate reads from the input.
    report.readable_by_reader = count_readable(input)?;
    let written = count_readable(tmp.path())?;
    if written != report.messages {
        return Err(LogError::Refused(format!(
            "the copy reads back {written} messages, {} were written; nothing written",
            report.messages
        )));
    }
    if written < report.readable_by_reader {
        return Err(LogError::Refused(format!(
            "the copy would hold {written} messages, fewer than the {} the input yields; \
             nothing written",
            report.readable_by_reader
        )));
    }
    tmp.persist(output)
        .map_err(|e| LogError::io(output, e.error))?;
    Ok(report)
}

/// Recovers every cut-short `*.mcap` in `dir` in place: the recovered file
/// takes the original name, the original is kept as `<name>.mcap.cut` (or
/// removed). A file that is not MCAP at all is renamed `<name>.mcap.bad` so it
/// is not tried again. Returns the recovered files. Problems with one file
/// are reported and do not stop the others or the start-up.
pub fn recover_dir(dir: &Path, keep_cut: bool) -> Result<Vec<PathBuf>, LogError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(LogError::io(dir, e)),
    };
    let mut candidates: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension().is_some_and(|x| x == "mcap")
                && !p
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with(".recovering-"))
        })
        .collect();
    candidates.sort();
    let mut recovered = Vec::new();
    for path in candidates {
        match is_complete(&path) {
            Ok(true) => continue,
            Ok(false) => {}
            Err(e) => {
                tracing::warn!("log recovery: {e}");
                continue;
            }
        }
        match recover_in_place(&path, keep_cut) {
            Ok(report) => {
                tracing::warn!("recovered the cut-short log {}: {report}", path.display());
                recovered.push(path);
            }
            Err(e) => tracing::error!("log recovery of {}: {e}", path.display()),
        }
    }
    Ok(recovered)
}

fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

fn recover_in_place(path: &Path, keep_cut: bool) -> Result<RecoverReport, LogError> {
    let tmp = with_suffix(path, ".recovering");
    let report = match recover(path, &tmp) {
        Ok(r) => r,
        Err(e) => {
            if matches!(e, LogError::Format { .. }) {
                let bad = with_suffix(path, ".bad");
                std::fs::rename(path, &bad).map_err(|e| LogError::io(path, e))?;
            }
            return Err(e);
        }
    };
    if keep_cut {
        std::fs::rename(path, with_suffix(path, ".cut")).map_err(|e| LogError::io(path, e))?;
    } else {
        std::fs::remove_file(path).map_err(|e| LogError::io(path, e))?;
    }
    std::fs::rename(&tmp, path).map_err(|e| LogError::io(&tmp, e))?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use std::sync::Arc;

    /// A small complete MCAP file with one schema and two channels, and a
    /// message on each.
    fn small_log(path: &Path) {
        let mut w = mcap::Writer::new(BufWriter::new(File::create(path).unwrap())).unwrap();
        let schema = Arc::new(mcap::Schema {
            id: 1,
            name: "s".into(),
            encoding: "jsonschema".into(),
            data: std::borrow::Cow::Borrowed(b"{}"),
        });
        for (id, topic) in [(1u16, "/a"), (2, "/b")] {
            let channel = Arc::new(mcap::Channel {
                id,
                topic: topic.into(),
                schema: Some(Arc::clone(&schema)),
                message_encoding: "json".into(),
                metadata: BTreeMap::new(),
            });
            w.write(&mcap::Message {
                channel,
                sequence: 0,
                log_time: 1,
                publish_time: 1,
                data: std::borrow::Cow::Borrowed(b"{}"),
            })
            .unwrap();
        }
        w.finish().unwrap();
    }

    #[test]
    fn the_summary_gives_its_schemas_and_channels_and_nothing_when_damaged() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("small.mcap");
        small_log(&path);
        let len = std::fs::metadata(&path).unwrap().len();
        let found = summary_schemas_and_channels(&mut File::open(&path).unwrap(), len);
        let opcodes: Vec<u8> = found.iter().map(|(o, _)| *o).collect();
        assert_eq!(opcodes, [op::SCHEMA, op::CHANNEL, op::CHANNEL]);
        // A byte of the summary changed: its CRC fails, nothing is taken.
        let mut bytes = std::fs::read(&path).unwrap();
        let summary_start = mcap::read::footer(&bytes).unwrap().summary_start as usize;
        bytes[summary_start + 12] ^= 0x20;
        let damaged = dir.path().join("damaged.mcap");
        std::fs::write(&damaged, &bytes).unwrap();
        let mut f = File::open(&damaged).unwrap();
        assert!(summary_schemas_and_channels(&mut f, len).is_empty());
        // Cut before its end: no footer, nothing.
        let cut = dir.path().join("cut.mcap");
        std::fs::write(&cut, &std::fs::read(&path).unwrap()[..len as usize - 5]).unwrap();
        let mut f = File::open(&cut).unwrap();
        assert!(summary_schemas_and_channels(&mut f, len - 5).is_empty());
    }
}
