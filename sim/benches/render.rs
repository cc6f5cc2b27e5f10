//! Render speed of one 1280x960 frame, single-threaded (target <= 16 ms).
//! `cargo bench -p drogue-sim --bench render -- --warm-up-time 1 --measurement-time 3`
//!
//! The probe is fixed to the receiver, so a run rasterises it once and keeps
//! its pixels; the `probe_redrawn` case moves it a hair every frame to time
//! a frame that has to draw it (a run's first frame).

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_sim::{Scenario, Simulator};
use std::hint::black_box;

/// Renders scenario `name` at frame `seq` repeatedly.
fn bench_frame(c: &mut Criterion, label: &str, name: &str, seq: u64, redraw_probe: bool) {
    let mut sim = Simulator::new(Scenario::builtin(name).unwrap()).unwrap();
    for _ in 0..seq {
        sim.next_truth();
    }
    let (_, truth) = sim.next_frame().unwrap();
    let scene = sim.last_scene().unwrap().clone();
    let mut nudged = scene.clone();
    if let Some(p) = nudged.probe.as_mut() {
        p.a.x += 1e-9;
    }
    let mut flip = false;
    c.bench_function(
        &format!("render_1280x960/{label} (range {:.1} m)", truth.range_m),
        |b| {
            b.iter(|| {
                flip = !flip;
                let s = if redraw_probe && flip {
                    &nudged
                } else {
                    &scene
                };
                black_box(sim.render_scene(black_box(s)))
            })
        },
    );
}

fn render(c: &mut Criterion) {
    bench_frame(c, "approach_start", "approach", 0, false);
    bench_frame(c, "approach_mid", "approach", 400, false);
    bench_frame(c, "contact", "contact", 170, false);
    bench_frame(c, "contact_probe_redrawn", "contact", 170, true);
    bench_frame(c, "low_sun_glare", "low_sun", 200, false);
    bench_frame(c, "severe_blur", "severe_turbulence", 300, false);
}

criterion_group!(benches, render);
criterion_main!(benches);
