//! The copy into the new file: each record the input still holds (top level
//! or inside a chunk, decompressed, or streamed when the chunk is above the
//! bound) parsed and written with the output's own channel and schema ids,
//! and every record that does not parse counted.

use super::super::error_chain;
use super::super::oversized::{ChunkContent, walk_chunk};
use super::{RECOVER_METADATA, RecoverReport};
use mcap::records::{self, MessageHeader, Record, op};
use std::collections::HashMap;
use std::io::{Read, Seek, Write};

/// Whether an attachment record's body has room for its CRC after its
/// header and data length (or is too short for those, which `parse_record`
/// reports as an error): the `mcap` crate's `parse_record` (0.26) slices
/// such a body at its length less 4 without a check, a panic when less
/// than 4 bytes follow (found by the `mcap_reader` fuzz target).
pub(super) fn attachment_has_its_crc(body: &[u8]) -> bool {
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

/// The records of a chunk that may hold records above the bound (its
/// uncompressed size is above it), streamed from its `compressed` records:
/// each record within the bound is copied, each above it read and dropped in
/// small pieces and counted. Returns the messages copied and what is wrong
/// with the chunk (None: size and CRC check out).
pub(super) fn stream_chunk<W: Write + Seek>(
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
pub(super) struct Copier<W: Write + Seek> {
    pub(super) out: mcap::Writer<W>,
    pub(super) schemas: HashMap<u16, (String, String, Vec<u8>)>,
    pub(super) out_schema: HashMap<u16, u16>,
    pub(super) channels: HashMap<u16, records::Channel>,
    pub(super) out_channel: HashMap<u16, u16>,
    pub(super) report: RecoverReport,
}

impl<W: Write + Seek> Copier<W> {
    /// Handles one record (top level or inside a chunk); returns whether it
    /// was a message written.
    pub(super) fn record(&mut self, opcode: u8, body: &[u8]) -> Result<bool, String> {
        if opcode == op::ATTACHMENT && !attachment_has_its_crc(body) {
            self.report.unreadable_records += 1;
            return Ok(false);
        }
        let Ok(record) = mcap::parse_record(opcode, body) else {
            self.report.unreadable_records += 1;
            return Ok(false);
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
                self.out.write_metadata(&m).map_err(|e| error_chain(&e))?;
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
                    .map_err(|e| error_chain(&e))?;
            }
            _ => {}
        }
        Ok(false)
    }

    pub(super) fn message(&mut self, header: MessageHeader, data: &[u8]) -> Result<bool, String> {
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
            .map_err(|e| error_chain(&e))?;
        self.report.messages += 1;
        self.report.last_log_time_ns = Some(header.log_time);
        Ok(true)
    }

    /// The output channel of an input channel id (added on first use).
    pub(super) fn output_channel(&mut self, id: u16) -> Result<Option<u16>, String> {
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
                        .map_err(|e| error_chain(&e))?;
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
            .map_err(|e| error_chain(&e))?;
        self.out_channel.insert(id, c);
        Ok(Some(c))
    }
}

/// The output's write options, made once: `WriteOptions::new` counts the
/// machine's physical cores by reading `/proc/cpuinfo` (for a default this
/// overrides), which was a tenth of the time of recovering a small file.
pub(super) static OUTPUT_OPTIONS: std::sync::LazyLock<mcap::WriteOptions> =
    std::sync::LazyLock::new(|| {
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
