//! Exact image of a circle: its image conic, the ellipse parameters, and the
//! mirror pose that images to the very same ellipse.
//!
//! All from the geometry, never from pixels: the circle (centre C, unit
//! normal n, radius r) maps to the image through the plane homography
//! H = K [b1 b2 C] (b1, b2 an orthonormal basis of the plane), so the image
//! conic is C_img = H^-T diag(1, 1, -r^2) H^-1 in undistorted pixels.

use crate::TruthEllipse;
use crate::camera::SimCamera;
use crate::geometry::{M3, V3, perpendicular};
use nalgebra::{Matrix2, SymmetricEigen, Vector2};

/// Intrinsic matrix K of the camera.
pub fn k_matrix(cam: &SimCamera) -> M3 {
    M3::new(cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0)
}

/// Image conic (undistorted pixels, homogeneous, scaled to unit Frobenius
/// norm) of the circle; `None` when the plane passes through the camera.
pub fn circle_image_conic(cam: &SimCamera, centre: &V3, normal: &V3, radius: f64) -> Option<M3> {
    let n = normal.normalize();
    let b1 = perpendicular(&n);
    let b2 = n.cross(&b1);
    let h = k_matrix(cam) * M3::from_columns(&[b1, b2, *centre]);
    let h_inv = h.try_inverse()?;
    let c_plane = M3::from_diagonal(&V3::new(1.0, 1.0, -radius * radius));
    let conic = h_inv.transpose() * c_plane * h_inv;
    let norm = conic.norm();
    (norm > 0.0 && norm.is_finite()).then(|| conic / norm)
}

/// Ellipse parameters of a conic; `None` if it is not a real ellipse.
pub fn conic_to_ellipse(c: &M3) -> Option<TruthEllipse> {
    let a2 = Matrix2::new(c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)]);
    let b = Vector2::new(c[(0, 2)], c[(1, 2)]);
    let centre = -a2.try_inverse()? * b;
    let f0 = c[(2, 2)] + b.dot(&centre);
    let eig = SymmetricEigen::new(a2);
    let (l0, l1) = (eig.eigenvalues[0], eig.eigenvalues[1]);
    if l0 * l1 <= 0.0 || f0 * l0 >= 0.0 {
        return None;
    }
    // Semi-axis along eigenvector i: sqrt(-f0 / l_i); the major axis has the
    // smaller |l|.
    let (major_i, minor_i) = if l0.abs() < l1.abs() { (0, 1) } else { (1, 0) };
    let a = (-f0 / eig.eigenvalues[major_i]).sqrt();
    let bb = (-f0 / eig.eigenvalues[minor_i]).sqrt();
    let dir = eig.eigenvectors.column(major_i);
    let mut theta = dir[1].atan2(dir[0]);
    if theta <= -std::f64::consts::FRAC_PI_2 {
        theta += std::f64::consts::PI;
    } else if theta > std::f64::consts::FRAC_PI_2 {
        theta -= std::f64::consts::PI;
    }
    Some(TruthEllipse {
        cx: centre[0],
        cy: centre[1],
        a,
        b: bb,
        theta,
    })
}

