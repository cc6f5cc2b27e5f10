//! Round trip: everything handed to the log comes back from the `mcap` crate's
//! own reader, every message of every topic, in order, with its content.

mod log_support;

use drogue_vision::log::{FlightLog, ImageEncoding, LogConfig};
use drogue_vision::source::replay;
use foxglove::Decode;
use foxglove::messages::{
    CameraCalibration, CompressedImage, FrameTransforms, ImageAnnotations, Log, PoseInFrame,
    RawImage,
};
use log_support as s;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tracing_subscriber::layer::SubscriberExt;

const FRAMES: u64 = 12;

/// (topic, log_time, sequence) of every message the writer must produce, in
/// order, for what [`write_log`] sends.
fn expected_messages() -> Vec<(String, u64, u32)> {
    let mut out = Vec::new();
    for seq in 0..FRAMES {
        let t = s::time_ns(seq);
        let sq = seq as u32;
        out.push(("/camera/image".into(), t, sq));
        out.push(("/camera/calibration".into(), t, sq));
        out.push(("/sim/truth".into(), t, sq));
        out.push(("/drogue/annotations".into(), t, sq));
        out.push(("/drogue/detection".into(), t, sq));
        if s::measurement(seq).detection.is_some() {
            out.push(("/drogue/pose".into(), t, sq));
        }
        out.push(("/tf".into(), t, sq));
        out.push(("/mavlink/out".into(), t, 0));
        out.push(("/mavlink/in".into(), s::link_event(seq, false).time_ns, 0));
    }
    out
}

/// Writes FRAMES frames with everything derived, plus one tracing event, and
/// returns the files written.
fn write_log(dir: &Path, cfg: &LogConfig) -> Vec<PathBuf> {
    let log = FlightLog::start(cfg, dir, &s::camera()).unwrap();
    for seq in 0..FRAMES {
        s::log_frame(&log, seq, true);
        log.mavlink(s::link_event(seq, true));
        log.mavlink(s::link_event(seq, false));
    }
    let subscriber = tracing_subscriber::registry().with(log.tracing_layer());
    tracing::subscriber::with_default(subscriber, || {
        tracing::warn!(answer = 42, "a warning for /log");
    });
    let summary = log.finish().unwrap();
    assert_eq!(summary.frames, FRAMES);
    assert_eq!(summary.dropped_queue_full, 0);
    assert_eq!(summary.write_errors, 0);
    summary.files
}

