//! Synthetic inputs for the log tests: frames, truth, measurements and MAVLink
//! events whose every value is known, so what the log gives back can be
//! compared with what went in.
#![allow(dead_code)]

use drogue_sim::FrameTruth;
use drogue_vision::camera::CameraModel;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::link::LinkEvent;
use drogue_vision::log::{FlightLog, LogConfig, LogHandle, MountTransforms, Storage, StorageFile};
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::miss::{MissReason, NotDetected};
use drogue_vision::measure::{Detection, FitQuality, Measurement, StageTimes};
use drogue_vision::record::DetectionRecord;
use drogue_vision::spatial::Point;
use drogue_vision::testing;
use image::GrayImage;
use nalgebra::{Matrix3, Vector3};
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

pub const WIDTH: u32 = 1280;
pub const HEIGHT: u32 = 960;
/// 2026-11-22T10:00:00Z, ns.
pub const T0_NS: u64 = 1_795_341_600_000_000_000;
pub const PERIOD_NS: u64 = 33_333_333;

/// The paper's camera (the reference data's intrinsics) with some distortion.
pub fn camera() -> CameraModel {
    testing::paper_camera([-0.05, 0.01, 0.0002, -0.0001, 0.0])
}

/// The embedded log settings with a queue that holds everything one test
/// writes (a few thousand items), so a loaded machine, where the writer
/// thread may not run until the test has queued it all, cannot drop items
/// that the test then counts. Dropping on a full queue is tested on its own
/// with `queue_len = 1`.
pub fn config() -> LogConfig {
    let mut cfg = drogue_vision::config::Config::embedded().log;
    cfg.queue_len = 4096;
    cfg
}

/// Noise-like pixels that differ for every frame.
pub fn image(seq: u64, width: u32, height: u32) -> GrayImage {
    testing::noise_image(seq, width, height)
}

pub fn time_ns(seq: u64) -> u64 {
    T0_NS + seq * PERIOD_NS
}

/// The drogue's true centre for frame `seq`: approaching from 20 m.
pub fn centre_camera_m(seq: u64) -> Vector3<f64> {
    let s = seq as f64;
    Vector3::new(0.1 * (s * 0.1).sin(), -0.05 + 0.01 * s, 20.0 - 0.1 * s)
}

pub fn normal_camera(seq: u64) -> Vector3<f64> {
    Vector3::new(0.05 * (seq as f64 * 0.2).cos(), 0.1, -1.0).normalize()
}

pub fn truth(seq: u64) -> FrameTruth {
    testing::frame_truth(seq, centre_camera_m(seq), normal_camera(seq), time_ns(seq))
}

pub fn frame(seq: u64, with_truth: bool) -> Frame {
    Frame {
        seq,
        capture_time_ns: time_ns(seq),
        image: image(seq, WIDTH, HEIGHT),
        origin: if with_truth {
            FrameOrigin::Sim
        } else {
            FrameOrigin::Camera {
                device: "test".into(),
            }
        },
    }
}

/// Detected in every frame except multiples of 5. The estimate is the truth
/// plus a known error of `error_m(seq)` along x (so review statistics have a
/// known answer).
pub fn measurement(seq: u64) -> Measurement {
    let detection = (!seq.is_multiple_of(5)).then(|| {
        let centre = centre_camera_m(seq) + Vector3::new(error_m(seq), 0.0, 0.0);
        let normal = normal_camera(seq);
        let rim: Vec<[f32; 2]> = (0..40)
            .map(|i| {
                let t = i as f32 * 0.157;
                [640.0 + 30.0 * t.cos(), 480.0 + 25.0 * t.sin()]
            })
            .collect();
        // Body FRD of the default forward-looking mount, as the fixture's.
        let body = |v: Vector3<f64>| Vector3::new(v.z, v.x, v.y);
        Detection {
            ellipse_px: Ellipse::new(640.0, 480.0, 30.0, 25.0, 0.1),
            position_from_probe_body_m: Point::new(Vector3::new(
                centre.z - 1.0,
                centre.x,
                centre.y,
            )),
            position_cov_body_m2: Matrix3::identity() * 1e-4,
            normal_sigma_rad: 0.01,
            quality: FitQuality {
                points: 40,
                inliers: 38,
                rms_residual_px: 0.3,
                score: 0.9,
            },
            inliers: (0..40u32).map(|i| !i.is_multiple_of(20)).collect(),
            rim_points_px: rim,
            ..testing::detection(body(centre), body(normal), 1)
        }
    });
    let miss = detection.is_none().then(|| NotDetected {
        reason: miss_reason(seq),
        candidates: 3,
    });
    Measurement {
        tracked: seq > 0,
        times: StageTimes {
            detect_us: 1000,
            fit_us: 500,
            pose_us: 100,
            total_us: 1600 + (seq as u32 % 10) * 100,
        },
        miss,
        ..testing::measurement(seq, time_ns(seq), detection)
    }
}

