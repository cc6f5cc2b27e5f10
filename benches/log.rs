//! Flight log throughput: 1280x960 frames with everything derived from them
//! (calibration, truth, annotations, detection JSON, pose, transforms) through
//! the queue and the writer thread. Target: >= 120 frames/s on one core.
//!
//! `taskset -c 0 cargo bench --bench log -- --warm-up-time 1 --measurement-time 3`
//!
//! Measured 2026-11-22 on the shared 2-core dev machine, whole process pinned to
//! one core, noise frames (incompressible: PNG's worst case): raw 838 frames/s
//! CPU only, 310 frames/s to disk; png 70 / 66 frames/s.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use drogue_sim::FrameTruth;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::log::{FileStorage, FlightLog, ImageEncoding, LogConfig, Storage, StorageFile};
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::{Detection, FitQuality, Measurement};
use drogue_vision::record::DetectionRecord;
use drogue_vision::testing;
use nalgebra::{Matrix3, Vector3};
use std::io::{self, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

const BATCH: u64 = 30;

/// Storage that keeps only the position: the writer's CPU cost alone.
struct Discard;

#[derive(Default)]
struct Counting {
    pos: u64,
    len: u64,
}

impl Write for Counting {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.pos += buf.len() as u64;
        self.len = self.len.max(self.pos);
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Seek for Counting {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        // Only the length matters; the mcap writer seeks to patch headers.
        self.pos = match pos {
            SeekFrom::Start(p) => p,
            SeekFrom::End(d) => self.len.saturating_add_signed(d),
            SeekFrom::Current(d) => self.pos.saturating_add_signed(d),
        };
        Ok(self.pos)
    }
}

impl Storage for Discard {
    fn create(&mut self, _: &Path) -> io::Result<StorageFile> {
        Ok(StorageFile {
            writer: Box::new(Counting::default()),
            sync: Box::new(|| Ok(())),
        })
    }
    fn remove(&mut self, _: &Path) -> io::Result<()> {
        Ok(())
    }
}

/// A frame as the pipeline logs it: the frame, its truth, its measurement
/// and the measurement's JSON record.
type LoggedFrame = (
    Arc<Frame>,
    Box<drogue_sim::FrameTruth>,
    Arc<Measurement>,
    serde_json::Value,
);

fn inputs() -> Vec<LoggedFrame> {
    (0..BATCH)
        .map(|seq| {
            let image = testing::noise_image(seq, 1280, 960);
            let centre = Vector3::new(0.1, -0.05, 10.0);
            let normal = Vector3::new(0.05, 0.1, -1.0).normalize();
            let t = 1_795_341_600_000_000_000 + seq * 33_333_333;
            let truth = FrameTruth {
                alt_normal_camera: normal.into(),
                ellipse: None,
                position_body: centre.into(),
                normal_body: normal.into(),
                position_ned: [0.0; 3],
                receiver_position_ned: [0.0; 3],
                ..testing::frame_truth(seq, centre, normal, t)
            };
            let frame = Frame {
                seq,
                capture_time_ns: t,
                image,
                origin: FrameOrigin::Sim,
            };
            // A typical detection: ~300 rim points.
            let n = 300;
            let m = Measurement {
                tracked: true,
                ..testing::measurement(
                    seq,
                    t,
                    Some(Detection {
                        ellipse_px: Ellipse::new(640.0, 480.0, 60.0, 50.0, 0.1),
                        position_cov_body_m2: Matrix3::identity() * 1e-4,
                        normal_sigma_rad: 0.01,
                        quality: FitQuality {
                            points: n,
                            inliers: n - 10,
                            rms_residual_px: 0.3,
                            score: 0.9,
                        },
                        rim_points_px: (0..n)
                            .map(|i| {
                                let a = i as f32 * std::f32::consts::TAU / n as f32;
                                [640.0 + 60.0 * a.cos(), 480.0 + 50.0 * a.sin()]
                            })
                            .collect(),
                        inliers: (0..n).map(|i| !i.is_multiple_of(30)).collect(),
                        ..testing::detection(centre, normal, 1)
                    }),
                )
            };
            let json = serde_json::to_value(DetectionRecord::from_measurement(seq.to_string(), &m))
                .unwrap();
            (Arc::new(frame), Box::new(truth), Arc::new(m), json)
        })
        .collect()
}

/// Time to log BATCH frames, from the first push to the file closed.
fn log_batch(
    cfg: &LogConfig,
    dir: &Path,
    storage: Box<dyn Storage>,
    inputs: &[LoggedFrame],
) -> Duration {
    let start = Instant::now();
    let log =
        FlightLog::start_with_storage(cfg, dir, &testing::paper_camera([0.0; 5]), storage).unwrap();
    for (f, truth, m, j) in inputs {
        log.frame_with_truth(f.clone(), Some(truth.clone()));
        log.measurement_with_transforms(m.clone(), j.clone(), testing::mount_transforms());
    }
    let summary = log.finish().unwrap();
    let elapsed = start.elapsed();
    assert_eq!(summary.frames, BATCH, "the queue dropped frames");
    for f in &summary.files {
        let _ = std::fs::remove_file(f);
    }
    elapsed
}

fn bench(c: &mut Criterion) {
    let inputs = inputs();
    let mut group = c.benchmark_group("log_1280x960");
    group.throughput(Throughput::Elements(BATCH));
    group.sample_size(10);
    for encoding in [ImageEncoding::Raw, ImageEncoding::Png] {
        let mut cfg = drogue_vision::config::Config::embedded().log;
        cfg.image_encoding = encoding;
        cfg.queue_len = 4 * BATCH as usize;
        cfg.recover_on_start = false;
        let name = format!("{encoding:?}").to_lowercase();
        group.bench_function(format!("{name}_cpu_only"), |b| {
            b.iter_custom(|iters| {
                let dir = tempfile::tempdir().unwrap();
                (0..iters)
                    .map(|_| log_batch(&cfg, dir.path(), Box::new(Discard), &inputs))
                    .sum()
            });
        });
        group.bench_function(format!("{name}_to_disk"), |b| {
            b.iter_custom(|iters| {
                let dir = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
                (0..iters)
                    .map(|_| log_batch(&cfg, dir.path(), Box::new(FileStorage), &inputs))
                    .sum()
            });
        });
    }
    group.finish();
}

/// One simulator frame (the `approach` scenario at 10 s) encoded for
/// `/camera/image`: raw copy, the log's PNG ([`GrayPngEncoder`]), and the png
/// crate's fast mode with the same filter, for comparison. Prints the sizes.
fn frame_encoding(c: &mut Criterion) {
    use drogue_sim::{Scenario, Simulator};
    use drogue_vision::log::png_gray::GrayPngEncoder;
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use std::hint::black_box;
    let mut sim = Simulator::new(Scenario::builtin("approach").unwrap()).unwrap();
    let (gray, _) = sim.nth(300).unwrap();
    let (w, h) = gray.dimensions();
    let raw = gray.as_raw().clone();
    let mut enc = GrayPngEncoder::default();
    let mut out = Vec::new();
    enc.encode(&raw, w, h, &mut out).unwrap();
    let mut crate_png = Vec::new();
    PngEncoder::new_with_quality(&mut crate_png, CompressionType::Fast, FilterType::Avg)
        .write_image(&raw, w, h, image::ExtendedColorType::L8)
        .unwrap();
    println!(
        "simulator frame {w}x{h}: raw {} B, log PNG {} B ({:.2}x), png crate fast+avg {} B ({:.2}x)",
        raw.len(),
        out.len(),
        raw.len() as f64 / out.len() as f64,
        crate_png.len(),
        raw.len() as f64 / crate_png.len() as f64
    );
    let mut group = c.benchmark_group("frame_encoding_1280x960");
    group.throughput(Throughput::Elements(1));
    group.bench_function("raw_copy", |b| b.iter(|| black_box(raw.clone())));
    group.bench_function("log_png", |b| {
        b.iter(|| enc.encode(black_box(&raw), w, h, &mut out).unwrap());
    });
    group.bench_function("png_crate_fast_avg", |b| {
        b.iter(|| {
            let mut v = Vec::with_capacity(raw.len());
            PngEncoder::new_with_quality(&mut v, CompressionType::Fast, FilterType::Avg)
                .write_image(black_box(&raw), w, h, image::ExtendedColorType::L8)
                .unwrap();
            v
        });
    });
    let mut jpeg = Vec::new();
    drogue_vision::log::topics::jpeg(&raw, w, h, 90, &mut jpeg).unwrap();
    let mut image_jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut image_jpeg, 90)
        .encode(&raw, w, h, image::ExtendedColorType::L8)
        .unwrap();
    println!(
        "JPEG quality 90: log (jpeg-encoder) {} B ({:.2}x), image crate {} B ({:.2}x)",
        jpeg.len(),
        raw.len() as f64 / jpeg.len() as f64,
        image_jpeg.len(),
        raw.len() as f64 / image_jpeg.len() as f64
    );
    group.bench_function("log_jpeg_q90", |b| {
        b.iter(|| drogue_vision::log::topics::jpeg(black_box(&raw), w, h, 90, &mut jpeg).unwrap());
    });
    group.bench_function("image_crate_jpeg_q90", |b| {
        b.iter(|| {
            let mut v = Vec::with_capacity(raw.len());
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut v, 90)
                .encode(black_box(&raw), w, h, image::ExtendedColorType::L8)
                .unwrap();
            v
        });
    });
    group.finish();
}

criterion_group!(benches, bench, frame_encoding);
criterion_main!(benches);
