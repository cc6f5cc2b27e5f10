//! Reading our logs back: the message reader every reader of a log uses
//! (replay, review, recover's check), with records above the bound left out
//! and chunk CRCs checked, and what a reader error means (cut short or
//! damaged). Apart from `recover` because it serves every reader, not only
//! the repair.

use super::LogError;
use super::oversized::{Oversized, RECORD_LIMIT_BYTES, SkipOversized};
use mcap::records::{Record, op};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::Arc;

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
