//! Render speed of one 1280x960 frame, single-threaded (target <= 16 ms).
//! `cargo bench -p drogue-sim --bench render -- --warm-up-time 1 --measurement-time 3`

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_sim::{Scenario, Simulator};
use std::hint::black_box;

/// Renders scenario `name` at frame `seq` repeatedly.
fn bench_frame(c: &mut Criterion, label: &str, name: &str, seq: u64) {
    let mut sim = Simulator::new(Scenario::builtin(name).unwrap()).unwrap();
    for _ in 0..seq {
        sim.next_truth();
    }
    let (_, truth) = sim.next_frame().unwrap();
    let scene = sim.last_scene().unwrap().clone();
    c.bench_function(
        &format!("render_1280x960/{label} (range {:.1} m)", truth.range_m),
        |b| b.iter(|| black_box(sim.render_scene(black_box(&scene)))),
    );
}

fn render(c: &mut Criterion) {
    bench_frame(c, "approach_start", "approach", 0);
    bench_frame(c, "approach_mid", "approach", 400);
    bench_frame(c, "contact", "contact", 170);
    bench_frame(c, "low_sun_glare", "low_sun", 200);
    bench_frame(c, "severe_blur", "severe_turbulence", 300);
}

criterion_group!(benches, render);
criterion_main!(benches);
