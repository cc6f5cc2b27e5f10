//! MCAP records above the record bound ([`RECORD_LIMIT_BYTES`]), skipped
//! and counted before the `mcap` crate's reader sees them.
//!
//! The crate's reader refuses a record above its length limit with an error
//! and reads nothing after it. A log can hold one such record between good
//! ones (a hostile or broken writer), so [`SkipOversized`] sits between the
//! file and that reader: it walks the top-level record framing (opcode, u64
//! length), passes every record within the bound through unchanged, and
//! seeks over a record above it without reading its bytes into memory. What
//! it skipped is counted in a shared [`Oversized`] for the caller to report.
//!
//! Only whole top-level records that fit the file are skipped: a length
//! running past the end of the file is a cut or damage and goes through, for
//! the reader to report. The footer's end magic and anything after it go
//! through unchanged.
//!
//! Chunks go through unchanged (the reader streams them record by record)
//! unless they can hold a record above the bound: a chunk whose records
//! decompress to more than the bound and that fits the file is first walked
//! once, streaming (`walk_chunk`: decompressed into a small buffer, every
//! record's bytes hashed and dropped, none held). When that walk finds
//! records above the bound, checks the chunk's CRC and size, the chunk is
//! handed to the reader as an uncompressed chunk of its other records,
//! decompressed a second time as the reader reads it, with a CRC of what it
//! now holds; the records above the bound are dropped on the way and
//! counted. A chunk whose walk finds damage (a CRC, a record running past
//! its end, no decompression) goes through unchanged, for the reader to
//! report as before. Only chunks that large cost the second pass; a log of
//! ours never has one.
//!
//! Inside an uncompressed chunk it also checks that each record ends within
//! the chunk's records, and ends the reading with an error where one does
//! not: the `mcap` crate's reader (0.26) subtracts such a length from its
//! count of the chunk's bytes without a check (found by the `mcap_reader`
//! fuzz target: an overflow panic where overflow is checked, and otherwise
//! the bytes after the chunk read as records of it).
//!
//! Skipping changes the bytes the data-section CRC covers, so readers fed
//! through this must leave that check off (the `mcap` default; chunk CRCs
//! are still checked).

use mcap::records::op;
use std::io::{self, Read, Seek, SeekFrom};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

mod chunk;
mod filtered;

pub(crate) use chunk::{ChunkContent, walk_chunk};
use filtered::Filtered;

/// Largest record the reader accepts: a raw mono8 frame of 5792x5792, far
/// above any camera this runs with. A top-level record above it that fits
/// the file is skipped without being read into memory, and counted (replay:
/// this module; recover: [`super::recover::RecoverReport::oversized_records`]); a
/// length beyond it that runs past the end of the file is a cut, reported
/// before anything is allocated for it (a 109-byte file claiming a 400 MiB
/// record costs nothing). So replay and recover stay within a few frames'
/// worth of memory.
pub const RECORD_LIMIT_BYTES: usize = 32 << 20;

/// What a [`SkipOversized`] skipped so far (shared with its owner's caller).
#[derive(Debug, Default)]
pub struct Oversized {
    records: AtomicU64,
    bytes: AtomicU64,
}

impl Oversized {
    /// Records skipped.
    pub fn records(&self) -> u64 {
        self.records.load(Ordering::Relaxed)
    }
    /// Their bytes (bodies, without the 9-byte record heads).
    pub fn bytes(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }
}

/// What follows a run of bytes passed through.
#[derive(Clone, Copy, Debug)]
enum After {
    /// The next top-level record head.
    Head,
    /// The next record inside an uncompressed chunk: `records` bytes of
    /// the chunk's records left, then `tail` bytes to the chunk's end.
    Inner { records: u64, tail: u64 },
}

/// Where the walk over the file is.
#[derive(Clone, Copy, Debug)]
enum State {
    /// The file's start magic.
    Magic,
    /// At a record head.
    Head,
    /// Passing `left` bytes through, then `then`.
    Pass { left: u64, then: After },
    /// Handing out the records of a chunk that held records above the
    /// bound, less those ([`Filtered`]).
    Filtered,
    /// After the footer, a cut or a length the reader is to report: all
    /// the rest as it is.
    Rest,
}

/// A reader of an MCAP file that leaves out records above
/// [`RECORD_LIMIT_BYTES`] (see the module docs).
pub struct SkipOversized<R: Read> {
    /// The file; None while a [`Filtered`] chunk has it.
    inner: Option<R>,
    len: u64,
    /// Bytes of the file after the position of `inner`.
    remaining: u64,
    state: State,
    /// Bytes read ahead (record heads, chunk headers), to hand out first.
    pending: Vec<u8>,
    pending_at: usize,
    filtered: Option<Filtered<R>>,
    skipped: Arc<Oversized>,
}

