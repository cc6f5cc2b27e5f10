//! A stand-in sender for `tests/interop/mavlink_check.py` while the `run`
//! command is not there (and a way to check the script itself): streams a
//! deterministic approach through the real [`Link`] and writes its truth in
//! the simulator's `truth.jsonl` fields. Run by the script:
//!
//! ```text
//! python tests/interop/mavlink_check.py --sender \
//!   "cargo test --release --test link_interop -- --ignored --nocapture"
//! ```
//! The script passes `LINK_INTEROP_PORT`, `LINK_INTEROP_CONFIG` and
//! `LINK_INTEROP_TRUTH` in the environment.

mod link_common;

use drogue_vision::config::Config;
use drogue_vision::link::Link;
use link_common::*;
use std::io::Write;
use std::time::{Duration, Instant};

#[test]
#[ignore = "driven by tests/interop/mavlink_check.py"]
fn interop_sender() {
    let port: u16 = std::env::var("LINK_INTEROP_PORT")
        .expect("LINK_INTEROP_PORT")
        .parse()
        .unwrap();
    let truth_path = std::env::var("LINK_INTEROP_TRUTH").expect("LINK_INTEROP_TRUTH");
    let config = match std::env::var("LINK_INTEROP_CONFIG") {
        Ok(p) if !p.is_empty() => Config::load(Some(std::path::Path::new(&p))).unwrap(),
        _ => Config::embedded(),
    };
    let rt = runtime();
    let link = Link::start(
        &config.link,
        Some(&format!("udpout:127.0.0.1:{port}")),
        rt.handle(),
    )
    .unwrap();
    let mut truth = std::fs::File::create(&truth_path).unwrap();
    let frames = 150u64;
    let period = Duration::from_nanos(1_000_000_000 / 30);
    let start_ns = unix_now_ns();
    let start = Instant::now();
    for seq in 0..frames {
        let t = seq as f64 / 30.0;
        // Closing from 20 m to 3 m with a slow lateral and vertical weave;
        // the drogue's axis tilted a few degrees.
        let x = 20.0 - 17.0 * t / 5.0;
        let y = 0.6 * (0.8 * t).sin();
        let z = -0.4 + 0.3 * (0.5 * t).cos();
        let n = nalgebra::Vector3::new(-1.0, 0.08 * (0.3 * t).sin(), -0.05).normalize();
        // Every 50th frame has no detection: nothing may be sent for it.
        let detected = seq % 50 != 49;
        let capture = start_ns + (t * 1e9) as u64;
        let det = detected.then(|| detection([x, y, z], [n.x, n.y, n.z], 1));
        let wake = start + period * seq as u32;
        std::thread::sleep(wake.saturating_duration_since(Instant::now()));
        link.submit(measurement(seq, capture, det));
        let line = serde_json::json!({
            "frame": format!("frame_{seq:06}.png"), "seq": seq, "t": t,
            "expect": if detected { "detect" } else { "no_detect" },
            "position_body": [x, y, z], "normal_body": [n.x, n.y, n.z],
        });
        writeln!(truth, "{line}").unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    eprintln!("link stats: {:?}", link.stats());
    link.shutdown();
}
