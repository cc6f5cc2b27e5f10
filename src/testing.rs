//! Fixtures shared by the tests, benches and examples: one place for the
//! hand-built values that were copied into each of them (a `Detection`, an
//! autopilot HEARTBEAT, the reference data's folder and truth, the cameras).
//!
//! Behind the `testing` cargo feature, which is not a default feature: the
//! package's own dev-dependency on itself turns it on for `cargo test` and
//! `cargo bench`, so a `cargo build --release` binary does not contain it.
//! The unit tests inside `src/` see it through `cfg(test)`.
//!
//! Every value here is a fixed input a test chooses (or, for the reference
//! data, a file's content); none is computed by the code under test. Helpers
//! that only the integration tests use stay in their support modules under
//! `tests/`.
//!
//! A fixture built from a struct literal breaks on every new field; build
//! variants with struct update syntax (`Detection { track_epoch: 9,
//! ..detection(p, n, 1) }`), so that the literal stands here only.

use crate::camera::CameraModel;
use crate::config::Config;
use crate::log::MountTransforms;
use crate::measure::detect::Detector;
use crate::measure::detect::canopy::DrogueCircles;
use crate::measure::ellipse::Ellipse;
use crate::measure::{CirclePose, Detection, Disambiguation, FitQuality, Measurement, StageTimes};
use crate::spatial::{Direction, Point};
use drogue_sim::camera::SimCamera;
use drogue_sim::{FrameTruth, TruthEllipse};
use image::GrayImage;
use mavlink::dialects::ardupilotmega::{
    ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavMessage, MavModeFlag,
    MavState, MavType,
};
use nalgebra::{Matrix3, Vector3};
use std::path::{Path, PathBuf};

/// The environment variable that names the reference frames' folder (the
/// independent renderer's sets, `../shared/data/reference` beside CI's clone).
pub const REFERENCE_DIR_VAR: &str = "DROGUE_REFERENCE_DIR";

/// The reference sets whose frames hold a drogue (every set but `negative`
/// and `badinput`), in the order the reports list them.
pub const DROGUE_REFERENCE_SETS: [&str; 8] = [
    "paper10",
    "range",
    "tilt",
    "occlusion",
    "noise",
    "hard",
    "hard_b",
    "hard_c",
];

/// The reference frames' folder from `DROGUE_REFERENCE_DIR`.
///
/// The tests that call it are `#[ignore]`d; run on purpose (`.ci/run` runs
/// them with `--include-ignored`), they panic when the variable is unset or
/// names a folder that is not the reference folder, so that they can never
/// pass without having looked at a frame.
///
/// # Panics
/// When the variable is unset or its folder has no `paper10/` set.
pub fn reference_dir() -> PathBuf {
    let dir = std::env::var_os(REFERENCE_DIR_VAR).map_or_else(
        || panic!("{REFERENCE_DIR_VAR} is not set: it must name the reference frames' folder"),
        PathBuf::from,
    );
    assert!(
        dir.join("paper10").is_dir(),
        "{REFERENCE_DIR_VAR}={} is not the reference frames' folder (no paper10/ in it)",
        dir.display()
    );
    dir
}

/// One reference set (`paper10`, `range`, ...) under [`reference_dir`].
///
/// # Panics
/// As [`reference_dir`], and when the set has no `truth.jsonl`.
pub fn reference_set(name: &str) -> PathBuf {
    let set = reference_dir().join(name);
    assert!(
        set.join("truth.jsonl").is_file(),
        "{REFERENCE_DIR_VAR} is set but {} has no truth.jsonl",
        set.display()
    );
    set
}

