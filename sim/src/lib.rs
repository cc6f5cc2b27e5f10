//! drogue-sim: the simulated drogue trajectory driver and synthetic camera.
//!
//! Deterministic for a seed. Every rendered frame comes with its exact truth
//! ([`FrameTruth`]), computed from the geometry, never from the pixels.
//!
//! Pieces: [`scenario`] (TOML scenarios, builtin or from a file),
//! [`trajectory`] (tanker, drogue with Dryden sway, bow wave and hose whip,
//! receiver approach), [`camera`] (pinhole + plumb_bob, independent of
//! drogue-vision's), [`conic`] (exact image ellipse and mirror pose),
//! [`render`] (8-bit gray frames) and [`Simulator`] tying them together;
//! [`sweep`] renders randomised unrelated frames, one factor at a time, for
//! robustness tests.

pub mod bounds;
pub mod camera;
pub mod conic;
pub mod error;
pub mod geometry;
pub mod render;
pub mod scenario;
pub mod simulator;
pub mod sweep;
pub mod trajectory;
pub mod turbulence;

pub use error::SimError;
pub use scenario::{MountSpec, Scenario};
pub use simulator::Simulator;
pub use turbulence::Intensity;

use serde::{Deserialize, Serialize};

/// The exact ellipse of the inner circle in undistorted pixels (from the
/// image conic): a >= b, theta from +u toward +v in (-pi/2, pi/2].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthEllipse {
    /// Centre u, undistorted pixels.
    pub cx: f64,
    /// Centre v, undistorted pixels.
    pub cy: f64,
    /// Semi-major axis, pixels.
    pub a: f64,
    /// Semi-minor axis, pixels.
    pub b: f64,
    /// Angle of the major axis from +u toward +v, radians.
    pub theta: f64,
}

/// `FrameTruth::ned_frame` of the simulator's own world NED.
pub const NED_FRAME_SCENARIO: &str = "scenario";
/// `FrameTruth::ned_frame` when a closed loop put the truth in the
/// autopilot's local NED (origin at its EKF origin).
pub const NED_FRAME_AUTOPILOT: &str = "autopilot";

fn scenario_ned_frame() -> String {
    NED_FRAME_SCENARIO.into()
}

/// Truth of one frame, in the field names and conventions of the reference
/// data's `truth.jsonl`, plus body, NED and time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTruth {
    /// File name the frame is written under (`frame_000123.png`).
    pub frame: String,
    /// Sequence number from 0.
    pub seq: u64,
    /// Simulation time, seconds from the scenario start.
    pub t: f64,
    /// `detect` when the inner circle is in view, else `no_detect`.
    pub expect: String,
    /// Radius of the inner circle, metres.
    pub radius: f64,
    /// Inner circle centre, camera frame (x right, y down, z forward), metres.
    pub position_camera: [f64; 3],
    /// Unit normal of the drogue plane, camera frame, toward the camera.
    pub normal_camera: [f64; 3],
    /// The mirror solution that images to the same ellipse.
    pub alt_position_camera: [f64; 3],
    /// Normal of the mirror solution, camera frame, toward the camera.
    pub alt_normal_camera: [f64; 3],
    /// Exact image ellipse of the inner circle; `None` when not in front.
    pub ellipse: Option<TruthEllipse>,
    /// Distance from the camera to the inner circle's centre, metres.
    pub range_m: f64,
    /// Angle between the drogue normal and the line of sight, degrees.
    pub tilt_deg: f64,
    /// Share of the inner rim hidden by the probe, 0..1.
    pub probe_rim_frac: f64,
    /// Share of the inner rim hidden by the hose, 0..1.
    pub hose_rim_frac: f64,
    /// The whole inner rim lies inside the image.
    pub rim_fully_in_image: bool,
    /// Inner circle centre, receiver body FRD, metres.
    pub position_body: [f64; 3],
    /// Drogue normal, body FRD.
    pub normal_body: [f64; 3],
    /// The frame of `position_ned`, `receiver_position_ned` and
    /// `receiver_q_ned_body`: [`NED_FRAME_SCENARIO`] (the scenario's world)
    /// or [`NED_FRAME_AUTOPILOT`] (SITL closed loop: the autopilot's local NED).
    #[serde(default = "scenario_ned_frame")]
    pub ned_frame: String,
    /// Inner circle centre, local NED (`ned_frame`), metres.
    pub position_ned: [f64; 3],
    /// Receiver (body origin) position, local NED (`ned_frame`), metres.
    pub receiver_position_ned: [f64; 3],
    /// Receiver attitude body → NED (`ned_frame`), Hamilton quaternion w, x, y, z.
    pub receiver_q_ned_body: [f64; 4],
    /// Capture time (mid-exposure), ns since the Unix epoch.
    pub capture_time_ns: u64,
    /// Radius of the canopy's outer rim, metres.
    pub canopy_radius: f64,
    /// Share of the inner rim visible (in front, in the image, not hidden).
    pub visible_rim_frac: f64,
    /// The probe is in the drogue (contact made).
    pub coupled: bool,
    /// The drogue's image motion during the exposure that the frame's
    /// motion blur was drawn with (u, v pixels, in the distorted frame):
    /// the relative translation's, not the camera's rotation. Zero without
    /// motion blur; absent from truth written before it was recorded.
    #[serde(default)]
    pub blur_px: [f64; 2],
}
