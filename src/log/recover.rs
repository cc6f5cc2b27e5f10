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

use super::LogError;
use super::oversized::{ChunkContent, Oversized, RECORD_LIMIT_BYTES, SkipOversized, walk_chunk};
use mcap::records::{self, MessageHeader, Record, op};
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Name of the metadata record that lists what a recovery found damaged.
pub const RECOVER_METADATA: &str = "drogue_vision.recover";

/// A chunk whose CRC failed or that did not decompress.
#[derive(Clone, Debug, PartialEq)]
pub struct DamagedChunk {
    /// Byte offset of the chunk record in the input.
    pub offset: u64,
    /// Log times the chunk header claims, ns.
    pub start_ns: u64,
    pub end_ns: u64,
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

/// Reader options shared by every reader of our logs: bounded records and
/// chunk CRCs checked.
pub fn reader_options() -> mcap::sans_io::LinearReaderOptions {
    mcap::sans_io::LinearReaderOptions::default()
        .with_record_length_limit(RECORD_LIMIT_BYTES)
        .with_validate_chunk_crcs(true)
}

/// The message reader of our logs: the `mcap` crate's linear reader over
/// the file with its records above [`RECORD_LIMIT_BYTES`] left out, and the
/// crate's channel bookkeeping, as the crate's own message reader does, but
/// parsing only the records it uses (schemas, channels, messages): the
/// crate's `parse_record` (0.26) panics on an attachment record without
/// room for its CRC (a slice index past the end; found by the `mcap_reader`
/// fuzz target), and replay never needs attachments or the other records.
pub struct LogMessageReader {
    source: SkipOversized<BufReader<File>>,
    reader: mcap::sans_io::LinearReader,
    channels: mcap::read::ChannelAccumulator<'static>,
    past_data_end: bool,
    done: bool,
}

impl LogMessageReader {
    fn next_inner(&mut self) -> Option<mcap::McapResult<mcap::Message<'static>>> {
        use mcap::sans_io::LinearReadEvent;
        loop {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(e) => return Some(Err(e)),
            };
            let (opcode, data) = match event {
                LinearReadEvent::ReadRequest(n) => {
                    match self.source.read(self.reader.insert(n)) {
                        Ok(got) => self.reader.notify_read(got),
                        Err(e) => return Some(Err(e.into())),
                    }
                    continue;
                }
                LinearReadEvent::Record { opcode, data } => (opcode, data),
            };
            // The summary repeats schemas and channels: read on to the end
            // magic (checked by the linear reader) without them.
            if opcode == op::DATA_END {
                self.past_data_end = true;
            }
            if self.past_data_end || !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
                continue;
            }
            let record = match mcap::parse_record(opcode, data) {
                Ok(r) => r,
                Err(e) => return Some(Err(e)),
            };
            match record {
                Record::Schema { header, data } => {
                    let data = std::borrow::Cow::Owned(data.into_owned());
                    if let Err(e) = self.channels.add_schema(header, data) {
                        return Some(Err(e));
                    }
                }
                Record::Channel(channel) => {
                    if let Err(e) = self.channels.add_channel(channel) {
                        return Some(Err(e));
                    }
                }
                Record::Message { header, data } => {
                    let Some(channel) = self.channels.get(header.channel_id) else {
                        return Some(Err(mcap::McapError::UnknownChannel(
                            header.sequence,
                            header.channel_id,
                        )));
                    };
                    return Some(Ok(mcap::Message {
                        channel,
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: std::borrow::Cow::Owned(data.into_owned()),
                    }));
                }
                _ => {}
            }
        }
    }
}

impl Iterator for LogMessageReader {
    type Item = mcap::McapResult<mcap::Message<'static>>;

    /// The next message; after an error or the end, None.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.next_inner();
        if !matches!(item, Some(Ok(_))) {
            self.done = true;
        }
        item
    }
}

/// A streaming message reader for our logs (also cut-short ones): reads
/// uncompressed, zstd and lz4 chunks and unchunked files, checks chunk CRCs,
/// skips top-level records above the bound ([`super::oversized`]).
pub fn message_reader(path: &Path) -> Result<LogMessageReader, LogError> {
    Ok(counted_message_reader(path)?.0)
}

