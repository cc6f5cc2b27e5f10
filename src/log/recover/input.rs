//! The damaged input, walked record by record with its position tracked:
//! a record's length that runs past the end is a cut, unless a valid chunk
//! follows further on (then the bytes in between are skipped). Apart from
//! the copy, so that what is read and what is written can be followed
//! separately.

use super::super::oversized::RECORD_LIMIT_BYTES;
use mcap::records::{self, Record, op};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};

/// A top-level record of the input.
pub(super) enum Next {
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
pub(super) struct Input {
    pub(super) r: BufReader<File>,
    pub(super) pos: u64,
    pub(super) len: u64,
}

impl Input {
    pub(super) fn next(&mut self) -> std::io::Result<Next> {
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
    pub(super) fn large_chunk_header(
        &mut self,
        len: u64,
    ) -> std::io::Result<Option<records::ChunkHeader>> {
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
    pub(super) fn resync(&mut self, from: u64) -> std::io::Result<Option<u64>> {
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
    pub(super) fn partial_chunk(
        &mut self,
        at: u64,
    ) -> std::io::Result<Option<(u64, u64, Vec<u8>)>> {
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
    pub(super) fn chunk_at(&mut self, at: u64) -> std::io::Result<bool> {
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

/// Where the first `byte` is in `hay`: std's `memchr` (a word at a time), by
/// way of `BufRead::skip_until`, where a loop over the bytes makes a compare
/// per byte (most of the time of recovering a damaged file went there).
pub(super) fn find_byte(hay: &[u8], byte: u8) -> Option<usize> {
    use std::io::BufRead;
    let mut rest = hay;
    let n = rest.skip_until(byte).ok()?;
    // Through the byte when found; otherwise to the end, where no byte is it.
    (n > 0 && hay[n - 1] == byte).then(|| n - 1)
}

/// Whether a chunk of `len` bytes at `at` fits the file (a chunk header is
/// at least 8+8+8+4+4+8 bytes).
pub(super) fn plausible_chunk_len(len: u64, at: u64, file_len: u64) -> bool {
    (40..=RECORD_LIMIT_BYTES as u64).contains(&len)
        && at.saturating_add(9).saturating_add(len) <= file_len
}

/// Reads until `buf` is full or the end of the input; returns bytes read.
pub(super) fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
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
pub(super) fn decompress(header: &records::ChunkHeader, data: &[u8]) -> (Vec<u8>, Option<String>) {
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
pub(super) fn inner_records(data: &[u8]) -> (Vec<(u8, &[u8])>, bool) {
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
