//! The outgoing messages, built from a [`Measurement`], and their JSON form
//! for the log.
//!
//! # The drogue frame
//! A circle fixes its centre and its axis, not a rotation about that axis, so
//! the drogue frame D is defined from the normal and the receiver's own down
//! axis:
//! - origin: the centre of the dark inner circle;
//! - x_D = -normal: along the drogue's axis, pointing away from the receiver
//!   (the direction the receiver flies to dock; with the drogue straight ahead
//!   and square to the camera, x_D = body x);
//! - z_D: body +z (down) made perpendicular to x_D; y_D = z_D x x_D.
//!
//! With the drogue straight ahead and square on, D has the body's axes and
//! the receiver sits at (-range, 0, 0) in D.
//!
//! # What is sent
//! - LANDING_TARGET (`landing_target`), MAV_FRAME_BODY_FRD: x y z = drogue
//!   centre in body FRD (m); distance = |xyz|; position_valid = 1;
//!   type = LANDING_TARGET_TYPE_VISION_OTHER; q = q_body_drogue (rotates D
//!   vectors into body); angle_x / angle_y = the centre's line-of-sight
//!   angles in the camera image, atan2(x_cam, z_cam) and atan2(y_cam, z_cam)
//!   (MAVLink's "angular offset from the centre of the image"); size_x/size_y
//!   = 0 (not known here). ArduPilot (AC_PrecLand_Companion, PLND_TYPE=1) with
//!   position_valid = 1 and MAV_FRAME_BODY_FRD uses xyz / distance as the line
//!   of sight and ignores the angles; it drops a target older than 1 s.
//! - LANDING_TARGET (`landing_target_ned`), MAV_FRAME_LOCAL_NED: x y z =
//!   vehicle NED position + R_ned_body * body xyz, with the vehicle pose from
//!   the link's LOCAL_POSITION_NED and ATTITUDE at the capture time; q =
//!   q_ned_drogue. PX4 (mavlink_receiver) accepts LANDING_TARGET only in this
//!   frame, as the target's absolute position (landing_target_pose.x_abs..).
//! - VISION_POSITION_ESTIMATE: x y z = receiver (body origin) in D, metres;
//!   roll pitch yaw = receiver attitude in D (ZYX, radians); covariance =
//!   upper triangle of the 6x6 (x y z roll pitch yaw), row by row;
//!   reset_counter = track_epoch (mod 256).
//! - ODOMETRY: the same pose, frame_id MAV_FRAME_LOCAL_FRD (= D),
//!   child_frame_id MAV_FRAME_BODY_FRD, q = q_D_body, velocities unknown
//!   (NaN, `velocity_covariance[0]` = NaN), estimator MAV_ESTIMATOR_TYPE_VISION.
//!
//! - TARGET_RELATIVE (`target_relative`, id 511, MAVLink `development`
//!   dialect, for PX4's vision_target_estimator): the drogue centre relative
//!   to the vehicle. With the vehicle attitude at the capture time (ATTITUDE
//!   on the link): frame TARGET_OBS_FRAME_LOCAL_OFFSET_NED, x y z =
//!   R_ned_body times body xyz, q_target = q_ned_drogue, q_sensor = identity (the frame
//!   already is vehicle-carried NED). Without it: TARGET_OBS_FRAME_BODY_FRD,
//!   x y z = body xyz, q_target = q_body_drogue, q_sensor = 0 (ignored: the
//!   autopilot rotates with its own attitude at the timestamp). The camera
//!   mount enters through x y z (camera → body happens in the measurement),
//!   the attitude through the frame choice. pos_std = square roots of the
//!   diagonal of the drogue centre's covariance in that frame (the
//!   measurement's `position_cov_body_m2`, rotated), times
//!   `[link] target_relative_std_scale`, at least
//!   `target_relative_std_floor_m`; yaw_std = the normal's sigma, scaled the
//!   same way. timestamp = capture time, µs, on our Unix clock (what PX4's
//!   receiver maps with its TIMESYNC), or on the autopilot's clock once our
//!   own TIMESYNC exchange has converged when `target_relative_clock =
//!   "autopilot"`. type = LANDING_TARGET_TYPE_VISION_OTHER, id = 0.
//!
//! Time fields carry the frame's capture time in microseconds on our clock
//! (Unix epoch), the same clock as our TIMESYNC replies' tc1: PX4 maps it
//! with its timesync (`sync_stamp`), ArduPilot with its offboard jitter
//! correction, both of which need one consistent clock and nothing else.

