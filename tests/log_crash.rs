//! Crash test: a writer killed with SIGKILL mid-flight leaves a file whose
//! complete chunks a reader reads, missing at most about the last second;
//! recovery makes it a complete, indexed file (by hand with `recover`, and at
//! the next start-up).
//!
//! The test re-runs its own binary as the child that writes and gets killed.
//! With `DROGUE_MCAP_CHECK_PYTHON=/path/to/venv/python` it also runs
//! `tests/interop/mcap_check.py` (the Python `mcap` reader) on both files.

mod log_support;

use drogue_vision::log::{FlightLog, reader, recover};
use log_support as s;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const CHILD_ENV: &str = "DROGUE_LOG_CRASH_CHILD_DIR";
const FPS: u64 = 30;
/// Frames the child writes before it is killed (about 2 s).
const KILL_AFTER: u64 = 60;

/// The child: logs frames with everything derived at 30 fps until killed,
/// printing the sequence number of each frame handed to the log. Not a test
/// of its own: the crash test below starts it (with `--ignored`) in a child
/// process and names the folder in `CHILD_ENV`.
#[test]
#[ignore = "the child process of sigkill_loses_at_most_a_second_and_recovery_indexes_the_rest, which starts it"]
fn child_writes_until_killed() {
    let dir = std::env::var(CHILD_ENV)
        .expect("DROGUE_LOG_CRASH_CHILD_DIR: run by the crash test, which sets it");
    let log = FlightLog::start(&s::config(), Path::new(&dir), &s::camera()).unwrap();
    let mut out = std::io::stdout().lock();
    for seq in 0.. {
        s::log_frame(&log, seq, true);
        writeln!(out, "enqueued {seq}").unwrap();
        out.flush().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(1000 / FPS));
    }
}

fn python_check(args: &[&str]) {
    let Ok(python) = std::env::var("DROGUE_MCAP_CHECK_PYTHON") else {
        eprintln!("mcap_check.py {args:?}: not run (DROGUE_MCAP_CHECK_PYTHON is not set)");
        return;
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/mcap_check.py");
    let status = Command::new(python)
        .arg(script)
        .args(args)
        .status()
        .unwrap();
    assert!(status.success(), "mcap_check.py {args:?}");
}

/// Frame sequence numbers a streaming reader gets from `path` before the cut.
fn readable_frames(path: &Path) -> (Vec<u64>, u64, bool) {
    let mut seqs = Vec::new();
    let mut messages = 0;
    let mut cut = false;
    for m in reader::message_reader(path).unwrap() {
        match m {
            Ok(m) => {
                messages += 1;
                if m.channel.topic == "/camera/image" {
                    seqs.push(u64::from(m.sequence));
                }
            }
            Err(_) => {
                cut = true;
                break;
            }
        }
    }
    (seqs, messages, cut)
}

#[test]
fn sigkill_loses_at_most_a_second_and_recovery_indexes_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "child_writes_until_killed",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, dir.path())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut last_enqueued = 0;
    for line in BufReader::new(child.stdout.take().unwrap()).lines() {
        let line = line.unwrap();
        if let Some(n) = line.strip_prefix("enqueued ") {
            last_enqueued = n.parse().unwrap();
            if last_enqueued >= KILL_AFTER {
                break;
            }
        }
    }
    child.kill().unwrap(); // SIGKILL: no destructor, no flush, no summary.
    child.wait().unwrap();
    assert!(last_enqueued >= KILL_AFTER);

    let files: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let cut_file = files[0].clone();
    assert!(!reader::is_complete(&cut_file).unwrap());

    let (seqs, messages, cut) = readable_frames(&cut_file);
    assert!(cut, "a killed writer leaves no end magic");
    assert_eq!(
        seqs,
        (0..seqs.len() as u64).collect::<Vec<_>>(),
        "in order, no gap"
    );
    let missing = last_enqueued + 1 - seqs.len() as u64;
    println!(
        "enqueued {} frames, {} readable after SIGKILL",
        last_enqueued + 1,
        seqs.len()
    );
    assert!(missing <= FPS, "lost {missing} frames, more than a second");
    python_check(&[
        "--cut",
        "--require",
        "/camera/image,/drogue/detection",
        cut_file.to_str().unwrap(),
    ]);

    // recover by hand: complete, indexed, everything that was readable.
    let fixed = dir.path().join("fixed.mcap.out");
    // The reader stops at the chunk the kill cut short; recovery also
    // keeps that chunk's complete messages (when the kill fell while the
    // writer was streaming one, as it does more often on a busy machine).
    let report = recover::recover(&cut_file, &fixed).unwrap();
    assert!(report.cut.is_some());
    assert_eq!(report.readable_by_reader, messages);
    assert!(report.messages >= messages, "{report:?}");
    assert!(reader::is_complete(&fixed).unwrap());
    let bytes = std::fs::read(&fixed).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.unwrap().message_count, report.messages);
    assert!(!summary.chunk_indexes.is_empty());
    let fixed_mcap = dir.path().join("fixed.mcap");
    std::fs::rename(&fixed, &fixed_mcap).unwrap();
    python_check(&[
        "--require",
        "/camera/image,/drogue/detection",
        fixed_mcap.to_str().unwrap(),
    ]);
    std::fs::remove_file(&fixed_mcap).unwrap();

    // The next start-up recovers it in place and keeps the original.
    let log = FlightLog::start(&s::config(), dir.path(), &s::camera()).unwrap();
    let summary = log.finish().unwrap();
    assert_eq!(summary.recovered, vec![cut_file.clone()]);
    assert!(reader::is_complete(&cut_file).unwrap());
    let (seqs_after, messages_after, cut_after) = readable_frames(&cut_file);
    assert!(!cut_after);
    assert_eq!(messages_after, report.messages);
    assert_eq!(
        seqs_after,
        (0..seqs_after.len() as u64).collect::<Vec<_>>(),
        "in order, no gap"
    );
    assert!(seqs_after.len() >= seqs.len());
    let mut kept = cut_file.into_os_string();
    kept.push(".cut");
    assert!(Path::new(&kept).exists());
}
