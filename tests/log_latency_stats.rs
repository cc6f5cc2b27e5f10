//! The run's per-frame latency stamps and resource records in the log: what
//! goes in (known send times, known CPU totals) comes back out of the MCAP
//! and out of `review`.

mod log_support;

use drogue_vision::log::{FlightLog, review};
use log_support as s;
use std::collections::BTreeMap;
use std::sync::Arc;

const FRAMES: u64 = 20;
/// A detected frame whose pose the link never sends.
const NOT_SENT: u64 = 13;

fn detections(path: &std::path::Path) -> BTreeMap<u64, serde_json::Value> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == "/drogue/detection")
        .map(|m| {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            (v["frame"].as_str().unwrap().parse().unwrap(), v)
        })
        .collect()
}

#[test]
fn detection_records_carry_captured_measured_sent_and_logged() {
    let dir = tempfile::tempdir().unwrap();
    let log = FlightLog::start(&s::config(), dir.path(), &s::camera()).unwrap();
    let started_ns = s::T0_NS;
    for seq in 0..FRAMES {
        let m = Arc::new(s::measurement(seq));
        let mut json = s::detection_json(&m);
        json["latency_ns"] = serde_json::json!({
            "captured": m.capture_time_ns,
            "measured": m.capture_time_ns + 1_000_000,
        });
        let detected = m.detection.is_some();
        let event = s::link_event(seq, true);
        // The send event reaches the log before the record on even frames,
        // after it on odd ones (two threads race in `run`).
        if detected && seq != NOT_SENT && seq % 2 == 0 {
            log.mavlink(event.clone());
        }
        log.measurement_with_transforms(m, json, s::mount());
        if detected && seq != NOT_SENT && seq % 2 == 1 {
            log.mavlink(event);
        }
    }
    let path = log.finish().unwrap().files[0].clone();
    let records = detections(&path);
    assert_eq!(records.len() as u64, FRAMES);
    for (seq, r) in &records {
        let latency = &r["latency_ns"];
        assert_eq!(latency["captured"], s::time_ns(*seq));
        assert_eq!(latency["measured"], s::time_ns(*seq) + 1_000_000);
        let detected = r["detected"] == true;
        let expect_sent = detected && *seq != NOT_SENT;
        if expect_sent {
            let sent = s::time_ns(*seq) + (s::latency_ms(*seq) * 1e6) as u64;
            assert_eq!(latency["sent"], sent, "frame {seq}");
        } else {
            assert!(latency["sent"].is_null(), "frame {seq}: {latency}");
        }
        // Logged on the wall clock, after the synthetic capture time.
        let logged = latency["logged"].as_u64().unwrap();
        assert!(logged > started_ns, "frame {seq}");
    }
}

#[test]
fn review_reports_the_runs_resources_from_its_stats_records() {
    let dir = tempfile::tempdir().unwrap();
    let log = FlightLog::start(&s::config(), dir.path(), &s::camera()).unwrap();
    // Three samples a second apart: the process used 0.5 s of CPU per second,
    // the source 0.3 s of it, so the pipeline 20 % and the source 30 %.
    let samples = [
        (0.0, 0.0, 0.0, 40e6, 3, 1),
        (0.5, 0.3, 0.05, 52e6, 9, 0),
        (1.0, 0.6, 0.1, 47e6, 2, 4),
    ];
    for (i, (process, source, writer, rss, log_q, link_q)) in samples.into_iter().enumerate() {
        log.stats(serde_json::json!({
            "time_ns": s::T0_NS + i as u64 * 1_000_000_000,
            "interval_s": 1.0,
            "cpu_pct": {"process": 50.0, "source": 30.0, "pipeline": 20.0 + i as f64, "measurement": 10.0},
            "cpu_s_total": {"process": process, "source": source, "measurement": 0.1, "log_writer": writer},
            "rss_bytes": rss as u64,
            "queues": {"log": log_q, "log_dropped": 0, "link_events": link_q, "link_events_dropped": 0},
            "frames": {"in": 30 * i, "measured": 30 * i, "skipped": 0},
        }));
    }
    let path = log.finish().unwrap().files[0].clone();
    let r = review::review(&path, &dir.path().join("review")).unwrap();
    println!("{r}");
    let res = r.resources.clone().expect("resources reviewed");
    assert_eq!(res.samples, 3);
    // Over 2 s: process 1.0 s, source 0.6 s, log writer 0.1 s of CPU.
    assert!((res.pipeline_cpu_pct - 15.0).abs() < 1e-9, "{res:?}");
    assert!((res.source_cpu_pct - 30.0).abs() < 1e-9, "{res:?}");
    assert!((res.log_writer_cpu_pct - 5.0).abs() < 1e-9, "{res:?}");
    assert_eq!(res.pipeline_cpu_max_pct, 22.0);
    assert_eq!(res.peak_rss_bytes, 52_000_000);
    assert_eq!(res.max_log_queue, 9);
    assert_eq!(res.last_log_queue, 2);
    assert_eq!(res.max_link_event_queue, 4);
    assert!(r.to_string().contains("pipeline CPU 15.0 %"));
    assert!(r.to_string().contains("log writer 5.0 % besides"));
}
