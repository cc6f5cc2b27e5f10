//! Replay reproduces a run's detections exactly: `run` logs a simulated
//! flight, `process LOG.mcap` measures the logged frames again, and every
//! record matches the logged `/drogue/detection` (read with the `mcap` crate).

use std::collections::BTreeMap;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

/// The camera-frame part of a record, as logged or replayed.
fn key_fields(v: &serde_json::Value) -> serde_json::Value {
    serde_json::json!({
        "detected": v["detected"],
        "ellipse": v["ellipse"],
        "position_camera": v["position_camera"],
        "normal_camera": v["normal_camera"],
        "normal_camera_alt": v["normal_camera_alt"],
    })
}

#[test]
fn replaying_a_log_reproduces_its_detections_exactly() {
    let dir = tempfile::tempdir().expect("tmp");
    let logs = dir.path().join("logs");
    // --fast: every frame is measured (an offline source waits for the
    // measurement), so the replay sees the same sequence.
    let status = Command::new(BIN)
        .args([
            "run",
            "--source",
            "sim:contact",
            "--fast",
            "--max-frames",
            "60",
        ])
        .args(["--mavlink", "udpout:127.0.0.1:14593", "--log-dir"])
        .arg(&logs)
        .status()
        .expect("run");
    assert!(status.success());
    let log = std::fs::read_dir(&logs)
        .expect("logs")
        .map(|e| e.expect("entry").path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("an mcap log");

    let bytes = std::fs::read(&log).expect("log");
    let mut logged = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("mcap") {
        let m = m.expect("message");
        if m.channel.topic == "/drogue/detection" {
            let v: serde_json::Value = serde_json::from_slice(&m.data).expect("json");
            let seq: u64 = v["frame"].as_str().expect("frame").parse().expect("seq");
            logged.insert(seq, key_fields(&v));
        }
    }
    assert_eq!(logged.len(), 60);
    assert!(
        logged.values().filter(|v| v["detected"] == true).count() >= 50,
        "too few detections to compare"
    );

    let out = dir.path().join("replay.jsonl");
    let relog = dir.path().join("relog").join("replay.mcap");
    let status = Command::new(BIN)
        .args(["process"])
        .arg(&log)
        .arg("--out")
        .arg(&out)
        .arg("--log")
        .arg(&relog)
        .status()
        .expect("process");
    assert!(status.success());
    let replayed = drogue_vision::testing::read_json_lines(&out);
    assert_eq!(replayed.len(), logged.len());
    for r in &replayed {
        let seq: u64 = r["frame"].as_str().expect("frame").parse().expect("seq");
        assert_eq!(key_fields(r), logged[&seq], "frame {seq} differs on replay");
    }

    // `process --log` wrote the replay's own log: the same frames, pixel for
    // pixel, and one /drogue/detection per JSON line, equal to it.
    let images = |bytes: &[u8]| -> Vec<Vec<u8>> {
        mcap::MessageStream::new(bytes)
            .expect("mcap")
            .map(|m| m.expect("message"))
            .filter(|m| m.channel.topic == "/camera/image")
            .map(|m| m.data.to_vec())
            .collect()
    };
    let relog_bytes = std::fs::read(&relog).expect("process --log wrote the file");
    assert_eq!(images(&relog_bytes), images(&bytes));
    let relogged: Vec<serde_json::Value> = mcap::MessageStream::new(&relog_bytes)
        .expect("mcap")
        .map(|m| m.expect("message"))
        .filter(|m| m.channel.topic == "/drogue/detection")
        .map(|m| serde_json::from_slice(&m.data).expect("json"))
        .collect();
    assert_eq!(relogged, replayed);

    // And the same `drogue_vision.run` metadata record as `run` writes (read
    // with the mcap crate's record reader), saying where the frames came from.
    let run_meta = run_metadata(&bytes);
    let relog_meta = run_metadata(&relog_bytes);
    let keys = |m: &BTreeMap<String, String>| -> Vec<String> {
        m.keys()
            .filter(|k| !k.starts_with("source."))
            .cloned()
            .collect()
    };
    assert_eq!(keys(&relog_meta), keys(&run_meta));
    for key in ["version", "git_hash"] {
        assert_eq!(relog_meta[key], run_meta[key], "{key}");
    }
    assert_eq!(relog_meta["source"], format!("mcap:{}", log.display()));
    assert_eq!(relog_meta["source.replayed_log"], log.display().to_string());
    assert_eq!(relog_meta["clock"], "source");
    for key in ["config_toml", "mount_toml"] {
        let parsed: toml::Table = toml::from_str(&relog_meta[key]).expect(key);
        assert!(!parsed.is_empty(), "{key} is empty");
    }
    let config: toml::Table = toml::from_str(&relog_meta["config_toml"]).expect("config");
    for section in ["drogue", "detect", "mount", "log", "link"] {
        assert!(
            config.contains_key(section),
            "config_toml has no [{section}]"
        );
    }
}

/// The `drogue_vision.run` metadata record of a log.
fn run_metadata(bytes: &[u8]) -> BTreeMap<String, String> {
    let mut found = Vec::new();
    for record in mcap::read::LinearReader::new(bytes).expect("mcap") {
        if let mcap::records::Record::Metadata(m) = record.expect("record")
            && m.name == "drogue_vision.run"
        {
            found.push(m.metadata);
        }
    }
    assert!(!found.is_empty(), "no drogue_vision.run metadata");
    found.swap_remove(0)
}
