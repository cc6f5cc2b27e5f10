//! The loop closes: frames rendered by the simulator, measured by the
//! pipeline, compared with the simulator's exact truth.

mod common;

use common::{FrameErrors, errors, med_p95, report};
use drogue_sim::{Scenario, Simulator};
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::measure::Measurer;
use drogue_vision::source::sim::{camera_model, mount_config};
use drogue_vision::testing::Truth;

/// Outcome of measuring a stretch of a scenario.
struct Run {
    /// Frames whose truth says the drogue is detectable (rim <= 40 % hidden).
    detectable: usize,
    detected_of_detectable: usize,
    /// Detections on frames whose truth says there is nothing to detect.
    false_detections: usize,
    errs: Vec<FrameErrors>,
}

/// Measures frames `skip..skip+count` of a built-in scenario, in sequence.
fn run_scenario(name: &str, skip: usize, count: usize, config_toml: &str) -> Run {
    let scenario = Scenario::builtin(name).expect("scenario");
    let mut sim = Simulator::new(scenario).expect("simulator");
    let mut config = Config::from_toml_str(config_toml, "test").expect("config");
    config.mount = mount_config(sim.mount());
    config.drogue.inner_radius_m = sim.inner_radius_m();
    config.drogue.canopy_radius_m = sim.canopy_radius_m();
    let mut measurer =
        Measurer::new(camera_model(&sim).expect("camera"), &config.measure()).expect("measurer");
    let mut run = Run {
        detectable: 0,
        detected_of_detectable: 0,
        false_detections: 0,
        errs: Vec::new(),
    };
    for (image, truth) in sim.by_ref().skip(skip).take(count) {
        let t: Truth =
            serde_json::from_value(serde_json::to_value(&truth).expect("json")).expect("truth");
        let frame = Frame {
            seq: truth.seq,
            capture_time_ns: (truth.t * 1e9) as u64,
            image,
            origin: FrameOrigin::Sim,
        };
        let m = measurer.measure(&frame);
        let detectable = truth.expect == "detect" && truth.probe_rim_frac <= 0.4;
        if detectable {
            run.detectable += 1;
            run.detected_of_detectable += usize::from(m.detection.is_some());
        }
        if truth.expect != "detect" && m.detection.is_some() {
            run.false_detections += 1;
        }
        if detectable {
            // Body frame truth closes the loop through the mount as well.
            if let (Some(d), Some(e)) = (m.detection.as_ref(), errors(&m, &t)) {
                let body_err =
                    (d.position_body_m.vector() - common::v3(truth.position_body)).norm();
                assert!(
                    body_err <= (e.position_rel * e.range_m) + 1e-6,
                    "body and camera position errors disagree: {body_err} m"
                );
                run.errs.push(e);
            }
        }
    }
    run
}

#[test]
fn approach_meets_accuracy_targets() {
    let run = run_scenario("approach", 0, 150, "");
    eprintln!("{}", report("approach 0-150", &run.errs));
    assert!(
        run.detectable > 100,
        "too few detectable frames: {}",
        run.detectable
    );
    let rate = run.detected_of_detectable as f64 / run.detectable as f64;
    assert!(rate >= 0.99, "detection rate {rate}");
    assert_eq!(run.false_detections, 0);
    let (c50, c95) = med_p95(&run.errs, |e| Some(e.centre_px));
    let (a50, a95) = med_p95(&run.errs, |e| Some(e.axes_px));
    let (p50, p95) = med_p95(&run.errs, |e| Some(e.position_rel));
    assert!(c50 <= 0.1 && c95 <= 0.5, "centre med {c50} p95 {c95} px");
    assert!(a50 <= 0.1 && a95 <= 0.5, "axes med {a50} p95 {a95} px");
    assert!(
        p50 <= 0.003 && p95 <= 0.01,
        "position med {p50} p95 {p95} of range"
    );
}

#[test]
fn contact_meets_targets_with_the_probe_over_the_rim() {
    // The whole contact scenario: 3 m to contact, the probe hiding part of the
    // rim in the last metre.
    let run = run_scenario("contact", 0, 240, "");
    eprintln!("{}", report("contact 0-240", &run.errs));
    let rate = run.detected_of_detectable as f64 / run.detectable as f64;
    assert!(rate >= 0.99, "detection rate {rate}");
    let (c50, c95) = med_p95(&run.errs, |e| Some(e.centre_px));
    let (p50, p95) = med_p95(&run.errs, |e| Some(e.position_rel));
    assert!(c50 <= 0.1 && c95 <= 0.5, "centre med {c50} p95 {c95} px");
    assert!(
        p50 <= 0.003 && p95 <= 0.01,
        "position med {p50} p95 {p95} of range"
    );
}