/// Fixed part of a chunk header: start, end, uncompressed size, CRC,
/// compression name length.
const CHUNK_FIXED: usize = 8 + 8 + 8 + 4 + 4;
/// Longest compression name looked at (the known ones are 3 or 4 bytes).
const MAX_COMPRESSION_NAME: u32 = 16;

impl<R: Read + Seek> SkipOversized<R> {
    /// Wraps `inner`, positioned at the start of a file of `len` bytes.
    pub fn new(inner: R, len: u64) -> Self {
        Self {
            inner: Some(inner),
            len,
            remaining: len,
            state: State::Magic,
            pending: Vec::with_capacity(64),
            pending_at: 0,
            filtered: None,
            skipped: Arc::default(),
        }
    }

    /// The count of what was skipped, live while reading.
    pub fn skipped(&self) -> Arc<Oversized> {
        Arc::clone(&self.skipped)
    }

    fn inner(&mut self) -> io::Result<&mut R> {
        self.inner
            .as_mut()
            .ok_or_else(|| io::Error::other("the MCAP file was lost in a chunk's decompression"))
    }

    /// Reads up to `n` bytes onto the end of `pending`; returns how many.
    fn read_ahead(&mut self, n: usize) -> io::Result<usize> {
        let from = self.pending.len();
        self.pending.resize(from + n, 0);
        let inner = self
            .inner
            .as_mut()
            .ok_or_else(|| io::Error::other("no file"))?;
        let got = read_up_to(inner, &mut self.pending[from..])?;
        self.pending.truncate(from + got);
        self.remaining = self.remaining.saturating_sub(got as u64);
        Ok(got)
    }

    /// Moves the walk on by one step, reading ahead into `pending` what is
    /// to be handed out next.
    fn step(&mut self) -> io::Result<()> {
        self.pending.clear();
        self.pending_at = 0;
        match self.state {
            State::Magic => {
                self.read_ahead(mcap::MAGIC.len())?;
                self.state = State::Head;
            }
            State::Head => loop {
                if self.read_ahead(9)? < 9 {
                    // The end, or a head cut short: the reader says which.
                    self.state = State::Rest;
                    return Ok(());
                }
                let opcode = self.pending[0];
                let len = u64_at(&self.pending, 1);
                if len > RECORD_LIMIT_BYTES as u64 && opcode != op::CHUNK && len <= self.remaining {
                    let skip = i64::try_from(len).map_err(io::Error::other)?;
                    self.inner()?.seek(SeekFrom::Current(skip))?;
                    self.remaining -= len;
                    self.skipped.records.fetch_add(1, Ordering::Relaxed);
                    self.skipped.bytes.fetch_add(len, Ordering::Relaxed);
                    self.pending.clear();
                    continue;
                }
                if opcode == op::CHUNK {
                    // Also when its length runs past the end: the reader
                    // streams a chunk, and reads its records up to the cut.
                    return self.chunk_header(len);
                }
                self.state = if opcode == op::FOOTER || len > self.remaining {
                    // The end magic follows the footer; a length past the
                    // end is the reader's to report.
                    State::Rest
                } else {
                    State::Pass {
                        left: len,
                        then: After::Head,
                    }
                };
                return Ok(());
            },
            State::Pass { .. } | State::Filtered | State::Rest => {}
        }
        Ok(())
    }

    /// Reads a chunk's header ahead after its head (in `pending`), for a
    /// chunk record of `body` bytes; decides how its records go through.
    fn chunk_header(&mut self, body: u64) -> io::Result<()> {
        const FIXED: u64 = CHUNK_FIXED as u64;
        let pass_all = |left: u64| State::Pass {
            left,
            then: After::Head,
        };
        if body < FIXED + 8 || self.read_ahead(CHUNK_FIXED)? < CHUNK_FIXED {
            self.state = State::Rest;
            return Ok(());
        }
        let size = u64_at(&self.pending, 9 + 16);
        let name_len = u32_at(&self.pending, 9 + 28);
        if name_len != 0 {
            let rest = body - FIXED;
            if size <= RECORD_LIMIT_BYTES as u64
                || name_len > MAX_COMPRESSION_NAME
                || rest > self.remaining
                || rest < u64::from(name_len) + 8
            {
                self.state = pass_all(rest);
                return Ok(());
            }
            // Large enough to hold a record above the bound.
            let n = name_len as usize + 8;
            if self.read_ahead(n)? < n {
                self.state = State::Rest;
                return Ok(());
            }
            let data = rest - n as u64;
            let compressed = u64_at(&self.pending, 9 + CHUNK_FIXED + name_len as usize);
            let name =
                String::from_utf8_lossy(&self.pending[9 + CHUNK_FIXED..][..name_len as usize])
                    .into_owned();
            if compressed <= data && self.filter(&name, compressed, data)? {
                return Ok(());
            }
            self.state = pass_all(data);
            return Ok(());
        }
        if self.read_ahead(8)? < 8 {
            self.state = State::Rest;
            return Ok(());
        }
        let records = u64_at(&self.pending, 9 + CHUNK_FIXED);
        let data = body - FIXED - 8;
        let Some(tail) = data.checked_sub(records) else {
            // The reader refuses a size past the chunk's end.
            self.state = pass_all(data);
            return Ok(());
        };
        if records > RECORD_LIMIT_BYTES as u64
            && data <= self.remaining
            && self.filter("", records, data)?
        {
            return Ok(());
        }
        self.state = State::Pass {
            left: 0,
            then: After::Inner { records, tail },
        };
        Ok(())
    }

