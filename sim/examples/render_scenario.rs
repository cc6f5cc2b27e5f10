//! Renders every n-th frame of a scenario to a folder, for a look:
//! `cargo run -p drogue-sim --example render_scenario -- approach /tmp/out 30`.

use drogue_sim::{Scenario, Simulator};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("approach", String::as_str);
    let out = std::path::PathBuf::from(args.get(2).map_or("/tmp/drogue-sim", String::as_str));
    let every: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(30);
    std::fs::create_dir_all(&out)?;
    let sim = Simulator::new(Scenario::resolve(name)?)?;
    let cpu0 = cpu_seconds();
    let start = Instant::now();
    let mut n = 0;
    for (img, truth) in sim {
        n += 1;
        if truth.seq % every == 0 {
            img.save(out.join(&truth.frame))?;
            println!(
                "{} t={:.2} range={:.2} expect={} probe={:.2} hose={:.2} coupled={} ellipse={:?}",
                truth.frame,
                truth.t,
                truth.range_m,
                truth.expect,
                truth.probe_rim_frac,
                truth.hose_rim_frac,
                truth.coupled,
                truth
                    .ellipse
                    .map(|e| (e.cx as i32, e.cy as i32, e.a as i32))
            );
        }
    }
    println!(
        "{n} frames, {:.2} ms wall, {:.2} ms CPU per frame (incl. truth)",
        start.elapsed().as_secs_f64() * 1e3 / n as f64,
        (cpu_seconds() - cpu0) * 1e3 / n as f64
    );
    Ok(())
}

/// CPU time of this process (user + system), seconds, from /proc (Linux).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}
