//! Cross-check of the exact truth against the independent renderer's
//! reference truth (`../shared/data/reference`, path in
//! `DROGUE_REFERENCE_DIR`): the image ellipse and the mirror pose from the
//! same circle must agree.
//!
//! Ignored by a plain `cargo test` (it needs the data); `.ci/run` runs it
//! with `--include-ignored`, and it fails when the variable is unset or names
//! a missing folder. (The simulator cannot use `drogue_vision::testing`: the
//! vision crate depends on this one, so the folder check is written here.)

use drogue_sim::camera::SimCamera;
use drogue_sim::conic::{circle_image_conic, conic_to_ellipse, mirror_pose};
use nalgebra::Vector3;
use std::path::PathBuf;

/// The reference frames' folder from `DROGUE_REFERENCE_DIR`; panics when the
/// variable is unset or names a folder without the `paper10/` set.
fn reference_dir() -> PathBuf {
    let dir = std::env::var_os("DROGUE_REFERENCE_DIR")
        .map(PathBuf::from)
        .expect("DROGUE_REFERENCE_DIR is not set: it must name the reference frames' folder");
    assert!(
        dir.join("paper10").is_dir(),
        "DROGUE_REFERENCE_DIR={} is not the reference frames' folder (no paper10/ in it)",
        dir.display()
    );
    dir
}

fn v3(v: &serde_json::Value) -> Vector3<f64> {
    Vector3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn truth_matches_the_independent_renderer() {
    let dir = reference_dir();
    let mut checked = 0;
    for set in ["paper10", "occlusion"] {
        let cam_text = std::fs::read_to_string(dir.join(set).join("camera.yaml")).unwrap();
        let cam = SimCamera::from_ros_yaml(&cam_text, "camera.yaml").unwrap();
        let truth = std::fs::read_to_string(dir.join(set).join("truth.jsonl")).unwrap();
        for line in truth.lines() {
            let t: serde_json::Value = serde_json::from_str(line).unwrap();
            if t["ellipse"].is_null() {
                continue;
            }
            let (c, n, r) = (
                v3(&t["position_camera"]),
                v3(&t["normal_camera"]),
                t["radius"].as_f64().unwrap(),
            );
            let e = conic_to_ellipse(&circle_image_conic(&cam, &c, &n, r).unwrap()).unwrap();
            let re = &t["ellipse"];
            let f = |k: &str| re[k].as_f64().unwrap();
            assert!(
                (e.cx - f("cx")).abs() < 1e-6 && (e.cy - f("cy")).abs() < 1e-6,
                "{set} {}",
                t["frame"]
            );
            assert!(
                (e.a - f("a")).abs() < 1e-6 && (e.b - f("b")).abs() < 1e-6,
                "{set} {}",
                t["frame"]
            );
            // theta is undefined for a circle; compare modulo pi otherwise.
            if e.a - e.b > 1e-3 {
                let d = (e.theta - f("theta")).rem_euclid(std::f64::consts::PI);
                assert!(
                    d.min(std::f64::consts::PI - d) < 1e-6,
                    "{set} {} theta",
                    t["frame"]
                );
            }
            let (mc, mn) = mirror_pose(&cam, &c, &n, r).unwrap();
            assert!(
                (mc - v3(&t["alt_position_camera"])).norm() < 1e-7,
                "{set} {} alt centre",
                t["frame"]
            );
            assert!(
                (mn - v3(&t["alt_normal_camera"])).norm() < 1e-7,
                "{set} {} alt normal",
                t["frame"]
            );
            checked += 1;
        }
    }
    assert!(checked >= 20, "only {checked} frames checked");
}
