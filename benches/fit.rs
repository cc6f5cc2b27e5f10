//! Ellipse fit speed, single-threaded: each method on the same 1000-point
//! rims (a clean 80 % arc, and a 65 % arc whose hidden part is a probe-like
//! straight run plus scattered points). Target: adaptive <= 0.5 ms.

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_vision::config::Config;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::fit::synth::{self, Occluder, RimSpec};
use drogue_vision::measure::fit::{FitMethod, fit_with};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

fn rim(visible_fraction: f64, occluder: Occluder, scattered: usize) -> Vec<[f64; 2]> {
    let spec = RimSpec {
        truth: Ellipse::new(640.0, 480.0, 160.0, 110.0, 0.4),
        visible_start: 0.3,
        visible_fraction,
        // 1000 points in all: a gap's hidden arc has none, so it gets more
        // rim points.
        rim_points: if occluder == Occluder::Gap {
            (1000.0 / visible_fraction).round() as usize - scattered
        } else {
            1000 - scattered
        },
        noise_px: 0.2,
        occluder,
        scattered,
    };
    synth::generate(&spec, &mut ChaCha8Rng::seed_from_u64(5)).points
}

fn bench(c: &mut Criterion) {
    let cfg = Config::embedded().fit;
    let sets = [
        ("clean80", rim(0.8, Occluder::Gap, 0)),
        ("occluded65", rim(0.65, Occluder::Chord, 10)),
    ];
    for (name, points) in &sets {
        assert_eq!(points.len(), 1000, "{name}");
        for m in FitMethod::ALL {
            c.bench_function(
                &format!("fit/{}/{name}_{}pts", m.name(), points.len()),
                |b| b.iter(|| fit_with(m, &cfg, black_box(points), 7)),
            );
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
