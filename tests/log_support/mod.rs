//! Synthetic inputs for the log tests: frames, truth, measurements and MAVLink
//! events whose every value is known, so what the log gives back can be
//! compared with what went in.
#![allow(dead_code)]

use drogue_sim::{FrameTruth, TruthEllipse};
use drogue_vision::camera::CameraModel;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::link::LinkEvent;
use drogue_vision::log::{LogConfig, MountTransforms};
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::{
    CirclePose, Detection, Disambiguation, FitQuality, Measurement, StageTimes,
};
use drogue_vision::record::DetectionRecord;
use drogue_vision::spatial::{Direction, Point};
use image::GrayImage;
use nalgebra::{Matrix3, Vector3};

pub const WIDTH: u32 = 1280;
pub const HEIGHT: u32 = 960;
/// 2026-11-22T10:00:00Z, ns.
pub const T0_NS: u64 = 1_795_341_600_000_000_000;
pub const PERIOD_NS: u64 = 33_333_333;

/// The paper's camera (the reference data's intrinsics) with some distortion.
pub fn camera() -> CameraModel {
    let k = Matrix3::new(1336.2, 0.0, 646.3, 0.0, 1335.4, 473.8, 0.0, 0.0, 1.0);
    CameraModel::new(
        "test",
        WIDTH,
        HEIGHT,
        k,
        [-0.05, 0.01, 0.0002, -0.0001, 0.0],
    )
    .unwrap()
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

/// Noise-like pixels that differ for every frame (an xorshift of seq, x, y).
pub fn image(seq: u64, width: u32, height: u32) -> GrayImage {
    let mut s = seq.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    GrayImage::from_fn(width, height, |_, _| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        image::Luma([(s >> 24) as u8])
    })
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
    let c = centre_camera_m(seq);
    let n = normal_camera(seq);
    FrameTruth {
        frame: format!("frame_{seq:06}.png"),
        seq,
        t: seq as f64 / 30.0,
        expect: "detect".into(),
        radius: 0.15,
        position_camera: c.into(),
        normal_camera: n.into(),
        alt_position_camera: c.into(),
        alt_normal_camera: [-n.x, -n.y, n.z],
        ellipse: Some(TruthEllipse {
            cx: 646.3,
            cy: 473.8,
            a: 10.0,
            b: 9.0,
            theta: 0.1,
        }),
        range_m: c.norm(),
        tilt_deg: 5.0,
        probe_rim_frac: 0.0,
        hose_rim_frac: 0.0,
        rim_fully_in_image: true,
        position_body: [c.z, c.x, c.y],
        normal_body: [n.z, n.x, n.y],
        ned_frame: drogue_sim::NED_FRAME_SCENARIO.into(),
        position_ned: [100.0, 0.0, -50.0],
        receiver_position_ned: [80.0, 0.0, -50.0],
        receiver_q_ned_body: [1.0, 0.0, 0.0, 0.0],
        capture_time_ns: time_ns(seq),
        canopy_radius: 0.33,
        visible_rim_frac: 1.0,
        coupled: false,
    }
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
        Detection {
            ellipse_px: Ellipse::new(640.0, 480.0, 30.0, 25.0, 0.1),
            pose_camera: CirclePose {
                centre_camera_m: centre,
                normal_camera: normal,
            },
            alt_pose_camera: None,
            disambiguation: Disambiguation::CanopyRim,
            position_body_m: Point::new(Vector3::new(centre.z, centre.x, centre.y)),
            normal_body: Direction::new(Vector3::new(normal.z, normal.x, normal.y)),
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
            track_epoch: 1,
            inliers: (0..40u32).map(|i| !i.is_multiple_of(20)).collect(),
            rim_points_px: rim,
        }
    });
    Measurement {
        seq,
        capture_time_ns: time_ns(seq),
        detection,
        tracked: seq > 0,
        times: StageTimes {
            detect_us: 1000,
            fit_us: 500,
            pose_us: 100,
            total_us: 1600 + (seq as u32 % 10) * 100,
        },
    }
}

/// Position error along camera x built into [`measurement`], metres.
pub fn error_m(seq: u64) -> f64 {
    0.01 * (1 + seq % 3) as f64
}

pub fn detection_json(m: &Measurement) -> serde_json::Value {
    serde_json::to_value(DetectionRecord::from_measurement(m.seq.to_string(), m)).unwrap()
}

/// Capture → send latency built into outgoing [`link_event`]s, milliseconds.
pub fn latency_ms(i: u64) -> f64 {
    2.0 + (i % 10) as f64 * 0.5
}

pub fn mount() -> MountTransforms {
    MountTransforms {
        camera_in_body_m: [1.5, 0.0, -0.2],
        // Camera looking forward: R_body_cam0 (cam x = body y, cam y = body z,
        // cam z = body x) as a quaternion, w first.
        q_body_camera: [0.5, 0.5, 0.5, 0.5],
        probe_in_body_m: [3.0, 0.4, -0.5],
    }
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
