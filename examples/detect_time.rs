//! Times the detector on frames: `detect_time CAMERA.yaml FRAME...`
//! (env `N` iterations, default 20). For quick checks; the numbers to report
//! come from `cargo bench --bench detect`.
use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::image_io::read_gray8;
use drogue_vision::measure::detect::Detector;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let cam_path = args
        .get(1)
        .ok_or("usage: detect_time CAMERA.yaml FRAME...")?;
    let cam = CameraModel::load(Path::new(cam_path)).map_err(|e| e.to_string())?;
    let cfg = Config::embedded();
    let mut d = Detector::new(&cfg.detect, &cam, cfg.drogue.inner_radius_m);
    let n: usize = std::env::var("N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20);
    let mode = std::env::var("MODE").unwrap_or_default();
    for f in &args[2..] {
        let img = read_gray8(Path::new(f))?;
        let first = d.detect(&img, None);
        let hint = first.as_ref().map(|c| c.ellipse_px);
        let t = Instant::now();
        for _ in 0..n {
            if mode == "tracked" {
                d.detect(&img, hint.as_ref());
            } else {
                d.detect(&img, None);
            }
        }
        let ms = t.elapsed().as_secs_f64() / n as f64 * 1e3;
        println!(
            "{f}: {} {ms:.3} ms/frame (wall) {:?}",
            if mode == "tracked" { "tracked" } else { "full" },
            first.map(|c| (c.ellipse_px, c.score, c.rim_points_px.len()))
        );
    }
    Ok(())
}
