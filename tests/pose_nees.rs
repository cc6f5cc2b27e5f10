//! The position covariance is honest (issue 15): over simulator frames with
//! exact truth, and over the independent renderer's reference sets, the
//! normalised estimation error squared (NEES, 3 degrees of freedom) stays
//! near chi-square(3), per set (never pooled). Print the full table with
//! `cargo run --release --example pose_nees -- --scenario-frames 300`.
//!
//! Bounds, from chi-square(3) statistics:
//! - median at most 6 and at least `2.37 - 3 se`: chi-square(3)'s median is
//!   2.37 and the median of `n` draws has a standard error
//!   `se = 1 / (2 f(m) sqrt(n)) = 2.66 / sqrt(n)` (`f(m) = 0.188` the density
//!   at the median): 0.49 for 30 frames, so an honest covariance gives
//!   0.9-3.8 at three standard errors. The upper end, 6, allows the model a
//!   factor of 2.5 in variance (1.6 in standard deviation); below the lower
//!   end the covariance is over-reported beyond what sampling explains.
//! - share above chi-square(3)'s 99 % point (11.34) at most 10 % on the
//!   simulator: an honest covariance leaves 1 % (3 of 30 frames has a
//!   probability below 0.4 %); a variance under-reported by 2 leaves
//!   P(chi2(3) > 5.67) = 13 %.
//!
//! The NEES is scored against the centre of the solution given (the truth's
//! or its mirror's, which images to the same ellipse): which of the two is
//! right is the disambiguation's to say and is tested apart
//! (`tests/reference_sets.rs`, `tests/robustness_sweep.rs`). An unresolved
//! answer's covariance covers both (`pose::with_unresolved_mirror`);
//! `cargo run --release --example pose_nees -- --against-truth` scores the
//! reference sets against the true centre throughout.
//!
//! Open (printed by the example, not held here): the probe touching the rim
//! (`probe occlusion 0-10 %`, median 4.5; the probe's outline displaces the
//! rim points next to it), 30-40 % of the rim hidden (median 2.7, 10 %
//! above 11.34: 27 % before the fit was tried without runs of the probe's
//! outline) and blur beyond 20 px (most detections there are gross).

mod nees;

use drogue_sim::sweep::{Factor, Level, Sweep};
use drogue_vision::config::Config;
use nees::{CHI2_3_MEDIAN, SetNees};

/// Largest median NEES accepted (2.5 x chi-square(3)'s median).
const MAX_MEDIAN: f64 = 6.0;
/// Frames per sweep level.
const FRAMES: u64 = 30;

/// Smallest median NEES an honest covariance gives over `n` frames at three
/// standard errors of the median (see the module doc).
fn min_median(n: usize) -> f64 {
    CHI2_3_MEDIAN - 3.0 * 2.66 / (n as f64).sqrt()
}

fn check(set: &SetNees, min_frames: usize, max_share: f64) -> Option<String> {
    eprintln!("{}", set.row());
    if set.count() < min_frames {
        return Some(format!(
            "{}: only {} frames scored (of {} expected)",
            set.name,
            set.count(),
            set.expected
        ));
    }
    let (median, share) = (set.median(), set.share_above_p99());
    let low = min_median(set.count());
    if !(low..=MAX_MEDIAN).contains(&median) || share > max_share {
        return Some(format!(
            "{}: NEES median {median:.2} (allowed {low:.2}-{MAX_MEDIAN}), share above 11.34 {:.0} % (allowed {:.0} %)",
            set.name,
            100.0 * share,
            100.0 * max_share
        ));
    }
    None
}

#[test]
fn position_nees_on_simulator_frames_is_near_three_dof() {
    let levels = [
        Level::new(Factor::Baseline, 0.0),
        Level::new(Factor::Tilt, 0.0),
        Level::new(Factor::Blur, 8.0),
        Level::new(Factor::Blur, 16.0),
        Level::new(Factor::Noise, 10.0),
        Level::new(Factor::Range, 12.0),
        Level::new(Factor::Tilt, 45.0),
        Level::new(Factor::Tilt, 75.0),
        Level::new(Factor::Distortion, -0.12),
        Level::new(Factor::Occlusion, 0.2),
        // A glow lifting the canopy past 255: its rim's steps are clipped
        // (17 % above 11.34 at 135 px before their systematic term).
        Level::new(Factor::GlareGlow, 70.0),
        Level::new(Factor::GlareGlow, 135.0),
        // A glare streak's skirt, convex across the rim's steps, lifts both
        // their level reads above the light at the edge (10 % above 11.34
        // before the light's curvature was taken out).
        Level::new(Factor::Glare, 30.0),
    ];
    let mut sweep = Sweep::new(nees::SEED);
    let mut failures: Vec<String> = levels
        .iter()
        .filter_map(|l| check(&nees::sweep_level(&mut sweep, l, FRAMES), 20, 0.10))
        .collect();
    // A tracked run as `run` measures it.
    failures.extend(check(&nees::scenario("approach", 0, 150), 100, 0.10));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Per reference set, twice. The measurement's own covariance (calibrated
/// on the simulator) is held to what it reaches on this other renderer,
/// whose blurred rims are displaced several times more than the
/// simulator's (`examples/rim_bias.rs --reference`): median at most 6 and
/// at most 30 % above 11.34 (22-44 % before the systematic terms). What
/// TARGET_RELATIVE sends, with the shipped `target_relative_std_scale`,
/// must have its median within the chi-square band; above 11.34 at most
/// 20 %: `hard_b`'s frames blurred 10-14 px in noise exceed it (3 of 19),
/// `occlusion` has 1 of 15, the other sets none (since the rim is placed
/// for the canopy's shading and faint steps are smoothed for their
/// contrast; `hard` had 3 of 18 before).
#[test]
#[ignore = "needs the reference frames: set DROGUE_REFERENCE_DIR (.ci/run does)"]
fn position_nees_on_reference_sets_is_near_three_dof() {
    let dir = std::env::var_os("DROGUE_REFERENCE_DIR")
        .map(std::path::PathBuf::from)
        .expect("DROGUE_REFERENCE_DIR is not set: it must name the reference frames' folder");
    assert!(
        dir.join("paper10").is_dir(),
        "DROGUE_REFERENCE_DIR={} is not the reference frames' folder (no paper10/ in it)",
        dir.display()
    );
    let scale = Config::embedded().link.target_relative_std_scale;
    let mut failures = Vec::new();
    for name in drogue_vision::testing::DROGUE_REFERENCE_SETS {
        let set = nees::reference_set(&dir, name);
        let own_median = set.median();
        eprintln!("{}", set.row());
        if !(own_median <= MAX_MEDIAN && set.share_above_p99() <= 0.30) {
            failures.push(format!(
                "{name}: the measurement's covariance: NEES median {own_median:.2}, share above 11.34 {:.0} %",
                100.0 * set.share_above_p99()
            ));
        }
        failures.extend(check(&set.scaled(scale), 9, 0.20));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
