//! Scenarios: TOML files describing one simulated refuelling run.
//!
//! Every key has a default (the `approach` run), so a scenario file names
//! only what it changes; an unknown key is an error naming the file and key.
//! Builtin scenarios are embedded, so they work with no files around.

use crate::bounds::{self, Range};
use crate::camera::SimCamera;
use crate::error::SimError;
use crate::turbulence::{self, Intensity};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The builtin scenarios: name and TOML text.
pub const BUILTINS: [(&str, &str); 5] = [
    ("approach", include_str!("../scenarios/approach.toml")),
    (
        "station_keeping",
        include_str!("../scenarios/station_keeping.toml"),
    ),
    (
        "severe_turbulence",
        include_str!("../scenarios/severe_turbulence.toml"),
    ),
    ("low_sun", include_str!("../scenarios/low_sun.toml")),
    ("contact", include_str!("../scenarios/contact.toml")),
];

/// Largest whole number a TOML file can hold (its integers are i64).
const ANY_U64: f64 = i64::MAX as f64;
/// Metres of a position within the scene (tanker, drogue, receiver offsets).
const SCENE_M: Range = Range::closed(-1000.0, 1000.0);
/// Metres of a position on the receiver's body.
const BODY_M: Range = Range::closed(-100.0, 100.0);
/// An angle, degrees.
const ANGLE_DEG: Range = Range::closed(-360.0, 360.0);
/// A relative radiance (1 = the sensor's white at gain 1).
const RADIANCE: Range = Range::closed(0.0, 1.0);

/// The allowed range of every number of a scenario, by dotted key (vectors:
/// each element). A value outside it (NaN and infinities always are) is
/// refused naming the file, the key and this range; a key missing here is
/// refused too (the tests load every key). This table is the scenario
/// reference's list of ranges (README: "Scenarios").
pub const RANGES: &[(&str, Range)] = &[
    ("seed", Range::closed(0.0, ANY_U64)),
    ("fps", Range::above(0.0, 1000.0)),
    ("duration_s", Range::above(0.0, 1_000_000.0)),
    ("start_time_ns", Range::closed(0.0, ANY_U64)),
    ("camera.width", Range::closed(16.0, 16_384.0)),
    ("camera.height", Range::closed(16.0, 16_384.0)),
    ("camera.fx", Range::above(0.0, 1_000_000.0)),
    ("camera.fy", Range::above(0.0, 1_000_000.0)),
    ("camera.cx", Range::closed(-100_000.0, 100_000.0)),
    ("camera.cy", Range::closed(-100_000.0, 100_000.0)),
    ("camera.distortion", Range::closed(-100.0, 100.0)),
    ("camera.exposure_ms", Range::closed(0.0, 1000.0)),
    ("camera.gain", Range::above(0.0, 100.0)),
    ("camera.read_noise_dn", Range::closed(0.0, 255.0)),
    ("camera.shot_noise_dn", Range::closed(0.0, 255.0)),
    ("camera.vignette", Range::closed(0.0, 1.0)),
    ("mount.position_body_m", BODY_M),
    ("mount.roll_deg", ANGLE_DEG),
    ("mount.pitch_deg", ANGLE_DEG),
    ("mount.yaw_deg", ANGLE_DEG),
    ("mount.probe_tip_body_m", BODY_M),
    ("mount.probe_base_body_m", BODY_M),
    ("mount.probe_base_radius_m", Range::above(0.0, 10.0)),
    ("mount.probe_tip_radius_m", Range::above(0.0, 10.0)),
    ("tanker.airspeed_mps", Range::above(0.0, 1000.0)),
    (
        "tanker.altitude_m",
        Range::closed(turbulence::MIN_ALTITUDE_M, 25_000.0),
    ),
    ("tanker.heading_deg", ANGLE_DEG),
    ("drogue.inner_radius_m", Range::above(0.0, 10.0)),
    ("drogue.canopy_radius_m", Range::above(0.0, 20.0)),
    ("drogue.trail_offset_m", SCENE_M),
    ("drogue.hose_exit_m", SCENE_M),
    ("drogue.hose_radius_m", Range::above(0.0, 1.0)),
    ("drogue.struts", Range::closed(0.0, 64.0)),
    ("drogue.strut_width_m", Range::closed(0.0, 1.0)),
    ("drogue.rim_width_m", Range::closed(0.0, 1.0)),
    ("drogue.roll_deg", ANGLE_DEG),
    ("drogue.disc_radiance", RADIANCE),
    ("drogue.canopy_radiance", RADIANCE),
    ("drogue.rim_radiance", RADIANCE),
    ("drogue.strut_radiance", RADIANCE),
    ("drogue.hose_radiance", RADIANCE),
    ("drogue.probe_radiance", RADIANCE),
    ("turbulence.hose_lever_m", Range::above(0.0, 1000.0)),
    ("turbulence.sway_lag_s", Range::above(0.0, 100.0)),
    ("bow_wave.max_push_m", Range::closed(0.0, 10.0)),
    ("bow_wave.decay_m", Range::above(0.0, 100.0)),
    ("bow_wave.width_m", Range::above(0.0, 100.0)),
    ("whip.amplitude_m", Range::closed(0.0, 10.0)),
    ("whip.frequency_hz", Range::closed(0.0, 100.0)),
    ("whip.damping_s", Range::above(0.0, 1000.0)),
    ("whip.capture_radius_m", Range::closed(0.0, 10.0)),
    ("receiver.start_offset_m", SCENE_M),
    ("receiver.end_offset_m", SCENE_M),
    ("receiver.approach_start_s", Range::closed(0.0, 1_000_000.0)),
    ("receiver.approach_end_s", Range::closed(0.0, 1_000_000.0)),
    ("receiver.tracking_lag_s", Range::closed(0.0, 100.0)),
    ("receiver.roll_deg", ANGLE_DEG),
    ("receiver.pitch_deg", ANGLE_DEG),
    ("receiver.yaw_deg", ANGLE_DEG),
    ("receiver.wobble_deg", Range::closed(0.0, 90.0)),
    ("receiver.wobble_hz", Range::closed(0.0, 100.0)),
    ("scene.sky_zenith", RADIANCE),
    ("scene.sky_horizon", RADIANCE),
    ("scene.ground", RADIANCE),
    ("scene.cloud_cover", Range::closed(0.0, 1.0)),
    ("scene.cloud_radiance", RADIANCE),
    ("scene.sun_azimuth_deg", ANGLE_DEG),
    ("scene.sun_elevation_deg", Range::closed(-90.0, 90.0)),
    ("scene.glare", Range::closed(0.0, 10.0)),
    ("scene.haze", Range::closed(0.0, 1.0)),
    ("scene.haze_radiance", RADIANCE),
];

