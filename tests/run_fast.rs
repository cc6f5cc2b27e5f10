//! `run --fast` does what a user means (issue 15, item 6): the simulated
//! approach as fast as the pipeline goes still sends a pose for every
//! detected frame, and its log's time span (MCAP log_time, first to last,
//! across every topic) is the scenario's length, not the replay's date to
//! today. Then the same for a replay of that log (`mcap:`), whose capture
//! times are in the past.
//!
//! Truth from outside the code under test: the frames' capture times and the
//! scenario's length come from `drogue_sim` directly; the poses are counted
//! by a rust-mavlink peer on UDP; the log is read with the `mcap` crate.

mod run_support;

use drogue_sim::{Scenario, Simulator};
use run_support::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// `N detected` from the summary line.
fn detected_in_summary(stderr: &str) -> u64 {
    let line = stderr
        .lines()
        .find(|l| l.starts_with("run ended:"))
        .unwrap_or_else(|| panic!("no summary line in:\n{stderr}"));
    let words: Vec<&str> = line.split_whitespace().collect();
    let i = words
        .iter()
        .position(|w| *w == "detected")
        .unwrap_or_else(|| panic!("{line}"));
    words[i - 1].parse().unwrap()
}

/// What a fast run left: the poses received, and the log read back.
struct FastRun {
    received_us: Vec<u64>,
    detected_summary: u64,
    frames_summary: u64,
    log: Vec<Logged>,
    log_path: std::path::PathBuf,
}

fn fast_run(source: &str, dir: &Path, name: &str) -> FastRun {
    let logs = dir.join(name);
    // The default config: `max_rate_hz` 50 is kept on the source's clock,
    // so a 30 fps source is not thinned.
    let config = dir.join(format!("{name}.toml"));
    std::fs::write(&config, "").unwrap();
    let peer = Autopilot::start(None, 50.0);
    let run = run_with_peer(
        &["--fast".into(), "--source".into(), source.into()],
        peer,
        &logs,
        &config,
        &dir.join(format!("{name}.stderr")),
    );
    assert!(run.status.success(), "{}", run.stderr);
    let log_path = only_log(&logs);
    FastRun {
        received_us: run.received.iter().map(|r| r.target.time_usec).collect(),
        detected_summary: detected_in_summary(&run.stderr),
        frames_summary: frames_in_summary(&run.stderr),
        log: read_log(&log_path),
        log_path,
    }
}

/// Capture times (µs) of the frames the log's `/drogue/detection` says were
/// detected.
fn detected_frames_us(log: &[Logged]) -> BTreeSet<u64> {
    log.iter()
        .filter(|m| m.topic == "/drogue/detection")
        .filter(|m| {
            let r: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            r["detected"].as_bool().unwrap()
        })
        .map(|m| m.log_time_ns / 1000)
        .collect()
}

/// Every detected frame's pose was received, once, and nothing else.
fn check_a_pose_per_detected_frame(run: &FastRun, what: &str) {
    let detected = detected_frames_us(&run.log);
    assert_eq!(
        detected.len() as u64,
        run.detected_summary,
        "{what}: every measurement is logged"
    );
    let received: BTreeSet<u64> = run.received_us.iter().copied().collect();
    assert_eq!(
        received.len(),
        run.received_us.len(),
        "{what}: a frame's pose sent twice"
    );
    assert_eq!(
        received, detected,
        "{what}: poses received vs detected frames"
    );
}

/// First and last log_time over every topic, and per topic.
fn spans(log: &[Logged]) -> ((u64, u64), BTreeMap<String, (u64, u64)>) {
    let mut per: BTreeMap<String, (u64, u64)> = BTreeMap::new();
    for m in log {
        let e = per
            .entry(m.topic.clone())
            .or_insert((m.log_time_ns, m.log_time_ns));
        e.0 = e.0.min(m.log_time_ns);
        e.1 = e.1.max(m.log_time_ns);
    }
    let all = (
        per.values().map(|s| s.0).min().unwrap(),
        per.values().map(|s| s.1).max().unwrap(),
    );
    (all, per)
}

