//! The cone pose and the canopy-rim check on the independent renderer's
//! reference frames (`paper10`), fed with the TRUTH ellipse: the pose must
//! match the truth's position and both normals, and the canopy rim in the real
//! image must pick the true normal wherever the tilt makes the two differ.
//!
//! Runs when `DROGUE_REFERENCE_DIR` names the reference folder (the one with
//! `paper10/`); skipped, saying so, when it is not set.

use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::measure::Disambiguation;
use drogue_vision::measure::ambiguity::canopy_support;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::pose::{CirclePose, cone_pose};
use drogue_vision::measure::track::Tracker;
use nalgebra::Vector3;
use serde_json::Value;
use std::path::PathBuf;

fn reference_set(name: &str) -> Option<PathBuf> {
    let Some(dir) = std::env::var_os("DROGUE_REFERENCE_DIR") else {
        eprintln!("SKIPPED: DROGUE_REFERENCE_DIR is not set (the reference frames' folder)");
        return None;
    };
    let set = PathBuf::from(dir).join(name);
    assert!(
        set.join("truth.jsonl").is_file(),
        "DROGUE_REFERENCE_DIR is set but {} has no truth.jsonl",
        set.display()
    );
    Some(set)
}

fn vec3(v: &Value) -> Vector3<f64> {
    let a = v.as_array().expect("a 3-vector");
    Vector3::new(
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    )
}

fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

#[test]
fn paper10_truth_ellipse_gives_truth_pose_and_rim_picks_it() {
    let Some(set) = reference_set("paper10") else {
        return;
    };
    let camera = CameraModel::load(&set.join("camera.yaml")).unwrap();
    let config = Config::embedded();
    let canopy_radius = config.drogue.canopy_radius_m;
    let text = std::fs::read_to_string(set.join("truth.jsonl")).unwrap();
    let mut frames = 0;
    let mut answer_errors_deg = Vec::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let truth: Value = serde_json::from_str(line).unwrap();
        let name = truth["frame"].as_str().unwrap();
        let radius = truth["radius"].as_f64().unwrap();
        let e = &truth["ellipse"];
        let ellipse = Ellipse::new(
            e["cx"].as_f64().unwrap(),
            e["cy"].as_f64().unwrap(),
            e["a"].as_f64().unwrap(),
            e["b"].as_f64().unwrap(),
            e["theta"].as_f64().unwrap(),
        );
        let position = vec3(&truth["position_camera"]);
        let normal = vec3(&truth["normal_camera"]);
        let alt_position = vec3(&truth["alt_position_camera"]);
        let alt_normal = vec3(&truth["alt_normal_camera"]);
        let tilt_deg = truth["tilt_deg"].as_f64().unwrap();

        let solutions = cone_pose(&ellipse, &camera, radius).expect("a pose");
        let i = if angle(&solutions[0].normal_camera, &normal)
            <= angle(&solutions[1].normal_camera, &normal)
        {
            0
        } else {
            1
        };
        let (found, other): (CirclePose, CirclePose) = (solutions[i], solutions[1 - i]);
        let pos_err = (found.centre_camera_m - position).norm();
        let alt_pos_err = (other.centre_camera_m - alt_position).norm();
        let n_err = angle(&found.normal_camera, &normal);
        let alt_n_err = angle(&other.normal_camera, &alt_normal);
        println!(
            "{name}: tilt {tilt_deg:5.1} deg, position {pos_err:.1e} m (alt {alt_pos_err:.1e}), \
             normal {n_err:.1e} rad (alt {alt_n_err:.1e})"
        );
        assert!(pos_err < 1e-6, "{name}: position {pos_err}");
        assert!(alt_pos_err < 1e-6, "{name}: alt position {alt_pos_err}");
        assert!(n_err < 1e-6, "{name}: normal {n_err}");
        assert!(alt_n_err < 1e-6, "{name}: alt normal {alt_n_err}");

        let image = image::open(set.join(name)).unwrap().to_luma8();
        let supports = solutions.map(|s| canopy_support(&image, &camera, &s, canopy_radius));
        let mut tracker = Tracker::new(&config.track);
        let choice = tracker.choose(solutions, supports, 0, &ellipse);
        println!(
            "    canopy support: true {:?}, mirror {:?} -> {:?}",
            supports[i],
            supports[1 - i],
            choice.how
        );
        let given_err_deg = angle(&choice.pose.normal_camera, &normal).to_degrees();
        answer_errors_deg.push(given_err_deg);
        if tilt_deg > 5.0 {
            assert_eq!(
                choice.how,
                Disambiguation::CanopyRim,
                "{name}: the rim should decide at tilt {tilt_deg:.1} deg"
            );
            assert!(
                given_err_deg < 1e-4,
                "{name}: the rim picked the mirror solution"
            );
        }
        frames += 1;
    }
    assert_eq!(frames, 10, "paper10 has 10 frames");
    answer_errors_deg.sort_by(f64::total_cmp);
    println!(
        "normal error of the answer given (truth ellipse): median {:.2e} deg, max {:.2e} deg",
        answer_errors_deg[frames / 2],
        answer_errors_deg[frames - 1]
    );
}