/// One simulated run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    pub name: String,
    /// Seed of every random process (turbulence, scene, noise).
    pub seed: u64,
    pub fps: f64,
    pub duration_s: f64,
    /// Capture time of frame 0, ns since the Unix epoch.
    pub start_time_ns: u64,
    pub camera: CameraSpec,
    pub mount: MountSpec,
    pub tanker: TankerSpec,
    pub drogue: DrogueSpec,
    pub turbulence: TurbulenceSpec,
    pub bow_wave: BowWaveSpec,
    pub whip: WhipSpec,
    pub receiver: ReceiverSpec,
    pub scene: SceneSpec,
    /// Folder of the scenario file (for a relative camera file); not a key.
    #[serde(skip)]
    pub base_dir: String,
    /// File name the scenario came from (for error messages); not a key.
    #[serde(skip)]
    pub source_name: String,
}

/// Camera intrinsics (inline, or from a ROS camera_info file) and exposure.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSpec {
    /// ROS camera_info YAML; relative to the scenario file. "" = the keys below.
    pub file: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// plumb_bob k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
    /// Exposure time, ms: the motion blur window, centred on the capture time.
    pub exposure_ms: f64,
    /// Exposure gain: digital number = 255 * gain * radiance.
    pub gain: f64,
    /// Read noise, digital numbers (RMS).
    pub read_noise_dn: f64,
    /// Shot noise: variance in DN^2 per DN of signal.
    pub shot_noise_dn: f64,
    /// Vignetting: relative fall-off at the image corner (0 = none).
    pub vignette: f64,
}

/// Camera and probe on the receiver, body FRD (the shared mount convention).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MountSpec {
    pub position_body_m: [f64; 3],
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    pub probe_tip_body_m: [f64; 3],
    /// Where the probe leaves the fuselage.
    pub probe_base_body_m: [f64; 3],
    pub probe_base_radius_m: f64,
    pub probe_tip_radius_m: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TankerSpec {
    pub airspeed_mps: f64,
    pub altitude_m: f64,
    pub heading_deg: f64,
}

