//! `sim:` source: frames rendered by the simulator, with their truth.

use super::{Captured, FrameSource, SourceError, SourceItem};
use crate::camera::CameraModel;
use crate::frame::{Frame, FrameOrigin};
use crate::measure::mount::MountConfig;
use crate::spatial::{quaternion_from_wxyz, quaternion_to_wxyz};
use drogue_sim::trajectory::World;
use drogue_sim::{MountSpec, NED_FRAME_AUTOPILOT, Scenario, Simulator};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// The simulator's camera mount in the config's terms (both use the mount
/// convention of ARCHITECTURE.md section 3).
pub fn mount_config(spec: &MountSpec) -> MountConfig {
    MountConfig {
        camera_position_body_m: spec.position_body_m,
        camera_roll_deg: spec.roll_deg,
        camera_pitch_deg: spec.pitch_deg,
        camera_yaw_deg: spec.yaw_deg,
        probe_tip_body_m: spec.probe_tip_body_m,
    }
}

/// The exposure time over which a scenario's frames are blurred; `None`
/// when they are not (no motion blur, or no exposure time).
pub fn scenario_exposure(scenario: &Scenario) -> Option<Duration> {
    let ms = scenario.camera.exposure_ms;
    (scenario.scene.motion_blur && ms > 0.0)
        .then(|| Duration::try_from_secs_f64(ms * 1e-3).ok())
        .flatten()
}

/// The simulator's camera as the pipeline reads it (through its YAML, as any
/// camera file).
pub fn camera_model(sim: &Simulator) -> Result<CameraModel, SourceError> {
    CameraModel::from_yaml_str(&sim.camera_yaml(), "of the simulator").map_err(|e| {
        SourceError::Open {
            source_name: "sim".into(),
            message: e.to_string(),
        }
    })
}

/// Renders a scenario frame by frame.
pub struct SimSource {
    sim: Simulator,
    camera: CameraModel,
    mount: MountConfig,
    /// Frames handed out so far (the next frame's time is this / fps).
    delivered: u64,
}

impl SimSource {
    /// Opens a built-in scenario by name, or a scenario file.
    pub fn open(name_or_path: &str) -> Result<Self, SourceError> {
        let open_err = |message: String| SourceError::Open {
            source_name: format!("sim:{name_or_path}"),
            message,
        };
        let scenario = Scenario::resolve(name_or_path).map_err(|e| open_err(e.to_string()))?;
        let sim = Simulator::new(scenario).map_err(|e| open_err(e.to_string()))?;
        Ok(Self {
            camera: camera_model(&sim)?,
            mount: mount_config(sim.mount()),
            sim,
            delivered: 0,
        })
    }

    /// The simulator (its scenario, camera, timeline).
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The simulator, for the SITL closed loop (receiver pose from outside).
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    /// Radius of the scenario's inner circle, metres.
    pub fn inner_radius_m(&self) -> f64 {
        self.sim.inner_radius_m()
    }

    /// The next frame's time on the scenario's timeline, ns since the Unix
    /// epoch (its `capture_time_ns` when the run is not paced).
    pub fn next_frame_time_ns(&self) -> u64 {
        self.sim.start_time_ns() + (self.delivered as f64 / self.sim.fps() * 1e9).round() as u64
    }

    /// Moves past the next frame without rendering it (a dropped frame);
    /// `None` at the end of the scenario.
    pub fn skip_frame(&mut self) -> Option<()> {
        self.sim.next_truth()?;
        self.delivered += 1;
        Some(())
    }

    /// SITL closed loop: renders the next frame with the receiver at the
    /// autopilot's pose (its local NED), captured at `capture_time_ns`. The
    /// frame's truth is put in the autopilot's frame too (`ned_frame =
    /// "autopilot"`), so it compares directly with what the autopilot and
    /// LANDING_TARGET in LOCAL_NED say.
    pub fn next_frame_from_autopilot(
        &mut self,
        anchor: &AutopilotAnchor,
        position_autopilot_m: [f64; 3],
        q_autopilot_body: [f64; 4],
        capture_time_ns: u64,
    ) -> Option<SourceItem> {
        let t_s = self.delivered as f64 / self.sim.fps();
        let (position_world_m, q_world_body) =
            anchor.to_world(position_autopilot_m, q_autopilot_body, t_s);
        self.sim.set_receiver_pose(position_world_m, q_world_body);
        let mut item = self.next_frame()?;
        if let Ok(captured) = &mut item {
            captured.frame.capture_time_ns = capture_time_ns;
            if let Some(truth) = &mut captured.truth {
                anchor.truth_to_autopilot(truth);
                truth.capture_time_ns = capture_time_ns;
            }
        }
        Some(item)
    }
}

