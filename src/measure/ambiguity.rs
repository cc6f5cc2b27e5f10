//! Telling the two cone solutions apart from the canopy's outer rim.
//!
//! A single circle's image fits two poses (mirror images about the cone's
//! widest plane). The drogue's canopy ends in a rim: a circle concentric with
//! the dark inner circle, in the same plane, with a known radius. Each pose
//! predicts where that rim must appear; the two predictions differ visibly
//! once the tilt is more than a few degrees, and only the true one lies on the
//! rim's edge in the image. Near a frontal view (tilt ~ 0) both predictions
//! coincide, both get the same support, and then the choice hardly matters:
//! the two solutions are then nearly the same pose.
//!
//! The rim is darker than the sky around it (a dark band at the canopy's edge),
//! so the edge we look for gets brighter going outward. Its inner side (band
//! against the lighter canopy) has the opposite polarity and is not counted.

use super::detect::rim;
use super::pose::CirclePose;
use crate::camera::CameraModel;
use image::GrayImage;
use nalgebra::Vector3;

/// Points sampled along the predicted rim (every 5 degrees of the circle:
/// on the reference sets 120 points, every 3 degrees, decided the same
/// frames but one of 300 noisy occlusion trials, at 1.7 times the cost).
const SAMPLES: usize = 72;
/// How far across the predicted curve the edge is looked for, pixels.
const SEARCH_PX: f64 = 3.0;
/// Step of the search across the curve, pixels.
const SEARCH_STEP_PX: f64 = 0.5;
/// How close to the predicted curve the edge must be to support the pose,
/// pixels. The two solutions' predicted rims can be only a pixel or two
/// apart at small tilts, so this is tight; it still covers the prediction's
/// own error: the inner ellipse's fit error (~0.1 px) scaled up by the
/// canopy/inner radius ratio (about 2.2), plus the edge's sub-pixel
/// localisation error.
const TOLERANCE_PX: f64 = 0.75;
/// Smallest outward brightening that counts as an edge, grey levels per pixel
/// (central difference over 2 px). Sensor noise of ~1.5 grey levels gives
/// ~1 grey level/px of derivative noise: 6 keeps noise-only maxima out, while
/// a rim against the sky gives tens.
const MIN_EDGE_GREY_PER_PX: f64 = 6.0;
/// Share of the predicted rim that must fall inside the image to judge.
const MIN_SHARE_IN_IMAGE: f64 = 0.5;
/// Smallest predicted rim (semi-minor axis, pixels) worth judging: below this
/// the two predictions are within the search band of each other anyway.
const MIN_RIM_SIZE_PX: f64 = 4.0;

/// Offsets searched across the curve: -SEARCH_PX..=SEARCH_PX.
const SEARCH_STEPS: usize = (2.0 * SEARCH_PX / SEARCH_STEP_PX) as usize + 1;
/// Grey values sampled across the curve: the search band plus the 1 px on
/// each side that the central difference needs.
const PROFILE_LEN: usize = SEARCH_STEPS + 2 * STEPS_PER_PX;
const STEPS_PER_PX: usize = (1.0 / SEARCH_STEP_PX) as usize;

/// Where across the predicted curve the strongest outward brightening lies:
/// its offset from `p` along the unit image direction `out` (pixels,
/// sub-pixel by a parabola through the peak) if it is within `SEARCH_PX` and
/// at least `MIN_EDGE_GREY_PER_PX` strong; `Some(None)` for no edge; `None`
/// if the search leaves the image. `grey` is scratch for the profile.
fn outward_edge_offset(
    image: &GrayImage,
    p: [f64; 2],
    out: [f64; 2],
    grey: &mut Vec<f32>,
) -> Option<Option<f64>> {
    // The detector's ray sampler: bilinear, stopping at the image border.
    let start = -SEARCH_PX - 1.0;
    let end = start + (PROFILE_LEN - 1) as f64 * SEARCH_STEP_PX;
    rim::profile(image, p, out, start, end, SEARCH_STEP_PX, grey);
    if grey.len() < PROFILE_LEN {
        return None;
    }
    // Central difference over 2 px at each searched offset.
    let mut gradient = [0.0; SEARCH_STEPS];
    for (i, g) in gradient.iter_mut().enumerate() {
        *g = f64::from(grey[i + 2 * STEPS_PER_PX] - grey[i]) / 2.0;
    }
    let (i_best, &best) = gradient
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    if best < MIN_EDGE_GREY_PER_PX {
        return Some(None);
    }
    let mut offset = i_best as f64 * SEARCH_STEP_PX - SEARCH_PX;
    if i_best > 0 && i_best + 1 < SEARCH_STEPS {
        let (l, c, r) = (gradient[i_best - 1], best, gradient[i_best + 1]);
        let curvature = l - 2.0 * c + r;
        if curvature < 0.0 {
            offset += 0.5 * (l - r) / curvature * SEARCH_STEP_PX;
        }
    }
    Some(Some(offset))
}

/// (cos t, sin t) of the `SAMPLES` points along the rim, computed once.
fn rim_directions() -> &'static [(f64, f64); SAMPLES] {
    static TABLE: std::sync::OnceLock<[(f64, f64); SAMPLES]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|k| {
            let t = k as f64 * std::f64::consts::TAU / SAMPLES as f64;
            let (s, c) = t.sin_cos();
            (c, s)
        })
    })
}

