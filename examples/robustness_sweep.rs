//! Prints the robustness sweep as the README's markdown table:
//! `cargo run --release --example robustness_sweep -- [--frames N] [--seed S] [--only TEXT] [--dump DIR]`.
//!
//! `--frames` is per level (default 10, the test's); `--seed` changes the
//! scenes (default the test's); `--only` keeps the levels whose label
//! contains TEXT (e.g. `range`); `--dump` writes the frames to DIR as PNG.
//! `SWEEP_TRACE=1` prints each frame's truth and result on stderr, and
//! `RUST_LOG=drogue_vision::measure::detect=debug` the detector's reasons.

#[path = "../tests/sweep/mod.rs"]
mod sweep;

use drogue_sim::sweep::standard_levels;
use std::time::Instant;

fn usage(message: &str) -> ! {
    eprintln!(
        "{message}\nusage: robustness_sweep [--frames N] [--seed S] [--only TEXT] [--dump DIR]"
    );
    std::process::exit(2)
}

fn main() {
    // `RUST_LOG=drogue_vision::measure::detect=debug` shows why each
    // candidate was rejected; `SWEEP_TRACE=1` prints one line per frame.
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let mut frames: u64 = 10;
    let mut seed = sweep::SEED;
    let mut only: Option<String> = None;
    let mut dump: Option<std::path::PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = |name: &str| {
            args.next()
                .unwrap_or_else(|| usage(&format!("{name} needs a value")))
        };
        match arg.as_str() {
            "--frames" => {
                frames = value("--frames")
                    .parse()
                    .ok()
                    .filter(|n| *n > 0)
                    .unwrap_or_else(|| usage("--frames: a whole number > 0"));
            }
            "--seed" => {
                seed = value("--seed")
                    .parse()
                    .unwrap_or_else(|_| usage("--seed: a whole number"));
            }
            "--only" => only = Some(value("--only")),
            "--dump" => dump = Some(value("--dump").into()),
            other => usage(&format!("unknown argument {other}")),
        }
    }
    let levels: Vec<_> = standard_levels()
        .into_iter()
        .filter(|l| only.as_deref().is_none_or(|o| l.label().contains(o)))
        .collect();
    if levels.is_empty() {
        usage("--only matches no level");
    }
    let start = Instant::now();
    if let Some(dir) = &dump
        && let Err(e) = std::fs::create_dir_all(dir)
    {
        usage(&format!("--dump {}: {e}", dir.display()));
    }
    let stats = sweep::run(&levels, frames, seed, dump.as_deref());
    print!("{}", sweep::markdown(&stats));
    let total: usize = stats.iter().map(|s| s.frames).sum();
    eprintln!(
        "{total} frames ({frames} per level, seed {seed}) in {:.1} s",
        start.elapsed().as_secs_f64()
    );
}
