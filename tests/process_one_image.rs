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
