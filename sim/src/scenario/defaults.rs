//! The default of every key: the `approach` run. A scenario file names only
//! what it changes from these.

use super::{
    BowWaveSpec, CameraSpec, DrogueSpec, MountSpec, ReceiverSpec, Scenario, SceneSpec, TankerSpec,
    TurbulenceSpec, WhipSpec,
};
use crate::turbulence::Intensity;

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            name: "approach".into(),
            seed: 1,
            fps: 30.0,
            duration_s: 20.0,
            start_time_ns: 1_790_000_000_000_000_000,
            camera: CameraSpec::default(),
            mount: MountSpec::default(),
            tanker: TankerSpec::default(),
            drogue: DrogueSpec::default(),
            turbulence: TurbulenceSpec::default(),
            bow_wave: BowWaveSpec::default(),
            whip: WhipSpec::default(),
            receiver: ReceiverSpec::default(),
            scene: SceneSpec::default(),
            base_dir: String::new(),
            source_name: "approach".into(),
        }
    }
}

impl Default for CameraSpec {
    fn default() -> Self {
        // The paper's 5 mm lens on 3.75 um pixels, with mild barrel distortion.
        CameraSpec {
            file: String::new(),
            width: 1280,
            height: 960,
            fx: 1336.2,
            fy: 1335.4,
            cx: 646.3,
            cy: 473.8,
            distortion: [-0.08, 0.05, 0.0004, -0.0003, 0.0],
            exposure_ms: 2.0,
            gain: 1.0,
            read_noise_dn: 1.5,
            shot_noise_dn: 0.02,
            vignette: 0.15,
        }
    }
}

impl Default for MountSpec {
    fn default() -> Self {
        MountSpec {
            position_body_m: [2.5, 0.3, -0.9],
            roll_deg: 0.0,
            pitch_deg: 2.0,
            yaw_deg: 6.0,
            probe_tip_body_m: [6.0, 0.75, -0.85],
            probe_base_body_m: [3.0, 0.75, -0.7],
            probe_base_radius_m: 0.06,
            probe_tip_radius_m: 0.035,
        }
    }
}

impl Default for TankerSpec {
    fn default() -> Self {
        TankerSpec {
            airspeed_mps: 120.0,
            altitude_m: 3000.0,
            heading_deg: 0.0,
        }
    }
}

impl Default for DrogueSpec {
    fn default() -> Self {
        DrogueSpec {
            inner_radius_m: 0.15,
            canopy_radius_m: 0.33,
            trail_offset_m: [-40.0, 10.0, 12.0],
            hose_exit_m: [-18.0, 10.0, 2.0],
            hose_radius_m: 0.045,
            struts: 8,
            strut_width_m: 0.018,
            rim_width_m: 0.018,
            roll_deg: 10.0,
            disc_radiance: 0.10,
            canopy_radiance: 0.72,
            rim_radiance: 0.38,
            strut_radiance: 0.40,
            hose_radiance: 0.09,
            probe_radiance: 0.16,
            throat_shade: 0.0,
            throat_shade_width_m: 0.03,
        }
    }
}

impl Default for TurbulenceSpec {
    fn default() -> Self {
        TurbulenceSpec {
            intensity: Intensity::Light,
            hose_lever_m: 15.0,
            sway_lag_s: 0.8,
        }
    }
}

impl Default for BowWaveSpec {
    fn default() -> Self {
        BowWaveSpec {
            enabled: true,
            max_push_m: 0.25,
            decay_m: 1.5,
            width_m: 0.8,
        }
    }
}

impl Default for WhipSpec {
    fn default() -> Self {
        WhipSpec {
            enabled: true,
            amplitude_m: 0.6,
            frequency_hz: 1.2,
            damping_s: 1.5,
            capture_radius_m: 0.12,
        }
    }
}

impl Default for ReceiverSpec {
    fn default() -> Self {
        ReceiverSpec {
            start_offset_m: [-12.0, 0.4, -0.3],
            end_offset_m: [0.0, 0.0, 0.0],
            approach_start_s: 1.0,
            approach_end_s: 19.0,
            tracking_lag_s: 0.6,
            roll_deg: 0.0,
            pitch_deg: 3.0,
            yaw_deg: 0.0,
            wobble_deg: 0.3,
            wobble_hz: 0.4,
        }
    }
}

impl Default for SceneSpec {
    fn default() -> Self {
        SceneSpec {
            sky_zenith: 0.50,
            sky_horizon: 0.68,
            ground: 0.55,
            cloud_cover: 0.5,
            cloud_radiance: 0.85,
            sun_azimuth_deg: 140.0,
            sun_elevation_deg: 45.0,
            glare: 0.0,
            haze: 0.0,
            haze_radiance: 0.75,
            motion_blur: true,
        }
    }
}
