//! Camera buffer → gray frame, per 1280x960 frame, single-threaded: what
//! each V4L2 format costs the companion computer before the measurement
//! starts (GREY: a copy; YUYV: every other byte; MJPG: a JPEG decode).
//! The frame is a simulator frame (sky, drogue, noise), so the JPEG is as
//! hard to decode as a real one; MJPG at quality 85.

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_sim::{Scenario, Simulator};
use drogue_vision::source::v4l::convert::{BufferLayout, PixelFormat, to_gray};
use image::ImageEncoder;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let mut sim = Simulator::new(Scenario::builtin("approach").unwrap()).unwrap();
    let (gray, _) = sim.nth(300).unwrap();
    let (w, h) = gray.dimensions();
    let grey_buf = gray.as_raw().clone();
    let yuyv_buf: Vec<u8> = grey_buf.iter().flat_map(|&y| [y, 128]).collect();
    // A colour JPEG (YCbCr, chroma subsampled), as UVC cameras send even of
    // a gray scene: the decoder converts to RGB, then to luma.
    let rgb_buf: Vec<u8> = grey_buf.iter().flat_map(|&y| [y, y, y]).collect();
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 85)
        .write_image(&rgb_buf, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    let layout = |format| BufferLayout {
        format,
        width: w,
        height: h,
        stride_bytes: 0,
    };
    let mut g = c.benchmark_group(format!("v4l_convert_{w}x{h}"));
    g.bench_function("GREY", |b| {
        b.iter(|| to_gray(&layout(PixelFormat::Grey), black_box(&grey_buf)).unwrap());
    });
    g.bench_function("YUYV", |b| {
        b.iter(|| to_gray(&layout(PixelFormat::Yuyv), black_box(&yuyv_buf)).unwrap());
    });
    g.bench_function(format!("MJPG_{}KiB", jpeg.len() / 1024), |b| {
        b.iter(|| to_gray(&layout(PixelFormat::Mjpeg), black_box(&jpeg)).unwrap());
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