/// [`message_reader`], with the live count of the records it skipped.
pub fn counted_message_reader(path: &Path) -> Result<(LogMessageReader, Arc<Oversized>), LogError> {
    let file = File::open(path).map_err(|e| LogError::io(path, e))?;
    let len = file.metadata().map_err(|e| LogError::io(path, e))?.len();
    let source = SkipOversized::new(BufReader::with_capacity(1 << 20, file), len);
    let skipped = source.skipped();
    Ok((
        LogMessageReader {
            source,
            reader: mcap::sans_io::LinearReader::new_with_options(reader_options()),
            channels: Default::default(),
            past_data_end: false,
            done: false,
        },
        skipped,
    ))
}

/// Whether a reader error means the file ends early (a crash), as opposed
/// to damage or something this reader does not support.
pub fn is_cut_short(e: &mcap::McapError) -> bool {
    match e {
        mcap::McapError::UnexpectedEof => true,
        mcap::McapError::Io(io) => io.kind() == std::io::ErrorKind::UnexpectedEof,
        _ => false,
    }
}

/// Says what a reader error means for the user: cut short, or damaged.
pub fn describe_read_error(e: &mcap::McapError) -> String {
    let text = super::error_chain(e);
    if is_cut_short(e) {
        format!("cut short: {text}")
    } else {
        format!("damaged or unreadable: {text}")
    }
}

/// Whether the file ends with the MCAP end magic (was finished properly).
pub fn is_complete(path: &Path) -> Result<bool, LogError> {
    let mut f = File::open(path).map_err(|e| LogError::io(path, e))?;
    let len = f.metadata().map_err(|e| LogError::io(path, e))?.len();
    let magic_len = mcap::MAGIC.len() as u64;
    if len < 2 * magic_len {
        return Ok(false);
    }
    let mut tail = [0u8; 8];
    f.seek(SeekFrom::End(-(magic_len as i64)))
        .and_then(|_| f.read_exact(&mut tail))
        .map_err(|e| LogError::io(path, e))?;
    Ok(tail.as_slice() == mcap::MAGIC)
}

/// Messages the `mcap` crate's validating reader reads from `path` before
/// its first error.
pub fn count_readable(path: &Path) -> Result<u64, LogError> {
    let mut n = 0;
    for m in message_reader(path)? {
        if m.is_err() {
            break;
        }
        n += 1;
    }
    Ok(n)
}

/// Whether two paths name the same existing file (hard links, symlinks).
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// A top-level record of the input.
enum Next {
    Record {
        offset: u64,
        opcode: u8,
        body: Vec<u8>,
    },
    /// A record above [`RECORD_LIMIT_BYTES`] that fits the file: passed
    /// over unread.
    Oversized,
    /// A chunk above [`RECORD_LIMIT_BYTES`] that fits the file, its header
    /// read: the reader is at its compressed records, to be streamed.
    LargeChunk {
        offset: u64,
        header: records::ChunkHeader,
        /// Where the chunk record ends.
        end: u64,
    },
    /// Clean end of the file at a record boundary.
    End,
    /// A record header or body runs past the end of the file.
    Short {
        offset: u64,
        opcode: Option<u8>,
        message: String,
    },
}

/// The input, read record by record with its position tracked.
struct Input {
    r: BufReader<File>,
    pos: u64,
    len: u64,
}

