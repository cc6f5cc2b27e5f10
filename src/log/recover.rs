//! Recovery of cut-short logs (a crash, a power cut, a full disk): everything
//! up to the cut is copied, streaming, into a complete, indexed MCAP file.

use super::LogError;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Largest record the reader accepts: a raw mono8 frame of 5792x5792, far
/// above any camera this runs with. A corrupt or hostile length beyond it
/// ends the reading with an error before anything is allocated for it (a
/// 109-byte file claiming a 400 MiB record costs nothing), so replay and
/// recover stay within a few frames' worth of memory.
pub const RECORD_LIMIT_BYTES: usize = 32 << 20;

/// What a recovery copied.
#[derive(Clone, Debug, PartialEq)]
pub struct RecoverReport {
    pub messages: u64,
    /// Why the input ended early (None: it was complete).
    pub cut: Option<String>,
    /// Log time of the last message copied, ns.
    pub last_log_time_ns: Option<u64>,
}

/// A streaming message reader for our logs (also cut-short ones).
pub fn message_reader(path: &Path) -> Result<mcap::io::MessageReader<BufReader<File>>, LogError> {
    let file = File::open(path).map_err(|e| LogError::io(path, e))?;
    let options =
        mcap::sans_io::LinearReaderOptions::default().with_record_length_limit(RECORD_LIMIT_BYTES);
    Ok(mcap::io::MessageReader::new_with_options(
        BufReader::with_capacity(1 << 20, file),
        options,
    ))
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

/// Copies every readable message of `input` into a new complete file `output`.
/// Fails only when `input` is not an MCAP file at all or `output` cannot be
/// written.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, LogError> {
    let reader = message_reader(input)?;
    let out = File::create(output).map_err(|e| LogError::io(output, e))?;
    let options = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .library(concat!(
            "drogue-vision ",
            env!("CARGO_PKG_VERSION"),
            " recover"
        ));
    let mut writer = mcap::Writer::with_options(BufWriter::with_capacity(1 << 20, out), options)
        .map_err(|e| LogError::io(output, e))?;
    let mut report = RecoverReport {
        messages: 0,
        cut: None,
        last_log_time_ns: None,
    };
    for message in reader {
        match message {
            Ok(m) => {
                writer
                    .write(&m)
                    .map_err(|e| LogError::io(output, super::error_chain(&e)))?;
                report.messages += 1;
                report.last_log_time_ns = Some(m.log_time);
            }
            Err(e) => {
                if report.messages == 0 && matches!(e, mcap::McapError::BadMagic) {
                    return Err(LogError::format(input, e));
                }
                report.cut = Some(super::error_chain(&e));
                break;
            }
        }
    }
    writer.finish().map_err(|e| LogError::io(output, e))?;
    let mut inner = writer.into_inner();
    inner.flush().map_err(|e| LogError::io(output, e))?;
    inner
        .get_ref()
        .sync_all()
        .map_err(|e| LogError::io(output, e))?;
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
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "mcap"))
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
                tracing::warn!(
                    "recovered the cut-short log {}: {} messages{}",
                    path.display(),
                    report.messages,
                    report
                        .cut
                        .map(|c| format!(" (cut: {c})"))
                        .unwrap_or_default()
                );
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
            let _ = std::fs::remove_file(&tmp);
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
