//! Disk full with buffered writes, as the real file storage does them
//! (issue 16): each retry while the disk is still full creates a file whose
//! header sits in the write buffer and whose first write fails. No such
//! empty file may stay behind, and logging resumes in the next part number
//! once there is room, as before.

mod log_support;

use drogue_vision::log::{FlightLog, Storage, StorageFile, recover, replay};
use log_support as s;
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// A "disk" with a shared byte budget behind a 64 KiB write buffer.
struct BufferedSmallDisk {
    free: Arc<AtomicU64>,
}

struct SmallFile {
    file: File,
    free: Arc<AtomicU64>,
}

impl Write for SmallFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let free = self.free.load(Ordering::SeqCst);
        if free == 0 {
            return Err(io::Error::new(
                io::ErrorKind::StorageFull,
                "no space left on device (test disk)",
            ));
        }
        let n = self.file.write(&buf[..buf.len().min(free as usize)])?;
        self.free.fetch_sub(n as u64, Ordering::SeqCst);
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Seek for SmallFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

impl Storage for BufferedSmallDisk {
    fn create(&mut self, path: &Path) -> io::Result<StorageFile> {
        let file = File::create_new(path)?;
        let sync = file.try_clone()?;
        Ok(StorageFile {
            writer: Box::new(BufWriter::with_capacity(
                64 << 10,
                SmallFile {
                    file,
                    free: self.free.clone(),
                },
            )),
            sync: Box::new(move || sync.sync_data()),
        })
    }
}

#[test]
fn retries_on_a_full_disk_leave_no_empty_files() {
    let dir = tempfile::tempdir().unwrap();
    let free = Arc::new(AtomicU64::new(3_000_000)); // about 2 frames
    let mut cfg = s::config();
    cfg.retry_after_error_s = 1;
    let log = FlightLog::start_with_storage(
        &cfg,
        dir.path(),
        &s::camera(),
        Box::new(BufferedSmallDisk { free: free.clone() }),
    )
    .unwrap();
    // Frames for ~3.5 s with the disk full after the second: three retries
    // find it still full.
    for seq in 0..35 {
        log.frame(Arc::new(s::frame(seq, false)));
        std::thread::sleep(Duration::from_millis(100));
    }
    free.store(u64::MAX / 2, Ordering::SeqCst);
    std::thread::sleep(Duration::from_millis(1200));
    for seq in 100..105 {
        log.frame(Arc::new(s::frame(seq, false)));
    }
    let summary = log.finish().unwrap();
    println!("{summary:?}");
    assert!(summary.write_errors >= 3, "{summary:?}");

    let mut on_disk: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    on_disk.sort();
    for p in &on_disk {
        let len = std::fs::metadata(p).unwrap().len();
        assert!(len > 0, "{} is empty", p.display());
    }
    // The first part (cut by the full disk) and the part logging resumed in,
    // numbered 000 and 001 as before; nothing else.
    assert_eq!(on_disk, summary.files, "{on_disk:?}");
    assert_eq!(on_disk.len(), 2, "{on_disk:?}");
    assert!(on_disk[1].to_string_lossy().ends_with("_001.mcap"));
    assert!(recover::is_complete(&on_disk[1]).unwrap());
    let resumed: Vec<u64> = replay::open(&on_disk[1])
        .unwrap()
        .map(|f| f.unwrap().seq)
        .collect();
    assert_eq!(resumed, (100..105).collect::<Vec<_>>());
}