use super::telemetry::VehiclePose;
use crate::measure::{Detection, Measurement};
use crate::spatial::{quaternion_from_wxyz, quaternion_to_wxyz};
use mavlink::Message;
use mavlink::dialects::ardupilotmega::{
    HEARTBEAT_DATA, LANDING_TARGET_DATA, LandingTargetType, MavAutopilot, MavBool,
    MavEstimatorType, MavFrame, MavMessage, MavModeFlag, MavState, MavType, ODOMETRY_DATA,
    TIMESYNC_DATA, VISION_POSITION_ESTIMATE_DATA,
};
use mavlink::dialects::development as dev;
use nalgebra::{Matrix3, Matrix6, Rotation3, UnitQuaternion, Vector3};
use serde_json::{Value, json};

/// A message the link writes: one of the `ardupilotmega` dialect, or
/// TARGET_RELATIVE of the `development` dialect (id 511, which
/// `ardupilotmega` does not include). Both share the MAVLink 2 framing.
#[derive(Clone, Debug)]
pub enum Outbound {
    /// A message of the `ardupilotmega` dialect.
    Ardupilot(MavMessage),
    /// A message of the `development` dialect (TARGET_RELATIVE).
    Development(dev::MavMessage),
}

impl From<MavMessage> for Outbound {
    fn from(m: MavMessage) -> Self {
        Self::Ardupilot(m)
    }
}

impl Outbound {
    /// The message's MAVLink name, e.g. `LANDING_TARGET`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Ardupilot(m) => m.message_name(),
            Self::Development(m) => m.message_name(),
        }
    }

    /// The fields as JSON for `/mavlink/out` (see [`fields_json`]).
    pub fn fields_json(&self) -> Value {
        match self {
            Self::Ardupilot(m) => fields_json(m),
            Self::Development(dev::MavMessage::TARGET_RELATIVE(d)) => json!({
                "timestamp": d.timestamp, "id": d.id, "frame": format!("{:?}", d.frame),
                "x": d.x, "y": d.y, "z": d.z, "pos_std": d.pos_std, "yaw_std": d.yaw_std,
                "q_target": d.q_target, "q_sensor": d.q_sensor,
                "type": format!("{:?}", d.mavtype),
            }),
            Self::Development(other) => {
                json!({ "id": other.message_id(), "debug": format!("{other:?}") })
            }
        }
    }
}

/// What TARGET_RELATIVE needs besides the measurement.
#[derive(Clone, Copy, Debug)]
pub struct TargetRelativeInputs {
    /// Vehicle attitude (body → NED) at the capture time, if known.
    pub q_ned_body: Option<UnitQuaternion<f64>>,
    /// Autopilot clock minus ours, ns: stamps the capture time on the
    /// autopilot's clock; `None`: our Unix clock.
    pub autopilot_offset_ns: Option<i64>,
    /// Factor on the reported standard deviations (>= 1: inflation).
    pub std_scale: f64,
    /// Smallest position standard deviation reported, metres.
    pub std_floor_m: f64,
}

