//! Calibrates the detector's score thresholds on the simulator's randomised
//! frames (issue 12: "calibrate the acceptance threshold on the simulator's
//! randomised frames, not on the reference files"):
//! `cargo run --release --example calibrate_scores -- [--frames N] [--seeds 3,7,21]`.
//!
//! Every frame of every sweep level (`drogue_sim::sweep::standard_levels`)
//! is searched without the early exit (`Detector::scored_candidates`), and
//! each verified candidate is labelled by the simulator's truth
//! (`tests/sweep/scores.rs`): the drogue's disc, or anything else (probe,
//! hose, distractor, the canopy's rim, a look-alike). Printed, per factor
//! and score threshold: the share of drogue frames whose disc scores at
//! least that much, and the frames with a false candidate that does.
//!
//! `accept_score` ends the search at the first candidate scoring it: it is
//! safe only above every false candidate's score, or a false candidate tried
//! first would end the search before the drogue is verified. `min_score` is
//! the floor of any detection. The seeds default to ones other than the
//! robustness test's (12), so that the test's frames stay a check.

#[path = "../tests/sweep/mod.rs"]
mod sweep;

use std::collections::BTreeMap;
use sweep::scores::{ScoredFrame, scored_frames};

fn usage(message: &str) -> ! {
    eprintln!("{message}\nusage: calibrate_scores [--frames N] [--seeds S,S,...]");
    std::process::exit(2)
}

/// A markdown table: one row per factor, one column per threshold, each
/// cell what `cell` says of the factor's frames at that threshold.
fn table(
    by_factor: &BTreeMap<&str, Vec<&ScoredFrame>>,
    thresholds: &[f64],
    cell: impl Fn(&[&ScoredFrame], f64) -> Option<String>,
) {
    let head: Vec<String> = thresholds.iter().map(|t| format!("{t:.2}")).collect();
    println!("| factor | frames | {} |", head.join(" | "));
    println!("|---|---:|{}", "---:|".repeat(thresholds.len()));
    for (factor, frames) in by_factor {
        let cells: Vec<Option<String>> = thresholds.iter().map(|&t| cell(frames, t)).collect();
        if cells.iter().all(Option::is_none) {
            continue;
        }
        print!("| {factor} | {} |", frames.len());
        for c in cells {
            print!(" {} |", c.unwrap_or_default());
        }
        println!();
    }
}

fn main() {
    let mut frames: u64 = 20;
    let mut seeds: Vec<u64> = vec![3, 7, 21];
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let value = args
            .next()
            .unwrap_or_else(|| usage(&format!("{arg} needs a value")));
        match arg.as_str() {
            "--frames" => {
                frames = value
                    .parse()
                    .ok()
                    .filter(|n| *n > 0)
                    .unwrap_or_else(|| usage("--frames: a whole number > 0"));
            }
            "--seeds" => {
                seeds = value
                    .split(',')
                    .map(|s| s.trim().parse())
                    .collect::<Result<_, _>>()
                    .unwrap_or_else(|_| usage("--seeds: whole numbers, comma-separated"));
            }
            other => usage(&format!("unknown argument {other}")),
        }
    }
    let scored: Vec<ScoredFrame> = seeds
        .iter()
        .flat_map(|&seed| scored_frames(seed, frames))
        .collect();
    let mut by_factor: BTreeMap<&str, Vec<&ScoredFrame>> = BTreeMap::new();
    for f in &scored {
        by_factor.entry(f.factor.as_str()).or_default().push(f);
    }
    let thresholds: Vec<f64> = (6..=20).map(|k| f64::from(k) * 0.05).collect();
    println!(
        "seeds {seeds:?}, {frames} frames a level, {} frames\n",
        scored.len()
    );
    println!("Share of drogue frames whose disc scores >= t:\n");
    table(&by_factor, &thresholds, |frames, t| {
        let drogue: Vec<_> = frames.iter().filter(|f| f.drogue).collect();
        (!drogue.is_empty()).then(|| {
            let n = drogue.iter().filter(|f| f.disc_score >= t).count();
            format!("{:.0} %", 100.0 * n as f64 / drogue.len() as f64)
        })
    });
    println!("\nFrames with a false candidate scoring >= t:\n");
    table(&by_factor, &thresholds, |frames, t| {
        let n = frames
            .iter()
            .filter(|f| f.false_scores.iter().any(|s| *s >= t))
            .count();
        Some(n.to_string())
    });
    let mut worst: Vec<(f64, &str)> = scored
        .iter()
        .flat_map(|f| f.false_scores.iter().map(|s| (*s, f.level.as_str())))
        .collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!("\nThe highest false candidates:");
    for (score, level) in worst.iter().take(8) {
        println!("- {score:.3} ({level})");
    }
}
