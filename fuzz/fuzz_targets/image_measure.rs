//! An image file's bytes to a measurement: the header checked against a
//! 64x48 camera, decoded (any format the build reads), measured.
#![no_main]

use drogue_vision::camera::CameraModel;
use drogue_vision::config::Config;
use drogue_vision::frame::{Frame, FrameOrigin};
use drogue_vision::image_io::decode_gray8;
use drogue_vision::measure::Measurer;
use libfuzzer_sys::fuzz_target;
use std::cell::RefCell;

thread_local! {
    /// One measurer for the run (its setup parses the config); its track is
    /// forgotten before each input, so every input is measured alone.
    static MEASURER: RefCell<Measurer> = RefCell::new({
        let k = nalgebra::Matrix3::new(60.0, 0.0, 32.0, 0.0, 60.0, 24.0, 0.0, 0.0, 1.0);
        let camera = CameraModel::new("fuzz", 64, 48, k, [-0.1, 0.01, 0.0, 0.0, 0.0]).unwrap();
        Measurer::new(camera, &Config::embedded().measure()).unwrap()
    });
}

fuzz_target!(|data: &[u8]| {
    let Ok(image) = decode_gray8(data, None, Some((64, 48))) else {
        return;
    };
    assert_eq!(image.dimensions(), (64, 48));
    let frame = Frame {
        seq: 0,
        capture_time_ns: 0,
        image,
        origin: FrameOrigin::File(Default::default()),
    };
    MEASURER.with(|m| {
        let mut m = m.borrow_mut();
        m.forget_track();
        let _ = m.measure(&frame);
    });
});