/// TARGET_RELATIVE (see the module doc); `None` when a value is not finite.
pub fn target_relative(
    m: &Measurement,
    pose: &DroguePose,
    det: &Detection,
    inputs: &TargetRelativeInputs,
) -> Option<dev::MavMessage> {
    let cov_body = det.position_cov_body_m2;
    let (frame, p, cov, q_target, q_sensor) = match inputs.q_ned_body {
        Some(q_nb) => {
            let r = q_nb.to_rotation_matrix();
            (
                dev::TargetObsFrame::TARGET_OBS_FRAME_LOCAL_OFFSET_NED,
                q_nb * pose.position_body_m,
                r.matrix() * cov_body * r.matrix().transpose(),
                wxyz(&(q_nb * pose.q_body_drogue())),
                [1.0, 0.0, 0.0, 0.0],
            )
        }
        None => (
            dev::TargetObsFrame::TARGET_OBS_FRAME_BODY_FRD,
            pose.position_body_m,
            cov_body,
            wxyz(&pose.q_body_drogue()),
            [0.0; 4],
        ),
    };
    let std = |var: f64| (var.max(0.0).sqrt() * inputs.std_scale).max(inputs.std_floor_m);
    let pos_std = [std(cov[(0, 0)]), std(cov[(1, 1)]), std(cov[(2, 2)])];
    let yaw_std = det.normal_sigma_rad * inputs.std_scale;
    if !(finite3(&p) && pos_std.iter().all(|s| s.is_finite()) && yaw_std.is_finite()) {
        return None;
    }
    let t_ns = match inputs.autopilot_offset_ns {
        Some(off) => u64::try_from(i128::from(m.capture_time_ns) + i128::from(off)).ok()?,
        None => m.capture_time_ns,
    };
    Some(dev::MavMessage::TARGET_RELATIVE(
        dev::TARGET_RELATIVE_DATA {
            timestamp: t_ns / 1000,
            id: 0,
            frame,
            x: p.x as f32,
            y: p.y as f32,
            z: p.z as f32,
            pos_std: pos_std.map(|s| s as f32),
            yaw_std: yaw_std as f32,
            q_target,
            q_sensor,
            mavtype: dev::LandingTargetType::LANDING_TARGET_TYPE_VISION_OTHER,
        },
    ))
}

/// The drogue frame and the receiver's pose in it, from one detection.
#[derive(Clone, Debug)]
pub struct DroguePose {
    /// Rotates drogue-frame vectors into body FRD.
    pub r_body_drogue: Rotation3<f64>,
    /// Drogue centre, body FRD, metres.
    pub position_body_m: Vector3<f64>,
    /// Receiver (body origin) in the drogue frame, metres.
    pub receiver_drogue_m: Vector3<f64>,
    /// Covariance of (x y z roll pitch yaw) of the receiver in the drogue frame.
    pub covariance_drogue: Matrix6<f64>,
}

fn finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|c| c.is_finite())
}

impl DroguePose {
    /// `None` for a degenerate detection (non-finite values, zero distance).
    pub fn new(det: &Detection) -> Option<Self> {
        let p = *det.position_body_m.vector();
        let n = *det.normal_body.vector();
        if !finite3(&p) || !finite3(&n) || p.norm() <= 0.0 || n.norm() <= 0.0 {
            return None;
        }
        let x_d = -n.normalize();
        // Down, made perpendicular to the axis; forward if the axis is vertical.
        let reference = if x_d.z.abs() < 0.999 {
            Vector3::z()
        } else {
            Vector3::x()
        };
        let z_d = (reference - x_d * reference.dot(&x_d)).normalize();
        let y_d = z_d.cross(&x_d);
        let r_body_drogue =
            Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x_d, y_d, z_d]));
        let r_drogue_body = r_body_drogue.inverse();
        let receiver_drogue_m = -(r_drogue_body * p);

        // Position: the body covariance rotated into D, plus the lateral
        // spread from the normal's uncertainty (the axis tilts by sigma, the
        // receiver at range r moves sideways by r * sigma).
        let sigma = if det.normal_sigma_rad.is_finite() {
            det.normal_sigma_rad.max(0.0)
        } else {
            return None;
        };
        let rot = r_drogue_body.matrix();
        let mut cov_pos = rot * det.position_cov_body_m2 * rot.transpose();
        let lateral = (p.norm() * sigma).powi(2);
        cov_pos[(1, 1)] += lateral;
        cov_pos[(2, 2)] += lateral;
        let mut covariance_drogue = Matrix6::zeros();
        covariance_drogue
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&cov_pos);
        for k in 3..6 {
            covariance_drogue[(k, k)] = sigma * sigma;
        }
        if !covariance_drogue.iter().all(|c| c.is_finite()) {
            return None;
        }
        Some(Self {
            r_body_drogue,
            position_body_m: p,
            receiver_drogue_m,
            covariance_drogue,
        })
    }

    pub(crate) fn q_body_drogue(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&self.r_body_drogue)
    }

    /// The 21 upper-triangle entries of the 6x6 covariance, row by row.
    pub fn covariance_upper(&self) -> [f32; 21] {
        let mut out = [0f32; 21];
        let mut k = 0;
        for r in 0..6 {
            for c in r..6 {
                out[k] = self.covariance_drogue[(r, c)] as f32;
                k += 1;
            }
        }
        out
    }
}