/// Image evidence (0..1) that the canopy's outer rim, a circle of
/// `canopy_radius_m` concentric with the inner circle and in its plane, lies
/// where `pose` predicts it: the share of points along the predicted rim
/// (projected through the camera's distortion) with an outward-brightening
/// edge within `TOLERANCE_PX` of it. `None` where the rim cannot be judged: less than
/// half of it in the image, or too small. A rim hidden by clouds, glare or
/// the hose gives a low support for both solutions; the tracker then does not
/// use it.
pub fn canopy_support(
    image: &GrayImage,
    camera: &CameraModel,
    pose: &CirclePose,
    canopy_radius_m: f64,
) -> Option<f64> {
    let n = pose.normal_camera;
    if !(canopy_radius_m > 0.0 && n.iter().all(|x| x.is_finite()) && n.norm() > 0.5) {
        return None;
    }
    let n = n.normalize();
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    let e2 = n.cross(&e1);

    let (mut judged, mut with_edge) = (0usize, 0usize);
    let mut grey = Vec::with_capacity(PROFILE_LEN);
    let (mut min_u, mut max_u, mut min_v, mut max_v) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(cos_t, sin_t) in rim_directions() {
        let radial = cos_t * e1 + sin_t * e2;
        // The image's outward direction is where the rim point moves as the
        // radius grows: the projection's derivative along `radial`.
        let Some((p, d)) = camera.project_px_with_derivative(
            &(pose.centre_camera_m + canopy_radius_m * radial),
            &radial,
        ) else {
            continue;
        };
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if !(len > 0.0 && len.is_finite()) {
            continue;
        }
        min_u = min_u.min(p[0]);
        max_u = max_u.max(p[0]);
        min_v = min_v.min(p[1]);
        max_v = max_v.max(p[1]);
        if let Some(edge) = outward_edge_offset(image, p, [d[0] / len, d[1] / len], &mut grey) {
            judged += 1;
            if edge.is_some_and(|o| o.abs() <= TOLERANCE_PX) {
                with_edge += 1;
            }
        }
    }
    let big_enough = (max_u - min_u).min(max_v - min_v) >= 2.0 * MIN_RIM_SIZE_PX;
    if !big_enough || (judged as f64) < MIN_SHARE_IN_IMAGE * SAMPLES as f64 {
        return None;
    }
    Some(with_edge as f64 / judged as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;
    use nalgebra::Matrix3;

    fn camera() -> CameraModel {
        lens([0.0; 5])
    }

    fn lens(distortion: [f64; 5]) -> CameraModel {
        let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
        CameraModel::new("t", 640, 480, k, distortion).unwrap()
    }

    /// Paints a synthetic drogue, exact per pixel centre: sky 170, canopy 150,
    /// dark band at the rim (r in [0.30, 0.33]) 70, inner circle 30.
    fn render(cam: &CameraModel, pose: &CirclePose) -> GrayImage {
        let n = pose.normal_camera;
        GrayImage::from_fn(640, 480, |x, y| {
            let ray = cam.ray_camera(cam.undistort_px([f64::from(x), f64::from(y)]));
            let t = n.dot(&pose.centre_camera_m) / n.dot(&ray);
            let r = (ray * t - pose.centre_camera_m).norm();
            let g = if r < 0.15 {
                30
            } else if r < 0.30 {
                150
            } else if r < 0.33 {
                70
            } else {
                170
            };
            Luma([g])
        })
    }

    #[test]
    fn the_true_pose_has_the_support() {
        support_through(&camera(), Vector3::new(0.1, -0.05, 3.0));
    }

    #[test]
    fn the_true_pose_has_the_support_through_lens_distortion() {
        // Strong barrel distortion: an undistorted prediction would miss.
        // Off-centre, where it moves the rim by several pixels.
        support_through(
            &lens([-0.3, 0.1, 0.001, -0.001, 0.0]),
            Vector3::new(0.6, 0.4, 3.0),
        );
    }

    fn support_through(cam: &CameraModel, centre_camera_m: Vector3<f64>) {
        let cam = cam.clone();
        let n = nalgebra::Rotation3::new(Vector3::new(0.0, 0.6, 0.2)) * -Vector3::z();
        let truth = CirclePose {
            centre_camera_m,
            normal_camera: n.normalize(),
        };
        let image = render(&cam, &truth);
        let good = canopy_support(&image, &cam, &truth, 0.33).unwrap();
        assert!(good > 0.95, "true pose support {good}");
        // A pose with the same centre and a mirrored tilt.
        let mirrored = CirclePose {
            normal_camera: Vector3::new(-n.x, -n.y, n.z).normalize(),
            ..truth
        };
        let bad = canopy_support(&image, &cam, &mirrored, 0.33).unwrap();
        assert!(bad < 0.5, "wrong pose support {bad}");
        // Wrong polarity: the band's inner edge (r = 0.30) is not the rim.
        let inner = canopy_support(&image, &cam, &truth, 0.30).unwrap();
        assert!(inner < 0.1, "inner edge support {inner}");
    }

    #[test]
    fn rim_outside_the_image_cannot_be_judged() {
        let cam = camera();
        let pose = CirclePose {
            centre_camera_m: Vector3::new(0.0, 0.0, 0.3),
            normal_camera: -Vector3::z(),
        };
        let image = GrayImage::new(640, 480);
        assert_eq!(canopy_support(&image, &cam, &pose, 0.33), None);
        // Far away the rim is a few pixels: no judgement either.
        let far = CirclePose {
            centre_camera_m: Vector3::new(0.0, 0.0, 200.0),
            ..pose
        };
        assert_eq!(canopy_support(&image, &cam, &far, 0.33), None);
        // A blank image gives no support at all.
        let near = CirclePose {
            centre_camera_m: Vector3::new(0.0, 0.0, 3.0),
            ..pose
        };
        assert_eq!(canopy_support(&image, &cam, &near, 0.33), Some(0.0));
    }
}