#[test]
fn default_fit_is_at_least_as_accurate_as_algorithm1_on_occluded_rims() {
    // Frames where the probe hides part of the rim: the last metre of contact.
    let only_occluded = |name: &str, toml: &str| {
        let scenario = Scenario::builtin(name).expect("scenario");
        let sim = Simulator::new(scenario).expect("sim");
        let picks: Vec<usize> = sim
            .map(|(_, t)| t)
            .enumerate()
            .filter(|(_, t)| {
                t.probe_rim_frac > 0.05 && t.probe_rim_frac <= 0.4 && t.expect == "detect"
            })
            .map(|(i, _)| i)
            .collect();
        assert!(picks.len() >= 10, "only {} occluded frames", picks.len());
        let first = picks[0];
        let run = run_scenario(name, first, picks[picks.len() - 1] + 1 - first, toml);
        (run, picks.len())
    };
    let (ours, n) = only_occluded("contact", "");
    let (paper, _) = only_occluded("contact", "[fit]\nmethod = \"algorithm1\"\n");
    eprintln!(
        "{}",
        report(&format!("occluded ({n}) adaptive"), &ours.errs)
    );
    eprintln!(
        "{}",
        report(&format!("occluded ({n}) algorithm1"), &paper.errs)
    );
    for (what, f) in [
        (
            "centre",
            (|e: &FrameErrors| Some(e.centre_px)) as fn(&FrameErrors) -> Option<f64>,
        ),
        ("axes", |e: &FrameErrors| Some(e.axes_px)),
        ("position", |e: &FrameErrors| Some(e.position_rel)),
    ] {
        let (o50, o95) = med_p95(&ours.errs, f);
        let (a50, a95) = med_p95(&paper.errs, f);
        assert!(
            o50 <= a50 && o95 <= a95,
            "{what}: adaptive {o50}/{o95} vs algorithm1 {a50}/{a95}"
        );
    }
    assert!(ours.detected_of_detectable >= paper.detected_of_detectable);
}

/// The motion blur a track predicts (its rim's travel over the exposure,
/// from the detections' frame-to-frame motion) against the blur the
/// simulator drew each frame with. The severe-turbulence scenario with a
/// 25 ms exposure (blurs of up to 9 px, 2.3 px at the median) and without
/// the receiver's attitude wobble: the simulator's blur is the relative
/// translation's only, while the image motion a track sees includes the
/// camera's rotation. Predicting no blur would be off by the blur itself.
#[test]
fn the_blur_a_track_predicts_is_the_blur_drawn() {
    let mut scenario = Scenario::builtin("severe_turbulence").expect("scenario");
    scenario.camera.exposure_ms = 25.0;
    scenario.receiver.wobble_deg = 0.0;
    let exposure = drogue_vision::source::sim::scenario_exposure(&scenario).expect("blurred");
    let mut sim = Simulator::new(scenario).expect("simulator");
    let mut config = Config::embedded();
    config.mount = mount_config(sim.mount());
    config.camera.exposure_ms = exposure.as_secs_f64() * 1e3;
    let mut measurer =
        Measurer::new(camera_model(&sim).expect("camera"), &config.measure()).expect("measurer");
    let (mut misses, mut drawn) = (Vec::new(), Vec::new());
    for (image, truth) in sim.by_ref().take(450) {
        let capture_time_ns = (truth.t * 1e9) as u64;
        if let Some(sweep) = measurer.predicted_blur(capture_time_ns) {
            let predicted = [sweep.end.cx - sweep.start.cx, sweep.end.cy - sweep.start.cy];
            let [du, dv] = truth.blur_px;
            misses.push((predicted[0] - du).hypot(predicted[1] - dv));
            drawn.push(du.hypot(dv));
        }
        measurer.measure(&Frame {
            seq: truth.seq,
            capture_time_ns,
            image,
            origin: FrameOrigin::Sim,
        });
    }
    assert!(misses.len() >= 400, "only {} predictions", misses.len());
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (miss, length) = (median(&mut misses.clone()), median(&mut drawn));
    let p90 = {
        misses.sort_by(f64::total_cmp);
        misses[misses.len() * 9 / 10]
    };
    eprintln!(
        "predicted blur off by {miss:.2} px (median), {p90:.2} px (90th percentile); drawn {length:.2} px (median)"
    );
    assert!(length > 1.5, "too little blur to judge: {length} px");
    assert!(
        miss < 0.5 * length && p90 < 1.5 * length,
        "{miss} / {p90} px off for {length} px"
    );
}