impl Input {
    fn next(&mut self) -> std::io::Result<Next> {
        let offset = self.pos;
        let mut head = [0u8; 9];
        let got = read_up_to(&mut self.r, &mut head)?;
        self.pos += got as u64;
        if got == 0 {
            return Ok(Next::End);
        }
        if got < head.len() {
            return Ok(Next::Short {
                offset,
                opcode: None,
                message: format!("a record header at byte {offset} is cut off"),
            });
        }
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0; 8]));
        let remaining = self.len.saturating_sub(self.pos);
        if len > RECORD_LIMIT_BYTES as u64 && len <= remaining && opcode != op::CHUNK {
            // Seeks over it.
            self.r
                .seek_relative(i64::try_from(len).unwrap_or(i64::MAX))?;
            self.pos += len;
            return Ok(Next::Oversized);
        }
        if len > RECORD_LIMIT_BYTES as u64 && len <= remaining && opcode == op::CHUNK {
            // Streamed when its header is sound; otherwise it goes the way
            // of damage (looked past for the next valid chunk).
            if let Some(header) = self.large_chunk_header(len)? {
                return Ok(Next::LargeChunk {
                    offset,
                    header,
                    end: offset + 9 + len,
                });
            }
            self.r.seek(SeekFrom::Start(self.pos))?;
        }
        if len > remaining || len > RECORD_LIMIT_BYTES as u64 {
            return Ok(Next::Short {
                offset,
                opcode: Some(opcode),
                message: format!(
                    "the record at byte {offset} (opcode {opcode:#04x}) claims {len} bytes, \
                     {remaining} remain"
                ),
            });
        }
        let mut body = vec![0u8; len as usize];
        self.r.read_exact(&mut body)?;
        self.pos += len;
        Ok(Next::Record {
            offset,
            opcode,
            body,
        })
    }

    /// The header of a chunk record of `len` bytes whose head was just
    /// read, when it is sound (its compressed records within the chunk);
    /// the reader is then at those records. None: not sound, the reader
    /// anywhere.
    fn large_chunk_header(&mut self, len: u64) -> std::io::Result<Option<records::ChunkHeader>> {
        // start, end, uncompressed size, CRC, compression name length.
        let mut fixed = [0u8; 32];
        if read_up_to(&mut self.r, &mut fixed)? < fixed.len() {
            return Ok(None);
        }
        let u64_at = |i: usize| u64::from_le_bytes(fixed[i..i + 8].try_into().unwrap_or([0; 8]));
        let name_len = u32::from_le_bytes(fixed[28..32].try_into().unwrap_or([0; 4])) as usize;
        if name_len > 16 {
            return Ok(None);
        }
        let mut name = vec![0u8; name_len + 8];
        if read_up_to(&mut self.r, &mut name)? < name.len() {
            return Ok(None);
        }
        let compressed = u64::from_le_bytes(name[name_len..].try_into().unwrap_or([0; 8]));
        let header_len = (32 + name_len + 8) as u64;
        if compressed > len - header_len {
            return Ok(None);
        }
        Ok(Some(records::ChunkHeader {
            message_start_time: u64_at(0),
            message_end_time: u64_at(8),
            uncompressed_size: u64_at(16),
            uncompressed_crc: u32::from_le_bytes(fixed[24..28].try_into().unwrap_or([0; 4])),
            compression: String::from_utf8_lossy(&name[..name_len]).into_owned(),
            compressed_size: compressed,
        }))
    }

    /// Looks for the next chunk whose header parses and whose CRC holds,
    /// after `from`; leaves the reader at it. Returns its offset.
    fn resync(&mut self, from: u64) -> std::io::Result<Option<u64>> {
        const WINDOW: usize = 1 << 20;
        let mut base = from;
        // No larger than what is left to look at (zeroing a whole window
        // for a small file was a tenth of the time of recovering it).
        let left = usize::try_from(self.len.saturating_sub(from)).unwrap_or(usize::MAX);
        let mut buf = vec![0u8; WINDOW.min(left)];
        while base < self.len {
            self.r.seek(SeekFrom::Start(base))?;
            let n = read_up_to(&mut self.r, &mut buf)?;
            if n < 9 {
                break;
            }
            // Candidates whose 9-byte head lies in this window; the last 8
            // bytes are looked at again at the start of the next one.
            let mut found = None;
            let mut from = 0;
            while let Some(k) = find_byte(&buf[from..n - 8], op::CHUNK) {
                let i = from + k;
                from = i + 1;
                let at = base + i as u64;
                let len = u64::from_le_bytes(buf[i + 1..i + 9].try_into().unwrap_or([0; 8]));
                if plausible_chunk_len(len, at, self.len) && self.chunk_at(at)? {
                    found = Some(at);
                    break;
                }
            }
            if let Some(at) = found {
                self.r.seek(SeekFrom::Start(at))?;
                self.pos = at;
                return Ok(Some(at));
            }
            base += (n - 8) as u64;
        }
        self.pos = self.len;
        Ok(None)
    }

    /// The records of a chunk cut off by the end of the file (its length
    /// and CRC are still the writer's placeholders): its data decompressed
    /// as far as it goes. None when not even its header is there.
    fn partial_chunk(&mut self, at: u64) -> std::io::Result<Option<(u64, u64, Vec<u8>)>> {
        self.r.seek(SeekFrom::Start(at + 9))?;
        let avail = self
            .len
            .saturating_sub(at + 9)
            .min(RECORD_LIMIT_BYTES as u64);
        let mut body = vec![0u8; avail as usize];
        self.r.read_exact(&mut body)?;
        // start, end, uncompressed size, crc, compression (u32 length +
        // bytes), compressed size, then the data.
        let u64_at = |b: &[u8], i: usize| -> Option<u64> {
            Some(u64::from_le_bytes(b.get(i..i + 8)?.try_into().ok()?))
        };
        let (Some(start), Some(end)) = (u64_at(&body, 0), u64_at(&body, 8)) else {
            return Ok(None);
        };
        let Some(name_len) = body
            .get(28..32)
            .and_then(|b| b.try_into().ok())
            .map(|b: [u8; 4]| u32::from_le_bytes(b) as usize)
        else {
            return Ok(None);
        };
        let data_at = 32 + name_len + 8;
        let (Some(name), Some(data)) = (body.get(32..32 + name_len), body.get(data_at..)) else {
            return Ok(None);
        };
        let header = records::ChunkHeader {
            message_start_time: start,
            message_end_time: end,
            uncompressed_size: u64::MAX,
            uncompressed_crc: 0,
            compression: String::from_utf8_lossy(name).into_owned(),
            compressed_size: data.len() as u64,
        };
        let (plain, _) = decompress(&header, data);
        Ok(Some((start, end, plain)))
    }

    /// Whether a complete chunk with a valid CRC starts at `at`.
    fn chunk_at(&mut self, at: u64) -> std::io::Result<bool> {
        self.r.seek(SeekFrom::Start(at))?;
        let mut head = [0u8; 9];
        if read_up_to(&mut self.r, &mut head)? < 9 {
            return Ok(false);
        }
        let len = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0; 8]));
        if !plausible_chunk_len(len, at, self.len) {
            return Ok(false);
        }
        let mut body = vec![0u8; len as usize];
        self.r.read_exact(&mut body)?;
        match mcap::parse_record(op::CHUNK, &body) {
            Ok(Record::Chunk { header, data }) => {
                let (_, problem) = decompress(&header, &data);
                Ok(problem.is_none() && header.uncompressed_crc != 0)
            }
            _ => Ok(false),
        }
    }
}

