//! The camera's mounting on the receiver: camera frame → body FRD.
//! INTERFACE STUB (issue 2, item 6).

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// `[mount]` in the config: degrees and metres at this edge.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MountConfig {}

/// Camera → body FRD transform and the probe tip.
#[derive(Clone, Debug)]
pub struct Mount {}

impl Mount {
    pub fn from_config(_cfg: &MountConfig) -> Result<Self, String> {
        Ok(Self {})
    }
    pub fn point_camera_to_body(&self, p_camera_m: &Vector3<f64>) -> Vector3<f64> {
        *p_camera_m
    }
    pub fn vector_camera_to_body(&self, v_camera: &Vector3<f64>) -> Vector3<f64> {
        *v_camera
    }
    pub fn covariance_camera_to_body(&self, cov_camera: &Matrix3<f64>) -> Matrix3<f64> {
        *cov_camera
    }
    pub fn point_body_from_probe(&self, p_body_m: &Vector3<f64>) -> Vector3<f64> {
        *p_body_m
    }
}
