//! Render speed of one 1280x960 frame, single-threaded (target <= 16 ms).
//! `cargo bench -p drogue-sim --bench render -- --warm-up-time 1 --measurement-time 3`
//!
//! `render_1280x960/*` is wall-clock time; `render_cpu_1280x960/*` the same
//! renders timed by the thread's CPU clock, which a busy shared machine
//! inflates far less (waiting for a core is not counted).
//!
//! The probe is fixed to the receiver, so a run rasterises it once and keeps
//! its pixels; the `probe_redrawn` case moves it a hair every frame to time
//! a frame that has to draw it (a run's first frame).

use cpu_time::ThreadTime;
use criterion::{Criterion, criterion_group, criterion_main};
use drogue_sim::render::FrameScene;
use drogue_sim::{Scenario, Simulator};
use std::hint::black_box;

/// A simulator at frame `seq` of scenario `name`: its scene, the scene with
/// the probe moved a hair, and the range to the drogue.
fn setup(name: &str, seq: u64) -> (Simulator, FrameScene, FrameScene, f64) {
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
    (sim, scene, nudged, truth.range_m)
}

/// Renders scenario `name` at frame `seq` repeatedly, by wall clock and by
/// CPU clock; with `redraw_probe`, every other frame has the probe moved.
fn bench_frame(c: &mut Criterion, label: &str, name: &str, seq: u64, redraw_probe: bool) {
    let (mut sim, scene, nudged, range_m) = setup(name, seq);
    // Rendered in turn: the probe moves every frame when they differ.
    let scenes = if redraw_probe {
        [nudged, scene]
    } else {
        [scene.clone(), scene]
    };
    let mut k = 0usize;
    c.bench_function(
        &format!("render_1280x960/{label} (range {range_m:.1} m)"),
        |b| {
            b.iter(|| {
                k += 1;
                black_box(sim.render_scene(black_box(&scenes[k % 2])))
            });
        },
    );
    c.bench_function(
        &format!("render_cpu_1280x960/{label} (range {range_m:.1} m)"),
        |b| {
            b.iter_custom(|iters| {
                let start = ThreadTime::now();
                for _ in 0..iters {
                    k += 1;
                    black_box(sim.render_scene(black_box(&scenes[k % 2])));
                }
                start.elapsed()
            });
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
