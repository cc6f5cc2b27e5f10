//! `run` end to end: the simulated approach for 300 frames, paced at 30 fps,
//! with a rust-mavlink peer listening on UDP. The LANDING_TARGET (BODY_FRD)
//! it receives must match the simulator's truth, computed here by
//! `drogue_sim` directly (not read from the run's log), within 1 % of range;
//! every frame must be in the MCAP; the process must end by itself with
//! status 0.
//!
//! Matching: a LANDING_TARGET's time_usec is its frame's capture time; the
//! log's `/camera/image` gives each frame's capture time by sequence number,
//! and the sequence number picks the truth.

mod run_support;

use drogue_sim::{Scenario, Simulator};
use mavlink::dialects::ardupilotmega::{LandingTargetType, MavBool, MavFrame};
use run_support::*;
use std::collections::HashMap;
use std::time::Instant;

const FRAMES: u64 = 300;

#[test]
fn approach_landing_targets_match_the_truth_and_every_frame_is_logged() {
    let tmp = tempfile::tempdir().unwrap();
    let logs = tmp.path().join("logs");
    let config = tmp.path().join("e2e.toml");
    // Every measurement goes out (no rate limit), so every detected frame
    // can be checked.
    std::fs::write(&config, "[link]\nmax_rate_hz = 0.0\n").unwrap();
    let peer = Autopilot::start(None, 50.0);
    let started = Instant::now();
    let PeerRun {
        status,
        received,
        stderr,
    } = run_with_peer(
        &[
            "--source".into(),
            "sim:approach".into(),
            "--max-frames".into(),
            FRAMES.to_string(),
        ],
        peer,
        &logs,
        &config,
        &tmp.path().join("stderr.txt"),
    );
    let elapsed = started.elapsed();
    assert!(status.success(), "run ended with {status:?}:\n{stderr}");
    assert_eq!(frames_in_summary(&stderr), FRAMES, "{stderr}");

    // Every frame is in the log; each one's capture time by sequence number.
    let log = read_log(&only_log(&logs));
    let capture_us_by_seq: HashMap<u32, u64> = log
        .iter()
        .filter(|m| m.topic == "/camera/image")
        .map(|m| (m.sequence, m.log_time_ns / 1000))
        .collect();
    let images = log.iter().filter(|m| m.topic == "/camera/image").count();
    assert_eq!(images as u64, FRAMES);
    assert_eq!(
        capture_us_by_seq.len() as u64,
        FRAMES,
        "repeated sequence numbers"
    );
    let seq_by_capture_us: HashMap<u64, u32> =
        capture_us_by_seq.iter().map(|(s, t)| (*t, *s)).collect();

    // The truth, from the simulator itself.
    let mut sim = Simulator::new(Scenario::resolve("approach").unwrap()).unwrap();
    let truth: Vec<_> = (0..FRAMES).map(|_| sim.next_truth().unwrap()).collect();
    let expected_detections = truth.iter().filter(|t| t.expect == "detect").count();

    let mut errors = Vec::new();
    for r in &received {
        let t = &r.target;
        assert_eq!(t.frame, MavFrame::MAV_FRAME_BODY_FRD);
        assert_eq!(
            t.mavtype,
            LandingTargetType::LANDING_TARGET_TYPE_VISION_OTHER
        );
        assert_eq!(t.position_valid, MavBool::MAV_BOOL_TRUE);
        let seq = *seq_by_capture_us
            .get(&t.time_usec)
            .unwrap_or_else(|| panic!("LANDING_TARGET time_usec {} is no frame's", t.time_usec));
        let tr = &truth[seq as usize];
        let got = [t.x, t.y, t.z].map(f64::from);
        let want = tr.position_body;
        let err = (0..3)
            .map(|i| (got[i] - want[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        let range = want.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(
            err <= 0.01 * range,
            "frame {seq}: LANDING_TARGET {got:?} vs truth {want:?}: {err:.3} m at {range:.1} m"
        );
        let distance = got.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((f64::from(t.distance) - distance).abs() < 1e-3 * distance);
        errors.push(err / range);
    }
    assert!(
        received.len() * 10 >= expected_detections * 9,
        "{} LANDING_TARGET for {expected_detections} frames with the drogue in view",
        received.len()
    );
    // Per-frame latency stamps in /drogue/detection: in order, and the sent
    // stamp of every frame whose LANDING_TARGET the peer received lies
    // between its measurement and the peer's arrival time (same host clock;
    // the link stamps as the socket write starts).
    let arrival_by_capture_us: HashMap<u64, u64> = received
        .iter()
        .map(|r| (r.target.time_usec, r.arrival_ns))
        .collect();
    let mut stamped_sent = 0;
    for m in log.iter().filter(|m| m.topic == "/drogue/detection") {
        let record: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let l = &record["latency_ns"];
        let stamp = |k: &str| l[k].as_u64();
        let (captured, measured, logged) = (
            stamp("captured").unwrap(),
            stamp("measured").unwrap(),
            stamp("logged").unwrap(),
        );
        assert_eq!(captured, m.log_time_ns);
        assert!(captured <= measured && measured <= logged, "{l}");
        if let Some(arrival) = arrival_by_capture_us.get(&(captured / 1000)) {
            let sent =
                stamp("sent").unwrap_or_else(|| panic!("received but not stamped sent: {l}"));
            assert!(
                measured <= sent && sent <= *arrival,
                "{l}, arrival {arrival}"
            );
            stamped_sent += 1;
        }
    }
    assert_eq!(stamped_sent, received.len());
    errors.sort_by(f64::total_cmp);
    eprintln!(
        "end to end: {} LANDING_TARGET for {FRAMES} frames ({expected_detections} in view) in \
         {:.1} s; error / range median {:.3} %, worst {:.3} %",
        received.len(),
        elapsed.as_secs_f64(),
        100.0 * errors[errors.len() / 2],
        100.0 * errors[errors.len() - 1]
    );
}
