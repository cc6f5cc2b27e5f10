//! The SITL closed loop (`run --vehicle-pose mavlink`): the simulator flown
//! by the autopilot on the link.

use super::pacing::Pacer;
use crate::link::{LinkHandle, VehiclePose};
use crate::source::SourceItem;
use crate::source::dir::unix_now_ns;
use crate::source::sim::{AutopilotAnchor, SimSource, SitlAnchor};
use crate::spatial::quaternion_to_wxyz;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// SITL closed loop (`--vehicle-pose mavlink`): each frame is rendered with
/// the receiver at the pose the autopilot reports on the link
/// (LOCAL_POSITION_NED + ATTITUDE) for the frame's capture time, while the
/// drogue flies its own trajectory. The autopilot's local NED is placed in
/// the scenario's world at its first pose ([`AutopilotAnchor`]).
pub struct ClosedLoop {
    sim: SimSource,
    mode: SitlAnchor,
    anchor: Option<AutopilotAnchor>,
    /// The last pose used: held while the autopilot's is stale.
    held: Option<VehiclePose>,
    stale: bool,
    held_frames: u64,
    /// Frames dropped because the rendering fell behind.
    dropped: u64,
}

impl ClosedLoop {
    pub fn new(sim: SimSource, mode: SitlAnchor) -> Self {
        Self {
            sim,
            mode,
            anchor: None,
            held: None,
            stale: false,
            held_frames: 0,
            dropped: 0,
        }
    }

    /// The simulator it renders with.
    pub fn sim(&self) -> &SimSource {
        &self.sim
    }

    /// Frames rendered with a held pose (the autopilot's was stale).
    pub fn held_frames(&self) -> u64 {
        self.held_frames
    }

    /// The next frame on the wall clock, captured `delay_ns` before it is
    /// rendered, from the autopilot's pose at the capture (or the last one
    /// while it is stale). Frames the run is too late for are dropped, as a
    /// camera drops them: the scenario's clock stays on the autopilot's.
    pub fn next_frame(
        &mut self,
        link: &LinkHandle,
        pacer: &mut Pacer,
        delay_ns: u64,
    ) -> Option<SourceItem> {
        let due_ns = loop {
            match pacer.wait_until_due_or_drop(self.sim.next_frame_time_ns()) {
                Some(due) => break due,
                None => {
                    self.sim.skip_frame()?;
                    self.dropped += 1;
                    pacer.late += 1;
                    if self.dropped.is_power_of_two() {
                        tracing::warn!(
                            dropped = self.dropped,
                            "closed loop: rendering behind the frame rate, frames dropped"
                        );
                    }
                }
            }
        };
        let capture_time_ns = due_ns.saturating_sub(delay_ns);
        let pose = match (link.vehicle_pose_at(capture_time_ns), self.held) {
            (Some(p), _) => {
                if self.stale {
                    self.stale = false;
                    tracing::info!("closed loop: the autopilot's pose is back");
                }
                p
            }
            (None, Some(held)) => {
                if !self.stale {
                    self.stale = true;
                    tracing::warn!(
                        "closed loop: the autopilot's pose is stale (no LOCAL_POSITION_NED + \
                         ATTITUDE near the capture time): holding the last one"
                    );
                }
                self.held_frames += 1;
                held
            }
            (None, None) => {
                return Some(Err(
                    "closed loop: no pose from the autopilot for this frame".into(),
                ));
            }
        };
        self.held = Some(pose);
        if self.anchor.is_none() {
            self.anchor = self.anchor_at(&pose);
        }
        let Some(anchor) = &self.anchor else {
            return Some(Err(
                "closed loop: the autopilot's first pose cannot be placed in the scenario".into(),
            ));
        };
        self.sim.next_frame_from_autopilot(
            anchor,
            pose.position_ned_m.to_array(),
            quaternion_to_wxyz(&pose.q_ned_body),
            capture_time_ns,
        )
    }

    /// Places the autopilot's local NED in the scenario's world at its first
    /// pose, and says so (tracing, MCAP `/log`): it holds for the whole run.
    fn anchor_at(&self, pose: &VehiclePose) -> Option<AutopilotAnchor> {
        let anchor = AutopilotAnchor::new(
            self.sim.simulator().scenario(),
            self.mode,
            pose.position_ned_m.to_array(),
            quaternion_to_wxyz(&pose.q_ned_body),
        )?;
        tracing::info!(
            mode = ?self.mode,
            yaw_world_autopilot_deg = anchor.yaw_world_autopilot_rad.to_degrees(),
            origin_autopilot_m = ?anchor.origin_autopilot_m,
            origin_world_m = ?anchor.origin_world_m,
            velocity_world_mps = ?anchor.velocity_world_mps,
            "closed loop: the autopilot's local NED placed in the scenario's world \
             (world = R_yaw (p - origin_autopilot) + origin_world + velocity t); \
             /sim/truth NED fields are in the autopilot's frame"
        );
        Some(anchor)
    }
}

/// Waits until the autopilot's pose is on the link (the link keeps
/// heartbeating meanwhile), then `delay` more, so that the first frame's
/// capture time (`delay` before it is rendered) comes after the first
/// report. `Ok(false)`: a signal ended the wait.
pub fn wait_for_autopilot_pose(
    link: &LinkHandle,
    timeout_s: f64,
    delay: Duration,
    stop: &AtomicBool,
) -> Result<bool, String> {
    let deadline = Instant::now() + Duration::from_secs_f64(timeout_s);
    let mut said = false;
    loop {
        if link.vehicle_pose_at(unix_now_ns()).is_some() {
            if said {
                tracing::info!("closed loop: the autopilot's pose arrived");
            }
            std::thread::sleep(delay);
            return Ok(!stop.load(Ordering::SeqCst));
        }
        if stop.load(Ordering::SeqCst) {
            return Ok(false);
        }
        if Instant::now() > deadline {
            return Err(format!(
                "no pose from the autopilot within {timeout_s} s: stream LOCAL_POSITION_NED and \
                 ATTITUDE on the MAVLink link (see README, SITL docking)"
            ));
        }
        if !said {
            said = true;
            tracing::info!(
                "waiting for the autopilot's pose (LOCAL_POSITION_NED + ATTITUDE on the link)"
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
