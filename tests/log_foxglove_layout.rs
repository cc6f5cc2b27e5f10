//! The shipped Foxglove layout (`config/foxglove-layout.json`) names only
//! what a `run` log has: every topic of every panel, every field of every
//! plot, every transform frame, and the topics and fields its user script
//! reads. The log is made by the binary itself (`run`, simulated, 40 frames)
//! and read with the `mcap` crate.

use foxglove::Decode;
use foxglove::messages::FrameTransforms;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Follows `a.b[1].c` into a JSON value.
fn field<'a>(v: &'a Value, path: &str) -> Option<&'a Value> {
    let mut cur = v;
    for part in path.split('.') {
        let (name, index) = match part.split_once('[') {
            Some((n, rest)) => (n, rest.trim_end_matches(']').parse::<usize>().ok()),
            None => (part, None),
        };
        cur = cur.get(name)?;
        if let Some(i) = index {
            cur = cur.get(i)?;
        }
    }
    Some(cur)
}

/// Names after `prefix.` in the script source (`m.position_body` -> position_body).
fn fields_after(source: &str, prefix: &str) -> BTreeSet<String> {
    let pat = format!("{prefix}.");
    source
        .match_indices(&pat)
        .filter(|(i, _)| {
            *i == 0
                || !source.as_bytes()[i - 1].is_ascii_alphanumeric()
                    && source.as_bytes()[i - 1] != b'_'
        })
        .map(|(i, _)| {
            source[i + pat.len()..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect::<String>()
        })
        .filter(|f| !f.is_empty() && f != "size" && f != "set" && f != "get")
        .collect()
}

#[test]
fn every_topic_field_and_frame_the_layout_names_is_in_a_run_log() {
    let dir = tempfile::tempdir().unwrap();
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_drogue-vision"))
        .args(["run", "--max-frames", "40", "--fast", "--log-dir"])
        .arg(dir.path())
        .status()
        .unwrap();
    assert!(status.success());
    let log = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let bytes = std::fs::read(&log).unwrap();

    // What the log has: topics, the JSON messages per topic, /tf frames.
    let mut topics = BTreeSet::new();
    let mut json: BTreeMap<String, Vec<Value>> = BTreeMap::new();
    let mut frames = BTreeSet::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        topics.insert(m.channel.topic.clone());
        if m.channel.message_encoding == "json" {
            json.entry(m.channel.topic.clone())
                .or_default()
                .push(serde_json::from_slice(&m.data).unwrap());
        }
        if m.channel.topic == "/tf" {
            for t in FrameTransforms::decode(m.data.as_ref()).unwrap().transforms {
                frames.insert(t.parent_frame_id);
                frames.insert(t.child_frame_id);
            }
        }
    }

    let layout_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/foxglove-layout.json");
    let layout: Value = serde_json::from_slice(&std::fs::read(layout_path).unwrap()).unwrap();
    let configs = layout["configById"].as_object().unwrap();

    // The user scripts: their inputs must be in the log, their outputs are
    // topics the plots may use, the fields they read must be in the inputs.
    let mut script_outputs: BTreeMap<String, String> = BTreeMap::new();
    for node in layout["userNodes"].as_object().unwrap().values() {
        let src = node["sourceCode"].as_str().unwrap();
        let quoted = |after: &str| -> Vec<String> {
            let start = src.find(after).unwrap() + after.len();
            let end = start + src[start..].find(';').unwrap();
            src[start..end]
                .split('"')
                .skip(1)
                .step_by(2)
                .map(String::from)
                .collect()
        };
        for input in quoted("export const inputs =") {
            assert!(
                topics.contains(&input),
                "script input {input} not in the log"
            );
        }
        for output in quoted("export const output =") {
            script_outputs.insert(output, src.to_string());
        }
        for (prefix, topic) in [("m", "/drogue/detection"), ("truth", "/sim/truth")] {
            for f in fields_after(src, prefix) {
                assert!(
                    json[topic].iter().any(|v| v.get(&f).is_some()),
                    "script reads {topic}.{f}, not in the log"
                );
            }
        }
    }

    let mut named_topics = BTreeSet::new();
    let mut checked_fields = 0;
    for (id, cfg) in configs {
        let kind = id.split('!').next().unwrap();
        match kind {
            "Image" => {
                let im = &cfg["imageMode"];
                named_topics.insert(im["imageTopic"].as_str().unwrap().to_string());
                named_topics.insert(im["calibrationTopic"].as_str().unwrap().to_string());
                for t in im["annotations"].as_object().unwrap().keys() {
                    named_topics.insert(t.clone());
                }
            }
            "3D" => {
                for t in cfg["topics"].as_object().unwrap().keys() {
                    named_topics.insert(t.clone());
                }
                let follow = cfg["followTf"].as_str().unwrap();
                assert!(
                    frames.contains(follow),
                    "followTf {follow}: frames {frames:?}"
                );
                for k in cfg["transforms"].as_object().unwrap().keys() {
                    let f = k.strip_prefix("frame:").unwrap();
                    assert!(frames.contains(f), "frame {f} not in /tf: {frames:?}");
                }
            }
            "Plot" => {
                for p in cfg["paths"].as_array().unwrap() {
                    let value = p["value"].as_str().unwrap();
                    let (topic, path) = value[1..].split_once('.').unwrap();
                    let topic = format!("/{topic}");
                    if let Some(src) = script_outputs.get(&topic) {
                        assert!(
                            src.contains(&format!("{path}:")),
                            "{value}: not in the script"
                        );
                        continue;
                    }
                    named_topics.insert(topic.clone());
                    let messages = json
                        .get(&topic)
                        .unwrap_or_else(|| panic!("{value}: {topic} has no JSON messages"));
                    assert!(
                        messages
                            .iter()
                            .any(|m| field(m, path).is_some_and(serde_json::Value::is_number)),
                        "{value}: no number at that path in the log"
                    );
                    checked_fields += 1;
                }
            }
            "RawMessages" => {
                named_topics.insert(cfg["topicPath"].as_str().unwrap().to_string());
            }
            "Log" => {
                named_topics.insert(cfg["topicToRender"].as_str().unwrap().to_string());
            }
            other => panic!("panel {other} is not checked by this test"),
        }
    }
    for t in &named_topics {
        assert!(topics.contains(t), "{t} not in the log ({topics:?})");
    }
    assert!(checked_fields >= 6, "{checked_fields}");
    // The panels the issue asks for are all there.
    for kind in ["Image", "3D", "Plot", "RawMessages", "Log"] {
        assert!(configs.keys().any(|k| k.starts_with(kind)), "{kind}");
    }
    // Every panel of the mosaic has a config, and every config is placed.
    fn leaves(v: &Value, out: &mut BTreeSet<String>) {
        match v {
            Value::String(s) => {
                out.insert(s.clone());
            }
            Value::Object(o) => {
                for k in ["first", "second"] {
                    if let Some(c) = o.get(k) {
                        leaves(c, out);
                    }
                }
            }
            _ => {}
        }
    }
    let mut placed = BTreeSet::new();
    leaves(&layout["layout"], &mut placed);
    assert_eq!(placed, configs.keys().cloned().collect());
}