    /// The next record inside an uncompressed chunk: its head is read ahead
    /// and must leave the record within the chunk's records. (The `mcap`
    /// crate's reader does not check this: its count of the chunk's bytes
    /// left would wrap around, and it would read what follows the chunk as
    /// records of the chunk.)
    fn inner_head(&mut self, records: u64, tail: u64) -> io::Result<()> {
        self.pending.clear();
        self.pending_at = 0;
        if records == 0 {
            self.state = State::Pass {
                left: tail,
                then: After::Head,
            };
            return Ok(());
        }
        let past_end = || {
            io::Error::new(
                io::ErrorKind::InvalidData,
                "a record inside a chunk runs past the end of the chunk's records",
            )
        };
        if records < 9 {
            return Err(past_end());
        }
        if self.read_ahead(9)? < 9 {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the file ends inside a chunk",
            ));
        }
        let len = u64_at(&self.pending, 1);
        if len > records - 9 {
            return Err(past_end());
        }
        self.state = State::Pass {
            left: len,
            then: After::Inner {
                records: records - 9 - len,
                tail,
            },
        };
        Ok(())
    }
}

/// A chunk read a second time did not give what it gave the first.
fn changed() -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        "a chunk's records changed between two reads (the file is being written?)",
    )
}

/// The little-endian u64 at `at` (the caller has checked the length).
fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut x = [0u8; 8];
    x.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(x)
}

/// The little-endian u32 at `at` (the caller has checked the length).
fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut x = [0u8; 4];
    x.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(x)
}

impl<R: Read + Seek> Read for SkipOversized<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            if self.pending_at < self.pending.len() {
                let n = (self.pending.len() - self.pending_at).min(buf.len());
                buf[..n].copy_from_slice(&self.pending[self.pending_at..self.pending_at + n]);
                self.pending_at += n;
                return Ok(n);
            }
            match self.state {
                State::Pass { left: 0, then } => match then {
                    After::Head => {
                        self.state = State::Head;
                        self.step()?;
                    }
                    After::Inner { records, tail } => self.inner_head(records, tail)?,
                },
                State::Pass { left, then } => {
                    let n = usize::try_from(left).unwrap_or(usize::MAX).min(buf.len());
                    let got = self.inner()?.read(&mut buf[..n])?;
                    self.remaining = self.remaining.saturating_sub(got as u64);
                    self.state = State::Pass {
                        left: left - got as u64,
                        then,
                    };
                    return Ok(got);
                }
                State::Filtered => {
                    if let Some(n) = self.read_filtered(buf)? {
                        return Ok(n);
                    }
                }
                State::Rest => {
                    let got = self.inner()?.read(buf)?;
                    self.remaining = self.remaining.saturating_sub(got as u64);
                    return Ok(got);
                }
                // Each step leaves these states.
                State::Magic | State::Head => self.step()?,
            }
        }
    }
}

