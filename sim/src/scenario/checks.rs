//! What a scenario may hold: the range of every number (the table the
//! scenario reference lists) and the rules that tie keys together. A file
//! that breaks one is refused naming the file and the key.

use super::Scenario;
use crate::bounds::Range;
use crate::error::SimError;
use crate::turbulence;

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
    ("drogue.throat_shade", Range::closed(0.0, 1.0)),
    ("drogue.throat_shade_width_m", Range::above(0.0, 1.0)),
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

impl Scenario {
    pub(super) fn bad(&self, key: &str, message: &str) -> SimError {
        SimError::Scenario {
            file: self.source_name.clone(),
            key: key.to_string(),
            message: message.to_string(),
        }
    }

    pub(super) fn validate(&self) -> Result<(), SimError> {
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
}