/// `[run] sitl_anchor`: the autopilot's local NED in the scenario's world.
/// Both are placed at the autopilot's first pose (a translation and a yaw);
/// they differ in whether that placement then moves with the tanker.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SitlAnchor {
    /// Moves with the tanker: a vehicle holding its position keeps station
    /// behind the drogue (multicopter SITL).
    Tanker,
    /// Fixed in the world: the vehicle itself must fly the tanker's speed
    /// and course (fixed-wing SITL, scenario `[tanker] airspeed_mps`).
    World,
}

/// Where the autopilot's local NED (origin at its EKF origin, any heading)
/// sits in the scenario's world NED, for the SITL closed loop.
///
/// Fixed at the autopilot's first pose: the vehicle is put where the
/// scenario's scripted receiver is at t = 0 (pre-contact, the drogue ahead of
/// it), its heading turned onto the receiver's heading (a rotation about down
/// only: both frames are NED). With [`SitlAnchor::Tanker`] the placement then
/// moves at the tanker's constant velocity, so a vehicle that holds its
/// position keeps station behind the drogue; with [`SitlAnchor::World`] it
/// stays put and the vehicle must fly the tanker's speed and course.
///
/// world = R_world_autopilot (p_autopilot - autopilot_origin) + world_origin
/// + velocity * t.
#[derive(Clone, Debug, PartialEq)]
pub struct AutopilotAnchor {
    /// Yaw of the autopilot's NED in the world's (world heading minus
    /// autopilot heading at the first pose), radians.
    pub yaw_world_autopilot_rad: f64,
    /// The vehicle's first position, autopilot NED, metres.
    pub origin_autopilot_m: [f64; 3],
    /// Where it was put: the scripted receiver at t = 0, world NED, metres.
    pub origin_world_m: [f64; 3],
    /// How the placement moves, world NED, m/s (the tanker's velocity, or 0).
    pub velocity_world_mps: [f64; 3],
}

fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    q.euler_angles().2
}

