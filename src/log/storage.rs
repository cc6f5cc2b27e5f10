//! Where log files go: file naming by UTC start time, and the storage the
//! writer writes through (the real file system, or a failing one in tests).

use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// A writable, seekable byte sink (the `mcap` writer seeks back to patch
/// chunk headers).
pub trait WriteSeek: Write + Seek + Send {}
impl<T: Write + Seek + Send> WriteSeek for T {}

/// An opened log file: the bytes go to `writer`; `sync` makes everything
/// written and flushed so far durable (fsync/`sync_data`).
pub struct StorageFile {
    /// Where the log's bytes go.
    pub writer: Box<dyn WriteSeek>,
    /// Makes what was written so far durable.
    pub sync: Box<dyn FnMut() -> io::Result<()> + Send>,
}

/// Creates log files. Moved into the writer thread.
pub trait Storage: Send {
    /// Creates a new file at `path` (failing if it exists).
    fn create(&mut self, path: &Path) -> io::Result<StorageFile>;
    /// Removes a file that could not even get its header (a full disk).
    fn remove(&mut self, path: &Path) -> io::Result<()> {
        std::fs::remove_file(path)
    }
}

/// The real file system: buffered writes, `sync_data` on the same file.
pub struct FileStorage;

/// Write buffer: large enough that a frame goes out in few syscalls.
const WRITE_BUFFER_BYTES: usize = 1 << 20;

impl Storage for FileStorage {
    fn create(&mut self, path: &Path) -> io::Result<StorageFile> {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .read(true)
            .create_new(true)
            .open(path)?;
        let sync_handle = file.try_clone()?;
        Ok(StorageFile {
            writer: Box::new(BufWriter::with_capacity(WRITE_BUFFER_BYTES, file)),
            sync: Box::new(move || sync_handle.sync_data()),
        })
    }
}

/// Now, nanoseconds since the Unix epoch (0 if the clock is before 1970).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// `YYYYMMDDTHHMMSSZ` of a Unix time (proleptic Gregorian calendar, UTC).
pub fn utc_stamp(unix_ns: u64) -> String {
    let secs = unix_ns / 1_000_000_000;
    let days = i64::try_from(secs / 86_400).unwrap_or(i64::MAX / 2);
    let rem = secs % 86_400;
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

/// Days since 1970-01-01 to (year, month, day): Howard Hinnant's algorithm.
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    // d is 1..=31 and m 1..=12 by construction.
    (y, m as u32, d as u32)
}

/// The run's base name `<prefix>_<UTC start>` (with `-2`, `-3`, ... when a
/// run of the same second already left files in `dir`).
pub fn run_base_name(dir: &Path, prefix: &str, start_ns: u64) -> String {
    let stamp = format!("{prefix}_{}", utc_stamp(start_ns));
    let mut base = stamp.clone();
    let mut n = 2;
    while part_path(dir, &base, 0).exists() {
        base = format!("{stamp}-{n}");
        n += 1;
    }
    base
}

/// `<dir>/<base>_<part>.mcap`, part numbered from 000.
pub fn part_path(dir: &Path, base: &str, part: u32) -> PathBuf {
    dir.join(format!("{base}_{part:03}.mcap"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_stamps_of_known_dates() {
        // Reference values: `date -u -d @SECONDS +%Y%m%dT%H%M%SZ`.
        assert_eq!(utc_stamp(0), "19700101T000000Z");
        assert_eq!(utc_stamp(951_782_400 * 1_000_000_000), "20000229T000000Z");
        assert_eq!(
            utc_stamp(1_700_000_000 * 1_000_000_000 + 999_999_999),
            "20231114T221320Z"
        );
        assert_eq!(utc_stamp(4_102_444_799 * 1_000_000_000), "20991231T235959Z");
    }

    #[test]
    fn base_name_avoids_existing_runs() {
        let dir = tempfile::tempdir().unwrap();
        let a = run_base_name(dir.path(), "drogue", 0);
        assert_eq!(a, "drogue_19700101T000000Z");
        std::fs::write(part_path(dir.path(), &a, 0), b"x").unwrap();
        let b = run_base_name(dir.path(), "drogue", 0);
        assert_eq!(b, "drogue_19700101T000000Z-2");
    }
}
