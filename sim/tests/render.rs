//! Rendering checked against the geometric truth.

use drogue_sim::{FrameTruth, Intensity, Scenario, Simulator};
use image::GrayImage;

/// The approach without noise, clouds, vignetting, distortion, blur, struts.
fn clean_approach() -> Scenario {
    let mut s = Scenario::builtin("approach").unwrap();
    s.camera.read_noise_dn = 0.0;
    s.camera.shot_noise_dn = 0.0;
    s.camera.vignette = 0.0;
    s.camera.distortion = [0.0; 5];
    s.scene.cloud_cover = 0.0;
    s.scene.motion_blur = false;
    s.drogue.struts = 0;
    s.turbulence.intensity = Intensity::None;
    s
}

fn frame_at(s: Scenario, seq: u64) -> (GrayImage, FrameTruth) {
    let mut sim = Simulator::new(s).unwrap();
    for _ in 0..seq {
        sim.next_truth().unwrap();
    }
    sim.next_frame().unwrap()
}

/// Dark pixels (below the mid level between disc and canopy) near the
/// truth ellipse: their count and centroid.
fn dark_blob(img: &GrayImage, t: &FrameTruth) -> (f64, f64, f64) {
    let e = t.ellipse.unwrap();
    let threshold = ((0.10 + 0.72 * 0.82) / 2.0 * 255.0) as u8;
    let m = e.a as i64 + 4;
    let (mut n, mut su, mut sv) = (0.0, 0.0, 0.0);
    for v in (e.cy as i64 - m)..=(e.cy as i64 + m) {
        for u in (e.cx as i64 - m)..=(e.cx as i64 + m) {
            if img.get_pixel(u as u32, v as u32)[0] < threshold {
                n += 1.0;
                su += u as f64;
                sv += v as f64;
            }
        }
    }
    (n, su / n, sv / n)
}

#[test]
fn dark_disc_area_and_centre_match_the_truth_ellipse() {
    // Frames at camera ranges of about 15, 11 and 6 m, no probe in the way.
    for seq in [0, 240, 420] {
        let (img, t) = frame_at(clean_approach(), seq);
        assert_eq!(t.expect, "detect");
        assert_eq!(t.probe_rim_frac, 0.0);
        let e = t.ellipse.unwrap();
        let area = std::f64::consts::PI * e.a * e.b;
        let (n, cu, cv) = dark_blob(&img, &t);
        // Thresholding an anti-aliased edge errs by a fraction of a pixel per
        // edge pixel, at random: about sqrt(perimeter) pixels in all.
        let tol = 3.0 * (2.0 * std::f64::consts::PI * e.a).sqrt();
        assert!(
            (n - area).abs() < tol,
            "seq {seq}: {n} dark px vs area {area:.1} (tol {tol:.1})"
        );
        // The centroid of an ellipse's area is its centre.
        assert!(
            (cu - e.cx).abs() < 0.1 && (cv - e.cy).abs() < 0.1,
            "seq {seq}: centroid ({cu:.3}, {cv:.3}) vs ({:.3}, {:.3})",
            e.cx,
            e.cy
        );
    }
}

#[test]
fn same_seed_gives_identical_frames_and_truth() {
    let s = Scenario::builtin("severe_turbulence").unwrap();
    let a: Vec<_> = Simulator::new(s.clone()).unwrap().take(4).collect();
    let b: Vec<_> = Simulator::new(s.clone()).unwrap().take(4).collect();
    assert_eq!(a, b);
    let mut s2 = s;
    s2.seed += 1;
    let c: Vec<_> = Simulator::new(s2).unwrap().take(4).collect();
    assert_ne!(a[3].1, c[3].1);
    assert_ne!(a[3].0, c[3].0);
}