/// The drogue's geometry, its trail position and its look.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DrogueSpec {
    pub inner_radius_m: f64,
    pub canopy_radius_m: f64,
    /// Steady drogue centre relative to the tanker, tanker axes (fwd, right, down).
    pub trail_offset_m: [f64; 3],
    /// Hose exit on the tanker, tanker axes.
    pub hose_exit_m: [f64; 3],
    pub hose_radius_m: f64,
    /// Struts across the canopy (0 = none).
    pub struts: u32,
    pub strut_width_m: f64,
    /// Width of the darker rim band at the canopy edge.
    pub rim_width_m: f64,
    /// Rotation of the strut pattern, degrees.
    pub roll_deg: f64,
    /// Relative radiances (0..1) of the parts.
    pub disc_radiance: f64,
    pub canopy_radiance: f64,
    pub rim_radiance: f64,
    pub strut_radiance: f64,
    pub hose_radiance: f64,
    pub probe_radiance: f64,
}

/// Turbulence and the sway model (see [`crate::turbulence`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TurbulenceSpec {
    /// none | light | moderate | severe (MIL-F-8785C).
    pub intensity: Intensity,
    /// Lever of the gust-to-displacement model, metres.
    pub hose_lever_m: f64,
    /// Drogue lag time constant, seconds.
    pub sway_lag_s: f64,
}

/// Bow wave (see [`crate::trajectory`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BowWaveSpec {
    pub enabled: bool,
    /// Push at zero separation on the probe axis, metres.
    pub max_push_m: f64,
    /// Along-track e-folding length, metres.
    pub decay_m: f64,
    /// Lateral Gaussian width, metres.
    pub width_m: f64,
}

/// Hose whip after a missed contact (see [`crate::trajectory`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WhipSpec {
    pub enabled: bool,
    pub amplitude_m: f64,
    pub frequency_hz: f64,
    pub damping_s: f64,
    /// The probe tip must pass within this of the drogue centre to couple.
    pub capture_radius_m: f64,
}

/// The receiver's scripted approach: the probe tip's offset from the
/// drogue, tanker axes (fwd, right, down), moves from `start_offset_m` to
/// `end_offset_m` between `approach_start_s` and `approach_end_s`
/// (smoothstep), while the pilot follows the drogue's sideways motion
/// through a lag of `tracking_lag_s` (0 = not at all).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReceiverSpec {
    pub start_offset_m: [f64; 3],
    pub end_offset_m: [f64; 3],
    pub approach_start_s: f64,
    pub approach_end_s: f64,
    pub tracking_lag_s: f64,
    /// Trim attitude relative to the tanker's heading, degrees.
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    /// Attitude wobble amplitude (degrees) and frequency (Hz).
    pub wobble_deg: f64,
    pub wobble_hz: f64,
}

/// Sky, clouds, sun and haze.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneSpec {
    pub sky_zenith: f64,
    pub sky_horizon: f64,
    /// Radiance of the undercast below the horizon.
    pub ground: f64,
    /// Cloud cover 0..1 and brightness.
    pub cloud_cover: f64,
    pub cloud_radiance: f64,
    pub sun_azimuth_deg: f64,
    pub sun_elevation_deg: f64,
    /// Strength of lens glare from the sun (0 = none).
    pub glare: f64,
    /// Haze 0..1: mixes object radiance toward `haze_radiance`.
    pub haze: f64,
    pub haze_radiance: f64,
    /// Motion blur from the relative motion during exposure.
    pub motion_blur: bool,
}

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

