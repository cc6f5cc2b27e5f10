//! Prints the position covariance's consistency (NEES) per set: the
//! reference sets of the independent renderer, the simulator's sweep levels
//! (unrelated views with exact truth) and simulator scenario runs.
//!
//! `cargo run --release --example pose_nees -- [--reference DIR] [--sim-frames N]
//! [--seed S] [--only TEXT] [--scenario-frames N] [--worst K] [--scale F] [--against-truth]`
//!
//! `--reference` defaults to `$DROGUE_REFERENCE_DIR` (sets skipped when
//! neither is given); `--sim-frames` per sweep level (default 20, 0: none);
//! `--only` keeps the sets whose name contains TEXT; `--scenario-frames`
//! per scenario (approach, station_keeping; default 0: none); `--worst K`
//! lists each set's K largest NEES frames (a sweep frame with the settings
//! it was drawn with); `--scale F` also prints each set
//! with its standard deviations times F (`[link] target_relative_std_scale`);
//! `--against-truth` scores the reference sets against the true centre
//! also where the solution given is the mirror's (by default against the
//! centre of the solution given).

#[path = "../tests/nees/mod.rs"]
mod nees;

use drogue_sim::sweep::{Sweep, standard_levels};
use nees::SetNees;
use std::path::PathBuf;

fn usage(message: &str) -> ! {
    eprintln!(
        "{message}\nusage: pose_nees [--reference DIR] [--sim-frames N] [--seed S] [--only TEXT] [--scenario-frames N] [--worst K] [--scale F] [--against-truth]"
    );
    std::process::exit(2)
}

fn print(set: &SetNees, worst: usize, scale: f64) {
    println!("{}", set.row());
    if scale != 1.0 {
        println!("{}", set.scaled(scale).row());
    }
    let mut frames = set.frames.clone();
    frames.sort_by(|a, b| b.nees.total_cmp(&a.nees));
    for f in frames.iter().take(worst) {
        println!(
            "    NEES {:9.2}  err {:7.2} mm  sigma {:7.2} mm  range {:+7.2}/{:.2} lateral {:8.4}/{:.4} mm  inliers {:4}  rms {:.3} px  {}",
            f.nees,
            f.error_m * 1e3,
            f.sigma_m * 1e3,
            f.error_range_m * 1e3,
            f.sigma_range_m * 1e3,
            f.error_lateral_m * 1e3,
            f.sigma_lateral_m * 1e3,
            f.inliers,
            f.rms_px,
            f.label
        );
    }
}

fn main() {
    let mut reference = std::env::var_os("DROGUE_REFERENCE_DIR").map(PathBuf::from);
    let (mut sim_frames, mut seed, mut scenario_frames, mut worst) =
        (20u64, nees::SEED, 0usize, 0usize);
    let mut only: Option<String> = None;
    let mut scale = 1.0;
    let mut against_truth = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = |name: &str| {
            args.next()
                .unwrap_or_else(|| usage(&format!("{name} needs a value")))
        };
        let mut number = |name: &str| -> u64 {
            value(name)
                .parse()
                .unwrap_or_else(|_| usage(&format!("{name}: a whole number")))
        };
        match arg.as_str() {
            "--reference" => reference = Some(PathBuf::from(value("--reference"))),
            "--sim-frames" => sim_frames = number("--sim-frames"),
            "--seed" => seed = number("--seed"),
            "--scenario-frames" => scenario_frames = number("--scenario-frames") as usize,
            "--worst" => worst = number("--worst") as usize,
            "--scale" => {
                scale = value("--scale")
                    .parse()
                    .ok()
                    .filter(|s: &f64| *s >= 1.0)
                    .unwrap_or_else(|| usage("--scale: a number >= 1"));
            }
            "--only" => only = Some(value("--only")),
            "--against-truth" => against_truth = true,
            other => usage(&format!("unknown argument {other}")),
        }
    }
    let wanted = |name: &str| only.as_deref().is_none_or(|o| name.contains(o));
    println!("{}", SetNees::header());
    if let Some(dir) = &reference {
        for name in drogue_vision::testing::DROGUE_REFERENCE_SETS {
            if wanted(name) {
                print(
                    &nees::reference_set_scored(dir, name, against_truth),
                    worst,
                    scale,
                );
            }
        }
    }
    if sim_frames > 0 {
        let mut sweep = Sweep::new(seed);
        for level in standard_levels()
            .into_iter()
            .filter(|l| l.factor.has_drogue())
        {
            if wanted(&format!("sim {}", level.label())) {
                print(
                    &nees::sweep_level(&mut sweep, &level, sim_frames),
                    worst,
                    scale,
                );
            }
        }
    }
    if scenario_frames > 0 {
        for name in ["approach", "station_keeping"] {
            if wanted(&format!("sim scenario {name}")) {
                print(&nees::scenario(name, 0, scenario_frames), worst, scale);
            }
        }
    }
}
