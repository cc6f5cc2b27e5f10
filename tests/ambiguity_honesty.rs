//! Ambiguity honesty (issue 12, item 4): the canopy rim settles the two-fold
//! pose ambiguity only where its two predictions really separate, and
//! continuity only between poses close in time and space. Frames and truth
//! from the simulator (`drogue_sim::sweep`, exact conics); the reference
//! range set through `DROGUE_REFERENCE_DIR` (ignored by a plain `cargo test`;
//! `.ci/run` runs it with `--include-ignored`).

mod common;
mod sweep;

use drogue_sim::TruthEllipse;
use drogue_sim::conic::{circle_image_conic, conic_to_ellipse};
use drogue_sim::geometry::V3;
use drogue_sim::sweep::{CANOPY_RADIUS_M, DrogueTruth, Factor, Level, Sweep, SweepFrame};
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::measure::{Disambiguation, Measurement, Measurer};
use drogue_vision::testing;
use std::path::{Path, PathBuf};

fn frame(f: &SweepFrame, seq: u64, capture_time_ns: u64) -> Frame {
    Frame {
        seq,
        capture_time_ns,
        image: f.image.clone(),
        origin: FrameOrigin::File(PathBuf::from(format!("sweep/{}", f.level.label()))),
    }
}

fn measurer(f: &SweepFrame) -> Measurer {
    let camera = testing::camera_from_sim(&f.camera, "sim");
    Measurer::new(camera, &Config::embedded().measure()).unwrap()
}

fn point_on(e: &TruthEllipse, t: f64) -> [f64; 2] {
    let (s, c) = e.theta.sin_cos();
    let (x, y) = (e.a * t.cos(), e.b * t.sin());
    [e.cx + c * x - s * y, e.cy + s * x + c * y]
}