impl Scenario {
    /// Names of the builtin scenarios.
    pub fn builtin_names() -> Vec<&'static str> {
        BUILTINS.iter().map(|(n, _)| *n).collect()
    }

    /// A builtin scenario by name.
    pub fn builtin(name: &str) -> Result<Scenario, SimError> {
        let (n, text) =
            BUILTINS
                .iter()
                .find(|(n, _)| *n == name)
                .ok_or_else(|| SimError::NotFound {
                    name: name.to_string(),
                    builtins: Self::builtin_names().join(", "),
                    message: "no builtin of that name".into(),
                })?;
        Self::from_toml_str(text, &format!("builtin:{n}"))
    }

    /// A scenario file.
    pub fn load(path: &Path) -> Result<Scenario, SimError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
            file: file.clone(),
            message: e.to_string(),
        })?;
        let mut s = Self::from_toml_str(&text, &file)?;
        s.base_dir = path
            .parent()
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        s.camera_model()?;
        Ok(s)
    }

    /// A builtin name, else a file path.
    pub fn resolve(name_or_path: &str) -> Result<Scenario, SimError> {
        if BUILTINS.iter().any(|(n, _)| *n == name_or_path) {
            return Self::builtin(name_or_path);
        }
        let path = Path::new(name_or_path);
        if path.is_file() {
            return Self::load(path);
        }
        Err(SimError::NotFound {
            name: name_or_path.to_string(),
            builtins: Self::builtin_names().join(", "),
            message: "no such file".into(),
        })
    }

    /// Parses and validates scenario TOML; `file_name` is used in errors.
    pub fn from_toml_str(text: &str, file_name: &str) -> Result<Scenario, SimError> {
        let mut s: Scenario = toml::from_str(text).map_err(|e| {
            let key = e
                .message()
                .split('`')
                .nth(1)
                .map(str::to_string)
                .unwrap_or_else(|| "(toml)".into());
            SimError::Scenario {
                file: file_name.to_string(),
                key,
                message: e.to_string().trim().replace('\n', " "),
            }
        })?;
        s.source_name = file_name.to_string();
        // The numbers as written (the parse above already refused unknown
        // keys and wrong types).
        let written: toml::Value =
            toml::from_str(text).map_err(|e| s.bad("(toml)", &e.to_string()))?;
        bounds::check(&written, RANGES).map_err(|v| {
            s.bad(
                &v.key,
                &format!(
                    "{} is outside the allowed range {}",
                    v.value,
                    v.range
                        .map_or("(none known)".to_string(), |r| r.to_string())
                ),
            )
        })?;
        s.validate()?;
        Ok(s)
    }

    fn bad(&self, key: &str, message: &str) -> SimError {
        SimError::Scenario {
            file: self.source_name.clone(),
            key: key.to_string(),
            message: message.to_string(),
        }
    }

    fn validate(&self) -> Result<(), SimError> {
        let positive = [
            ("fps", self.fps),
            ("duration_s", self.duration_s),
            ("tanker.airspeed_mps", self.tanker.airspeed_mps),
            ("drogue.inner_radius_m", self.drogue.inner_radius_m),
            ("drogue.hose_radius_m", self.drogue.hose_radius_m),
            ("turbulence.hose_lever_m", self.turbulence.hose_lever_m),
            ("turbulence.sway_lag_s", self.turbulence.sway_lag_s),
            ("bow_wave.decay_m", self.bow_wave.decay_m),
            ("bow_wave.width_m", self.bow_wave.width_m),
            ("whip.damping_s", self.whip.damping_s),
            ("camera.gain", self.camera.gain),
            ("mount.probe_base_radius_m", self.mount.probe_base_radius_m),
            ("mount.probe_tip_radius_m", self.mount.probe_tip_radius_m),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(self.bad(key, "must be a finite number > 0"));
            }
        }
        let non_negative = [
            ("camera.exposure_ms", self.camera.exposure_ms),
            ("camera.read_noise_dn", self.camera.read_noise_dn),
            ("camera.shot_noise_dn", self.camera.shot_noise_dn),
            ("camera.vignette", self.camera.vignette),
            ("receiver.tracking_lag_s", self.receiver.tracking_lag_s),
            ("scene.glare", self.scene.glare),
            ("bow_wave.max_push_m", self.bow_wave.max_push_m),
            ("whip.amplitude_m", self.whip.amplitude_m),
            ("whip.frequency_hz", self.whip.frequency_hz),
            ("whip.capture_radius_m", self.whip.capture_radius_m),
            ("drogue.strut_width_m", self.drogue.strut_width_m),
            ("drogue.rim_width_m", self.drogue.rim_width_m),
        ];
        for (key, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(self.bad(key, "must be a finite number >= 0"));
            }
        }
        if self.drogue.canopy_radius_m <= self.drogue.inner_radius_m {
            return Err(self.bad("drogue.canopy_radius_m", "must exceed inner_radius_m"));
        }
        if self.receiver.approach_end_s < self.receiver.approach_start_s {
            return Err(self.bad("receiver.approach_end_s", "must be >= approach_start_s"));
        }
        if self.tanker.altitude_m < turbulence::MIN_ALTITUDE_M {
            return Err(self.bad(
                "tanker.altitude_m",
                "must be >= 610 m (2000 ft): the medium/high-altitude Dryden model",
            ));
        }
        if self.frame_count() > 10_000_000 {
            return Err(self.bad("duration_s", "more than 10 million frames"));
        }
        for (key, v) in [
            ("scene.haze", self.scene.haze),
            ("scene.cloud_cover", self.scene.cloud_cover),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(self.bad(key, "must be within 0..1"));
            }
        }
        let all_finite = [
            self.drogue.trail_offset_m,
            self.drogue.hose_exit_m,
            self.mount.position_body_m,
            self.mount.probe_tip_body_m,
            self.mount.probe_base_body_m,
            self.receiver.start_offset_m,
            self.receiver.end_offset_m,
        ]
        .iter()
        .flatten()
        .chain(self.camera.distortion.iter())
        .all(|v| v.is_finite());
        if !all_finite {
            return Err(self.bad("(vectors)", "every number must be finite"));
        }
        if self.camera.file.is_empty() {
            if self.camera.width < 16
                || self.camera.height < 16
                || self.camera.width > 16384
                || self.camera.height > 16384
            {
                return Err(self.bad("camera.width", "image size must be within 16..16384"));
            }
            if !(self.camera.fx > 0.0 && self.camera.fy > 0.0) {
                return Err(self.bad("camera.fx", "focal lengths must be > 0"));
            }
        }
        Ok(())
    }

    /// Number of frames of the run.
    pub fn frame_count(&self) -> u64 {
        (self.duration_s * self.fps).round().max(0.0) as u64
    }

    /// The camera: from `camera.file` when set, else the inline keys.
    pub fn camera_model(&self) -> Result<SimCamera, SimError> {
        if self.camera.file.is_empty() {
            let c = &self.camera;
            return Ok(SimCamera {
                width: c.width,
                height: c.height,
                fx: c.fx,
                fy: c.fy,
                cx: c.cx,
                cy: c.cy,
                distortion: c.distortion,
            });
        }
        let path = Path::new(&self.base_dir).join(&self.camera.file);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| self.bad("camera.file", &format!("{}: {e}", path.display())))?;
        let cam = SimCamera::from_ros_yaml(&text, &path.display().to_string())?;
        let d = cam.distortion;
        let numbers = [
            ("camera.width", f64::from(cam.width)),
            ("camera.height", f64::from(cam.height)),
            ("camera.fx", cam.fx),
            ("camera.fy", cam.fy),
            ("camera.cx", cam.cx),
            ("camera.cy", cam.cy),
        ]
        .into_iter()
        .chain(d.iter().map(|&v| ("camera.distortion", v)));
        for (key, v) in numbers {
            if let Some(r) = bounds::range_of(RANGES, key).filter(|r| !r.contains(v)) {
                return Err(self.bad(
                    "camera.file",
                    &format!(
                        "{}: {key} = {v} is outside the allowed range {r}",
                        path.display()
                    ),
                ));
            }
        }
        Ok(cam)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtins_parse() {
        for name in Scenario::builtin_names() {
            let s = Scenario::builtin(name).unwrap();
            assert_eq!(s.name, name);
            assert!(s.frame_count() > 0);
        }
        assert_eq!(Scenario::builtin("approach").unwrap().frame_count(), 600);
    }

    /// Every number of a scenario (all keys, from the defaults) has a range
    /// that holds its default and every builtin's value.
    #[test]
    fn every_number_has_a_range() {
        let all = toml::Value::try_from(Scenario::default()).unwrap();
        let mut keys = 0;
        bounds::walk_numbers(&all, "", &mut |key, _| {
            keys += 1;
            assert!(
                bounds::range_of(RANGES, key).is_some(),
                "{key} has no range"
            );
        });
        assert!(keys > 60);
        bounds::check(&all, RANGES).unwrap();
        for (_, key) in RANGES.iter().enumerate().map(|(i, (k, _))| (i, k)) {
            assert!(
                RANGES.iter().filter(|(k, _)| k == key).count() == 1,
                "{key} twice"
            );
        }
    }

    /// The reproducers (issue 16): refused naming the file, the key
    /// and the range.
    #[test]
    fn the_reproducers_are_refused() {
        let cases = [
            (
                "[drogue]\nstruts = 4294967295\n",
                "drogue.struts",
                "[0, 64]",
            ),
            (
                "[drogue]\ntrail_offset_m = [1e300, 0.0, 0.0]\n",
                "drogue.trail_offset_m",
                "[-1000, 1000]",
            ),
            (
                "[tanker]\naltitude_m = nan\n",
                "tanker.altitude_m",
                "[609.6, 25000]",
            ),
            (
                "[tanker]\nheading_deg = nan\n",
                "tanker.heading_deg",
                "[-360, 360]",
            ),
            (
                "[mount]\npitch_deg = nan\n",
                "mount.pitch_deg",
                "[-360, 360]",
            ),
            (
                "[camera]\ndistortion = [1e300, 0.0, 0.0, 0.0, 0.0]\n",
                "camera.distortion",
                "[-100, 100]",
            ),
            ("fps = inf\n", "fps", "(0, 1000]"),
        ];
        for (text, key, range) in cases {
            let e = Scenario::from_toml_str(text, "s.toml")
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with("s.toml: key `") && e.contains(key) && e.contains(range),
                "{text}: {e}"
            );
        }
    }

    /// A camera file with absurd intrinsics is refused by name.
    #[test]
    fn a_camera_file_out_of_range_is_refused() {
        let dir = std::env::temp_dir().join(format!("scenario-cam-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cam = "image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [1.0e300, 0.0, 0.0, 0.0, 0.0]\n";
        std::fs::write(dir.join("cam.yaml"), cam).unwrap();
        std::fs::write(dir.join("s.toml"), "[camera]\nfile = \"cam.yaml\"\n").unwrap();
        let e = Scenario::load(&dir.join("s.toml")).unwrap_err().to_string();
        assert!(
            e.contains("camera.distortion") && e.contains("[-100, 100]"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Random values, finite or not, for every number of a scenario: an
    /// answer (never a panic), and only in-range values accepted.
    #[test]
    fn random_values_for_every_number_are_accepted_in_range_or_refused() {
        use proptest::prelude::*;
        use proptest::test_runner::{Config as PropConfig, TestRunner};
        let all = toml::Value::try_from(Scenario::default()).unwrap();
        let mut keys: Vec<(String, usize)> = Vec::new();
        bounds::walk_numbers(
            &all,
            "",
            &mut |key, _| match keys.iter_mut().find(|(k, _)| k == key) {
                Some((_, n)) => *n += 1,
                None => keys.push((key.to_string(), 1)),
            },
        );
        let value = prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(0.0),
            Just(1e300),
            -2000.0..2000.0f64,
            any::<f64>(),
        ];
        let mut runner = TestRunner::new(PropConfig::with_cases(512));
        runner
            .run(&(0..keys.len(), value, any::<bool>()), |(i, x, as_int)| {
                let (key, n) = &keys[i];
                let number = if as_int && x.is_finite() && x.abs() < 9e18 {
                    format!("{}", x.trunc() as i64)
                } else {
                    toml::Value::Float(x).to_string()
                };
                let value = if *n > 1 {
                    format!("[{}]", vec![number.clone(); *n].join(", "))
                } else {
                    number.clone()
                };
                let text = match key.split_once('.') {
                    Some((section, name)) => format!("[{section}]\n{name} = {value}\n"),
                    None => format!("{key} = {value}\n"),
                };
                match Scenario::from_toml_str(&text, "p.toml") {
                    Ok(_) => {
                        let v: f64 = number.parse().unwrap();
                        let r = bounds::range_of(RANGES, key).unwrap();
                        prop_assert!(r.contains(v), "{text} accepted");
                    }
                    Err(e) => prop_assert!(e.to_string().starts_with("p.toml: key `"), "{e}"),
                }
                Ok(())
            })
            .unwrap();
    }

    #[test]
    fn errors_name_file_and_key() {
        let e = Scenario::from_toml_str("[drogue]\ninner_radius = 0.1\n", "my.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("my.toml") && e.contains("inner_radius"), "{e}");
        let e = Scenario::from_toml_str("fps = -3.0\n", "f.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("f.toml") && e.contains("`fps`"), "{e}");
        let e = Scenario::from_toml_str("[camera]\nfx = \"wide\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.toml") && e.contains("fx"), "{e}");
        let e = Scenario::from_toml_str("[turbulence]\nintensity = \"extreme\"\n", "i.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("i.toml") && e.contains("intensity"), "{e}");
        let e = Scenario::resolve("/nonexistent/x.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/nonexistent/x.toml") && e.contains("approach"),
            "{e}"
        );
    }
}
