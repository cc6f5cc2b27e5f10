//! The whole measurement (detect + fit + pose + mount + track) per frame,
//! single-threaded, on simulator frames:
//! - full frame: no track, the whole frame is searched;
//! - tracked: the tracker has measured the two previous frames (a track
//!   with its velocity, as in a live run), so this frame is searched near
//!   the predicted ellipse first. Each iteration measures a fresh copy of
//!   that primed measurer; only `measure` is timed, with the caches as a
//!   live loop leaves them (the measurer's state and the frame just used),
//!   as in the full-frame case and the OpenCV baseline (best of 20 on one
//!   frame);
//! - tracked, cold cache: the same after 32 MB of other memory has been
//!   written, so that the frame, the measurer's state and the code all come
//!   from DRAM: the worst case, for comparison.
//!
//! Compare with `benches/opencv_baseline.py` on the same frames (written to
//! `target/bench-frames/` by this benchmark).

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_sim::{Scenario, Simulator};
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::measure::Measurer;
use drogue_vision::source::sim::{camera_model, mount_config};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Frames `k - 1` and `k` (the track) and `k + 1` (measured) of a scenario
/// for each pick, with a measurer set up for the scenario's camera and mount.
fn frame_triples(scenario: &str, picks: &[usize]) -> (Measurer, Vec<([Frame; 2], Frame)>) {
    frame_triples_of(Scenario::builtin(scenario).unwrap(), scenario, picks, None)
}

/// [`frame_triples`] of `scenario` (its frames written under `name`), the
/// measurer told the camera's exposure time `exposure_ms` when given.
fn frame_triples_of(
    scenario: Scenario,
    name: &str,
    picks: &[usize],
    exposure_ms: Option<f64>,
) -> (Measurer, Vec<([Frame; 2], Frame)>) {
    let mut sim = Simulator::new(scenario).unwrap();
    let mut config = Config::embedded();
    config.mount = mount_config(sim.mount());
    config.camera.exposure_ms = exposure_ms.unwrap_or(0.0);
    let measurer = Measurer::new(camera_model(&sim).unwrap(), &config.measure()).unwrap();
    let out = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("target/bench-frames")
        .join(name);
    let _ = std::fs::create_dir_all(&out);
    let last = picks.iter().copied().max().unwrap_or(0) + 1;
    let mut frames = Vec::new();
    for (i, (image, truth)) in sim.by_ref().take(last + 1).enumerate() {
        if picks.iter().any(|&k| i + 1 >= k && i <= k + 1) {
            let _ = image.save(out.join(&truth.frame));
            frames.push((
                i,
                Frame {
                    seq: truth.seq,
                    capture_time_ns: truth.capture_time_ns,
                    image,
                    origin: FrameOrigin::Sim,
                },
            ));
        }
    }
    let frame = |n: usize| Some(frames.iter().find(|(i, _)| *i == n)?.1.clone());
    let triples = picks
        .iter()
        .filter_map(|&k| Some(([frame(k.checked_sub(1)?)?, frame(k)?], frame(k + 1)?)))
        .collect();
    (measurer, triples)
}

/// Time of `iters` tracked measurements of `frame`, each by a fresh copy of
/// `primed` (the copy is not timed); with `flush`, that memory is written
/// before each one.
fn time_tracked(
    primed: &Measurer,
    frame: &Frame,
    iters: u64,
    mut flush: Option<&mut Vec<u8>>,
) -> Duration {
    let mut total = Duration::ZERO;
    for i in 0..iters {
        let mut m = primed.clone();
        if let Some(other) = flush.as_deref_mut() {
            other.iter_mut().step_by(64).for_each(|b| *b = i as u8);
        }
        let start = Instant::now();
        black_box(m.measure(black_box(frame)));
        total += start.elapsed();
    }
    total
}

fn bench(c: &mut Criterion) {
    for (scenario, picks) in [("approach", vec![60usize, 300, 540]), ("contact", vec![80])] {
        let (mut measurer, triples) = frame_triples(scenario, &picks);
        for (track, frame) in &triples {
            let name = format!("{scenario}/{}", frame.seq);
            c.bench_function(&format!("measure full frame {name}"), |b| {
                b.iter(|| {
                    measurer.forget_track();
                    black_box(measurer.measure(black_box(frame)))
                });
            });
            measurer.forget_track();
            for previous in track {
                measurer.measure(previous);
            }
            let primed = measurer.clone();
            c.bench_function(&format!("measure tracked {name}"), |b| {
                b.iter_custom(|iters| time_tracked(&primed, frame, iters, None));
            });
            let mut other = vec![0u8; 32 << 20];
            c.bench_function(&format!("measure tracked cold-cache {name}"), |b| {
                b.iter_custom(|iters| time_tracked(&primed, frame, iters, Some(&mut other)));
            });
        }
    }
}

/// A tracked frame blurred 5-6 px across its rim (`severe_turbulence` with
/// a 25 ms exposure, frame 415, a 60 px disc): with the exposure time known
/// the pass starts at the window the track's motion predicts, without it
/// the pass finds that window by widening. Both in the same run.
fn bench_long_exposure(c: &mut Criterion) {
    let mut scenario = Scenario::builtin("severe_turbulence").unwrap();
    scenario.camera.exposure_ms = 25.0;
    for (label, exposure_ms) in [("exposure known", Some(25.0)), ("exposure unknown", None)] {
        let (mut measurer, triples) = frame_triples_of(
            scenario.clone(),
            "severe_turbulence_25ms",
            &[414],
            exposure_ms,
        );
        for (track, frame) in &triples {
            for previous in track {
                measurer.measure(previous);
            }
            let primed = measurer.clone();
            let name = format!(
                "measure tracked severe_turbulence_25ms/{} {label}",
                frame.seq
            );
            c.bench_function(&name, |b| {
                b.iter_custom(|iters| time_tracked(&primed, frame, iters, None));
            });
        }
    }
}

criterion_group!(benches, bench, bench_long_exposure);
criterion_main!(benches);
