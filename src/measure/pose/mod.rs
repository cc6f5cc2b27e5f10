//! Circle pose from its image ellipse: the paper's visual cone (eqs. 11-27)
//! in `cone`, and the pose's uncertainty from the fit in `uncertainty`.

mod cone;
mod uncertainty;

pub use cone::cone_pose;
pub(crate) use uncertainty::{EllipseParams, ellipse_from_params, ellipse_params};
pub use uncertainty::{
    EllipseSpread, PoseUncertainty, RimSteps, ellipse_spread, ellipse_spreads, pose_uncertainty,
    pose_uncertainty_from_spread, pose_uncertainty_with_edges, with_unresolved_mirror,
};

use crate::spatial::{Camera, Direction, Point};
use nalgebra::Vector3;

/// A circle's pose in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CirclePose {
    /// Circle centre, metres.
    pub centre_camera_m: Point<Camera>,
    /// Unit normal of the circle's plane, pointing toward the camera.
    pub normal_camera: Direction<Camera>,
}

/// Two unit vectors spanning the plane of a circle with unit-ish normal `n`
/// (camera frame), orthogonal to it and to each other; `None` for a
/// non-finite or near-zero normal.
pub fn circle_plane_basis(n: &Vector3<f64>) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if !(n.iter().all(|x| x.is_finite()) && n.norm() > 0.5) {
        return None;
    }
    let n = n.normalize();
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    Some((e1, n.cross(&e1)))
}
