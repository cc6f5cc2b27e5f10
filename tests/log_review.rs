//! `review` on a log whose every figure is known from what was written.

mod log_support;

use drogue_vision::link::LinkEvent;
use drogue_vision::log::{FlightLog, LogError, review};
use log_support as s;
use std::path::{Path, PathBuf};
use tracing_subscriber::layer::SubscriberExt;

const FRAMES: u64 = 60;
/// A frame the source "lost": never logged.
const LOST: u64 = 7;

fn logged_seqs() -> impl Iterator<Item = u64> {
    (0..FRAMES).filter(|&s| s != LOST)
}

/// Autopilot heartbeats at these seconds: one gap of 6 s (> 3 s).
const HEARTBEAT_S: [u64; 5] = [0, 1, 2, 8, 9];

fn write(dir: &Path) -> PathBuf {
    let log = FlightLog::start(&s::config(), dir, &s::camera()).unwrap();
    for seq in logged_seqs() {
        s::log_frame(&log, seq, true);
        log.mavlink(s::link_event(seq, true));
    }
    for k in HEARTBEAT_S {
        log.mavlink(LinkEvent {
            time_ns: s::T0_NS + k * 1_000_000_000,
            outgoing: false,
            name: "HEARTBEAT".into(),
            capture_time_ns: None,
            fields: serde_json::json!({}),
        });
    }
    let subscriber = tracing_subscriber::registry().with(log.tracing_layer());
    tracing::subscriber::with_default(subscriber, || tracing::warn!("autopilot heartbeat lost"));
    let summary = log.finish().unwrap();
    summary.files[0].clone()
}

/// Nearest-rank quantile of a sample, computed directly.
fn nearest_rank(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

#[test]
fn review_counts_rates_latencies_link_and_errors_by_range() {
    let dir = tempfile::tempdir().unwrap();
    let log = write(dir.path());
    let out = dir.path().join("review");
    let r = review::review(&log, &out).unwrap();
    println!("{r}");

    let n = logged_seqs().count() as u64;
    let detected = logged_seqs().filter(|s| !s.is_multiple_of(5)).count() as u64;
    assert_eq!(r.cut, None);
    assert_eq!((r.frames, r.measurements, r.detected), (n, n, detected));
    assert_eq!(r.frames_lost, 1);
    let span_s = (s::time_ns(FRAMES - 1) - s::time_ns(0)) as f64 * 1e-9;
    assert!((r.duration_s() - span_s).abs() < 1e-9);
    assert!((r.detection_rate() - detected as f64 / n as f64).abs() < 1e-12);
    // The frames without a drogue, by the reason each record gave.
    let mut reasons = std::collections::BTreeMap::new();
    for seq in logged_seqs().filter(|s| s.is_multiple_of(5)) {
        *reasons
            .entry(s::miss_reason(seq).code().to_string())
            .or_insert(0u64) += 1;
    }
    assert_eq!(r.missed_by_reason, reasons);
    assert!(
        r.to_string()
            .contains("not detected: blurred 6, no_canopy 6"),
        "{r}"
    );

    // Latency and processing percentiles against the values written.
    let latencies: Vec<f64> = logged_seqs().map(s::latency_ms).collect();
    let processing: Vec<f64> = logged_seqs()
        .map(|s| f64::from(1600 + (s as u32 % 10) * 100) / 1000.0)
        .collect();
    for q in [0.5, 0.95, 0.99] {
        assert!((r.latency_ms.quantile(q) - nearest_rank(latencies.clone(), q)).abs() <= 0.01);
        assert!((r.processing_ms.quantile(q) - nearest_rank(processing.clone(), q)).abs() <= 0.01);
    }

    assert_eq!(r.mavlink_out.get("LANDING_TARGET"), Some(&n));
    assert_eq!(r.heartbeats_in, HEARTBEAT_S.len() as u64);
    assert_eq!(r.link_losses, 1);
    assert!((r.longest_heartbeat_gap_s - 6.0).abs() < 1e-9);
    assert_eq!((r.warnings, r.errors), (1, 0));
    assert!(r.problems[0].contains("autopilot heartbeat lost"));

    // Errors against truth by range: the estimates are truth + error_m(seq)
    // along x, normals exact.
    assert_eq!(r.truth_frames, n);
    for b in r.by_range.iter() {
        let in_bin: Vec<u64> = logged_seqs()
            .filter(|&s| {
                let range = s::truth(s).range_m;
                range >= b.lo_m && range < b.hi_m
            })
            .collect();
        let det: Vec<f64> = in_bin
            .iter()
            .filter(|&&s| !s.is_multiple_of(5))
            .map(|&s| s::error_m(s))
            .collect();
        assert_eq!(b.frames, in_bin.len() as u64, "bin {b}");
        assert_eq!(b.detected, det.len() as u64, "bin {b}");
        if !det.is_empty() {
            let mean = det.iter().sum::<f64>() / det.len() as f64;
            assert!((b.mean_pos_err_m() - mean).abs() < 1e-9, "bin {b}");
            assert!(b.max_normal_err_deg < 1e-5, "bin {b}");
        }
    }
    assert!(r.by_range.iter().filter(|b| b.frames > 0).count() >= 2);

    // poses.csv: a header and one row per measurement, with the error.
    let csv = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len() as u64, n + 1);
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let row: Vec<&str> = lines[2].split(',').collect(); // seq 1, detected
    assert_eq!(row[col("seq")], "1");
    assert_eq!(row[col("detected")], "1");
    let err: f64 = row[col("position_error_m")].parse().unwrap();
    assert!((err - s::error_m(1)).abs() < 1e-9);
    let z: f64 = row[col("truth_position_camera_z_m")].parse().unwrap();
    assert_eq!(z, s::centre_camera_m(1).z);
    assert_eq!(row[col("not_detected")], "");
    // seq 10, not detected: its reason's code.
    let missed: Vec<&str> = lines[10].split(',').collect();
    assert_eq!(missed[col("seq")], "10");
    assert_eq!(missed[col("not_detected")], s::miss_reason(10).code());

    for name in [
        "position_body.png",
        "position_camera.png",
        "detections.png",
        "error_vs_time.png",
        "error_vs_range.png",
        "latency.png",
    ] {
        let img = image::open(out.join(name)).unwrap();
        assert!(img.width() > 100, "{name}");
    }
    assert_eq!(r.plot_error, None);
}

#[test]
fn review_of_a_cut_short_log_reads_up_to_the_cut_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let log = write(dir.path());
    let bytes = std::fs::read(&log).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let r = review::review(&cut, &dir.path().join("review")).unwrap();
    assert!(r.cut.is_some());
    assert!(r.frames > 0 && r.frames < logged_seqs().count() as u64);
    assert!(format!("{r}").contains("CUT SHORT"));
}

#[test]
fn review_of_a_file_that_is_not_mcap_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.mcap");
    std::fs::write(&bad, b"this is not an MCAP file at all").unwrap();
    let e = review::review(&bad, &dir.path().join("review")).unwrap_err();
    assert!(matches!(e, LogError::Format { .. }), "{e}");
}