/// Both circle poses (centre, normal toward the camera) of radius `radius`
/// whose image is the conic `c_img`, in the closed form of the cone's
/// eigen-decomposition. The cone Q = K^T C_img K is brought to two positive
/// eigenvalues l1 >= l2 > 0 > l3; the circular sections have normals
/// n = sqrt((l1-l2)/(l1-l3)) e1 +- sqrt((l2-l3)/(l1-l3)) e3, and each
/// centre follows from cutting the cone with the plane n.X = 1 and scaling
/// the section to the radius.
pub fn circle_poses(cam: &SimCamera, c_img: &M3, radius: f64) -> Option<[(V3, V3); 2]> {
    let k = k_matrix(cam);
    let mut q = k.transpose() * c_img * k;
    q = (q + q.transpose()) * 0.5;
    let mut eig = SymmetricEigen::new(q);
    if eig.eigenvalues.iter().filter(|l| **l > 0.0).count() < 2 {
        q = -q;
        eig = SymmetricEigen::new(q);
    }
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|a, b| eig.eigenvalues[*b].total_cmp(&eig.eigenvalues[*a]));
    let (l1, l2, l3) = (
        eig.eigenvalues[idx[0]],
        eig.eigenvalues[idx[1]],
        eig.eigenvalues[idx[2]],
    );
    if !(l2 > 0.0 && l3 < 0.0) {
        return None;
    }
    let e1: V3 = eig.eigenvectors.column(idx[0]).into();
    let e3: V3 = eig.eigenvectors.column(idx[2]).into();
    let s1 = ((l1 - l2) / (l1 - l3)).max(0.0).sqrt();
    let s3 = ((l2 - l3) / (l1 - l3)).max(0.0).sqrt();
    let pose = |sign: f64| -> Option<(V3, V3)> {
        let mut n = (e1 * s1 + e3 * (sign * s3)).normalize();
        if n.z < 0.0 {
            n = -n;
        }
        let b1 = perpendicular(&n);
        let b2 = n.cross(&b1);
        let basis = M3::from_columns(&[b1, b2, n]);
        let m = basis.transpose() * q * basis;
        let a2 = Matrix2::new(m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]);
        let bv = Vector2::new(m[(0, 2)], m[(1, 2)]);
        let a2_inv = a2.try_inverse()?;
        let x0 = -a2_inv * bv;
        let rho2 = (bv.dot(&(a2_inv * bv)) - m[(2, 2)]) / (0.5 * a2.trace());
        if rho2.is_nan() || rho2 <= 0.0 {
            return None;
        }
        let centre_unit = b1 * x0[0] + b2 * x0[1] + n;
        let centre = centre_unit * (radius / rho2.sqrt());
        Some((centre, -n))
    };
    Some([pose(1.0)?, pose(-1.0)?])
}

