use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::image_io::read_gray8;
use drogue_vision::measure::detect::Detector;
use std::path::Path;
use std::time::Instant;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cam = CameraModel::load(Path::new(&args[1])).unwrap();
    let cfg = Config::embedded();
    let mut d = Detector::new(&cfg.detect, &cam, 0.15);
    for f in &args[2..] {
        let img = read_gray8(Path::new(f)).unwrap();
        let t = Instant::now();
        let mut r = None;
        for _ in 0..20 {
            r = d.detect(&img, None);
        }
        let full = t.elapsed().as_secs_f64() / 20.0 * 1e3;
        let h = r.as_ref().map(|c| c.ellipse_px);
        println!(
            "full: {:?}",
            r.as_ref()
                .map(|c| (c.ellipse_px, c.score, c.rim_points_px.len()))
        );
        let t = Instant::now();
        for _ in 0..20 {
            r = d.detect(&img, h.as_ref());
        }
        let tr = t.elapsed().as_secs_f64() / 20.0 * 1e3;
        println!(
            "{f}: full {full:.3} ms tracked {tr:.3} ms {:?}",
            r.map(|c| (c.ellipse_px, c.score, c.rim_points_px.len()))
        );
    }
}