/// Whether an attachment record's body has room for its CRC after its
/// header and data length (or is too short for those, which `parse_record`
/// reports as an error): the `mcap` crate's `parse_record` (0.26) slices
/// such a body at its length less 4 without a check, a panic when less
/// than 4 bytes follow (found by the `mcap_reader` fuzz target).
fn attachment_has_its_crc(body: &[u8]) -> bool {
    // log time, create time, name, media type, data length.
    let string_end = |at: usize| -> Option<usize> {
        let n = u32::from_le_bytes(body.get(at..at + 4)?.try_into().ok()?) as usize;
        (at + 4).checked_add(n)
    };
    let Some(after_name) = string_end(16) else {
        return true;
    };
    let Some(header_end) = string_end(after_name).and_then(|e| e.checked_add(8)) else {
        return true;
    };
    // A header running past the body is the parser's error to report.
    header_end > body.len() || body.len() - header_end >= 4
}

/// Where the first `byte` is in `hay`: std's `memchr` (a word at a time), by
/// way of `BufRead::skip_until`, where a loop over the bytes makes a compare
/// per byte (most of the time of recovering a damaged file went there).
fn find_byte(hay: &[u8], byte: u8) -> Option<usize> {
    use std::io::BufRead;
    let mut rest = hay;
    let n = rest.skip_until(byte).ok()?;
    // Through the byte when found; otherwise to the end, where no byte is it.
    (n > 0 && hay[n - 1] == byte).then(|| n - 1)
}

/// Whether a chunk of `len` bytes at `at` fits the file (a chunk header is
/// at least 8+8+8+4+4+8 bytes).
fn plausible_chunk_len(len: u64, at: u64, file_len: u64) -> bool {
    (40..=RECORD_LIMIT_BYTES as u64).contains(&len)
        && at.saturating_add(9).saturating_add(len) <= file_len
}

