//! `drogue-vision sim`: files written, their formats, and errors.

use drogue_vision::camera::CameraModel;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_drogue-vision"))
}

#[test]
fn sim_writes_frames_truth_and_camera() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("contact");
    let status = bin()
        .args(["sim", "--scenario", "contact", "--frames", "3", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    for k in 0..3 {
        let png = out.join(format!("frame_{k:06}.png"));
        let img = image::open(&png).unwrap();
        assert_eq!((img.width(), img.height()), (1280, 960));
        assert_eq!(img.color(), image::ColorType::L8);
    }
    assert!(!out.join("frame_000003.png").exists());
    let lines = drogue_vision::testing::read_json_lines(&out.join("truth.jsonl"));
    assert_eq!(lines.len(), 3);
    for (k, t) in lines.iter().enumerate() {
        assert_eq!(t["frame"], format!("frame_{k:06}.png"));
        for key in [
            "expect",
            "position_camera",
            "normal_camera",
            "alt_position_camera",
            "alt_normal_camera",
            "ellipse",
            "range_m",
            "tilt_deg",
            "probe_rim_frac",
            "hose_rim_frac",
            "position_body",
            "position_ned",
            "t",
        ] {
            assert!(!t[key].is_null(), "{key} missing");
        }
        let e = &t["ellipse"];
        assert!(e["a"].as_f64().unwrap() >= e["b"].as_f64().unwrap());
    }
    // camera.yaml is the simulator's camera, readable by drogue-vision.
    let yaml = std::fs::read_to_string(out.join("camera.yaml")).unwrap();
    let cam = CameraModel::from_yaml_str(&yaml, "camera.yaml").unwrap();
    let sim_cam = drogue_sim::Scenario::builtin("contact")
        .unwrap()
        .camera_model()
        .unwrap();
    assert!((cam.fx() - sim_cam.fx).abs() < 1e-12 && (cam.cy() - sim_cam.cy).abs() < 1e-12);
    assert!(cam.has_distortion());
}

#[test]
fn bad_scenario_names_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    std::fs::write(&file, "name = \"x\"\n[drogue]\ninner_radius_m = \"big\"\n").unwrap();
    let o = bin()
        .args(["sim", "--scenario"])
        .arg(&file)
        .arg("--out")
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("bad.toml") && err.contains("inner_radius_m"),
        "{err}"
    );
    let o = bin()
        .args(["sim", "--scenario", "no_such_scenario", "--out"])
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no_such_scenario"));
}
