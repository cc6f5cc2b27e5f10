//! `run` ends cleanly on SIGINT and survives SIGKILL with a readable log.
//! The logs are read with the `mcap` crate's own readers, not ours.

mod run_support;

use run_support::only_log;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

/// Starts `run` on the simulated approach (paced at 30 fps) into `log_dir`.
fn start_run(log_dir: &Path, port: u16) -> Child {
    Command::new(BIN)
        .args(["run", "--source", "sim:approach", "--mavlink"])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .arg("--log-dir")
        .arg(log_dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start run")
}

fn signal(child: &Child, sig: &str) {
    let status = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
}

/// `/camera/image` messages readable by streaming, and whether the stream
/// reached the file's end without an error.
fn stream_frames(bytes: &[u8]) -> (usize, bool) {
    let mut frames = 0;
    let Ok(stream) = mcap::MessageStream::new(bytes) else {
        return (0, false);
    };
    for m in stream {
        match m {
            Ok(m) if m.channel.topic == "/camera/image" => frames += 1,
            Ok(_) => {}
            Err(_) => return (frames, false),
        }
    }
    (frames, true)
}

/// Waits until the process has run for `secs` seconds of frames.
fn let_it_fly(secs: f64) -> Instant {
    let start = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(secs));
    start
}

#[test]
fn sigint_finishes_a_complete_indexed_log() {
    let dir = tempfile::tempdir().expect("tmp");
    let mut child = start_run(dir.path(), 14591);
    let_it_fly(3.0);
    signal(&child, "-INT");
    let status = child.wait().expect("wait");
    assert!(status.success(), "run ended with {status:?} on SIGINT");
    let bytes = std::fs::read(only_log(dir.path())).expect("log");
    let summary = mcap::Summary::read(&bytes)
        .expect("summary readable")
        .expect("an indexed log has a summary");
    assert!(!summary.chunk_indexes.is_empty(), "no chunk index");
    let (frames, complete) = stream_frames(&bytes);
    assert!(complete, "the log does not read to its end");
    // About 3 s at 30 fps went by before the signal.
    assert!(frames >= 45, "only {frames} frames logged");
}

#[test]
fn sigkill_leaves_a_log_readable_to_its_last_second() {
    let dir = tempfile::tempdir().expect("tmp");
    let mut child = start_run(dir.path(), 14592);
    // Wait until the log shows frames, then a little more, then kill.
    let log = loop {
        if let Ok(Some(p)) = std::fs::read_dir(dir.path()).map(|mut d| {
            d.find_map(|e| {
                e.ok()
                    .map(|e| e.path())
                    .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            })
        }) {
            break p;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    std::thread::sleep(Duration::from_secs(4));
    signal(&child, "-KILL");
    let _ = child.wait();
    let bytes = std::fs::read(&log).expect("log");
    let (frames, _) = stream_frames(&bytes);
    // Four seconds at 30 fps; at most about the last second may be lost
    // (sync every 0.5 s by default), plus start-up.
    assert!(frames >= 80, "only {frames} frames readable after SIGKILL");

    // `recover` makes it a complete, indexed file with those frames.
    let fixed = dir.path().join("fixed.mcap");
    let status = Command::new(BIN)
        .args(["recover"])
        .arg(&log)
        .arg("--out")
        .arg(&fixed)
        .status()
        .expect("recover");
    assert!(status.success());
    let fixed_bytes = std::fs::read(&fixed).expect("fixed");
    assert!(
        mcap::Summary::read(&fixed_bytes)
            .expect("summary")
            .is_some()
    );
    let (recovered_frames, complete) = stream_frames(&fixed_bytes);
    assert!(complete);
    // All of them, and possibly more: a plain read stops at a chunk the
    // kill cut short, while `recover` salvages that chunk's whole records
    // (seen as 120 against 119 on a loaded machine).
    assert!(
        recovered_frames >= frames,
        "{recovered_frames} frames recovered, {frames} readable before"
    );
}

/// `[run] realtime_priority`: out of range is a setup error (exit 2) naming
/// the key; in range, the three latency-path threads are made SCHED_FIFO
/// where the process may (root here, as in CI), and otherwise the run warns
/// and goes on.
#[test]
fn realtime_priority_is_applied_or_refused_with_a_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "[run]\nrealtime_priority = 120\n").unwrap();
    let out = Command::new(BIN)
        .args(["run", "--config"])
        .arg(&bad)
        .args(["--mavlink", "udpout:127.0.0.1:9", "--log-dir"])
        .arg(tmp.path().join("unused"))
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("realtime_priority = 120"), "{err}");

    let good = tmp.path().join("good.toml");
    std::fs::write(&good, "[run]\nrealtime_priority = 10\n").unwrap();
    let out = Command::new(BIN)
        .args(["run", "--max-frames", "20", "--config"])
        .arg(&good)
        .args(["--mavlink", "udpout:127.0.0.1:9", "--log-dir"])
        .arg(tmp.path().join("logs"))
        .env("RUST_LOG", "info")
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(0));
    let err = String::from_utf8_lossy(&out.stderr);
    // SAFETY: geteuid has no preconditions.
    let root = unsafe { libc::geteuid() } == 0;
    for thread in ["capture", "measurement", "link"] {
        let applied = format!("{thread} thread: SCHED_FIFO priority 10");
        let refused = format!("{thread} thread stays at normal priority");
        if root {
            assert!(err.contains(&applied), "{thread}: {err}");
        } else {
            assert!(
                err.contains(&refused) || err.contains(&applied),
                "{thread}: {err}"
            );
        }
    }
}