/// The mirror solution: of the two poses imaging to the circle's ellipse,
/// the one whose normal is farther from the true normal.
pub fn mirror_pose(cam: &SimCamera, centre: &V3, normal: &V3, radius: f64) -> Option<(V3, V3)> {
    let c = circle_image_conic(cam, centre, normal, radius)?;
    let [p0, p1] = circle_poses(cam, &c, radius)?;
    Some(if p0.1.dot(normal) < p1.1.dot(normal) {
        p0
    } else {
        p1
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(distorted: bool) -> SimCamera {
        SimCamera {
            width: 1280,
            height: 960,
            fx: 1336.2,
            fy: 1335.4,
            cx: 646.3,
            cy: 473.8,
            distortion: if distorted {
                [-0.15, 0.09, 0.0008, -0.0005, -0.02]
            } else {
                [0.0; 5]
            },
        }
    }

    /// First-order geometric distance of a pixel to the ellipse, from the
    /// ellipse parameters alone.
    fn distance_to_ellipse(e: &TruthEllipse, p: [f64; 2]) -> f64 {
        let (s, c) = e.theta.sin_cos();
        let (dx, dy) = (p[0] - e.cx, p[1] - e.cy);
        let x = c * dx + s * dy;
        let y = -s * dx + c * dy;
        let f = x * x / (e.a * e.a) + y * y / (e.b * e.b) - 1.0;
        let g = 2.0 * ((x / (e.a * e.a)).powi(2) + (y / (e.b * e.b)).powi(2)).sqrt();
        f / g
    }

    fn poses() -> Vec<(V3, V3)> {
        vec![
            (V3::new(0.0, 0.0, 3.0), V3::new(0.0, 0.0, -1.0)),
            (
                V3::new(-0.3, 0.1, 2.5),
                V3::new(0.3, -0.4, -0.8).normalize(),
            ),
            (
                V3::new(0.8, -0.5, 4.0),
                V3::new(-0.6, 0.2, -0.7).normalize(),
            ),
            (
                V3::new(0.05, 0.2, 1.2),
                V3::new(0.75, 0.4, -0.5).normalize(),
            ),
        ]
    }

    #[test]
    fn rim_points_lie_on_truth_ellipse() {
        for distorted in [false, true] {
            let c = cam(distorted);
            for (centre, normal) in poses() {
                let conic = circle_image_conic(&c, &centre, &normal, 0.15).unwrap();
                let e = conic_to_ellipse(&conic).unwrap();
                let b1 = perpendicular(&normal);
                let b2 = normal.cross(&b1);
                for k in 0..360 {
                    let a = (k as f64).to_radians();
                    let p = centre + (b1 * a.cos() + b2 * a.sin()) * 0.15;
                    // With distortion: the real image point, then undistorted.
                    let px = if distorted {
                        c.undistort_px(c.project_px(&p).unwrap()).unwrap()
                    } else {
                        c.project_undistorted_px(&p).unwrap()
                    };
                    let d = distance_to_ellipse(&e, px);
                    assert!(d.abs() < 1e-6, "distorted {distorted}: {d} px");
                }
            }
        }
    }

    #[test]
    fn both_poses_image_to_the_same_ellipse_and_one_is_the_truth() {
        let c = cam(false);
        for (centre, normal) in poses() {
            let conic = circle_image_conic(&c, &centre, &normal, 0.15).unwrap();
            let e = conic_to_ellipse(&conic).unwrap();
            let [p0, p1] = circle_poses(&c, &conic, 0.15).unwrap();
            let err = |p: &(V3, V3)| (p.0 - centre).norm() + (p.1 - normal).norm();
            // 1e-7: the head-on view is degenerate (sqrt of a vanishing gap).
            assert!(err(&p0).min(err(&p1)) < 1e-7, "{} {}", err(&p0), err(&p1));
            for (pc, pn) in [p0, p1] {
                assert!(pn.dot(&pc) < 0.0, "normal toward the camera");
                let other =
                    conic_to_ellipse(&circle_image_conic(&c, &pc, &pn, 0.15).unwrap()).unwrap();
                assert!((other.cx - e.cx).abs() < 1e-7 && (other.cy - e.cy).abs() < 1e-7);
                assert!((other.a - e.a).abs() < 1e-7 && (other.b - e.b).abs() < 1e-7);
            }
            let (mc, mn) = mirror_pose(&c, &centre, &normal, 0.15).unwrap();
            if (normal.z + 1.0).abs() > 1e-3 {
                assert!((mn - normal).norm() > 1e-3);
                assert!((mc - centre).norm() < 0.05);
            }
        }
    }

    #[test]
    fn reference_truth_is_reproduced() {
        // Independent renderer's truth (paper10 frame_0000): ellipse and mirror.
        let c = cam(false);
        let centre = V3::new(
            0.006244937389415365,
            -0.10892659248181318,
            1.3583419078914165,
        );
        let normal = V3::new(0.7486238285487202, 0.41865213725274614, -0.5140941074382825);
        let e = conic_to_ellipse(&circle_image_conic(&c, &centre, &normal, 0.15).unwrap()).unwrap();
        assert!((e.cx - 646.170906521853).abs() < 1e-6);
        assert!((e.cy - 362.20710537042254).abs() < 1e-6);
        assert!((e.a - 148.55788873925775).abs() < 1e-6);
        assert!((e.b - 80.79794068521886).abs() < 1e-6);
        assert!((e.theta - -1.1085667233054934).abs() < 1e-9);
        let (mc, mn) = mirror_pose(&c, &centre, &normal, 0.15).unwrap();
        let alt_c = V3::new(
            -0.007277281521789971,
            -0.11567603366788592,
            1.357778640624221,
        );
        let alt_n = V3::new(
            -0.7482093361782459,
            -0.32847283365816593,
            -0.5764446086175873,
        );
        assert!((mc - alt_c).norm() < 1e-9, "{mc}");
        assert!((mn - alt_n).norm() < 1e-9, "{mn}");
    }
}