/// One line of a reference set's `truth.jsonl` (the fields the tests use;
/// the simulator's `truth.jsonl` has the same names). Fields a set may leave
/// out (a frame without a drogue has no ellipse) are options.
#[derive(Clone, Debug, serde::Deserialize)]
pub struct Truth {
    /// The image's file name in the set.
    pub frame: String,
    /// `detect`, `no_detect`, `error`, ...: what the frame must give.
    pub expect: String,
    /// The set's sub-group (`range=01m`), where it has them.
    pub group: Option<String>,
    /// Exact image ellipse of the inner circle, undistorted pixels.
    pub ellipse: Option<Ellipse>,
    /// The inner circle's radius, metres.
    pub radius: Option<f64>,
    /// Inner circle centre, camera frame, metres.
    pub position_camera: Option<[f64; 3]>,
    /// Unit normal of the drogue, camera frame, toward the camera.
    pub normal_camera: Option<[f64; 3]>,
    /// The mirror solution of the same image ellipse.
    pub alt_position_camera: Option<[f64; 3]>,
    /// Normal of the mirror solution, camera frame.
    pub alt_normal_camera: Option<[f64; 3]>,
    /// Distance from the camera to the inner circle's centre, metres.
    pub range_m: Option<f64>,
    /// Angle between the drogue normal and the line of sight, degrees.
    pub tilt_deg: Option<f64>,
    /// Share of the inner rim hidden by the probe, 0..1.
    pub probe_rim_frac: Option<f64>,
    /// Inner circle centre, body FRD, metres.
    pub position_body: Option<[f64; 3]>,
}

/// Every line of `set/truth.jsonl`, in file order.
///
/// # Panics
/// When the file cannot be read or a line is not a truth record: the
/// reference data is the test's input, and a broken one must fail it.
pub fn read_truths(set: &Path) -> Vec<Truth> {
    let path = set.join("truth.jsonl");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            serde_json::from_str(l)
                .unwrap_or_else(|e| panic!("{}: not a truth line ({e}): {l}", path.display()))
        })
        .collect()
}

/// Every line of a JSON-lines file (`process --out`, `replay`, a
/// `truth.jsonl`) as a JSON value, in file order.
///
/// # Panics
/// When the file cannot be read or a line is not JSON (a blank line
/// included): the file is what the test checks.
pub fn read_json_lines(path: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    text.lines()
        .map(|l| {
            serde_json::from_str(l)
                .unwrap_or_else(|e| panic!("{}: not JSON ({e}): {l:?}", path.display()))
        })
        .collect()
}

/// The reference sets' camera: 1280x960, the paper's intrinsics, with the
/// given plumb-bob distortion (k1, k2, p1, p2, k3).
pub fn paper_camera(distortion: [f64; 5]) -> CameraModel {
    let k = Matrix3::new(1336.2, 0.0, 646.3, 0.0, 1335.4, 473.8, 0.0, 0.0, 1.0);
    CameraModel::new("test", 1280, 960, k, distortion).expect("the paper's camera is valid")
}

/// A small 640x480 camera, f = 800 px, centred principal point, with the
/// given distortion: cheap frames for unit tests.
pub fn vga_camera(distortion: [f64; 5]) -> CameraModel {
    let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
    CameraModel::new("t", 640, 480, k, distortion).expect("the VGA camera is valid")
}

/// drogue-vision's model of a simulator camera (the same pinhole and lens).
///
/// # Panics
/// When the simulator's camera is not a valid camera model.
pub fn camera_from_sim(cam: &SimCamera, name: &str) -> CameraModel {
    let k = Matrix3::new(cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0);
    CameraModel::new(name, cam.width, cam.height, k, cam.distortion)
        .expect("the simulator's camera is valid")
}

/// The drogue's two circles and its canopy's band as `config` gives them.
pub fn drogue_circles(config: &Config) -> DrogueCircles {
    config.drogue.circles()
}

/// A detector with `config`'s settings and drogue, for `camera`.
pub fn detector(config: &Config, camera: &CameraModel) -> Detector {
    Detector::new(&config.detect, camera, drogue_circles(config))
}

/// Noise-like pixels that differ for every `seq` (an xorshift of seq, x, y):
/// frames that no codec can shrink much, and that tell frames apart.
pub fn noise_image(seq: u64, width: u32, height: u32) -> GrayImage {
    let mut s = seq.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    GrayImage::from_fn(width, height, |_, _| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        image::Luma([(s >> 24) as u8])
    })
}

/// The simulator's truth for frame `seq` with the drogue at `centre_camera_m`
/// and axis `normal_camera`, captured at `capture_time_ns`: the body frame
/// of the default forward-looking mount, a fixed small image ellipse, the
/// scenario's NED frame with fixed positions. What a log stores and gives
/// back, not what a measurement is compared with.
pub fn frame_truth(
    seq: u64,
    centre_camera_m: Vector3<f64>,
    normal_camera: Vector3<f64>,
    capture_time_ns: u64,
) -> FrameTruth {
    let (c, n) = (centre_camera_m, normal_camera);
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
        capture_time_ns,
        canopy_radius: 0.33,
        visible_rim_frac: 1.0,
        coupled: false,
        blur_px: [0.0, 0.0],
    }
}