fn check_all_messages(cfg: &LogConfig) {
    let dir = tempfile::tempdir().unwrap();
    let files = write_log(dir.path(), cfg);
    assert_eq!(files.len(), 1);
    let bytes = std::fs::read(&files[0]).unwrap();

    // The summary section exists and counts every message.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let expected = expected_messages();
    let stats = summary.stats.unwrap();
    assert_eq!(stats.message_count, expected.len() as u64 + 1);

    let messages: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let got: Vec<(String, u64, u32)> = messages
        .iter()
        .filter(|m| m.channel.topic != "/log")
        .map(|m| (m.channel.topic.clone(), m.log_time, m.sequence))
        .collect();
    assert_eq!(got, expected);

    let camera = s::camera();
    let mut logs = 0;
    for m in &messages {
        let seq = u64::from(m.sequence);
        let schema = m.channel.schema.as_ref().unwrap();
        let data = m.data.as_ref();
        match m.channel.topic.as_str() {
            "/camera/image" => {
                let want = s::image(seq, s::WIDTH, s::HEIGHT).into_raw();
                match cfg.image_encoding {
                    ImageEncoding::Raw => {
                        assert_eq!(schema.name, "foxglove.RawImage");
                        let img = RawImage::decode(data).unwrap();
                        assert_eq!(
                            (img.width, img.height, img.step),
                            (s::WIDTH, s::HEIGHT, s::WIDTH)
                        );
                        assert_eq!(img.encoding, "mono8");
                        assert_eq!(img.frame_id, "camera");
                        assert_eq!(img.data.as_ref(), want.as_slice());
                    }
                    ImageEncoding::Png => {
                        assert_eq!(schema.name, "foxglove.CompressedImage");
                        let img = CompressedImage::decode(data).unwrap();
                        assert_eq!(img.format, "png");
                        let decoded = image::load_from_memory(&img.data).unwrap().into_luma8();
                        assert_eq!(decoded.into_raw(), want);
                    }
                    // Lossy or decimated: tests/log_modes.rs.
                    other => panic!("this round trip is for lossless frames, not {other:?}"),
                }
            }
            "/camera/calibration" => {
                assert_eq!(schema.name, "foxglove.CameraCalibration");
                let c = CameraCalibration::decode(data).unwrap();
                assert_eq!(c.k, camera.k.transpose().as_slice().to_vec());
                assert_eq!(c.d, camera.distortion.to_vec());
                assert_eq!((c.width, c.height), (s::WIDTH, s::HEIGHT));
            }
            "/sim/truth" => {
                assert_eq!(m.channel.message_encoding, "json");
                // Byte for byte (serde_json's default parser may be 1 ulp off).
                assert_eq!(data, serde_json::to_vec(&s::truth(seq)).unwrap().as_slice());
            }
            "/drogue/annotations" => {
                assert_eq!(schema.name, "foxglove.ImageAnnotations");
                let a = ImageAnnotations::decode(data).unwrap();
                let meas = s::measurement(seq);
                match &meas.detection {
                    Some(d) => {
                        // Rim points (+0.5: Foxglove's origin is the corner).
                        assert_eq!(a.points[0].points.len(), d.rim_points_px.len());
                        assert_eq!(
                            a.points[0].points[3].x,
                            f64::from(d.rim_points_px[3][0]) + 0.5
                        );
                        assert_eq!(a.points[0].outline_colors.len(), d.rim_points_px.len());
                        // The ellipse outline lies on the fitted ellipse once
                        // undistorted.
                        for p in &a.points[1].points {
                            let u = camera.undistort_px([p.x - 0.5, p.y - 0.5]);
                            assert!(d.ellipse_px.distance_px(u[0], u[1]) < 1e-3);
                        }
                        assert_eq!(a.circles.len(), 1);
                    }
                    None => assert!(a.points.is_empty() && a.circles.is_empty()),
                }
                assert_eq!(a.texts.len(), 1);
            }
            "/drogue/detection" => {
                let want = serde_json::to_vec(&s::detection_json(&s::measurement(seq))).unwrap();
                assert_eq!(data, want.as_slice());
            }
            "/drogue/pose" => {
                assert_eq!(schema.name, "foxglove.PoseInFrame");
                let p = PoseInFrame::decode(data).unwrap();
                assert_eq!(p.frame_id, "camera");
                let pose = p.pose.unwrap();
                let pos = pose.position.unwrap();
                let want = s::measurement(seq).detection.unwrap().pose_camera;
                assert_eq!([pos.x, pos.y, pos.z], want.centre_camera_m.to_array());
                // The drogue's z axis (the normal) from the quaternion.
                let q = pose.orientation.unwrap();
                let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    q.w, q.x, q.y, q.z,
                ));
                let z = uq * nalgebra::Vector3::z();
                assert!((z - *want.normal_camera).norm() < 1e-12);
            }
            "/tf" => {
                assert_eq!(schema.name, "foxglove.FrameTransforms");
                let tf = FrameTransforms::decode(data).unwrap();
                let detected = s::measurement(seq).detection.is_some();
                assert_eq!(tf.transforms.len(), if detected { 3 } else { 2 });
                let cam = &tf.transforms[0];
                assert_eq!(
                    (cam.parent_frame_id.as_str(), cam.child_frame_id.as_str()),
                    ("body", "camera")
                );
                let t = cam.translation.unwrap();
                assert_eq!([t.x, t.y, t.z], s::mount().camera_in_body_m);
                let r = cam.rotation.unwrap();
                assert_eq!([r.w, r.x, r.y, r.z], s::mount().q_body_camera);
                let probe = &tf.transforms[1];
                assert_eq!(probe.child_frame_id, "probe");
                let t = probe.translation.unwrap();
                assert_eq!([t.x, t.y, t.z], s::mount().probe_in_body_m);
            }
            "/mavlink/out" | "/mavlink/in" => {
                let e: drogue_vision::link::LinkEvent = serde_json::from_slice(data).unwrap();
                let outgoing = m.channel.topic == "/mavlink/out";
                assert_eq!(e.outgoing, outgoing);
                let i = e.fields["i"].as_u64().unwrap();
                assert_eq!(e, s::link_event(i, outgoing));
                assert_eq!(m.publish_time, e.time_ns);
            }
            "/log" => {
                assert_eq!(schema.name, "foxglove.Log");
                let l = Log::decode(data).unwrap();
                assert_eq!(l.message, "a warning for /log answer=42");
                assert_eq!(l.level, foxglove::messages::log::Level::Warning as i32);
                logs += 1;
            }
            other => panic!("unexpected topic {other}"),
        }
        if schema.encoding == "protobuf" {
            assert!(schema.name.starts_with("foxglove."), "{}", schema.name);
        }
    }
    assert_eq!(logs, 1);

    // Replay gives the very frames back, and the camera.
    let mut reader = replay::open(&files[0]).unwrap();
    for seq in 0..FRAMES {
        let f = reader.next().unwrap().unwrap();
        assert_eq!((f.seq, f.capture_time_ns), (seq, s::time_ns(seq)));
        assert_eq!(f.image, s::image(seq, s::WIDTH, s::HEIGHT));
    }
    assert!(reader.next().is_none());
    let cam = reader.camera().unwrap();
    assert_eq!((cam.k, cam.distortion), (camera.k, camera.distortion));
}