/// A rotation as MAVLink's `q` (w first, f32).
fn wxyz(q: &UnitQuaternion<f64>) -> [f32; 4] {
    quaternion_to_wxyz(q).map(|c| c as f32)
}

fn time_usec(m: &Measurement) -> u64 {
    m.capture_time_ns / 1000
}

fn line_of_sight(det: &Detection) -> (f32, f32) {
    let c = det.pose_camera.centre_camera_m;
    (c.x.atan2(c.z) as f32, c.y.atan2(c.z) as f32)
}

/// LANDING_TARGET in MAV_FRAME_BODY_FRD (see the module doc).
pub fn landing_target_body(m: &Measurement, pose: &DroguePose, det: &Detection) -> MavMessage {
    let p = pose.position_body_m;
    let (angle_x, angle_y) = line_of_sight(det);
    MavMessage::LANDING_TARGET(LANDING_TARGET_DATA {
        time_usec: time_usec(m),
        angle_x,
        angle_y,
        distance: p.norm() as f32,
        size_x: 0.0,
        size_y: 0.0,
        target_num: 0,
        frame: MavFrame::MAV_FRAME_BODY_FRD,
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        q: wxyz(&pose.q_body_drogue()),
        mavtype: LandingTargetType::LANDING_TARGET_TYPE_VISION_OTHER,
        position_valid: MavBool::MAV_BOOL_TRUE,
    })
}

/// LANDING_TARGET in MAV_FRAME_LOCAL_NED, absolute, from the vehicle's pose
/// at the capture time (see the module doc).
pub fn landing_target_ned(
    m: &Measurement,
    pose: &DroguePose,
    det: &Detection,
    vehicle: &VehiclePose,
) -> Option<MavMessage> {
    // The autopilot's attitude, refused unless finite and normalised once
    // more (w first and back: the same bits as when it crossed as an array).
    let q_ned_body = quaternion_from_wxyz(quaternion_to_wxyz(&vehicle.q_ned_body))?;
    let target_ned_m = *vehicle.position_ned_m + q_ned_body * pose.position_body_m;
    if !finite3(&target_ned_m) {
        return None;
    }
    let (angle_x, angle_y) = line_of_sight(det);
    Some(MavMessage::LANDING_TARGET(LANDING_TARGET_DATA {
        time_usec: time_usec(m),
        angle_x,
        angle_y,
        distance: pose.position_body_m.norm() as f32,
        size_x: 0.0,
        size_y: 0.0,
        target_num: 0,
        frame: MavFrame::MAV_FRAME_LOCAL_NED,
        x: target_ned_m.x as f32,
        y: target_ned_m.y as f32,
        z: target_ned_m.z as f32,
        q: wxyz(&(q_ned_body * pose.q_body_drogue())),
        mavtype: LandingTargetType::LANDING_TARGET_TYPE_VISION_OTHER,
        position_valid: MavBool::MAV_BOOL_TRUE,
    }))
}

