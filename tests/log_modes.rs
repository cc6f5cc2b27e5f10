//! The long-flight log modes (`[log] image_encoding = "crop"` and "jpeg"):
//! `run` on the simulator writes the topics each mode promises, and an
//! independent decoder (the `mcap` crate's reader, the `image` crate's PNG and
//! JPEG decoders) reads them back. The crops are checked against the
//! simulator's truth logged with them (`/sim/truth`: the exact image ellipse of
//! the inner circle and the canopy radius) and, on the frames that also have a
//! full frame, pixel for pixel against it; the JPEG frames against the
//! simulator's own rendering of the same frame.

use drogue_sim::{FrameTruth, Scenario, Simulator};
use drogue_vision::camera::CameraModel;
use drogue_vision::log::topics;
use drogue_vision::measure::ellipse::Ellipse;
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, CompressedImage};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

/// `run --fast` of the first `frames` frames of the `approach` scenario
/// with `log_toml` laid over the config; the log's bytes.
fn run_log(dir: &Path, log_toml: &str, frames: u32, port: u16) -> Vec<u8> {
    let config = dir.join("config.toml");
    std::fs::write(&config, format!("[log]\n{log_toml}\n")).expect("config");
    let logs = dir.join("logs");
    let status = Command::new(BIN)
        .args(["run", "--source", "sim:approach", "--fast", "--max-frames"])
        .arg(frames.to_string())
        .args(["--mavlink", &format!("udpout:127.0.0.1:{port}")])
        .arg("--config")
        .arg(&config)
        .arg("--log-dir")
        .arg(&logs)
        .status()
        .expect("run");
    assert!(status.success());
    let log: PathBuf = std::fs::read_dir(&logs)
        .expect("logs")
        .map(|e| e.expect("entry").path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("an mcap log");
    std::fs::read(log).expect("log")
}

/// Messages by topic: (sequence, schema name, data).
type Topics = BTreeMap<String, Vec<(u64, String, Vec<u8>)>>;

/// Messages of a log by topic.
fn by_topic(bytes: &[u8]) -> Topics {
    let mut out: BTreeMap<String, Vec<_>> = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).expect("mcap") {
        let m = m.expect("message");
        let schema = m.channel.schema.as_ref().map(|s| s.name.clone());
        out.entry(m.channel.topic.clone()).or_default().push((
            u64::from(m.sequence),
            schema.unwrap_or_default(),
            m.data.to_vec(),
        ));
    }
    out
}

fn gray(c: &CompressedImage, format: image::ImageFormat) -> image::GrayImage {
    image::load_from_memory_with_format(&c.data, format)
        .expect("decodes")
        .into_luma8()
}

fn camera_of(topics: &Topics) -> CameraModel {
    let cal = CameraCalibration::decode(topics["/camera/calibration"][0].2.as_slice())
        .expect("calibration");
    topics::camera_from_calibration(&cal).expect("camera")
}