/// Largest distance (undistorted px) from the canopy rim of the true pose to
/// that of the mirror pose: how far apart the two solutions' rims truly are,
/// from the simulator's conics.
fn rim_separation_px(f: &SweepFrame, t: &DrogueTruth) -> f64 {
    let rim = |c: [f64; 3], n: [f64; 3]| {
        conic_to_ellipse(
            &circle_image_conic(&f.camera, &V3::from(c), &V3::from(n), CANOPY_RADIUS_M).unwrap(),
        )
        .unwrap()
    };
    let truth = rim(t.position_camera, t.normal_camera);
    let mirror = rim(t.alt_position_camera, t.alt_normal_camera);
    let dense: Vec<[f64; 2]> = (0..2000)
        .map(|k| point_on(&mirror, k as f64 * std::f64::consts::TAU / 2000.0))
        .collect();
    (0..360)
        .map(|k| {
            let p = point_on(&truth, k as f64 * std::f64::consts::TAU / 360.0);
            dense
                .iter()
                .map(|q| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

fn chose_truth(m: &Measurement, t: &DrogueTruth) -> bool {
    let n = m.detection.as_ref().unwrap().pose_camera.normal_camera;
    let angle = |a: [f64; 3]| common::angle_deg(&n, &common::v3(a));
    angle(t.normal_camera) <= angle(t.alt_normal_camera)
}

/// Range-set-like frames (tilt 20 degrees, noise, the drogue anywhere): at
/// 12 and 16 m the rims are under a pixel apart and the answer must be
/// `unresolved`; wherever the rim decides, it must pick the truth; at 8 m,
/// where the rims are about a pixel apart on a clear frame, it still decides.
#[test]
fn the_rim_decides_only_where_the_rims_separate() {
    let mut sweep = Sweep::new(sweep::SEED);
    for range in [8.0, 12.0, 16.0] {
        let level = Level::new(Factor::Range, range);
        let (mut rim, mut unresolved, mut detected) = (0, 0, 0);
        for index in 0..10 {
            let f = sweep.frame(&level, index);
            let t = f.drogue.unwrap();
            let mut m = measurer(&f);
            let meas = m.measure(&frame(&f, index, 0));
            let Some(d) = &meas.detection else { continue };
            detected += 1;
            let separation = rim_separation_px(&f, &t);
            match d.disambiguation {
                Disambiguation::CanopyRim => {
                    rim += 1;
                    assert!(
                        chose_truth(&meas, &t),
                        "{range} m frame {index}: canopy_rim picked the mirror"
                    );
                    assert!(
                        separation >= 1.0,
                        "{range} m frame {index}: canopy_rim with rims {separation:.2} px apart"
                    );
                }
                Disambiguation::Unresolved => {
                    unresolved += 1;
                    assert!(d.alt_pose_camera.is_some());
                }
                Disambiguation::Continuity => panic!("continuity on a single frame"),
            }
        }
        eprintln!("{range} m: {detected} detected, canopy_rim {rim}, unresolved {unresolved}");
        assert!(detected >= 9, "{range} m: {detected} of 10 detected");
        if range >= 12.0 {
            assert_eq!(rim, 0, "{range} m: the rim decided");
        } else {
            assert!(
                rim >= 8,
                "{range} m: the rim decided only {rim} of {detected}"
            );
        }
    }
}

/// A rim-settled frame followed 33 ms later by an unrelated one (a folder
/// processed as a sequence): the second does not borrow the first's normal.
#[test]
fn an_unrelated_frame_in_sequence_does_not_use_continuity() {
    let mut sweep = Sweep::new(sweep::SEED);
    for index in 0..4 {
        let near = sweep.frame(&Level::new(Factor::Range, 3.0), index);
        let far = sweep.frame(&Level::new(Factor::Range, 16.0), index);
        let mut m = measurer(&near);
        let first = m.measure(&frame(&near, 0, 0));
        let d = first.detection.as_ref().expect("3 m drogue detected");
        assert_eq!(d.disambiguation, Disambiguation::CanopyRim);
        let second = m.measure(&frame(&far, 1, 33_333_333));
        let d = second.detection.as_ref().expect("16 m drogue detected");
        assert_eq!(
            d.disambiguation,
            Disambiguation::Unresolved,
            "pair {index}: the 16 m frame was settled by {:?}",
            d.disambiguation
        );
    }
}

/// `process` on a folder of unrelated frames without `--independent` (it
/// stamps them 33 ms apart): no record is settled by continuity.
#[test]
fn process_folder_without_independent_does_not_borrow_normals() {
    let dir = tempfile::tempdir().unwrap();
    let mut sweep = Sweep::new(sweep::SEED);
    let mut camera = None;
    for k in 0..8u64 {
        let range = if k % 2 == 0 { 3.0 } else { 12.0 };
        let f = sweep.frame(&Level::new(Factor::Range, range), 100 + k);
        f.image
            .save(dir.path().join(format!("frame_{k:02}.png")))
            .unwrap();
        camera = Some(f.camera);
    }
    let yaml = dir.path().join("camera.yaml");
    std::fs::write(&yaml, camera.unwrap().ros_yaml("sim")).unwrap();
    let out = dir.path().join("out.jsonl");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_drogue-vision"))
        .args(["process", "--camera"])
        .arg(&yaml)
        .arg("--out")
        .arg(&out)
        .arg(dir.path())
        .status()
        .unwrap();
    assert!(status.success());
    let how: Vec<String> = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter_map(|r| r["disambiguation"].as_str().map(str::to_string))
        .collect();
    assert!(how.len() >= 7, "{how:?}");
    assert!(how.iter().any(|h| h == "canopy_rim"), "{how:?}");
    assert!(!how.iter().any(|h| h == "continuity"), "{how:?}");
}

/// The reference range set, as unrelated views and as a sequence: never
/// `canopy_rim` with the mirror's normal, never `continuity`.
#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn reference_range_set_is_honest() {
    let set = testing::reference_set("range");
    let truth = testing::read_truths(&set);
    for independent in [true, false] {
        let records = process(&set, independent);
        for t in &truth {
            let frame = t.frame.as_str();
            let r = records.iter().find(|r| r["frame"] == frame).unwrap();
            let how = r["disambiguation"].as_str().unwrap_or("-");
            let group = t.group.as_deref().unwrap_or("-");
            eprintln!("independent {independent} {frame} {group}: {how}");
            assert_ne!(how, "continuity", "{frame}");
            if how == "canopy_rim" {
                let v = |x: &serde_json::Value| {
                    let a: Vec<f64> = x
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|v| v.as_f64().unwrap())
                        .collect();
                    common::v3([a[0], a[1], a[2]])
                };
                let n = v(&r["normal_camera"]);
                let truth_normal = |a: Option<[f64; 3]>| common::v3(a.expect("a truth normal"));
                let (e, e_alt) = (
                    common::angle_deg(&n, &truth_normal(t.normal_camera)),
                    common::angle_deg(&n, &truth_normal(t.alt_normal_camera)),
                );
                assert!(e <= e_alt, "{frame}: canopy_rim with the mirror normal");
            }
        }
    }
}

fn process(set: &Path, independent: bool) -> Vec<serde_json::Value> {
    let out = tempfile::tempdir().unwrap();
    let jsonl = out.path().join("out.jsonl");
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_drogue-vision"));
    cmd.arg("process");
    if independent {
        cmd.arg("--independent");
    }
    let status = cmd
        .arg("--camera")
        .arg(set.join("camera.yaml"))
        .arg("--out")
        .arg(&jsonl)
        .arg(set)
        .status()
        .unwrap();
    assert!(status.success());
    testing::read_json_lines(&jsonl)
}
