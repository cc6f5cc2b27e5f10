//! Detection speed on reference-like frames: the full-frame search and the
//! tracked search near a predicted ellipse. Frames come from
//! `$DROGUE_REFERENCE_DIR` (e.g. /work/shared/data/reference); without it the
//! benchmark uses a synthetic frame.

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::image_io::read_gray8;
use drogue_vision::measure::detect::Detector;
use drogue_vision::measure::ellipse::Ellipse;
use image::{GrayImage, Luma};
use nalgebra::Matrix3;
use std::hint::black_box;
use std::path::PathBuf;

fn camera() -> CameraModel {
    let k = Matrix3::new(1336.2, 0.0, 646.3, 0.0, 1335.4, 473.8, 0.0, 0.0, 1.0);
    CameraModel::new("bench", 1280, 960, k, [0.0; 5]).unwrap()
}

/// A dark disc on a light canopy with an outer band, on a sky gradient.
fn synthetic() -> GrayImage {
    GrayImage::from_fn(1280, 960, |x, y| {
        let (dx, dy) = (x as f64 - 600.3, y as f64 - 450.7);
        let r = (dx * dx / 1.2 + dy * dy).sqrt();
        let v = if r < 67.0 {
            30.0
        } else if r < 140.0 {
            180.0
        } else if r < 148.0 {
            80.0
        } else {
            120.0 + y as f64 * 0.05
        };
        Luma([v as u8])
    })
}

fn frames() -> Vec<(String, GrayImage)> {
    let Some(dir) = std::env::var_os("DROGUE_REFERENCE_DIR").map(PathBuf::from) else {
        return vec![("synthetic".into(), synthetic())];
    };
    [
        "paper10/frame_0003.png",
        "occlusion/frame_0000.png",
        "occlusion/frame_0012.png",
        "negative/frame_0008.png",
    ]
    .iter()
    .filter_map(|f| {
        read_gray8(&dir.join(f), None)
            .ok()
            .map(|img| (f.to_string(), img))
    })
    .collect()
}

fn bench(c: &mut Criterion) {
    let config = Config::embedded();
    let camera = camera();
    let mut detector = Detector::new(&config.detect, &camera, config.drogue.inner_radius_m);
    for (name, image) in frames() {
        c.bench_function(&format!("detect full {name}"), |b| {
            b.iter(|| black_box(detector.detect(black_box(&image), None)))
        });
        if let Some(found) = detector.detect(&image, None) {
            let hint: Ellipse = found.ellipse_px;
            c.bench_function(&format!("detect tracked {name}"), |b| {
                b.iter(|| black_box(detector.detect(black_box(&image), Some(&hint))))
            });
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