/// Why frame `seq` of [`measurement`] (a multiple of 5) has no drogue: no
/// canopy on multiples of 10, blurred on the others.
pub fn miss_reason(seq: u64) -> MissReason {
    if seq.is_multiple_of(10) {
        MissReason::NoCanopy(0.1)
    } else {
        MissReason::Blurred(0.6)
    }
}

/// Position error along camera x built into [`measurement`], metres.
pub fn error_m(seq: u64) -> f64 {
    0.01 * (1 + seq % 3) as f64
}

/// Logs frame `seq` (with its truth or not) and then its [`measurement`]
/// with the detection JSON and the mount's transforms, as `run` does.
pub fn log_frame(log: &LogHandle, seq: u64, with_truth: bool) {
    let m = Arc::new(measurement(seq));
    let json = detection_json(&m);
    log.frame_with_truth(
        Arc::new(frame(seq, with_truth)),
        with_truth.then(|| Box::new(truth(seq))),
    );
    log.measurement_with_transforms(m, json, mount());
}

pub fn detection_json(m: &Measurement) -> serde_json::Value {
    serde_json::to_value(DetectionRecord::from_measurement(m.seq.to_string(), m)).unwrap()
}

/// Capture → send latency built into outgoing [`link_event`]s, milliseconds.
pub fn latency_ms(i: u64) -> f64 {
    2.0 + (i % 10) as f64 * 0.5
}

pub fn mount() -> MountTransforms {
    testing::mount_transforms()
}

pub fn link_event(i: u64, outgoing: bool) -> LinkEvent {
    LinkEvent {
        time_ns: time_ns(i)
            + if outgoing {
                (latency_ms(i) * 1e6) as u64
            } else {
                2_000_000
            },
        outgoing,
        name: if outgoing {
            "LANDING_TARGET"
        } else {
            "HEARTBEAT"
        }
        .into(),
        capture_time_ns: outgoing.then(|| time_ns(i)),
        fields: serde_json::json!({"i": i, "x": 1.5}),
    }
}

/// A "disk" with a shared byte budget (`free`): writes past it fail with
/// `StorageFull`, as a full disk's do; raise `free` to give room back. With
/// `buffer_bytes`, each file sits behind a write buffer of that size, as the
/// real file storage's does (a new file's header then fails only when the
/// buffer is written out).
pub struct SmallDisk {
    pub free: Arc<AtomicU64>,
    pub buffer_bytes: Option<usize>,
}

/// A log in `dir` on a [`SmallDisk`] with `free_bytes` of room (and the
/// write buffer `buffer_bytes`), retrying every second after a write error;
/// with the budget, to give the disk room again.
pub fn log_on_small_disk(
    dir: &Path,
    free_bytes: u64,
    buffer_bytes: Option<usize>,
) -> (LogHandle, Arc<AtomicU64>) {
    let free = Arc::new(AtomicU64::new(free_bytes));
    let mut cfg = config();
    cfg.retry_after_error_s = 1;
    let disk = SmallDisk {
        free: free.clone(),
        buffer_bytes,
    };
    let log = FlightLog::start_with_storage(&cfg, dir, &camera(), Box::new(disk)).unwrap();
    (log, free)
}

struct SmallFile {
    file: File,
    free: Arc<AtomicU64>,
}

impl Write for SmallFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let free = self.free.load(Ordering::SeqCst);
        if free == 0 {
            return Err(io::Error::new(
                io::ErrorKind::StorageFull,
                "no space left on device (test disk)",
            ));
        }
        let n = self.file.write(&buf[..buf.len().min(free as usize)])?;
        self.free.fetch_sub(n as u64, Ordering::SeqCst);
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Seek for SmallFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

impl Storage for SmallDisk {
    fn create(&mut self, path: &Path) -> io::Result<StorageFile> {
        let file = File::create_new(path)?;
        let sync = file.try_clone()?;
        let small = SmallFile {
            file,
            free: self.free.clone(),
        };
        Ok(StorageFile {
            writer: match self.buffer_bytes {
                Some(capacity) => Box::new(BufWriter::with_capacity(capacity, small)),
                None => Box::new(small),
            },
            sync: Box::new(move || sync.sync_data()),
        })
    }
}