#[test]
fn raw_frames_every_topic_round_trips_in_order() {
    check_all_messages(&s::config());
}

#[test]
fn png_frames_every_topic_round_trips_in_order() {
    let mut cfg = s::config();
    cfg.image_encoding = ImageEncoding::Png;
    check_all_messages(&cfg);
}

#[test]
fn rotation_by_size_splits_into_numbered_complete_files_losing_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = s::config();
    cfg.rotate_size_mib = 2;
    let log = FlightLog::start(&cfg, dir.path(), &s::camera()).unwrap();
    let n = 10;
    for seq in 0..n {
        log.frame(Arc::new(s::frame(seq, false)));
    }
    let summary = log.finish().unwrap();
    // 1.2 MB frames, 2 MiB per file: a new file after every second frame.
    assert_eq!(summary.files.len(), 5, "{:?}", summary.files);
    let mut seqs = Vec::new();
    for (i, f) in summary.files.iter().enumerate() {
        assert!(
            f.to_string_lossy().ends_with(&format!("_{i:03}.mcap")),
            "{f:?}"
        );
        assert!(drogue_vision::log::reader::is_complete(f).unwrap());
        for frame in replay::open(f).unwrap() {
            seqs.push(frame.unwrap().seq);
        }
    }
    assert_eq!(seqs, (0..n).collect::<Vec<_>>());
}

/// A helper, not a check: writes a sample log for
/// `tests/interop/mcap_check.py` by hand, with
/// `DROGUE_LOG_SAMPLE_DIR=DIR cargo test --test log_roundtrip sample -- --ignored`
/// (CI checks the log of a real `run` instead).
#[test]
#[ignore = "a helper that writes a sample log to DROGUE_LOG_SAMPLE_DIR; it checks nothing"]
fn a_sample_log_for_the_interop_check() {
    let dir = std::env::var_os("DROGUE_LOG_SAMPLE_DIR")
        .map(PathBuf::from)
        .expect("DROGUE_LOG_SAMPLE_DIR must name the folder to write the sample log to");
    std::fs::create_dir_all(&dir).unwrap();
    let files = write_log(&dir, &s::config());
    println!("{}", files[0].display());
}

#[test]
fn rotation_by_duration_starts_a_new_numbered_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = s::config();
    cfg.rotate_duration_s = 1;
    let log = FlightLog::start(&cfg, dir.path(), &s::camera()).unwrap();
    log.frame(Arc::new(s::frame(0, false)));
    std::thread::sleep(std::time::Duration::from_millis(1300));
    log.frame(Arc::new(s::frame(1, false)));
    let summary = log.finish().unwrap();
    assert_eq!(summary.files.len(), 2, "{:?}", summary.files);
    for (i, f) in summary.files.iter().enumerate() {
        assert!(drogue_vision::log::reader::is_complete(f).unwrap());
        let seqs: Vec<u64> = replay::open(f).unwrap().map(|r| r.unwrap().seq).collect();
        assert_eq!(seqs, vec![i as u64]);
    }
}

#[test]
fn bad_config_values_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = s::config();
    cfg.sync_interval_ms = 5000;
    let e = FlightLog::start(&cfg, dir.path(), &s::camera())
        .err()
        .unwrap();
    assert!(e.to_string().contains("sync_interval_ms"), "{e}");
    let mut cfg = s::config();
    cfg.file_prefix = "../escape".into();
    assert!(FlightLog::start(&cfg, dir.path(), &s::camera()).is_err());
    // A log folder that cannot be created.
    let file = dir.path().join("a_file");
    std::fs::write(&file, b"x").unwrap();
    assert!(FlightLog::start(&s::config(), &file.join("logs"), &s::camera()).is_err());
}

#[test]
fn a_full_queue_drops_counts_and_reports_without_blocking_the_caller() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = s::config();
    cfg.queue_len = 1;
    let log = FlightLog::start(&cfg, dir.path(), &s::camera()).unwrap();
    let frames: Vec<_> = (0..40).map(|seq| Arc::new(s::frame(seq, false))).collect();
    for f in frames {
        log.frame(f);
    }
    let summary = log.finish().unwrap();
    assert!(summary.dropped_queue_full > 0, "{summary:?}");
    assert_eq!(summary.frames + summary.dropped_queue_full, 40);
    // The drop count is in /log, and review reads it back.
    let r = drogue_vision::log::review::review(&summary.files[0], &dir.path().join("r")).unwrap();
    assert_eq!(r.log_dropped, summary.dropped_queue_full);
    assert_eq!(r.frames, summary.frames);
}