impl AutopilotAnchor {
    /// The anchor for the autopilot's first pose (`position_autopilot_m`,
    /// `q_autopilot_body`) in `scenario`'s world; `None` for a non-finite or
    /// zero pose.
    pub fn new(
        scenario: &Scenario,
        mode: SitlAnchor,
        position_autopilot_m: [f64; 3],
        q_autopilot_body: [f64; 4],
    ) -> Option<Self> {
        let q_ap = quaternion_from_wxyz(q_autopilot_body)?;
        if !position_autopilot_m.iter().all(|v| v.is_finite()) {
            return None;
        }
        // The scripted world at t = 0 (a fresh copy: same seed, same start).
        let start = World::new(scenario).advance();
        let q_world_receiver =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&start.r_ned_body));
        let velocity = match mode {
            SitlAnchor::Tanker => {
                start.r_ned_tanker * Vector3::new(scenario.tanker.airspeed_mps, 0.0, 0.0)
            }
            SitlAnchor::World => Vector3::zeros(),
        };
        Some(Self {
            yaw_world_autopilot_rad: wrap_pi(yaw_of(&q_world_receiver) - yaw_of(&q_ap)),
            origin_autopilot_m: position_autopilot_m,
            origin_world_m: start.receiver_ned.into(),
            velocity_world_mps: velocity.into(),
        })
    }

    fn q_world_autopilot(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_world_autopilot_rad)
    }

    fn moved_origin_world(&self, t_s: f64) -> Vector3<f64> {
        Vector3::from(self.origin_world_m) + Vector3::from(self.velocity_world_mps) * t_s
    }

    /// An autopilot pose (local NED, body → NED) in the world at `t_s`
    /// (scenario time). An unusable quaternion gives a zero one, which the
    /// simulator ignores.
    pub fn to_world(
        &self,
        position_autopilot_m: [f64; 3],
        q_autopilot_body: [f64; 4],
        t_s: f64,
    ) -> ([f64; 3], [f64; 4]) {
        let r = self.q_world_autopilot();
        let p = r * (Vector3::from(position_autopilot_m) - Vector3::from(self.origin_autopilot_m))
            + self.moved_origin_world(t_s);
        let q = quaternion_from_wxyz(q_autopilot_body)
            .map_or([0.0; 4], |q| quaternion_to_wxyz(&(r * q)));
        (p.into(), q)
    }

    /// A world position at `t_s` in the autopilot's local NED.
    pub fn position_to_autopilot(&self, position_world_m: [f64; 3], t_s: f64) -> [f64; 3] {
        let p = self.q_world_autopilot().inverse()
            * (Vector3::from(position_world_m) - self.moved_origin_world(t_s))
            + Vector3::from(self.origin_autopilot_m);
        p.into()
    }

    /// The NED fields of a frame's truth, world → autopilot NED.
    pub fn truth_to_autopilot(&self, truth: &mut drogue_sim::FrameTruth) {
        truth.position_ned = self.position_to_autopilot(truth.position_ned, truth.t);
        truth.receiver_position_ned =
            self.position_to_autopilot(truth.receiver_position_ned, truth.t);
        if let Some(q) = quaternion_from_wxyz(truth.receiver_q_ned_body) {
            truth.receiver_q_ned_body =
                quaternion_to_wxyz(&(self.q_world_autopilot().inverse() * q));
        }
        truth.ned_frame = NED_FRAME_AUTOPILOT.into();
    }
}

fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

