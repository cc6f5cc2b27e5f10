//! `process IMAGE`: one image file is measured as a folder holding only it
//! (before, any file was read as an MCAP log: "Bad magic number"). Truth:
//! the simulator's `truth.jsonl`, and the same frame measured in its folder
//! as an unrelated view.

use drogue_vision::testing::read_json_lines;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_drogue-vision"))
}

#[test]
fn one_image_is_measured_as_in_its_folder() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    let sim = bin()
        .args(["sim", "--scenario", "approach", "--frames", "3", "--out"])
        .arg(&frames)
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let mut images: Vec<_> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    images.sort();
    let image = &images[1];
    let name = image.file_name().unwrap().to_string_lossy().into_owned();
    let camera = frames.join("camera.yaml");

    let one = dir.path().join("one.jsonl");
    let out = bin()
        .arg("process")
        .arg(image)
        .arg("--camera")
        .arg(&camera)
        .arg("--out")
        .arg(&one)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let one = read_json_lines(&one);
    assert_eq!(one.len(), 1);
    assert_eq!(one[0]["frame"], name.as_str());
    assert_eq!(one[0]["detected"], true, "{}", one[0]);

    let all = dir.path().join("all.jsonl");
    let out = bin()
        .arg("process")
        .arg(&frames)
        .arg("--independent")
        .arg("--camera")
        .arg(&camera)
        .arg("--out")
        .arg(&all)
        .output()
        .unwrap();
    assert!(out.status.success());
    let all = read_json_lines(&all);
    let same = all.iter().find(|r| r["frame"] == name.as_str()).unwrap();
    assert_eq!(one[0]["ellipse"], same["ellipse"]);
    assert_eq!(one[0]["position_camera"], same["position_camera"]);

    let truth = read_json_lines(&frames.join("truth.jsonl"));
    let t = truth.iter().find(|t| t["frame"] == name.as_str()).unwrap();
    let p = |v: &serde_json::Value| [0, 1, 2].map(|k| v[k].as_f64().unwrap());
    let (m, q) = (p(&one[0]["position_camera"]), p(&t["position_camera"]));
    let err = (0..3).map(|k| (m[k] - q[k]).powi(2)).sum::<f64>().sqrt();
    let range = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    assert!(err / range < 0.01, "{} % of range", 100.0 * err / range);
}

#[test]
fn one_image_needs_a_camera_and_leaves_no_files() {
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("frame.png");
    image::GrayImage::from_pixel(64, 48, image::Luma([128]))
        .save(&image)
        .unwrap();
    let out_path = dir.path().join("out.jsonl");
    let out = bin()
        .arg("process")
        .arg(&image)
        .arg("--out")
        .arg(&out_path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("needs --camera"), "{err}");
    assert!(!out_path.exists());
}

/// A folder (`frames` in `dir`) with the simulator's first approach frame
/// (a drogue, with its `camera.yaml`) and a uniform sky of the same size
/// under each of `skies` (no drogue, nothing dark).
fn drogue_and_skies(dir: &std::path::Path, skies: &[&str]) -> std::path::PathBuf {
    let frames = dir.join("frames");
    let sim = bin()
        .args(["sim", "--scenario", "approach", "--frames", "1", "--out"])
        .arg(&frames)
        .output()
        .unwrap();
    assert!(sim.status.success());
    let drogue = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "png"))
        .unwrap();
    let (w, h) = image::image_dimensions(&drogue).unwrap();
    for name in skies {
        image::GrayImage::from_pixel(w, h, image::Luma([170]))
            .save(frames.join(name))
            .unwrap();
    }
    frames
}

/// A frame without a drogue says why in its record (`not_detected`: the
/// reason's code, its words, the candidates tried); a frame with one has no
/// such field. Truth: a uniform sky has nothing dark in it (no candidate),
/// and the simulator's frame holds the drogue.
#[test]
fn a_frame_without_a_drogue_says_why_in_its_record() {
    let dir = tempfile::tempdir().unwrap();
    let frames = drogue_and_skies(dir.path(), &["sky.png"]);
    let out = dir.path().join("out.jsonl");
    let run = bin()
        .arg("process")
        .arg(&frames)
        .arg("--independent")
        .arg("--camera")
        .arg(frames.join("camera.yaml"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let summary = String::from_utf8_lossy(&run.stderr);
    assert!(
        summary.contains("not detected: no_candidate 1"),
        "{summary}"
    );
    let records = read_json_lines(&out);
    let sky = records.iter().find(|r| r["frame"] == "sky.png").unwrap();
    assert_eq!(sky["detected"], false);
    assert_eq!(sky["not_detected"]["reason"], "no_candidate", "{sky}");
    assert_eq!(sky["not_detected"]["candidates"], 0);
    assert!(
        sky["not_detected"]["detail"]
            .as_str()
            .unwrap()
            .contains("dark")
    );
    let found = records.iter().find(|r| r["frame"] != "sky.png").unwrap();
    assert_eq!(found["detected"], true, "{found}");
    assert!(found.get("not_detected").is_none(), "{found}");
}

/// `run` ends its summary with the misses by reason, as `process` does:
/// a folder of one drogue frame and two uniform skies gives
/// `not detected: no_candidate 2`.
#[test]
fn run_ends_with_the_misses_by_reason() {
    let dir = tempfile::tempdir().unwrap();
    let frames = drogue_and_skies(dir.path(), &["sky_1.png", "sky_2.png"]);
    let run = bin()
        .args(["run", "--fast", "--mavlink", "udpout:127.0.0.1:9"])
        .arg("--source")
        .arg(format!("dir:{}", frames.display()))
        .arg("--camera")
        .arg(frames.join("camera.yaml"))
        .arg("--log-dir")
        .arg(dir.path().join("logs"))
        .output()
        .unwrap();
    let summary = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{summary}");
    assert!(summary.contains("1 detected"), "{summary}");
    assert!(
        summary.contains("not detected: no_candidate 2"),
        "{summary}"
    );
}
