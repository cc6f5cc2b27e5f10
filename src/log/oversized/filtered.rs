//! A chunk that holds records above the bound, handed to the reader as an
//! uncompressed chunk of its other records: decompressed a second time as
//! the reader reads it, the records above the bound dropped on the way.

use super::chunk::{ChunkContent, walk_chunk};
use super::{CHUNK_FIXED, SkipOversized, State, changed, u32_at, u64_at};
use mcap::records::op;
use std::collections::VecDeque;
use std::io::{self, Read, Seek, SeekFrom};
use std::sync::atomic::Ordering;

/// A chunk handed out less its records above the bound.
pub(super) struct Filtered<R: Read> {
    pub(super) content: ChunkContent<R>,
    /// Content bytes read from `content` so far, and in all.
    pub(super) at: u64,
    pub(super) len: u64,
    /// The records to drop: (content offset, bytes), in order.
    pub(super) drop: VecDeque<(u64, u64)>,
    /// Where the chunk ends in the file.
    pub(super) end: u64,
}

impl<R: Read + Seek> SkipOversized<R> {
    /// At the compressed records (`compressed` bytes of the `data` bytes
    /// left in the chunk) of a chunk whose head and header are in
    /// `pending`: walks them once; when they hold records above the bound
    /// and are otherwise sound, rewrites the head and header in `pending`
    /// as those of an uncompressed chunk of the other records and starts
    /// handing those out. Returns whether it did; if not, the file is where
    /// it was.
    pub(super) fn filter(
        &mut self,
        compression: &str,
        compressed: u64,
        data: u64,
    ) -> io::Result<bool> {
        let start = self.len - self.remaining;
        let size = u64_at(&self.pending, 9 + 16);
        let crc = u32_at(&self.pending, 9 + 24);
        let walk = match ChunkContent::new(compression, self.inner()?, compressed) {
            Ok(Some(content)) => walk_chunk::<std::convert::Infallible>(content, size, crc, None)
                .unwrap_or_else(|e| match e {}),
            // An unknown compression, or no decoder: the reader reports it.
            Ok(None) | Err(_) => return Ok(false),
        };
        self.inner()?.seek(SeekFrom::Start(start))?;
        if walk.problem.is_some() || walk.oversized.is_empty() {
            return Ok(false);
        }
        let Some(file) = self.inner.take() else {
            return Ok(false);
        };
        let Ok(Some(content)) = ChunkContent::new(compression, file, compressed) else {
            return Err(io::Error::other(
                "a chunk's decoder could not be made a second time",
            ));
        };
        let dropped: u64 = walk.oversized.iter().map(|&(_, n)| n).sum();
        let kept = size - dropped;
        // The head and header of an uncompressed chunk of `kept` bytes of
        // records: its start and end times stay.
        let times: [u8; 16] = self.pending[9..25].try_into().unwrap_or([0; 16]);
        self.pending.clear();
        self.pending_at = 0;
        self.pending.push(op::CHUNK);
        self.pending
            .extend_from_slice(&(CHUNK_FIXED as u64 + 8 + kept).to_le_bytes());
        self.pending.extend_from_slice(&times);
        self.pending.extend_from_slice(&kept.to_le_bytes());
        let kept_crc = if crc == 0 { 0 } else { walk.kept_crc };
        self.pending.extend_from_slice(&kept_crc.to_le_bytes());
        self.pending.extend_from_slice(&0u32.to_le_bytes());
        self.pending.extend_from_slice(&kept.to_le_bytes());
        self.skipped
            .records
            .fetch_add(walk.oversized.len() as u64, Ordering::Relaxed);
        self.skipped
            .bytes
            .fetch_add(walk.oversized_bytes, Ordering::Relaxed);
        self.filtered = Some(Filtered {
            content,
            at: 0,
            len: size,
            drop: walk.oversized.into(),
            end: start + data,
        });
        self.state = State::Filtered;
        Ok(true)
    }

    /// Hands out the next bytes of a filtered chunk; at its end, takes the
    /// file back and goes on after the chunk.
    pub(super) fn read_filtered(&mut self, buf: &mut [u8]) -> io::Result<Option<usize>> {
        let Some(f) = self.filtered.as_mut() else {
            self.state = State::Rest;
            return Ok(None);
        };
        loop {
            let next_drop = f.drop.front().copied();
            if let Some((at, n)) = next_drop
                && at == f.at
            {
                let got = io::copy(&mut (&mut f.content).take(n), &mut io::sink())?;
                if got < n {
                    return Err(changed());
                }
                f.at += n;
                f.drop.pop_front();
                continue;
            }
            let until = next_drop.map_or(f.len, |(at, _)| at);
            if f.at == until {
                break;
            }
            let n = usize::try_from(until - f.at)
                .unwrap_or(usize::MAX)
                .min(buf.len());
            let got = f.content.read(&mut buf[..n])?;
            if got == 0 {
                return Err(changed());
            }
            f.at += got as u64;
            return Ok(Some(got));
        }
        // The chunk's end: the file back, after the chunk.
        let Some(f) = self.filtered.take() else {
            return Ok(None);
        };
        let mut file = f.content.into_inner();
        file.seek(SeekFrom::Start(f.end))?;
        self.remaining = self.len.saturating_sub(f.end);
        self.inner = Some(file);
        self.state = State::Head;
        self.step()?;
        Ok(None)
    }
}
