//! The pose stage per frame: cone pose, its uncertainty, the canopy-rim check
//! of both solutions and the tracker's choice. Single-threaded.

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::measure::FitQuality;
use drogue_vision::measure::ambiguity::{canopy_support, canopy_supports};
use drogue_vision::measure::ellipse::{Conic, Ellipse};
use drogue_vision::measure::pose::{CirclePose, cone_pose, pose_uncertainty};
use drogue_vision::measure::track::Tracker;
use drogue_vision::testing;
use image::{GrayImage, Luma};
use nalgebra::{Matrix3, Vector3};
use std::hint::black_box;

/// A drogue 3 m away tilted 30 degrees: its exact ellipse, rim points and a
/// rendered frame (sky, canopy, dark rim band, dark inner circle).
fn scene(cam: &CameraModel) -> (Ellipse, Vec<[f64; 2]>, GrayImage) {
    let centre = Vector3::new(0.2, -0.1, 3.0);
    let normal = nalgebra::Rotation3::new(Vector3::new(0.4, 0.3, 0.0).normalize() * 0.52)
        * -centre.normalize();
    let helper = Vector3::x();
    let u = normal.cross(&helper).normalize();
    let v = normal.cross(&u);
    let h = cam.k * Matrix3::from_columns(&[u * 0.15, v * 0.15, centre]);
    let h_inv = h.try_inverse().unwrap();
    let c0 = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    let ellipse = Conic::from_matrix(&(h_inv.transpose() * c0 * h_inv))
        .to_ellipse()
        .unwrap();
    let points = (0..600)
        .map(|k| ellipse.point_at(k as f64 * std::f64::consts::TAU / 600.0))
        .collect();
    let image = GrayImage::from_fn(1280, 960, |x, y| {
        let ray = cam.ray_camera([f64::from(x), f64::from(y)]);
        let r = (ray * (normal.dot(&centre) / normal.dot(&ray)) - centre).norm();
        Luma([match r {
            r if r < 0.15 => 30,
            r if r < 0.31 => 150,
            r if r < 0.33 => 70,
            _ => 170,
        }])
    });
    (ellipse, points, image)
}

fn bench(c: &mut Criterion) {
    // The reference sets' camera (1280x960, the paper's lens).
    let cam = testing::paper_camera([0.0; 5]);
    let config = Config::embedded();
    let (ellipse, points, image) = scene(&cam);
    let quality = FitQuality {
        points: points.len(),
        inliers: points.len(),
        rms_residual_px: 0.2,
        score: 1.0,
    };
    let solutions = cone_pose(&ellipse, &cam, 0.15).unwrap();
    c.bench_function("cone_pose", |b| {
        b.iter(|| cone_pose(black_box(&ellipse), &cam, 0.15));
    });
    c.bench_function("pose_uncertainty_600_points", |b| {
        b.iter(|| {
            pose_uncertainty(
                black_box(&ellipse),
                &cam,
                &solutions[0],
                0.15,
                &quality,
                &points,
            )
        });
    });
    c.bench_function("canopy_support", |b| {
        b.iter(|| canopy_support(&image, &cam, black_box(&solutions[0]), 0.33));
    });
    c.bench_function("pose_stage_per_frame", |b| {
        let mut tracker = Tracker::new(&config.track).unwrap();
        let mut t_ns = 0u64;
        b.iter(|| {
            let [s0, s1]: [CirclePose; 2] = cone_pose(black_box(&ellipse), &cam, 0.15).unwrap();
            let supports = canopy_supports(&image, &cam, &[s0, s1], 0.33, 0.018);
            t_ns += 33_000_000;
            let choice = tracker.choose([s0, s1], supports, t_ns, &ellipse);
            pose_uncertainty(&ellipse, &cam, &choice.pose, 0.15, &quality, &points)
        });
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
