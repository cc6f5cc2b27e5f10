//! Scenarios: TOML files describing one simulated refuelling run.
//!
//! Every key has a default (the `approach` run), so a scenario file names
//! only what it changes; an unknown key is an error naming the file and key.
//! Builtin scenarios are embedded, so they work with no files around.

use crate::bounds;
use crate::camera::SimCamera;
use crate::error::SimError;
use crate::turbulence::Intensity;
use serde::{Deserialize, Serialize};
use std::path::Path;

mod checks;
mod defaults;

pub use checks::RANGES;

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

/// One simulated run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// Run name, shown in logs and reports (the builtin's, or the file's choice).
    pub name: String,
    /// Seed of every random process (turbulence, scene, noise).
    pub seed: u64,
    /// Frame rate of the rendered stream, frames per second.
    pub fps: f64,
    /// Length of the run, seconds of simulated time.
    pub duration_s: f64,
    /// Capture time of frame 0, ns since the Unix epoch.
    pub start_time_ns: u64,
    /// The camera's intrinsics, distortion and exposure.
    pub camera: CameraSpec,
    /// Where the camera and the probe sit on the receiver.
    pub mount: MountSpec,
    /// The tanker's straight, level flight.
    pub tanker: TankerSpec,
    /// The drogue's geometry, trail position and look.
    pub drogue: DrogueSpec,
    /// Gusts that sway the drogue.
    pub turbulence: TurbulenceSpec,
    /// The receiver's bow wave pushing the drogue as the nose nears.
    pub bow_wave: BowWaveSpec,
    /// The hose's oscillation after a missed contact.
    pub whip: WhipSpec,
    /// The receiver's scripted approach and attitude.
    pub receiver: ReceiverSpec,
    /// Sky, clouds, sun and haze around the drogue.
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
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels from the top-left pixel's centre.
    pub cx: f64,
    /// Principal point y, pixels from the top-left pixel's centre.
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
    /// Camera position, body FRD, metres.
    pub position_body_m: [f64; 3],
    /// Roll of the camera's optical frame from the body axes, degrees.
    pub roll_deg: f64,
    /// Pitch of the camera's optical frame from the body axes, degrees.
    pub pitch_deg: f64,
    /// Yaw of the camera's optical frame from the body axes, degrees.
    pub yaw_deg: f64,
    /// The probe's tip, body FRD, metres: where contact is judged.
    pub probe_tip_body_m: [f64; 3],
    /// Where the probe leaves the fuselage.
    pub probe_base_body_m: [f64; 3],
    /// Probe radius where it leaves the fuselage, metres.
    pub probe_base_radius_m: f64,
    /// Probe radius at the tip, metres.
    pub probe_tip_radius_m: f64,
}

/// The tanker's flight: straight and level at constant airspeed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TankerSpec {
    /// True airspeed, metres per second (sets the gusts' time scale).
    pub airspeed_mps: f64,
    /// Altitude above the origin, metres (sets the gusts' strength).
    pub altitude_m: f64,
    /// Heading, degrees from north toward east.
    pub heading_deg: f64,
}

/// The drogue's geometry, its trail position and its look.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DrogueSpec {
    /// Radius of the dark inner circle (the measured target), metres.
    pub inner_radius_m: f64,
    /// Radius of the canopy's outer rim, metres.
    pub canopy_radius_m: f64,
    /// Steady drogue centre relative to the tanker, tanker axes (fwd, right, down).
    pub trail_offset_m: [f64; 3],
    /// Hose exit on the tanker, tanker axes.
    pub hose_exit_m: [f64; 3],
    /// Hose radius, metres.
    pub hose_radius_m: f64,
    /// Struts across the canopy (0 = none).
    pub struts: u32,
    /// Width of a strut, metres.
    pub strut_width_m: f64,
    /// Width of the darker rim band at the canopy edge.
    pub rim_width_m: f64,
    /// Rotation of the strut pattern, degrees.
    pub roll_deg: f64,
    /// Radiance of the dark inner disc, 0..1 (all radiances relative:
    /// digital number = 255 * gain * radiance).
    pub disc_radiance: f64,
    /// Radiance of the canopy's light fabric, 0..1.
    pub canopy_radiance: f64,
    /// Radiance of the rim band, 0..1.
    pub rim_radiance: f64,
    /// Radiance of the struts, 0..1.
    pub strut_radiance: f64,
    /// Radiance of the hose, 0..1.
    pub hose_radiance: f64,
    /// Radiance of the probe, 0..1.
    pub probe_radiance: f64,
    /// Share of the canopy's radiance lost at the disc's edge to the
    /// throat's shadow, 0..1 (0: none).
    pub throat_shade: f64,
    /// E-folding width of the throat's shadow outward from the disc, metres.
    pub throat_shade_width_m: f64,
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
    /// Whether the bow wave pushes the drogue at all.
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
    /// Whether a missed contact sets the hose whipping.
    pub enabled: bool,
    /// Whip amplitude along the miss direction at the miss, metres.
    pub amplitude_m: f64,
    /// Whip frequency, Hz.
    pub frequency_hz: f64,
    /// Time constant of the whip's decay, seconds.
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
    /// Probe tip offset from the drogue at the approach's start, tanker axes, metres.
    pub start_offset_m: [f64; 3],
    /// Probe tip offset from the drogue at the approach's end, tanker axes, metres.
    pub end_offset_m: [f64; 3],
    /// Start of the approach, seconds from the run's start.
    pub approach_start_s: f64,
    /// End of the approach, seconds from the run's start.
    pub approach_end_s: f64,
    /// Lag of the pilot following the drogue's sideways motion, seconds (0 = not at all).
    pub tracking_lag_s: f64,
    /// Trim roll relative to the tanker, degrees.
    pub roll_deg: f64,
    /// Trim pitch relative to the tanker, degrees.
    pub pitch_deg: f64,
    /// Trim yaw relative to the tanker's heading, degrees.
    pub yaw_deg: f64,
    /// Attitude wobble amplitude, degrees.
    pub wobble_deg: f64,
    /// Attitude wobble frequency, Hz.
    pub wobble_hz: f64,
}

/// Sky, clouds, sun and haze.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneSpec {
    /// Sky radiance at the zenith, 0..1.
    pub sky_zenith: f64,
    /// Sky radiance at the horizon, 0..1.
    pub sky_horizon: f64,
    /// Radiance of the undercast below the horizon.
    pub ground: f64,
    /// Cloud cover, 0..1.
    pub cloud_cover: f64,
    /// Radiance of the clouds, 0..1.
    pub cloud_radiance: f64,
    /// Sun azimuth, degrees from north toward east.
    pub sun_azimuth_deg: f64,
    /// Sun elevation above the horizon, degrees.
    pub sun_elevation_deg: f64,
    /// Strength of lens glare from the sun (0 = none).
    pub glare: f64,
    /// Haze 0..1: mixes object radiance toward `haze_radiance`.
    pub haze: f64,
    /// Radiance the haze mixes toward, 0..1 (the haze's own brightness).
    pub haze_radiance: f64,
    /// Motion blur from the relative motion during exposure.
    pub motion_blur: bool,
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
                .map_or_else(|| "(toml)".into(), str::to_string);
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