#[test]
fn contact_scenario_occludes_the_rim_near_contact() {
    let scenario = Scenario::builtin("contact").unwrap();
    let tip = scenario.mount.probe_tip_body_m;
    let mut sim = Simulator::new(scenario).unwrap();
    let truths: Vec<FrameTruth> = std::iter::from_fn(|| sim.next_truth()).collect();
    assert!(truths.iter().any(|t| t.coupled), "no contact");
    let max_probe = truths.iter().map(|t| t.probe_rim_frac).fold(0.0, f64::max);
    assert!(max_probe > 0.05, "probe never hides the rim: {max_probe}");
    // Occlusion happens in the last metre (probe tip to drogue) only.
    for t in &truths {
        let p = t.position_body;
        let tip_to_drogue =
            ((p[0] - tip[0]).powi(2) + (p[1] - tip[1]).powi(2) + (p[2] - tip[2]).powi(2)).sqrt();
        if t.probe_rim_frac > 0.0 {
            assert!(
                tip_to_drogue < 1.0,
                "{} at {tip_to_drogue} m",
                t.probe_rim_frac
            );
        }
        let visible_ok = t.visible_rim_frac >= 0.6;
        assert_eq!(
            t.expect == "detect",
            visible_ok && t.ellipse.is_some(),
            "{t:?}"
        );
    }
}

#[test]
fn truth_frames_are_consistent() {
    let mut sim = Simulator::new(Scenario::builtin("approach").unwrap()).unwrap();
    let start = sim.start_time_ns();
    let truths: Vec<FrameTruth> = std::iter::from_fn(|| sim.next_truth()).collect();
    assert_eq!(truths.len(), 600);
    assert!(
        truths[0].range_m > 11.0 && truths[0].range_m < 16.0,
        "{}",
        truths[0].range_m
    );
    assert!(truths[0].expect == "detect");
    for (k, t) in truths.iter().enumerate() {
        assert_eq!(t.frame, format!("frame_{k:06}.png"));
        assert_eq!(
            t.capture_time_ns,
            start + (k as f64 / 30.0 * 1e9).round() as u64
        );
        let n = t.normal_camera;
        let p = t.position_camera;
        assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-9);
        assert!(
            n[0] * p[0] + n[1] * p[1] + n[2] * p[2] < 0.0,
            "normal toward the camera"
        );
    }
}

#[test]
fn supplied_receiver_pose_is_followed() {
    let mut sim = Simulator::new(Scenario::builtin("station_keeping").unwrap()).unwrap();
    let (_, t0) = sim.next_frame().unwrap();
    let pos = t0.receiver_position_ned;
    let q = t0.receiver_q_ned_body;
    // Hold the receiver 2 m further back (north is the tanker's heading).
    sim.set_receiver_pose([pos[0] - 2.0, pos[1], pos[2]], q);
    let t1 = sim.next_truth().unwrap();
    assert_eq!(t1.receiver_position_ned, [pos[0] - 2.0, pos[1], pos[2]]);
    assert!((t1.receiver_q_ned_body[0] - q[0]).abs() < 1e-12);
    // Bad input is ignored, not a panic.
    sim.set_receiver_pose([f64::NAN, 0.0, 0.0], [0.0; 4]);
    assert!(sim.next_truth().is_some());
}

#[test]
fn probe_kept_between_frames_is_redrawn_when_it_moves() {
    // A run renders the probe once and keeps it: frame 170 after 169 others
    // must equal frame 170 from a fresh simulator.
    let scenario = Scenario::builtin("contact").unwrap();
    let mut run = Simulator::new(scenario.clone()).unwrap();
    let from_run = run.nth(170).unwrap();
    let from_fresh = frame_at(scenario.clone(), 170);
    assert!(from_run == from_fresh, "frame 170 differs after a run");
    // The same scene with the probe moved (and then without a probe) on a
    // renderer that has drawn the old probe, against a fresh renderer.
    let scene = run.last_scene().unwrap().clone();
    let mut moved = scene.clone();
    if let Some(p) = moved.probe.as_mut() {
        p.a.x += 0.05;
        p.radius_b *= 1.5;
    }
    let mut none = scene.clone();
    none.probe = None;
    for changed in [moved, none] {
        let kept = run.render_scene(&changed);
        let fresh = Simulator::new(scenario.clone())
            .unwrap()
            .render_scene(&changed);
        assert!(kept == fresh, "a stale probe was drawn");
        assert!(kept != run.render_scene(&scene), "the probe change shows");
    }
}
