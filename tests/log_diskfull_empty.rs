//! Disk full with buffered writes, as the real file storage does them
//! (issue 16): each retry while the disk is still full creates a file whose
//! header sits in the write buffer and whose first write fails. No such
//! empty file may stay behind, and logging resumes in the next part number
//! once there is room, as before.

mod log_support;

use drogue_vision::log::reader;
use drogue_vision::source::replay;
use log_support as s;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[test]
fn retries_on_a_full_disk_leave_no_empty_files() {
    let dir = tempfile::tempdir().unwrap();
    // Room for about 2 frames.
    let (log, free) = s::log_on_small_disk(dir.path(), 3_000_000, Some(64 << 10));
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
    assert!(reader::is_complete(&on_disk[1]).unwrap());
    let resumed: Vec<u64> = replay::open(&on_disk[1])
        .unwrap()
        .map(|f| f.unwrap().seq)
        .collect();
    assert_eq!(resumed, (100..105).collect::<Vec<_>>());
}
