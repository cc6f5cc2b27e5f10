//! Top-level MCAP records above the record bound ([`RECORD_LIMIT_BYTES`]),
//! skipped and counted before the `mcap` crate's reader sees them.
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
//! the reader to report. Chunks always go through (the reader streams them
//! record by record, whatever their size); a record above the bound inside
//! a chunk still ends the reading with the reader's error, as skipping it
//! would mean decompressing it. The footer's end magic and anything after
//! it go through unchanged.
//!
//! Skipping changes the bytes the data-section CRC covers, so readers fed
//! through this must leave that check off (the `mcap` default; chunk CRCs
//! are still checked).

use super::recover::RECORD_LIMIT_BYTES;
use mcap::records::op;
use std::io::{self, Read, Seek, SeekFrom};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

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

/// Where the walk over the file is.
#[derive(Clone, Copy, Debug)]
enum State {
    /// The file's start magic: this many bytes still to pass through.
    Magic(usize),
    /// At a record head.
    Head,
    /// Passing through the current record: head bytes `head[at..]`, then
    /// `body` more bytes.
    Record { at: usize, body: u64 },
    /// After the footer, or a head that did not parse: all the rest as is.
    Rest,
}

/// A reader of an MCAP file that leaves out top-level records above
/// [`RECORD_LIMIT_BYTES`] (see the module docs).
pub struct SkipOversized<R> {
    inner: R,
    /// Bytes of the file after the current position.
    remaining: u64,
    state: State,
    head: [u8; 9],
    head_len: usize,
    skipped: Arc<Oversized>,
}

impl<R: Read + Seek> SkipOversized<R> {
    /// Wraps `inner`, positioned at the start of a file of `len` bytes.
    pub fn new(inner: R, len: u64) -> Self {
        Self {
            inner,
            remaining: len,
            state: State::Magic(mcap::MAGIC.len()),
            head: [0; 9],
            head_len: 0,
            skipped: Arc::default(),
        }
    }

    /// The count of what was skipped, live while reading.
    pub fn skipped(&self) -> Arc<Oversized> {
        Arc::clone(&self.skipped)
    }

    /// Reads the next record head; skips records above the bound. Leaves
    /// the state at the record to pass through (or the rest of the file).
    fn next_head(&mut self) -> io::Result<()> {
        loop {
            let got = read_up_to(&mut self.inner, &mut self.head)?;
            self.remaining = self.remaining.saturating_sub(got as u64);
            self.head_len = got;
            if got < self.head.len() {
                // The end, or a head cut short: the reader says which.
                self.state = State::Record { at: 0, body: 0 };
                return Ok(());
            }
            let opcode = self.head[0];
            let len = u64::from_le_bytes([
                self.head[1],
                self.head[2],
                self.head[3],
                self.head[4],
                self.head[5],
                self.head[6],
                self.head[7],
                self.head[8],
            ]);
            if len > RECORD_LIMIT_BYTES as u64 && opcode != op::CHUNK && len <= self.remaining {
                let skip = i64::try_from(len).map_err(io::Error::other)?;
                self.inner.seek(SeekFrom::Current(skip))?;
                self.remaining -= len;
                self.skipped.records.fetch_add(1, Ordering::Relaxed);
                self.skipped.bytes.fetch_add(len, Ordering::Relaxed);
                continue;
            }
            self.state = if opcode == op::FOOTER || len > self.remaining {
                // The end magic follows the footer; a length past the end is
                // the reader's to report.
                State::Record {
                    at: 0,
                    body: u64::MAX,
                }
            } else {
                State::Record { at: 0, body: len }
            };
            return Ok(());
        }
    }
}

impl<R: Read + Seek> Read for SkipOversized<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            match self.state {
                State::Magic(0) => self.state = State::Head,
                State::Magic(left) => {
                    let n = left.min(buf.len());
                    let got = self.inner.read(&mut buf[..n])?;
                    self.remaining = self.remaining.saturating_sub(got as u64);
                    self.state = if got == 0 {
                        State::Rest
                    } else {
                        State::Magic(left - got)
                    };
                    return Ok(got);
                }
                State::Head => self.next_head()?,
                State::Record { at, body } if at < self.head_len => {
                    let n = (self.head_len - at).min(buf.len());
                    buf[..n].copy_from_slice(&self.head[at..at + n]);
                    self.state = State::Record { at: at + n, body };
                    return Ok(n);
                }
                State::Record { body: u64::MAX, .. } => self.state = State::Rest,
                State::Record { body: 0, .. } => {
                    if self.head_len < self.head.len() {
                        // The file ended in (or at) a head.
                        return Ok(0);
                    }
                    self.state = State::Head;
                }
                State::Record { at, body } => {
                    let n = usize::try_from(body).unwrap_or(usize::MAX).min(buf.len());
                    let got = self.inner.read(&mut buf[..n])?;
                    self.remaining = self.remaining.saturating_sub(got as u64);
                    if got == 0 {
                        return Ok(0);
                    }
                    self.state = State::Record {
                        at,
                        body: body - got as u64,
                    };
                    return Ok(got);
                }
                State::Rest => {
                    let got = self.inner.read(buf)?;
                    self.remaining = self.remaining.saturating_sub(got as u64);
                    return Ok(got);
                }
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

    #[test]
    fn a_length_past_the_end_goes_through_for_the_reader_to_report() {
        let mut file = mcap::MAGIC.to_vec();
        file.push(op::MESSAGE);
        file.extend_from_slice(&(400u64 << 20).to_le_bytes());
        file.resize(109, 0xAB);
        assert_eq!(filtered(&file), (file.clone(), 0));
    }
}