/// Reads until `buf` is full or the end of the input; returns bytes read.
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// A chunk's records: decompressed as far as possible, and what is wrong
/// with it (None: size and CRC check out).
fn decompress(header: &records::ChunkHeader, data: &[u8]) -> (Vec<u8>, Option<String>) {
    let expected = usize::try_from(header.uncompressed_size)
        .unwrap_or(usize::MAX)
        .min(RECORD_LIMIT_BYTES);
    let mut out = Vec::with_capacity(expected);
    let result = match header.compression.as_str() {
        "" => {
            out.extend_from_slice(data);
            Ok(())
        }
        "zstd" => zstd::stream::read::Decoder::new(data).and_then(|d| {
            d.take(RECORD_LIMIT_BYTES as u64 + 1)
                .read_to_end(&mut out)
                .map(|_| ())
        }),
        "lz4" => lz4::Decoder::new(data).and_then(|d| {
            d.take(RECORD_LIMIT_BYTES as u64 + 1)
                .read_to_end(&mut out)
                .map(|_| ())
        }),
        other => return (out, Some(format!("unsupported compression {other:?}"))),
    };
    if let Err(e) = result {
        return (out, Some(format!("does not decompress: {e}")));
    }
    if out.len() as u64 != header.uncompressed_size {
        let n = out.len();
        return (
            out,
            Some(format!(
                "decompresses to {n} bytes, its header says {}",
                header.uncompressed_size
            )),
        );
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&out);
        if crc != header.uncompressed_crc {
            return (
                out,
                Some(format!(
                    "CRC {crc:08X}, its header says {:08X}",
                    header.uncompressed_crc
                )),
            );
        }
    }
    (out, None)
}

/// The records of a chunk's body, one by one; stops where a length runs
/// past the end. Yields (opcode, body) and counts what did not fit.
fn inner_records(data: &[u8]) -> (Vec<(u8, &[u8])>, bool) {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < data.len() {
        if data.len() - pos < 9 {
            return (out, false);
        }
        let opcode = data[pos];
        let len = u64::from_le_bytes(data[pos + 1..pos + 9].try_into().unwrap_or([0; 8]));
        let start = pos + 9;
        let Some(end) = usize::try_from(len)
            .ok()
            .and_then(|l| start.checked_add(l))
            .filter(|&e| e <= data.len())
        else {
            return (out, false);
        };
        out.push((opcode, &data[start..end]));
        pos = end;
    }
    (out, true)
}

/// The records of a chunk that may hold records above the bound (its
/// uncompressed size is above it), streamed from its `compressed` records:
/// each record within the bound is copied, each above it read and dropped in
/// small pieces and counted. Returns the messages copied and what is wrong
/// with the chunk (None: size and CRC check out).
fn stream_chunk<W: Write + Seek>(
    c: &mut Copier<W>,
    header: &records::ChunkHeader,
    compressed: impl Read,
) -> Result<(u64, Option<String>), String> {
    let content = match ChunkContent::new(&header.compression, compressed, header.compressed_size) {
        Ok(Some(content)) => content,
        Ok(None) => {
            let name = &header.compression;
            return Ok((0, Some(format!("unsupported compression {name:?}"))));
        }
        Err(e) => return Ok((0, Some(format!("does not decompress: {e}")))),
    };
    let mut salvaged = 0;
    let mut each = |opcode: u8, body: &[u8]| -> Result<(), String> {
        if c.record(opcode, body)? {
            salvaged += 1;
        }
        Ok(())
    };
    let walk = walk_chunk(
        content,
        header.uncompressed_size,
        header.uncompressed_crc,
        Some(&mut each),
    )?;
    c.report.oversized_records += walk.oversized.len() as u64;
    Ok((salvaged, walk.problem))
}

/// The copy in progress: channel and schema ids of the input mapped to the
/// output's.
struct Copier<W: Write + Seek> {
    out: mcap::Writer<W>,
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    out_schema: HashMap<u16, u16>,
    channels: HashMap<u16, records::Channel>,
    out_channel: HashMap<u16, u16>,
    report: RecoverReport,
}

