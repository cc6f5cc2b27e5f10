use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::image_io::read_gray8;
use drogue_vision::measure::detect::Detector;
use std::path::Path;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cam = CameraModel::load(Path::new(&args[1])).unwrap();
    let cfg = Config::embedded();
    let mut d = Detector::new(&cfg.detect, &cam, 0.15);
    for f in &args[2..] {
        let img = read_gray8(Path::new(f)).unwrap();
        let r = d.detect(&img, None);
        println!(
            "{f}: {:?}",
            r.map(|c| (c.ellipse_px, c.score, c.rim_points_px.len()))
        );
    }
}
