//! MCAP metadata records of a log (as rosbag2 and Foxglove use them): what
//! the writer puts at the start of every file (`drogue_vision.run`: version,
//! git hash, config as TOML, camera, mount, scenario and seed, MAVLink
//! addresses and ids) and how any file's metadata is read back, also from a
//! cut-short file (the records sit in the data section, outside chunks, so
//! reading them skips over every chunk without decompressing it).

use super::LogError;
use super::oversized::RECORD_LIMIT_BYTES;
use mcap::records::{Record, op};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

/// Name of the run's metadata record.
pub const RUN_METADATA: &str = "drogue_vision.run";

/// The version of this build: the crate version, and the git commit when
/// the build had one (`build.rs`; "unknown" in a tarball without `.git`).
pub fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// The git commit this binary was built from ("unknown" without git).
pub fn git_hash() -> &'static str {
    option_env!("DROGUE_VISION_GIT_HASH").unwrap_or("unknown")
}

/// Metadata records: (name, key/values), in file order.
pub type MetadataRecords = Vec<(String, BTreeMap<String, String>)>;

/// Every metadata record of the file at `path`, in file order (a record in
/// the data section and its copy in the summary are one). Stops quietly at
/// a cut or a damaged record: what came before is returned.
pub fn read_metadata(path: &Path) -> Result<MetadataRecords, LogError> {
    let file = File::open(path).map_err(|e| LogError::io(path, e))?;
    let len = file.metadata().map_err(|e| LogError::io(path, e))?.len();
    let mut r = BufReader::with_capacity(1 << 16, file);
    let mut magic = [0u8; 8];
    if r.read_exact(&mut magic).is_err() || magic.as_slice() != mcap::MAGIC {
        return Err(LogError::format(path, "no MCAP magic at the start"));
    }
    let mut pos = magic.len() as u64;
    let mut out: MetadataRecords = Vec::new();
    loop {
        let mut head = [0u8; 9];
        if r.read_exact(&mut head).is_err() {
            break;
        }
        pos += 9;
        let opcode = head[0];
        let rec_len = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0; 8]));
        if rec_len > len.saturating_sub(pos) {
            break;
        }
        if opcode == op::METADATA && rec_len <= RECORD_LIMIT_BYTES as u64 {
            let mut body = vec![0u8; rec_len as usize];
            if r.read_exact(&mut body).is_err() {
                break;
            }
            if let Ok(Record::Metadata(m)) = mcap::parse_record(opcode, &body)
                && !out.iter().any(|(n, v)| *n == m.name && *v == m.metadata)
            {
                out.push((m.name, m.metadata));
            }
        } else if opcode == op::FOOTER {
            break;
        } else {
            let Ok(skip) = i64::try_from(rec_len) else {
                break;
            };
            if r.seek_relative(skip).is_err() {
                break;
            }
        }
        pos += rec_len;
    }
    Ok(out)
}