impl<W: Write + Seek> Copier<W> {
    /// Handles one record (top level or inside a chunk); returns whether it
    /// was a message written.
    fn record(&mut self, opcode: u8, body: &[u8]) -> Result<bool, String> {
        if opcode == op::ATTACHMENT && !attachment_has_its_crc(body) {
            self.report.unreadable_records += 1;
            return Ok(false);
        }
        let record = match mcap::parse_record(opcode, body) {
            Ok(r) => r,
            Err(_) => {
                self.report.unreadable_records += 1;
                return Ok(false);
            }
        };
        match record {
            Record::Schema { header, data } => {
                self.schemas
                    .insert(header.id, (header.name, header.encoding, data.into_owned()));
            }
            Record::Channel(c) => {
                self.channels.insert(c.id, c);
            }
            Record::Message { header, data } => return self.message(header, &data),
            Record::Metadata(m) if m.name != RECOVER_METADATA => {
                self.out
                    .write_metadata(&m)
                    .map_err(|e| super::error_chain(&e))?;
            }
            Record::Attachment { header, data, .. } => {
                self.out
                    .attach(&mcap::Attachment {
                        log_time: header.log_time,
                        create_time: header.create_time,
                        name: header.name,
                        media_type: header.media_type,
                        data,
                    })
                    .map_err(|e| super::error_chain(&e))?;
            }
            _ => {}
        }
        Ok(false)
    }

    fn message(&mut self, header: MessageHeader, data: &[u8]) -> Result<bool, String> {
        let Some(channel_id) = self.output_channel(header.channel_id)? else {
            self.report.unknown_channel_messages += 1;
            return Ok(false);
        };
        self.out
            .write_to_known_channel(
                &MessageHeader {
                    channel_id,
                    ..header
                },
                data,
            )
            .map_err(|e| super::error_chain(&e))?;
        self.report.messages += 1;
        self.report.last_log_time_ns = Some(header.log_time);
        Ok(true)
    }

    /// The output channel of an input channel id (added on first use).
    fn output_channel(&mut self, id: u16) -> Result<Option<u16>, String> {
        if let Some(&c) = self.out_channel.get(&id) {
            return Ok(Some(c));
        }
        let Some(channel) = self.channels.get(&id).cloned() else {
            return Ok(None);
        };
        let schema_id = if channel.schema_id == 0 {
            0
        } else {
            match self.out_schema.get(&channel.schema_id) {
                Some(&s) => s,
                None => {
                    let Some((name, encoding, data)) = self.schemas.get(&channel.schema_id) else {
                        return Ok(None);
                    };
                    let s = self
                        .out
                        .add_schema(name, encoding, data)
                        .map_err(|e| super::error_chain(&e))?;
                    self.out_schema.insert(channel.schema_id, s);
                    s
                }
            }
        };
        let c = self
            .out
            .add_channel(
                schema_id,
                &channel.topic,
                &channel.message_encoding,
                &channel.metadata,
            )
            .map_err(|e| super::error_chain(&e))?;
        self.out_channel.insert(id, c);
        Ok(Some(c))
    }
}

/// The output's write options, made once: `WriteOptions::new` counts the
/// machine's physical cores by reading `/proc/cpuinfo` (for a default this
/// overrides), which was a tenth of the time of recovering a small file.
static OUTPUT_OPTIONS: std::sync::LazyLock<mcap::WriteOptions> = std::sync::LazyLock::new(|| {
    mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(1)
        .compression_threads(0)
        .profile("")
        .library(concat!(
            "drogue-vision ",
            env!("CARGO_PKG_VERSION"),
            " recover"
        ))
});

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
    use super::find_byte;

    #[test]
    fn find_byte_finds_the_first_one_or_none() {
        assert_eq!(find_byte(b"", 6), None);
        assert_eq!(find_byte(&[1, 2, 3], 6), None);
        assert_eq!(find_byte(&[6], 6), Some(0));
        assert_eq!(find_byte(&[1, 6, 6], 6), Some(1));
        assert_eq!(find_byte(&[1, 2, 6], 6), Some(2));
        let mut long = vec![0u8; 1000];
        long[777] = 6;
        long[999] = 6;
        assert_eq!(find_byte(&long, 6), Some(777));
    }
}