/// The default forward-looking mount as the log records it: the camera
/// 1.5 m ahead of the body origin looking forward (camera x = body y,
/// camera y = body z, camera z = body x), the probe tip ahead and to the
/// right.
pub fn mount_transforms() -> MountTransforms {
    MountTransforms {
        camera_in_body_m: [1.5, 0.0, -0.2],
        // R_body_cam0 as a quaternion, w first.
        q_body_camera: [0.5, 0.5, 0.5, 0.5],
        probe_in_body_m: [3.0, 0.4, -0.5],
    }
}

/// A detection of a drogue centred at `position_body_m` with axis
/// `normal_body` (body FRD), seen through the default forward-looking mount
/// (camera x = body y, camera y = body z, camera z = body x), probe at the
/// body origin. The image ellipse, covariance and fit quality are fixed
/// plausible values; change what a test needs with struct update syntax.
pub fn detection(
    position_body_m: impl Into<Vector3<f64>>,
    normal_body: impl Into<Vector3<f64>>,
    track_epoch: u32,
) -> Detection {
    let p: Vector3<f64> = position_body_m.into();
    let n: Vector3<f64> = normal_body.into();
    Detection {
        ellipse_px: Ellipse {
            cx: 640.0,
            cy: 480.0,
            a: 40.0,
            b: 38.0,
            theta: 0.0,
        },
        pose_camera: CirclePose {
            centre_camera_m: Point::new(Vector3::new(p.y, p.z, p.x)),
            normal_camera: Direction::new(Vector3::new(n.y, n.z, n.x)),
        },
        alt_pose_camera: None,
        disambiguation: Disambiguation::CanopyRim,
        position_body_m: Point::new(p),
        normal_body: Direction::new(n),
        position_from_probe_body_m: Point::new(p),
        position_cov_body_m2: Matrix3::from_diagonal(&Vector3::new(4e-4, 1e-5, 2e-5)),
        normal_sigma_rad: 0.02,
        quality: FitQuality {
            points: 200,
            inliers: 180,
            rms_residual_px: 0.3,
            score: 0.8,
        },
        track_epoch,
        rim_points_px: vec![],
        inliers: vec![],
    }
}

/// A measurement of frame `seq` captured at `capture_time_ns` (ns since the
/// Unix epoch), not tracked, with zero stage times.
pub fn measurement(seq: u64, capture_time_ns: u64, detection: Option<Detection>) -> Measurement {
    Measurement {
        seq,
        capture_time_ns,
        detection,
        miss: None,
        tracked: false,
        times: StageTimes::default(),
    }
}

/// A HEARTBEAT as a vehicle of `mavtype` with `autopilot` sends it (active,
/// no base mode flags).
pub fn heartbeat(mavtype: MavType, autopilot: MavAutopilot, custom_mode: u32) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode,
        mavtype,
        autopilot,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// An ArduPilot quadrotor's HEARTBEAT in flight mode `custom_mode`.
pub fn autopilot_heartbeat(custom_mode: u32) -> MavMessage {
    heartbeat(
        MavType::MAV_TYPE_QUADROTOR,
        MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        custom_mode,
    )
}

/// ATTITUDE at `time_boot_ms` (the sender's boot clock) with roll, pitch
/// and yaw in radians, not turning.
pub fn attitude(time_boot_ms: u32, [roll, pitch, yaw]: [f32; 3]) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms,
        roll,
        pitch,
        yaw,
        rollspeed: 0.0,
        pitchspeed: 0.0,
        yawspeed: 0.0,
    })
}

/// LOCAL_POSITION_NED at `time_boot_ms` (the sender's boot clock), metres,
/// at rest.
pub fn local_position_ned(time_boot_ms: u32, [x, y, z]: [f32; 3]) -> MavMessage {
    MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms,
        x,
        y,
        z,
        vx: 0.0,
        vy: 0.0,
        vz: 0.0,
    })
}