/// Reads until `buf` is full or the end of the input; returns bytes read.
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
        let mut r = vec![opcode];
        r.extend_from_slice(&(body.len() as u64).to_le_bytes());
        r.extend_from_slice(body);
        r
    }

    fn filtered(file: &[u8]) -> (Vec<u8>, u64) {
        let mut f = SkipOversized::new(Cursor::new(file.to_vec()), file.len() as u64);
        let skipped = f.skipped();
        let mut out = Vec::new();
        // Small reads, so every state boundary is crossed mid-buffer.
        let mut buf = [0u8; 5];
        loop {
            let n = f.read(&mut buf).unwrap();
            if n == 0 {
                break;
            }
            out.extend_from_slice(&buf[..n]);
        }
        (out, skipped.records())
    }

    #[test]
    fn records_within_the_bound_pass_unchanged() {
        let mut file = mcap::MAGIC.to_vec();
        file.extend(record(op::HEADER, &[0; 8]));
        file.extend(record(op::MESSAGE, &[7; 30]));
        file.extend(record(op::FOOTER, &[0; 20]));
        file.extend_from_slice(mcap::MAGIC);
        file.extend_from_slice(b"trailing");
        assert_eq!(filtered(&file), (file.clone(), 0));
        // Cut short inside a head and inside a body: the bytes as they are.
        for cut in [file.len() - 40, 8 + 13, 8 + 4] {
            assert_eq!(filtered(&file[..cut]), (file[..cut].to_vec(), 0));
        }
    }

    #[test]
    fn a_record_above_the_bound_is_left_out_and_counted() {
        let big = vec![1u8; RECORD_LIMIT_BYTES + 1];
        let mut want = mcap::MAGIC.to_vec();
        want.extend(record(op::MESSAGE, &[7; 30]));
        let mut file = want.clone();
        file.extend(record(op::MESSAGE, &big));
        let tail = record(op::MESSAGE, &[9; 12]);
        file.extend(&tail);
        want.extend(&tail);
        assert_eq!(filtered(&file), (want, 1));
    }

    /// An uncompressed chunk holding `inner` as its records.
    fn plain_chunk(inner: &[u8]) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend_from_slice(&[0u8; 24]); // start, end, uncompressed size
        body.extend_from_slice(&0u32.to_le_bytes()); // CRC (none)
        body.extend_from_slice(&0u32.to_le_bytes()); // compression ""
        body.extend_from_slice(&(inner.len() as u64).to_le_bytes());
        body.extend_from_slice(inner);
        record(op::CHUNK, &body)
    }

    #[test]
    fn records_inside_an_uncompressed_chunk_pass_when_they_fit() {
        let mut file = mcap::MAGIC.to_vec();
        let mut inner = record(op::SCHEMA, &[1; 10]);
        inner.extend(record(op::MESSAGE, &[2; 3]));
        file.extend(plain_chunk(&inner));
        file.extend(record(op::MESSAGE, &[3; 4]));
        assert_eq!(filtered(&file), (file.clone(), 0));
    }

    /// The shape of the `mcap_reader` fuzz target's first crash: a record
    /// inside an uncompressed chunk longer than the chunk's records.
    #[test]
    fn a_record_running_past_its_chunk_is_an_error() {
        for inner in [record(op::MESSAGE, &[2; 40])[..20].to_vec(), vec![5u8; 4]] {
            let mut file = mcap::MAGIC.to_vec();
            file.extend(plain_chunk(&inner));
            file.extend(record(op::MESSAGE, &[3; 64]));
            let mut f = SkipOversized::new(Cursor::new(file.clone()), file.len() as u64);
            let mut out = Vec::new();
            let e = f.read_to_end(&mut out).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        }
        // The same in a chunk whose own length runs past the end of the file.
        let mut file = mcap::MAGIC.to_vec();
        let mut chunk = plain_chunk(&record(op::MESSAGE, &[2; 40])[..20]);
        chunk[1..9].copy_from_slice(&1000u64.to_le_bytes());
        file.extend(chunk);
        let mut f = SkipOversized::new(Cursor::new(file.clone()), file.len() as u64);
        let e = f.read_to_end(&mut Vec::new()).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        // Through the crate's reader: an error, not a panic or a message.
        let mut file = mcap::MAGIC.to_vec();
        file.extend(record(op::HEADER, &[0; 8]));
        file.extend(plain_chunk(&record(op::MESSAGE, &[2; 40])[..20]));
        file.extend(record(op::MESSAGE, &[3; 64]));
        let source = SkipOversized::new(Cursor::new(file.clone()), file.len() as u64);
        let opts = super::super::reader::reader_options();
        let got: Vec<_> = mcap::io::MessageReader::new_with_options(source, opts).collect();
        assert_eq!(got.len(), 1);
        assert!(got[0].is_err());
    }

    /// A chunk of `inner` records (built here byte by byte, per the MCAP
    /// spec), compressed with `compression` ("" or "zstd"), its CRC that of
    /// `inner`.
    fn chunk(inner: &[u8], compression: &str) -> Vec<u8> {
        let data = match compression {
            "" => inner.to_vec(),
            _ => zstd::bulk::compress(inner, 1).unwrap(),
        };
        let mut body = Vec::new();
        body.extend_from_slice(&10u64.to_le_bytes()); // start
        body.extend_from_slice(&20u64.to_le_bytes()); // end
        body.extend_from_slice(&(inner.len() as u64).to_le_bytes());
        body.extend_from_slice(&crc32fast::hash(inner).to_le_bytes());
        body.extend_from_slice(&(compression.len() as u32).to_le_bytes());
        body.extend_from_slice(compression.as_bytes());
        body.extend_from_slice(&(data.len() as u64).to_le_bytes());
        body.extend_from_slice(&data);
        record(op::CHUNK, &body)
    }

    /// A record above the bound inside a chunk (uncompressed or zstd) is
    /// left out and counted: the reader gets an uncompressed chunk of the
    /// other records with their CRC, then the rest of the file unchanged.
    #[test]
    fn a_record_above_the_bound_inside_a_chunk_is_left_out_and_counted() {
        let big = record(op::MESSAGE, &vec![3u8; RECORD_LIMIT_BYTES + 1]);
        let (a, b) = (record(op::SCHEMA, &[1; 10]), record(op::MESSAGE, &[2; 7]));
        let mut inner = a.clone();
        inner.extend(&big);
        inner.extend(&b);
        inner.extend(&big);
        let kept = [a, b].concat();
        for compression in ["", "zstd"] {
            let mut file = mcap::MAGIC.to_vec();
            file.extend(chunk(&inner, compression));
            let tail = record(op::MESSAGE, &[9; 12]);
            file.extend(&tail);
            let mut want = mcap::MAGIC.to_vec();
            want.extend(chunk(&kept, ""));
            want.extend(&tail);
            let mut f = SkipOversized::new(Cursor::new(file.clone()), file.len() as u64);
            let skipped = f.skipped();
            let mut out = Vec::new();
            // Small reads, so every boundary is crossed mid-buffer.
            let mut buf = [0u8; 7];
            loop {
                let n = f.read(&mut buf).unwrap();
                if n == 0 {
                    break;
                }
                out.extend_from_slice(&buf[..n]);
            }
            assert!(out == want, "{compression:?}: {} bytes out", out.len());
            assert_eq!(skipped.records(), 2, "{compression:?}");
            assert_eq!(skipped.bytes(), 2 * (RECORD_LIMIT_BYTES as u64 + 1));
            // Through the crate's reader (CRCs checked): the kept records
            // and the one after the chunk, no error.
            let len = file.len() as u64;
            let got = records_read(SkipOversized::new(Cursor::new(file), len));
            let lens: Vec<(u8, usize)> = got.unwrap();
            assert_eq!(
                lens,
                [(op::SCHEMA, 10), (op::MESSAGE, 7), (op::MESSAGE, 12)],
                "{compression:?}"
            );
        }
    }

    /// (opcode, length) of every record the `mcap` crate's linear reader
    /// reads from `source` (into chunks, CRCs checked), or its first error.
    fn records_read(mut source: impl Read) -> Result<Vec<(u8, usize)>, mcap::McapError> {
        let opts = super::super::reader::reader_options()
            .with_skip_end_magic(true)
            .with_prevalidate_chunk_crcs(false);
        let mut reader = mcap::sans_io::LinearReader::new_with_options(opts);
        let mut out = Vec::new();
        while let Some(event) = reader.next_event() {
            match event? {
                mcap::sans_io::LinearReadEvent::ReadRequest(n) => {
                    let got = source.read(reader.insert(n))?;
                    reader.notify_read(got);
                }
                mcap::sans_io::LinearReadEvent::Record { data, opcode } => {
                    out.push((opcode, data.len()));
                }
            }
        }
        Ok(out)
    }

    /// A chunk that would be rewritten but whose CRC does not hold goes
    /// through unchanged, for the reader to report (and nothing is counted).
    #[test]
    fn a_damaged_chunk_with_a_record_above_the_bound_goes_through() {
        let big = record(op::MESSAGE, &vec![3u8; RECORD_LIMIT_BYTES + 1]);
        let mut file = mcap::MAGIC.to_vec();
        let mut c = chunk(&big, "zstd");
        // The CRC (after the head, start, end and size).
        c[9 + 24] ^= 0xFF;
        file.extend(&c);
        assert_eq!(filtered(&file), (file.clone(), 0));
    }

    #[test]
    fn a_length_past_the_end_goes_through_for_the_reader_to_report() {
        let mut file = mcap::MAGIC.to_vec();
        file.push(op::MESSAGE);
        file.extend_from_slice(&(400u64 << 20).to_le_bytes());
        file.resize(109, 0xAB);
        assert_eq!(filtered(&file), (file.clone(), 0));
    }
}
