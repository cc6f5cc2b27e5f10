//! Camera files (ROS / OpenCV YAML): parsed or refused, and what is
//! accepted undistorts and projects without a panic.
#![no_main]

use drogue_vision::camera::CameraModel;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(cam) = CameraModel::from_yaml_str(text, "fuzz.yaml") {
        let p = [f64::from(cam.width) * 0.3, f64::from(cam.height) * 0.7];
        let u = cam.undistort_px(p);
        let _ = cam.distort_px(u);
        let _ = cam.ray_camera(u);
    }
});