impl FrameSource for SimSource {
    fn camera(&self) -> Option<CameraModel> {
        Some(self.camera.clone())
    }
    fn provenance(&self) -> Vec<(String, String)> {
        let scenario = self.sim.scenario();
        let mut out = vec![
            ("scenario".to_string(), scenario.name.clone()),
            ("seed".to_string(), scenario.seed.to_string()),
        ];
        if let Ok(text) = toml::to_string(scenario) {
            out.push(("scenario_toml".to_string(), text));
        }
        out
    }
    fn mount(&self) -> Option<MountConfig> {
        Some(self.mount.clone())
    }
    fn fps(&self) -> Option<f64> {
        Some(self.sim.fps())
    }
    fn exposure(&self) -> Option<Duration> {
        scenario_exposure(self.sim.scenario())
    }
    fn recorded_timeline(&self) -> bool {
        true
    }
    fn renders_frames(&self) -> bool {
        true
    }
    fn next_frame(&mut self) -> Option<SourceItem> {
        let start_ns = self.sim.start_time_ns();
        let (image, truth) = self.sim.next_frame()?;
        self.delivered += 1;
        Some(Ok(Captured {
            frame: Frame {
                seq: truth.seq,
                capture_time_ns: start_ns + (truth.t * 1e9).round() as u64,
                image,
                origin: FrameOrigin::Sim,
            },
            truth: Some(Box::new(truth)),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn yaw_q(yaw: f64) -> [f64; 4] {
        quaternion_to_wxyz(&UnitQuaternion::from_euler_angles(0.01, -0.02, yaw))
    }

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() <= tol)
    }

    #[test]
    fn first_pose_lands_on_the_scripted_receiver_and_keeps_its_tilt() {
        let mut sc = Scenario::builtin("approach").unwrap();
        sc.receiver.wobble_deg = 0.0;
        sc.tanker.heading_deg = 40.0;
        let p0 = [12.0, -3.0, -20.0];
        let a = AutopilotAnchor::new(&sc, SitlAnchor::Tanker, p0, yaw_q(-2.0)).unwrap();
        let start = World::new(&sc).advance();
        let (p, q) = a.to_world(p0, yaw_q(-2.0), 0.0);
        assert!(close(p, start.receiver_ned.into(), 1e-9));
        // Heading: the scripted receiver's (tanker heading + trim yaw 0);
        // roll and pitch: the autopilot's own.
        let (r, pi, y) = quaternion_from_wxyz(q).unwrap().euler_angles();
        assert!((y - 40f64.to_radians()).abs() < 1e-9, "{y}");
        assert!((r - 0.01).abs() < 1e-9 && (pi + 0.02).abs() < 1e-9);
        // One metre ahead of the vehicle (its heading) is one metre ahead of
        // the receiver along the tanker's heading.
        let ahead = [p0[0] + (-2f64).cos(), p0[1] + (-2f64).sin(), p0[2]];
        let (pa, _) = a.to_world(ahead, yaw_q(-2.0), 0.0);
        let h = 40f64.to_radians();
        let want = [
            start.receiver_ned.x + h.cos(),
            start.receiver_ned.y + h.sin(),
            start.receiver_ned.z,
        ];
        assert!(close(pa, want, 1e-9), "{pa:?} vs {want:?}");
    }

    #[test]
    fn tanker_anchor_moves_at_the_tanker_velocity_world_anchor_stays() {
        let mut sc = Scenario::builtin("approach").unwrap();
        sc.tanker.heading_deg = 90.0;
        sc.tanker.airspeed_mps = 100.0;
        let p0 = [0.0, 0.0, -10.0];
        let tanker = AutopilotAnchor::new(&sc, SitlAnchor::Tanker, p0, yaw_q(0.3)).unwrap();
        let world = AutopilotAnchor::new(&sc, SitlAnchor::World, p0, yaw_q(0.3)).unwrap();
        let (a0, _) = tanker.to_world(p0, yaw_q(0.3), 0.0);
        let (a2, _) = tanker.to_world(p0, yaw_q(0.3), 2.0);
        // Heading 90 degrees: east at 100 m/s.
        assert!(close(
            [a2[0] - a0[0], a2[1] - a0[1], a2[2] - a0[2]],
            [0.0, 200.0, 0.0],
            1e-9
        ));
        let (w0, _) = world.to_world(p0, yaw_q(0.3), 0.0);
        let (w2, _) = world.to_world(p0, yaw_q(0.3), 2.0);
        assert!(close(w0, w2, 1e-12));
        // Round trip at any time.
        let p = [3.0, -7.0, 1.5];
        for a in [&tanker, &world] {
            let (pw, _) = a.to_world(p, yaw_q(0.3), 1.7);
            assert!(close(a.position_to_autopilot(pw, 1.7), p, 1e-9));
        }
    }

    #[test]
    fn closed_loop_frame_carries_its_truth_in_the_autopilot_frame() {
        let mut src = SimSource::open("approach").unwrap();
        let p0 = [5.0, 6.0, -30.0];
        let q0 = yaw_q(1.0);
        let anchor =
            AutopilotAnchor::new(src.simulator().scenario(), SitlAnchor::Tanker, p0, q0).unwrap();
        let capture = 1_800_000_000_123_456_789;
        let captured = src
            .next_frame_from_autopilot(&anchor, p0, q0, capture)
            .unwrap()
            .unwrap();
        assert_eq!(captured.frame.capture_time_ns, capture);
        let t = captured.truth.as_deref().unwrap();
        assert_eq!(t.ned_frame, NED_FRAME_AUTOPILOT);
        assert_eq!(t.capture_time_ns, capture);
        assert!(close(t.receiver_position_ned, p0, 1e-9));
        let dq = quaternion_from_wxyz(t.receiver_q_ned_body)
            .unwrap()
            .angle_to(&quaternion_from_wxyz(q0).unwrap());
        assert!(dq < 1e-9);
        // The body-frame truth does not depend on the frame of the NED fields.
        let q = quaternion_from_wxyz(q0).unwrap();
        let body = q.inverse() * (Vector3::from(t.position_ned) - Vector3::from(p0));
        assert!(close(body.into(), t.position_body, 1e-9));
        assert_eq!(
            src.next_frame_time_ns(),
            src.simulator().start_time_ns() + 33_333_333
        );
    }
}
