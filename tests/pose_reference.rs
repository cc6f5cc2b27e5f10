//! The cone pose and the canopy-rim check on the independent renderer's
//! reference frames (`paper10`, `occlusion`), fed with the TRUTH ellipse: the
//! pose must match the truth's position and both normals, and the canopy rim
//! in the real image must pick the true normal wherever the tilt exceeds 5
//! degrees. Then the same with the truth ellipse disturbed by fit-sized
//! errors: the answer given (counting the ambiguity) against the issue's
//! targets.
//!
//! Ignored by a plain `cargo test`; `.ci/run` runs it with
//! `--include-ignored` where `DROGUE_REFERENCE_DIR` names the reference
//! folder (the one with `paper10/`), and it fails when the variable is unset
//! or names a missing folder (`drogue_vision::testing::reference_set`).

use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::measure::Disambiguation;
use drogue_vision::measure::ambiguity::canopy_supports;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::pose::{CirclePose, cone_pose};
use drogue_vision::measure::track::Tracker;
use drogue_vision::testing::{read_truths, reference_set};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

/// One reference frame's truth with the fields every `paper10` and
/// `occlusion` frame has, taken out of its options.
struct Truth {
    name: String,
    radius: f64,
    ellipse: Ellipse,
    position: Vector3<f64>,
    normal: Vector3<f64>,
    alt_position: Vector3<f64>,
    alt_normal: Vector3<f64>,
    tilt_deg: f64,
    range_m: f64,
}

fn read_truth(set: &std::path::Path) -> Vec<Truth> {
    read_truths(set)
        .into_iter()
        .map(|t| {
            let v = |a: Option<[f64; 3]>, what: &str| {
                Vector3::from(a.unwrap_or_else(|| panic!("{}: no {what}", t.frame)))
            };
            let e = t.ellipse.expect("a truth ellipse");
            Truth {
                radius: t.radius.expect("radius"),
                ellipse: Ellipse::new(e.cx, e.cy, e.a, e.b, e.theta),
                position: v(t.position_camera, "position_camera"),
                normal: v(t.normal_camera, "normal_camera"),
                alt_position: v(t.alt_position_camera, "alt_position_camera"),
                alt_normal: v(t.alt_normal_camera, "alt_normal_camera"),
                tilt_deg: t.tilt_deg.expect("tilt_deg"),
                range_m: t.range_m.expect("range_m"),
                name: t.frame,
            }
        })
        .collect()
}

/// How the canopy rim decided on frames tilted more than 5 degrees.
#[derive(Debug, Default)]
struct RimStats {
    rim_right: usize,
    rim_wrong: usize,
    unresolved: usize,
}