#[test]
fn fast_simulation_and_fast_replay_send_every_pose_and_log_the_real_length() {
    let tmp = tempfile::tempdir().unwrap();

    // The truth: the approach scenario's frames and their capture times.
    let scenario = Scenario::resolve("approach").unwrap();
    let (fps, duration_s) = (scenario.fps, scenario.duration_s);
    let mut sim = Simulator::new(scenario.clone()).unwrap();
    let mut capture_ns = Vec::new();
    while let Some(t) = sim.next_truth() {
        capture_ns.push(t.capture_time_ns);
    }
    let frames = capture_ns.len() as u64;
    let frame_period_s = 1.0 / fps;

    // 1. The simulation as fast as it goes.
    let run = fast_run("sim:approach", tmp.path(), "sim");
    assert_eq!(run.frames_summary, frames);
    let images: Vec<u64> = run
        .log
        .iter()
        .filter(|m| m.topic == "/camera/image")
        .map(|m| m.log_time_ns)
        .collect();
    assert_eq!(images, capture_ns, "every frame logged at its capture time");
    check_a_pose_per_detected_frame(&run, "sim");
    assert!(
        run.detected_summary * 10 >= frames * 9,
        "{} detected of {frames}",
        run.detected_summary
    );

    let ((first, last), per_topic) = spans(&run.log);
    let span_s = (last - first) as f64 * 1e-9;
    assert!(
        (span_s - duration_s).abs() <= frame_period_s,
        "log spans {span_s:.3} s, the scenario {duration_s} s: {per_topic:?}"
    );
    // One clock: no topic (MAVLink traffic, /log, /drogue/stats included)
    // outside the frames' capture times.
    let (first_frame, last_frame) = (capture_ns[0], capture_ns[capture_ns.len() - 1]);
    for topic in [
        "/mavlink/out",
        "/log",
        "/drogue/stats",
        "/drogue/pose",
        "/drogue/detection",
    ] {
        let (a, b) = per_topic
            .get(topic)
            .unwrap_or_else(|| panic!("no {topic}: {per_topic:?}"));
        assert!(
            first_frame <= *a && *b <= last_frame,
            "{topic} from {a} to {b}, frames from {first_frame} to {last_frame}"
        );
    }
    // What `review` makes of it: the run's length, and no latency (the
    // source's clock stands still while a frame is processed).
    let review = std::process::Command::new(BIN)
        .arg("review")
        .arg(&run.log_path)
        .arg("--out")
        .arg(tmp.path().join("review"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&review.stdout);
    assert!(review.status.success(), "{text}");
    assert!(
        text.contains(&format!("duration   {duration_s:.1} s")),
        "{text}"
    );
    assert!(text.contains("latency    not measured"), "{text}");
    eprintln!(
        "run --fast sim:approach: {} poses received for {} detected frames of {frames}; \
         log span {span_s:.3} s for a {duration_s} s scenario",
        run.received_us.len(),
        run.detected_summary
    );

    // 2. A replay of that log, whose capture times are now in the past.
    let replay = fast_run(
        &format!("mcap:{}", run.log_path.display()),
        tmp.path(),
        "replay",
    );
    assert_eq!(replay.frames_summary, frames);
    check_a_pose_per_detected_frame(&replay, "replay");
    let ((first, last), per_topic) = spans(&replay.log);
    assert_eq!(
        (first, last),
        (first_frame, last_frame),
        "the replay's log spans the replayed frames: {per_topic:?}"
    );
    eprintln!(
        "run --fast mcap: {} poses received for {} detected frames; log span {:.3} s",
        replay.received_us.len(),
        replay.detected_summary,
        (last - first) as f64 * 1e-9
    );
}