/// VISION_POSITION_ESTIMATE: the receiver in the drogue frame.
pub fn vision_position_estimate(m: &Measurement, pose: &DroguePose, det: &Detection) -> MavMessage {
    let p = pose.receiver_drogue_m;
    let (roll, pitch, yaw) = pose.r_body_drogue.inverse().euler_angles();
    MavMessage::VISION_POSITION_ESTIMATE(VISION_POSITION_ESTIMATE_DATA {
        usec: time_usec(m),
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        roll: roll as f32,
        pitch: pitch as f32,
        yaw: yaw as f32,
        covariance: pose.covariance_upper(),
        reset_counter: (det.track_epoch % 256) as u8,
    })
}

/// ODOMETRY: the same pose as VISION_POSITION_ESTIMATE, velocities unknown.
pub fn odometry(m: &Measurement, pose: &DroguePose, det: &Detection) -> MavMessage {
    let p = pose.receiver_drogue_m;
    let q_drogue_body = pose.q_body_drogue().inverse();
    let mut velocity_covariance = [0f32; 21];
    velocity_covariance[0] = f32::NAN;
    MavMessage::ODOMETRY(ODOMETRY_DATA {
        time_usec: time_usec(m),
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        q: wxyz(&q_drogue_body),
        vx: f32::NAN,
        vy: f32::NAN,
        vz: f32::NAN,
        rollspeed: f32::NAN,
        pitchspeed: f32::NAN,
        yawspeed: f32::NAN,
        pose_covariance: pose.covariance_upper(),
        velocity_covariance,
        frame_id: MavFrame::MAV_FRAME_LOCAL_FRD,
        child_frame_id: MavFrame::MAV_FRAME_BODY_FRD,
        reset_counter: (det.track_epoch % 256) as u8,
        estimator_type: MavEstimatorType::MAV_ESTIMATOR_TYPE_VISION,
        quality: (det.quality.score.clamp(0.0, 1.0) * 99.0 + 1.0).round() as i8,
    })
}

/// Our HEARTBEAT: an onboard controller, not an autopilot.
pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// A TIMESYNC request (tc1 = 0) stamped with our clock.
pub fn timesync_request(now_ns: i64) -> MavMessage {
    MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1: now_ns,
        target_system: 0,
        target_component: 0,
    })
}

/// The answer to a TIMESYNC request: tc1 = our clock, ts1 echoed.
pub fn timesync_reply(
    now_ns: i64,
    request_ts1: i64,
    to_system: u8,
    to_component: u8,
) -> MavMessage {
    MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: now_ns,
        ts1: request_ts1,
        target_system: to_system,
        target_component: to_component,
    })
}