#[test]
fn crop_mode_logs_full_frames_every_nth_and_a_crop_around_the_drogue_on_every_frame() {
    const FRAMES: u32 = 90;
    const EVERY: u64 = 10;
    let dir = tempfile::tempdir().expect("tmp");
    let bytes = run_log(
        dir.path(),
        &format!("image_encoding = \"crop\"\nfull_frame_every = {EVERY}\ncrop_margin = 1.25"),
        FRAMES,
        14_611,
    );
    let topics = by_topic(&bytes);
    let camera = camera_of(&topics);

    // Full frames: exactly the sequence numbers divisible by EVERY, PNG.
    let full: BTreeMap<u64, image::GrayImage> = topics["/camera/image"]
        .iter()
        .map(|(seq, schema, data)| {
            assert_eq!(schema, "foxglove.CompressedImage");
            let c = CompressedImage::decode(data.as_slice()).expect("image");
            assert_eq!(c.format, "png");
            (*seq, gray(&c, image::ImageFormat::Png))
        })
        .collect();
    let expected: Vec<u64> = (0..u64::from(FRAMES))
        .filter(|s| s.is_multiple_of(EVERY))
        .collect();
    assert_eq!(full.keys().copied().collect::<Vec<_>>(), expected);

    // A crop and its place on every frame (the drogue is detected on all).
    let truth: BTreeMap<u64, FrameTruth> = topics["/sim/truth"]
        .iter()
        .map(|(seq, _, d)| (*seq, serde_json::from_slice(d).expect("truth")))
        .collect();
    let infos: BTreeMap<u64, serde_json::Value> = topics["/camera/crop_info"]
        .iter()
        .map(|(seq, _, d)| (*seq, serde_json::from_slice(d).expect("crop info")))
        .collect();
    let crops = &topics["/camera/crop"];
    assert_eq!(crops.len(), FRAMES as usize);
    assert_eq!(infos.len(), FRAMES as usize);
    let mut pixel_checked = 0;
    for (seq, schema, data) in crops {
        assert_eq!(schema, "foxglove.CompressedImage");
        let c = CompressedImage::decode(data.as_slice()).expect("crop");
        assert_eq!(c.format, "png");
        let crop = gray(&c, image::ImageFormat::Png);
        let info = &infos[seq];
        let field = |k: &str| info[k].as_u64().expect(k) as u32;
        let (x, y, w, h) = (field("x"), field("y"), field("width"), field("height"));
        assert_eq!(crop.dimensions(), (w, h), "frame {seq}");
        assert_eq!(info["around"], "detection", "frame {seq}");
        assert_eq!(
            (field("image_width"), field("image_height")),
            (camera.width, camera.height)
        );
        assert!(x + w <= camera.width && y + h <= camera.height);

        // The truth's canopy ring (inner-circle ellipse scaled by the
        // canopy/inner radius ratio, in the distorted image) lies inside.
        let t = &truth[seq];
        let e = t.ellipse.as_ref().expect("truth ellipse");
        let scale = t.canopy_radius / t.radius;
        let ring = Ellipse::new(e.cx, e.cy, e.a * scale, e.b * scale, e.theta);
        for i in 0..72 {
            let [u, v] = camera.distort_px(ring.point_at(f64::from(i) * 5f64.to_radians()));
            assert!(
                u >= f64::from(x)
                    && u < f64::from(x + w)
                    && v >= f64::from(y)
                    && v < f64::from(y + h),
                "frame {seq}: canopy point ({u:.1}, {v:.1}) outside the crop {x},{y} {w}x{h}"
            );
        }
        // Not much more than the canopy: the margin is 1.25.
        let canopy_diameter = 2.0 * e.a * scale;
        assert!(
            f64::from(w.max(h)) < 1.6 * canopy_diameter + 4.0,
            "frame {seq}: crop {w}x{h} for a canopy of {canopy_diameter:.0} px"
        );

        // Where a full frame exists, the crop is its pixels at (x, y).
        if let Some(frame) = full.get(seq) {
            let region = image::imageops::crop_imm(frame, x, y, w, h).to_image();
            assert_eq!(
                region, crop,
                "frame {seq}: crop pixels differ from the full frame"
            );
            pixel_checked += 1;
        }
    }
    assert_eq!(pixel_checked, expected.len());

    // Replay (`process LOG`) measures the full frames, and detects the drogue.
    let log = dir.path().join("crop.mcap");
    std::fs::write(&log, &bytes).expect("copy");
    let out = dir.path().join("replay.jsonl");
    let status = Command::new(BIN)
        .arg("process")
        .arg(&log)
        .arg("--out")
        .arg(&out)
        .status()
        .expect("process");
    assert!(status.success());
    let records = drogue_vision::testing::read_json_lines(&out);
    assert_eq!(records.len(), expected.len());
    assert!(records.iter().all(|r| r["detected"] == true));

    // `review` counts no frame lost for the full frames the mode leaves out.
    let review = Command::new(BIN)
        .arg("review")
        .arg(&log)
        .arg("--out")
        .arg(dir.path().join("review"))
        .output()
        .expect("review");
    assert!(review.status.success());
    let text = String::from_utf8_lossy(&review.stdout);
    let line = format!(
        "frames     {} logged (crop mode: full frames every {EVERY}th, crops on /camera/crop), 0 lost",
        expected.len()
    );
    assert!(text.contains(&line), "{text}");
}

#[test]
fn jpeg_mode_logs_every_frame_as_a_jpeg_close_to_the_rendered_frame() {
    const FRAMES: u32 = 30;
    let dir = tempfile::tempdir().expect("tmp");
    let bytes = run_log(
        dir.path(),
        "image_encoding = \"jpeg\"\njpeg_quality = 90",
        FRAMES,
        14_612,
    );
    let topics = by_topic(&bytes);
    assert!(!topics.contains_key("/camera/crop"));
    let images = &topics["/camera/image"];
    assert_eq!(images.len(), FRAMES as usize);
    // The simulator renders the same frames again (deterministic, seed 1).
    let mut sim = Simulator::new(Scenario::builtin("approach").expect("scenario")).expect("sim");
    for (seq, schema, data) in images {
        assert_eq!(schema, "foxglove.CompressedImage");
        let c = CompressedImage::decode(data.as_slice()).expect("image");
        assert_eq!(c.format, "jpeg");
        let decoded = gray(&c, image::ImageFormat::Jpeg);
        let (rendered, _) = sim.next().expect("frame");
        assert_eq!(decoded.dimensions(), rendered.dimensions());
        // Lossy but close: PSNR over 30 dB, and under a tenth of raw.
        let mse = decoded
            .as_raw()
            .iter()
            .zip(rendered.as_raw())
            .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
            .sum::<f64>()
            / decoded.as_raw().len() as f64;
        let psnr = 10.0 * (255.0f64 * 255.0 / mse.max(1e-9)).log10();
        assert!(psnr > 30.0, "frame {seq}: PSNR {psnr:.1} dB");
        assert!(
            decoded != rendered,
            "frame {seq}: JPEG should not be lossless"
        );
        assert!(
            c.data.len() * 5 < rendered.as_raw().len(),
            "frame {seq}: {} bytes",
            c.data.len()
        );
    }
}
