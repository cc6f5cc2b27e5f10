//! The per-frame JSON record: one line of `process` output and the payload of
//! the MCAP `/drogue/detection` topic (ARCHITECTURE.md section 5).

use crate::measure::ellipse::Ellipse;
use crate::measure::miss::NotDetectedRecord;
use crate::measure::{Disambiguation, FitQuality, Measurement, StageTimes};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

fn xyz(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// One frame's result. Field names and meanings are a contract: extend only.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectionRecord {
    /// File name, or the frame's sequence number for an MCAP input.
    pub frame: String,
    /// A drogue was found in the frame (the pose fields are null otherwise).
    pub detected: bool,
    /// Undistorted pixels; a >= b; theta from +u toward +v in (-pi/2, pi/2].
    pub ellipse: Option<Ellipse>,
    /// Centre of the dark circle, camera frame, metres.
    pub position_camera: Option<[f64; 3]>,
    /// Unit normal, camera frame, toward the camera.
    pub normal_camera: Option<[f64; 3]>,
    /// The other ambiguity solution's normal; null once resolved.
    pub normal_camera_alt: Option<[f64; 3]>,
    /// The other ambiguity solution's centre; null once resolved.
    pub position_camera_alt: Option<[f64; 3]>,
    /// Centre of the dark circle, body FRD, metres.
    pub position_body: Option<[f64; 3]>,
    /// Unit normal, body FRD.
    pub normal_body: Option<[f64; 3]>,
    /// Drogue centre relative to the probe tip, body FRD axes, metres.
    pub position_from_probe_body: Option<[f64; 3]>,
    /// Covariance of `position_body`, row-major 3x3, square metres.
    pub position_covariance_body: Option<[f64; 9]>,
    /// One-sigma uncertainty of the normal, radians.
    pub normal_sigma_rad: Option<f64>,
    /// How the two-fold ambiguity was settled.
    pub disambiguation: Option<Disambiguation>,
    /// Rim points, inliers, RMS residual and score of the fit.
    pub quality: Option<FitQuality>,
    /// Incremented each time the track is lost and found again.
    pub track_epoch: Option<u32>,
    /// Capture time, ns since the Unix epoch.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capture_time_ns: Option<u64>,
    /// Processing time of each stage, microseconds (left out when unknown).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub times_us: Option<StageTimes>,
    /// Why no drogue was found (reason code, the reason in words, candidates
    /// tried); left out when one was, or the frame could not be read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_detected: Option<NotDetectedRecord>,
    /// Only when the frame could not be read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl DetectionRecord {
    /// The record of a measured frame.
    pub fn from_measurement(frame: String, m: &Measurement) -> Self {
        let d = m.detection.as_ref();
        Self {
            frame,
            detected: d.is_some(),
            ellipse: d.map(|d| d.ellipse_px),
            position_camera: d.map(|d| xyz(&d.pose_camera.centre_camera_m)),
            normal_camera: d.map(|d| xyz(&d.pose_camera.normal_camera)),
            normal_camera_alt: d.and_then(|d| d.alt_pose_camera.map(|p| xyz(&p.normal_camera))),
            position_camera_alt: d.and_then(|d| d.alt_pose_camera.map(|p| xyz(&p.centre_camera_m))),
            position_body: d.map(|d| xyz(&d.position_body_m)),
            normal_body: d.map(|d| xyz(&d.normal_body)),
            position_from_probe_body: d.map(|d| xyz(&d.position_from_probe_body_m)),
            position_covariance_body: d.map(|d| {
                let c = d.position_cov_body_m2;
                [
                    c[(0, 0)],
                    c[(0, 1)],
                    c[(0, 2)],
                    c[(1, 0)],
                    c[(1, 1)],
                    c[(1, 2)],
                    c[(2, 0)],
                    c[(2, 1)],
                    c[(2, 2)],
                ]
            }),
            normal_sigma_rad: d.map(|d| d.normal_sigma_rad),
            disambiguation: d.map(|d| d.disambiguation),
            quality: d.map(|d| d.quality),
            track_epoch: d.map(|d| d.track_epoch),
            capture_time_ns: Some(m.capture_time_ns),
            times_us: Some(m.times),
            not_detected: m.miss.as_ref().map(NotDetectedRecord::from),
            error: None,
        }
    }

    /// The record of a frame that could not be read.
    pub fn unreadable(frame: String, error: String) -> Self {
        Self {
            frame,
            detected: false,
            ellipse: None,
            position_camera: None,
            normal_camera: None,
            normal_camera_alt: None,
            position_camera_alt: None,
            position_body: None,
            normal_body: None,
            position_from_probe_body: None,
            position_covariance_body: None,
            normal_sigma_rad: None,
            disambiguation: None,
            quality: None,
            track_epoch: None,
            capture_time_ns: None,
            times_us: None,
            not_detected: None,
            error: Some(error),
        }
    }
}