/// A message's fields as JSON for `/mavlink/out` and `/mavlink/in`. The
/// messages this link sends or reads are spelled out field by field (NaN
/// becomes null); any other message is given by its debug text.
pub fn fields_json(msg: &MavMessage) -> Value {
    match msg {
        MavMessage::LANDING_TARGET(d) => json!({
            "time_usec": d.time_usec, "angle_x": d.angle_x, "angle_y": d.angle_y,
            "distance": d.distance, "size_x": d.size_x, "size_y": d.size_y,
            "target_num": d.target_num, "frame": format!("{:?}", d.frame),
            "x": d.x, "y": d.y, "z": d.z, "q": d.q,
            "type": format!("{:?}", d.mavtype), "position_valid": d.position_valid.bits(),
        }),
        MavMessage::VISION_POSITION_ESTIMATE(d) => json!({
            "usec": d.usec, "x": d.x, "y": d.y, "z": d.z,
            "roll": d.roll, "pitch": d.pitch, "yaw": d.yaw,
            "covariance": d.covariance.to_vec(), "reset_counter": d.reset_counter,
        }),
        MavMessage::ODOMETRY(d) => json!({
            "time_usec": d.time_usec, "x": d.x, "y": d.y, "z": d.z, "q": d.q,
            "frame_id": format!("{:?}", d.frame_id),
            "child_frame_id": format!("{:?}", d.child_frame_id),
            "pose_covariance": d.pose_covariance.to_vec(),
            "reset_counter": d.reset_counter,
            "estimator_type": format!("{:?}", d.estimator_type), "quality": d.quality,
        }),
        MavMessage::HEARTBEAT(d) => json!({
            "type": format!("{:?}", d.mavtype), "autopilot": format!("{:?}", d.autopilot),
            "base_mode": d.base_mode.bits(), "custom_mode": d.custom_mode,
            "system_status": format!("{:?}", d.system_status),
            "mavlink_version": d.mavlink_version,
        }),
        MavMessage::TIMESYNC(d) => json!({
            "tc1": d.tc1, "ts1": d.ts1,
            "target_system": d.target_system, "target_component": d.target_component,
        }),
        MavMessage::ATTITUDE(d) => json!({
            "time_boot_ms": d.time_boot_ms, "roll": d.roll, "pitch": d.pitch, "yaw": d.yaw,
            "rollspeed": d.rollspeed, "pitchspeed": d.pitchspeed, "yawspeed": d.yawspeed,
        }),
        MavMessage::LOCAL_POSITION_NED(d) => json!({
            "time_boot_ms": d.time_boot_ms, "x": d.x, "y": d.y, "z": d.z,
            "vx": d.vx, "vy": d.vy, "vz": d.vz,
        }),
        MavMessage::SYSTEM_TIME(d) => json!({
            "time_unix_usec": d.time_unix_usec, "time_boot_ms": d.time_boot_ms,
        }),
        other => json!({ "id": other.message_id(), "debug": format!("{other:?}") }),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::measure::StageTimes;
    use crate::spatial::Point;
    use nalgebra::Matrix3;

    /// The shared test detection ([`crate::testing::detection`]) with the
    /// covariance, normal sigma and track epoch these tests check.
    pub(crate) fn detection(position_body_m: Vector3<f64>, normal_body: Vector3<f64>) -> Detection {
        Detection {
            position_cov_body_m2: Matrix3::from_diagonal(&Vector3::new(1e-4, 4e-6, 9e-6)),
            normal_sigma_rad: 0.01,
            ..crate::testing::detection(position_body_m, normal_body, 258)
        }
    }

    fn measurement(det: Detection) -> Measurement {
        Measurement {
            seq: 7,
            capture_time_ns: 1_700_000_000_123_456_789,
            detection: Some(det),
            miss: None,
            tracked: false,
            times: StageTimes::default(),
        }
    }

    #[test]
    fn square_on_drogue_ahead_gives_the_body_axes() {
        let det = detection(Vector3::new(5.0, 0.0, 0.0), Vector3::new(-1.0, 0.0, 0.0));
        let pose = DroguePose::new(&det).unwrap();
        assert!((pose.r_body_drogue.matrix() - Matrix3::identity()).norm() < 1e-12);
        assert!((pose.receiver_drogue_m - Vector3::new(-5.0, 0.0, 0.0)).norm() < 1e-12);
        // Lateral variance: body variance + (range * sigma)^2.
        let c = pose.covariance_drogue;
        assert!((c[(0, 0)] - 1e-4).abs() < 1e-15);
        assert!((c[(1, 1)] - (4e-6 + 25.0 * 1e-4)).abs() < 1e-12);
        assert!((c[(2, 2)] - (9e-6 + 25.0 * 1e-4)).abs() < 1e-12);
        let up = pose.covariance_upper();
        assert_eq!(up[0], c[(0, 0)] as f32); // (0,0)
        assert_eq!(up[6], c[(1, 1)] as f32); // (1,1) starts row 1
        assert_eq!(up[11], c[(2, 2)] as f32);
        assert_eq!(up[20], c[(5, 5)] as f32);
    }

    #[test]
    fn drogue_frame_is_a_rotation_and_maps_the_receiver_back() {
        // An oblique case: the receiver seen from the drogue must land back at
        // the body origin through the frame, whatever the normal.
        let p = Vector3::new(4.0, -0.7, 1.2);
        let n = Vector3::new(-0.8, 0.3, -0.2).normalize();
        let det = detection(p, n);
        let pose = DroguePose::new(&det).unwrap();
        let r = pose.r_body_drogue.matrix();
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        // x_D is minus the normal; z_D has no body-y... it lies in span(x_D, body z).
        assert!((r.column(0) + n).norm() < 1e-12);
        assert!(r.column(2).dot(&Vector3::z()) > 0.0);
        // body origin = drogue centre + R_body_drogue * receiver_in_D
        assert!((p + pose.r_body_drogue * pose.receiver_drogue_m).norm() < 1e-12);
    }

    #[test]
    fn landing_target_fields_follow_the_measurement() {
        let p = Vector3::new(6.0, 0.5, -0.3);
        let det = detection(p, Vector3::new(-1.0, 0.0, 0.0));
        let m = measurement(det.clone());
        let pose = DroguePose::new(&det).unwrap();
        let MavMessage::LANDING_TARGET(lt) = landing_target_body(&m, &pose, &det) else {
            panic!("not a LANDING_TARGET");
        };
        assert_eq!(lt.time_usec, 1_700_000_000_123_456);
        assert_eq!((lt.x, lt.y, lt.z), (6.0, 0.5, -0.3));
        assert!((f64::from(lt.distance) - p.norm()).abs() < 1e-5);
        assert_eq!(lt.frame, MavFrame::MAV_FRAME_BODY_FRD);
        // Camera x right = body y: angle_x = atan(0.5 / 6), angle_y = atan(-0.3 / 6).
        assert!((f64::from(lt.angle_x) - (0.5f64 / 6.0).atan()).abs() < 1e-6);
        assert!((f64::from(lt.angle_y) - (-0.3f64 / 6.0).atan()).abs() < 1e-6);
        assert_eq!(lt.position_valid, MavBool::MAV_BOOL_TRUE);
        assert_eq!(
            lt.mavtype,
            LandingTargetType::LANDING_TARGET_TYPE_VISION_OTHER
        );

        // NED: vehicle at (100, 20, -50), yawed 90 degrees east: body x = east.
        let yaw90 = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let vehicle = VehiclePose {
            time_ns: m.capture_time_ns,
            position_ned_m: Point::from_array([100.0, 20.0, -50.0]),
            q_ned_body: yaw90,
        };
        let MavMessage::LANDING_TARGET(ned) =
            landing_target_ned(&m, &pose, &det, &vehicle).unwrap()
        else {
            panic!("not a LANDING_TARGET");
        };
        assert_eq!(ned.frame, MavFrame::MAV_FRAME_LOCAL_NED);
        // forward 6 -> east +6, right 0.5 -> south (north -0.5), down -0.3.
        assert!(
            (ned.x - 99.5).abs() < 1e-4
                && (ned.y - 26.0).abs() < 1e-4
                && (ned.z + 50.3).abs() < 1e-4
        );
    }

    #[test]
    fn vision_estimate_and_odometry_carry_pose_and_epoch() {
        let det = detection(Vector3::new(5.0, 0.0, 0.0), Vector3::new(-1.0, 0.0, 0.0));
        let m = measurement(det.clone());
        let pose = DroguePose::new(&det).unwrap();
        let MavMessage::VISION_POSITION_ESTIMATE(v) = vision_position_estimate(&m, &pose, &det)
        else {
            panic!();
        };
        assert_eq!((v.x, v.y, v.z), (-5.0, 0.0, 0.0));
        assert_eq!((v.roll, v.pitch, v.yaw), (0.0, 0.0, 0.0));
        assert_eq!(v.reset_counter, (258 % 256) as u8);
        assert_eq!(v.usec, m.capture_time_ns / 1000);
        let MavMessage::ODOMETRY(o) = odometry(&m, &pose, &det) else {
            panic!();
        };
        assert_eq!((o.x, o.y, o.z), (-5.0, 0.0, 0.0));
        assert_eq!(o.q, [1.0, 0.0, 0.0, 0.0]);
        assert!(o.vx.is_nan() && o.velocity_covariance[0].is_nan());
        assert_eq!(o.pose_covariance, v.covariance);
    }

    #[test]
    fn target_relative_in_body_then_in_offset_ned() {
        let p = Vector3::new(6.0, 0.5, -0.3);
        let det = detection(p, Vector3::new(-1.0, 0.0, 0.0));
        let m = measurement(det.clone());
        let pose = DroguePose::new(&det).unwrap();
        let mut inputs = TargetRelativeInputs {
            q_ned_body: None,
            autopilot_offset_ns: None,
            std_scale: 1.0,
            std_floor_m: 0.0,
        };
        // No attitude: body FRD, q_sensor zero (ignored by the receiver).
        let dev::MavMessage::TARGET_RELATIVE(b) =
            target_relative(&m, &pose, &det, &inputs).unwrap()
        else {
            panic!("not TARGET_RELATIVE");
        };
        assert_eq!(b.frame, dev::TargetObsFrame::TARGET_OBS_FRAME_BODY_FRD);
        assert_eq!((b.x, b.y, b.z), (6.0, 0.5, -0.3));
        assert_eq!(b.timestamp, 1_700_000_000_123_456);
        // The test detection's covariance is diag(1e-4, 4e-6, 9e-6) m^2.
        let want = [1e-2f32, 2e-3, 3e-3];
        for (got, want) in b.pos_std.iter().zip(want) {
            assert!((got - want).abs() < 1e-7, "{:?}", b.pos_std);
        }
        assert!((b.yaw_std - 0.01).abs() < 1e-7);
        assert_eq!(b.q_sensor, [0.0; 4]);
        assert_eq!(b.q_target, [1.0, 0.0, 0.0, 0.0]);

        // Yawed 90 degrees east: forward -> east, right -> south; the
        // covariance's axes swap with it. Scale 2, floor 5 mm; clock offset.
        let yaw90 = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        inputs.q_ned_body = Some(yaw90);
        inputs.std_scale = 2.0;
        inputs.std_floor_m = 0.005;
        inputs.autopilot_offset_ns = Some(-1_699_000_000_000_000_000);
        let dev::MavMessage::TARGET_RELATIVE(n) =
            target_relative(&m, &pose, &det, &inputs).unwrap()
        else {
            panic!("not TARGET_RELATIVE");
        };
        assert_eq!(
            n.frame,
            dev::TargetObsFrame::TARGET_OBS_FRAME_LOCAL_OFFSET_NED
        );
        assert!((n.x + 0.5).abs() < 1e-5 && (n.y - 6.0).abs() < 1e-5 && (n.z + 0.3).abs() < 1e-5);
        let want = [0.005f32, 0.02, 0.006]; // north: max(2 * 2 mm, 5 mm); east: 2 * 10 mm
        for (got, want) in n.pos_std.iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "{:?}", n.pos_std);
        }
        assert_eq!(n.q_sensor, [1.0, 0.0, 0.0, 0.0]);
        // 1_700_000_000_123_456_789 ns - 1_699_000_000_000_000_000 ns, in µs.
        assert_eq!(n.timestamp, 1_000_000_123_456);
        let h = std::f32::consts::FRAC_1_SQRT_2;
        assert!((n.q_target[0] - h).abs() < 1e-6 && (n.q_target[3] - h).abs() < 1e-6);
    }

    #[test]
    fn degenerate_detections_are_refused() {
        let mut det = detection(Vector3::new(0.0, 0.0, 0.0), Vector3::new(-1.0, 0.0, 0.0));
        assert!(DroguePose::new(&det).is_none());
        det.position_body_m = Point::new(Vector3::new(f64::NAN, 0.0, 1.0));
        assert!(DroguePose::new(&det).is_none());
    }
}
