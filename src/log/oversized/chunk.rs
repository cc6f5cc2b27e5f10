//! One streaming walk over a chunk's records ([`walk_chunk`]): decompressed
//! into a small buffer, every record's bytes hashed and dropped, those
//! above the bound noted, the chunk's size and CRC checked. Used by the
//! reader's filter and by `recover` (which copies the records it is given).

use super::{RECORD_LIMIT_BYTES, read_up_to, u64_at};
use std::io::{self, BufReader, Read, Take, Write};

/// A chunk's compressed records being decompressed (or, uncompressed,
/// passed through) from `R`.
pub(crate) enum ChunkContent<R: Read> {
    Plain(Take<R>),
    Zstd(Box<zstd::stream::read::Decoder<'static, BufReader<Take<R>>>>),
    Lz4(Box<lz4::Decoder<Take<R>>>),
}

impl<R: Read> ChunkContent<R> {
    /// The content of a chunk compressed with `compression` (its MCAP
    /// name) whose `compressed` bytes `r` is at. None: a compression this
    /// build does not read.
    pub(crate) fn new(compression: &str, r: R, compressed: u64) -> io::Result<Option<Self>> {
        let r = r.take(compressed);
        Ok(Some(match compression {
            "" => Self::Plain(r),
            "zstd" => Self::Zstd(Box::new(zstd::stream::read::Decoder::new(r)?)),
            "lz4" => Self::Lz4(Box::new(lz4::Decoder::new(r)?)),
            _ => return Ok(None),
        }))
    }

    /// The reader back (its position anywhere within the chunk).
    pub(super) fn into_inner(self) -> R {
        match self {
            Self::Plain(r) => r.into_inner(),
            Self::Zstd(d) => d.into_inner().into_inner().into_inner(),
            Self::Lz4(d) => d.finish().0.into_inner(),
        }
    }
}

impl<R: Read> Read for ChunkContent<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self {
            Self::Plain(r) => r.read(buf),
            Self::Zstd(d) => d.read(buf),
            Self::Lz4(d) => d.read(buf),
        }
    }
}

/// What [`walk_chunk`] found in a chunk's content.
#[derive(Debug, Default)]
pub(crate) struct ChunkWalk {
    /// Records above the bound: (offset of the record head in the content,
    /// bytes with the head), in order.
    pub oversized: Vec<(u64, u64)>,
    /// Their body bytes.
    pub oversized_bytes: u64,
    /// Content bytes read.
    pub len: u64,
    /// CRC-32 of all the content read, and of the content less the records
    /// above the bound.
    pub crc: u32,
    pub kept_crc: u32,
    /// Why the walk stopped before the end of the content, or why the
    /// content is not what the header says (its size, its CRC).
    pub problem: Option<String>,
}

/// What [`walk_chunk`] hands each record within the bound to: (opcode,
/// body).
pub(crate) type RecordFn<'a, E> = &'a mut dyn FnMut(u8, &[u8]) -> Result<(), E>;

/// Walks the records of a chunk's content (decompressed) in `content`,
/// streaming: a record above [`RECORD_LIMIT_BYTES`] is read and dropped in
/// small pieces, never held; each other record is handed to `each` (read
/// into memory, within the bound) or, without `each`, dropped the same way.
/// `size` and `crc` are the chunk header's uncompressed size and CRC (0:
/// none). Stops at the first problem (noted in the result); an error of
/// `each` ends it with that error.
pub(crate) fn walk_chunk<E>(
    content: impl Read,
    size: u64,
    crc: u32,
    mut each: Option<RecordFn<'_, E>>,
) -> Result<ChunkWalk, E> {
    let mut r = Hashing {
        inner: content.take(size),
        hasher: crc32fast::Hasher::new(),
        read: 0,
    };
    let mut kept = crc32fast::Hasher::new();
    let mut walk = ChunkWalk::default();
    let problem = loop {
        let at = r.read;
        let mut head = [0u8; 9];
        match read_up_to(&mut r, &mut head) {
            Ok(0) => break None,
            Ok(9) => {}
            Ok(_) => {
                break Some(format!(
                    "a record head is cut off at byte {at} of its records"
                ));
            }
            Err(e) => break Some(format!("does not decompress: {e}")),
        }
        let (opcode, len) = (head[0], u64_at(&head, 1));
        if len > size - r.read {
            break Some(format!(
                "the record at byte {at} of its records claims {len} bytes, {} remain",
                size - r.read
            ));
        }
        if len > RECORD_LIMIT_BYTES as u64 {
            match io::copy(&mut (&mut r).take(len), &mut io::sink()) {
                Ok(n) if n == len => {}
                Ok(_) => break Some(format!("its records end inside the record at byte {at}")),
                Err(e) => break Some(format!("does not decompress: {e}")),
            }
            walk.oversized.push((at, 9 + len));
            walk.oversized_bytes += len;
            continue;
        }
        kept.update(&head);
        let got = match each.as_mut() {
            Some(each) => {
                let mut body = vec![0u8; len as usize];
                match r.read_exact(&mut body) {
                    Ok(()) => {
                        kept.update(&body);
                        each(opcode, &body)?;
                        Ok(len)
                    }
                    Err(e) => Err(e),
                }
            }
            None => io::copy(&mut (&mut r).take(len), &mut HashSink { hasher: &mut kept }),
        };
        match got {
            Ok(n) if n == len => {}
            Ok(_) => break Some(format!("its records end inside the record at byte {at}")),
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
                break Some(format!("its records end inside the record at byte {at}"));
            }
            Err(e) => break Some(format!("does not decompress: {e}")),
        }
    };
    walk.len = r.read;
    walk.crc = r.hasher.finalize();
    walk.kept_crc = kept.finalize();
    walk.problem = problem.or_else(|| {
        if walk.len != size {
            Some(format!(
                "decompresses to {} bytes, its header says {size}",
                walk.len
            ))
        } else if crc != 0 && walk.crc != crc {
            Some(format!("CRC {:08X}, its header says {crc:08X}", walk.crc))
        } else {
            None
        }
    });
    Ok(walk)
}

/// A reader that hashes and counts what it hands out.
pub(super) struct Hashing<R> {
    pub(super) inner: R,
    pub(super) hasher: crc32fast::Hasher,
    pub(super) read: u64,
}

impl<R: Read> Read for Hashing<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.hasher.update(&buf[..n]);
        self.read += n as u64;
        Ok(n)
    }
}

/// A sink that only hashes.
pub(super) struct HashSink<'a> {
    pub(super) hasher: &'a mut crc32fast::Hasher,
}

impl Write for HashSink<'_> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.hasher.update(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}
