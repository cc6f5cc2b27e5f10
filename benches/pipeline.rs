//! The whole measurement (detect + fit + pose + mount + track) per frame,
//! single-threaded, on simulator frames: a full-frame search (no track) and a
//! tracked frame (searched near the predicted ellipse). Compare with
//! `benches/opencv_baseline.py` on the same frames (written to
//! `target/bench-frames/` by this benchmark).

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_sim::{Scenario, Simulator};
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::measure::Measurer;
use drogue_vision::source::sim::{camera_model, mount_config};
use std::hint::black_box;

/// Frames of a scenario at the given indices, with a measurer set up for it.
fn frames(scenario: &str, picks: &[usize]) -> (Measurer, Vec<Frame>) {
    let mut sim = Simulator::new(Scenario::builtin(scenario).unwrap()).unwrap();
    let mut config = Config::embedded();
    config.mount = mount_config(sim.mount());
    let measurer = Measurer::new(camera_model(&sim).unwrap(), &config).unwrap();
    let last = picks.iter().copied().max().unwrap_or(0);
    let out = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("target/bench-frames")
        .join(scenario);
    let _ = std::fs::create_dir_all(&out);
    let mut picked = Vec::new();
    for (i, (image, truth)) in sim.by_ref().take(last + 1).enumerate() {
        if picks.contains(&i) {
            let _ = image.save(out.join(&truth.frame));
            picked.push(Frame {
                seq: truth.seq,
                capture_time_ns: truth.capture_time_ns,
                image,
                origin: FrameOrigin::Sim(Box::new(truth)),
            });
        }
    }
    (measurer, picked)
}

fn bench(c: &mut Criterion) {
    for (scenario, picks) in [("approach", vec![60usize, 300, 540]), ("contact", vec![80])] {
        let (mut measurer, frames) = frames(scenario, &picks);
        for frame in &frames {
            let name = format!("{scenario}/{}", frame.seq);
            c.bench_function(&format!("measure full frame {name}"), |b| {
                b.iter(|| {
                    measurer.forget_track();
                    black_box(measurer.measure(black_box(frame)))
                })
            });
            // Tracked: the track is settled on this very frame, so each
            // iteration searches near its prediction first.
            measurer.forget_track();
            measurer.measure(frame);
            c.bench_function(&format!("measure tracked {name}"), |b| {
                b.iter(|| black_box(measurer.measure(black_box(frame))))
            });
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
