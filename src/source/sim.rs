//! `sim:` source: frames rendered by the simulator, with their truth.

use super::{FrameSource, SourceError, SourceItem};
use crate::camera::CameraModel;
use crate::frame::{Frame, FrameOrigin};
use crate::measure::mount::MountConfig;
use drogue_sim::{MountSpec, Scenario, Simulator};

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

/// The simulator's camera as the pipeline reads it (through its YAML, as any
/// camera file).
pub fn camera_model(sim: &Simulator) -> Result<CameraModel, SourceError> {
    CameraModel::from_yaml_str(&sim.camera_yaml(), "(simulator camera)").map_err(|e| {
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
        })
    }

    /// The simulator, for the SITL closed loop (receiver pose from outside).
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    pub fn inner_radius_m(&self) -> f64 {
        self.sim.inner_radius_m()
    }
}

impl FrameSource for SimSource {
    fn camera(&self) -> Option<CameraModel> {
        Some(self.camera.clone())
    }
    fn mount(&self) -> Option<MountConfig> {
        Some(self.mount.clone())
    }
    fn fps(&self) -> Option<f64> {
        Some(self.sim.fps())
    }
    fn recorded_timeline(&self) -> bool {
        true
    }
    fn next_frame(&mut self) -> Option<SourceItem> {
        let start_ns = self.sim.start_time_ns();
        let (image, truth) = self.sim.next_frame()?;
        Some(Ok(Frame {
            seq: truth.seq,
            capture_time_ns: start_ns + (truth.t * 1e9).round() as u64,
            image,
            origin: FrameOrigin::Sim(Box::new(truth)),
        }))
    }
}
