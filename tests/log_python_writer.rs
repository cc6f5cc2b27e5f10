//! A log written by another tool: `tests/fixtures/python_zstd/log.mcap`, made
//! by the Python `mcap` writer (mcap-protobuf-support, zstd chunks) with our
//! topics by `tests/fixtures/make_python_zstd.py`, beside the same frames as
//! PNG files. Everything here reads it correctly: replay gives the PNGs'
//! pixels (decoded by the `image` crate), `process` gives exactly the
//! detections of the PNG folder, review reads it whole (not cut short, not
//! damaged), and recover copies every message.

use drogue_vision::log::{reader, recover};
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/python_zstd")
}

/// `process --independent` of `input`: the JSON records without the fields
/// that name the input (file name or sequence number) or time it.
fn process(input: &Path, camera: Option<&Path>, out: &Path) -> Vec<serde_json::Value> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_drogue-vision"));
    cmd.arg("process")
        .arg(input)
        .arg("--independent")
        .arg("--out")
        .arg(out);
    if let Some(c) = camera {
        cmd.arg("--camera").arg(c);
    }
    assert!(cmd.status().unwrap().success());
    std::fs::read_to_string(out)
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            let o = v.as_object_mut().unwrap();
            for k in ["frame", "times_us", "capture_time_ns"] {
                o.remove(k);
            }
            v
        })
        .collect()
}

#[test]
fn a_python_written_zstd_log_is_replayed_processed_reviewed_and_recovered() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture().join("log.mcap");
    let bytes = std::fs::read(&log).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(
        summary
            .chunk_indexes
            .iter()
            .all(|c| c.compression == "zstd")
    );

    // Replay: every frame, pixel for pixel the PNG written beside it.
    let frames: Vec<_> = drogue_vision::source::replay::open(&log)
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(frames.len(), 4);
    for f in &frames {
        let png = fixture().join(format!("frames/frame_{:06}.png", f.seq));
        assert_eq!(f.image, image::open(png).unwrap().into_luma8(), "{}", f.seq);
    }

    // process: the same detections as from the PNG folder and camera file.
    let from_log = process(&log, None, &dir.path().join("a.jsonl"));
    let from_pngs = process(
        &fixture().join("frames"),
        Some(&fixture().join("camera.yaml")),
        &dir.path().join("b.jsonl"),
    );
    assert_eq!(from_log.len(), 4);
    assert!(from_log.iter().all(|r| r["detected"] == true));
    assert_eq!(from_log, from_pngs);

    // review: whole, not cut short, not damaged.
    let r = drogue_vision::log::review::review(&log, &dir.path().join("rev")).unwrap();
    assert_eq!((r.cut.clone(), r.damaged.clone()), (None, None), "{r}");
    assert_eq!(r.frames, 4);
    assert!(!r.to_string().contains("CUT SHORT"));

    // recover: every message, nothing reported.
    let out = dir.path().join("copy.mcap");
    let rep = recover::recover(&log, &out).unwrap();
    let n = summary.stats.unwrap().message_count;
    assert_eq!(
        (rep.messages, rep.cut.clone(), rep.damaged.len()),
        (n, None, 0),
        "{rep}"
    );
    let copied = reader::message_reader(&out).unwrap().flatten().count();
    assert_eq!(copied as u64, n);
}