/// Standard normal sample (Box-Muller).
fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The whole pose stage (cone pose, canopy rim, tracker decision on a fresh
/// track) on each frame of `set`, with the truth ellipse disturbed by
/// Gaussian errors of `sigma_px` on centre and semi-axes (and the matching
/// angle error, sigma_px / a): the accuracy of the answer given, counting the
/// ambiguity, for fits of that quality.
fn answer_given_with_fit_error(set_name: &str, sigma_px: f64) -> (Vec<f64>, Vec<f64>, RimStats) {
    let set = reference_set(set_name);
    let camera = CameraModel::load(&set.join("camera.yaml")).unwrap();
    let config = Config::embedded();
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (mut normal_err_deg, mut position_err_pct) = (Vec::new(), Vec::new());
    let mut stats = RimStats::default();
    for t in read_truth(&set) {
        let image = image::open(set.join(&t.name)).unwrap().to_luma8();
        for _ in 0..20 {
            let e = t.ellipse;
            let disturbed = Ellipse::new(
                e.cx + sigma_px * gauss(&mut rng),
                e.cy + sigma_px * gauss(&mut rng),
                e.a + sigma_px * gauss(&mut rng),
                e.b + sigma_px * gauss(&mut rng),
                e.theta + sigma_px / e.a * gauss(&mut rng),
            );
            let solutions = cone_pose(&disturbed, &camera, t.radius).expect("a pose");
            let supports = canopy_supports(
                &image,
                &camera,
                &solutions,
                config.drogue.canopy_radius_m,
                config.drogue.canopy_band_m,
            );
            let choice = Tracker::new(&config.track)
                .unwrap()
                .choose(solutions, supports, 0, &disturbed);
            let err = angle(&choice.pose.normal_camera, &t.normal);
            let wrong = err > angle(&choice.pose.normal_camera, &t.alt_normal);
            if t.tilt_deg > 5.0 {
                match (choice.how, wrong) {
                    (Disambiguation::CanopyRim, true) => stats.rim_wrong += 1,
                    (Disambiguation::CanopyRim, false) => stats.rim_right += 1,
                    _ => stats.unresolved += 1,
                }
            }
            normal_err_deg.push(err.to_degrees());
            position_err_pct
                .push(100.0 * (*choice.pose.centre_camera_m - t.position).norm() / t.range_m);
        }
    }
    normal_err_deg.sort_by(f64::total_cmp);
    position_err_pct.sort_by(f64::total_cmp);
    (normal_err_deg, position_err_pct, stats)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn answer_given_with_realistic_fit_errors() {
    for set in ["paper10", "occlusion"] {
        for sigma_px in [0.05, 0.1, 0.2] {
            let (normal, position, rim) = answer_given_with_fit_error(set, sigma_px);
            println!(
                "{set}, ellipse error sigma {sigma_px} px: normal median {:.2} p95 {:.2} deg; \
                 position median {:.3} p95 {:.3} % of range; of {} answers, tilt > 5 deg: {rim:?}",
                percentile(&normal, 0.5),
                percentile(&normal, 0.95),
                percentile(&position, 0.5),
                percentile(&position, 0.95),
                normal.len()
            );
            if sigma_px <= 0.1 {
                // The targets, for fits as good as the fit's own
                // target (median error <= 0.1 px).
                assert!(percentile(&normal, 0.5) <= 0.5, "{set}: normal median");
                assert!(percentile(&position, 0.5) <= 0.3, "{set}: position median");
                assert!(percentile(&position, 0.95) <= 1.0, "{set}: position p95");
                assert_eq!(rim.unresolved, 0, "{set}: the rim should decide");
            }
            // The rim never settles on the wrong solution.
            assert_eq!(rim.rim_wrong, 0, "{set}: the rim picked a mirror solution");
        }
    }
}

#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn paper10_truth_ellipse_gives_truth_pose_and_rim_picks_it() {
    truth_ellipse_gives_truth_pose_and_rim_picks_it("paper10");
}

#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn occlusion_truth_ellipse_gives_truth_pose_and_rim_picks_it() {
    truth_ellipse_gives_truth_pose_and_rim_picks_it("occlusion");
}

fn truth_ellipse_gives_truth_pose_and_rim_picks_it(set_name: &str) {
    let set = reference_set(set_name);
    let camera = CameraModel::load(&set.join("camera.yaml")).unwrap();
    let config = Config::embedded();
    let canopy_radius = config.drogue.canopy_radius_m;
    let mut frames = 0;
    let mut answer_errors_deg = Vec::new();
    for t in read_truth(&set) {
        let (name, ellipse, normal, tilt_deg) = (t.name.as_str(), t.ellipse, t.normal, t.tilt_deg);
        let solutions = cone_pose(&ellipse, &camera, t.radius).expect("a pose");
        let i = if angle(&solutions[0].normal_camera, &normal)
            <= angle(&solutions[1].normal_camera, &normal)
        {
            0
        } else {
            1
        };
        let (found, other): (CirclePose, CirclePose) = (solutions[i], solutions[1 - i]);
        let pos_err = (*found.centre_camera_m - t.position).norm();
        let alt_pos_err = (*other.centre_camera_m - t.alt_position).norm();
        let n_err = angle(&found.normal_camera, &normal);
        let alt_n_err = angle(&other.normal_camera, &t.alt_normal);
        println!(
            "{name}: tilt {tilt_deg:5.1} deg, position {pos_err:.1e} m (alt {alt_pos_err:.1e}), \
             normal {n_err:.1e} rad (alt {alt_n_err:.1e})"
        );
        assert!(pos_err < 1e-6, "{name}: position {pos_err}");
        assert!(alt_pos_err < 1e-6, "{name}: alt position {alt_pos_err}");
        assert!(n_err < 1e-6, "{name}: normal {n_err}");
        assert!(alt_n_err < 1e-6, "{name}: alt normal {alt_n_err}");

        let image = image::open(set.join(name)).unwrap().to_luma8();
        let supports = canopy_supports(
            &image,
            &camera,
            &solutions,
            canopy_radius,
            Config::embedded().drogue.canopy_band_m,
        );
        let mut tracker = Tracker::new(&config.track).unwrap();
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
    assert!(frames >= 10, "{set_name} has only {frames} frames");
    answer_errors_deg.sort_by(f64::total_cmp);
    println!(
        "normal error of the answer given (truth ellipse): median {:.2e} deg, max {:.2e} deg",
        answer_errors_deg[frames / 2],
        answer_errors_deg[frames - 1]
    );
}
