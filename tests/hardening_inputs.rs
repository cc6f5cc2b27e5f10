//! Hostile input from files and the command line (issue 16): each of the
//! issue's reproducers is now refused with exit status 2 naming the file, the
//! key and the allowed range, or read as the unreadable frame it is; image
//! bombs and a lying MCAP stay within 64 MB of peak memory (measured by the
//! kernel, wait4's ru_maxrss of the child); a sample of random configs runs
//! the binary to exit 0 or 2 in bounded time.

use drogue_vision::testing::read_json_lines;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

/// How a child process ended.
struct Outcome {
    code: Option<i32>,
    stderr: String,
    max_rss_kib: i64,
}

/// Runs the binary with `args`, killed after `limit`; its exit status,
/// stderr and peak resident memory (the kernel's, for this child only).
/// The child is reaped by `wait4` (for its rusage), not by `Child::wait`.
#[allow(clippy::zombie_processes)]
fn run(args: &[&str], cwd: &Path, limit: Duration) -> Outcome {
    let stderr_path = cwd.join(format!("stderr-{}.txt", std::process::id()));
    let child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr_path).unwrap())
        .spawn()
        .unwrap();
    let pid = child.id() as libc::pid_t;
    let started = Instant::now();
    let mut status = 0;
    // SAFETY: a zeroed rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: pid is our own child, the pointers are to live locals.
        let r = unsafe { libc::wait4(pid, &raw mut status, libc::WNOHANG, &raw mut usage) };
        if r == pid {
            break;
        }
        assert!(r == 0, "wait4 failed");
        if started.elapsed() > limit {
            // SAFETY: signalling our own child.
            unsafe { libc::kill(pid, libc::SIGKILL) };
            // SAFETY: as above; reaps it.
            unsafe { libc::wait4(pid, &raw mut status, 0, &raw mut usage) };
            panic!("{args:?} still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    let _ = std::fs::remove_file(&stderr_path);
    Outcome {
        code,
        stderr,
        max_rss_kib: usage.ru_maxrss,
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Exit 2, and stderr names every one of `words`.
fn assert_refused(o: &Outcome, words: &[&str]) {
    assert_eq!(o.code, Some(2), "stderr: {}", o.stderr);
    for w in words {
        assert!(o.stderr.contains(w), "{w:?} not in: {}", o.stderr);
    }
}

const SHORT: Duration = Duration::from_secs(60);

#[test]
fn config_reproducers_exit_2_naming_file_key_and_range() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: [(&str, &[&str], &[&str]); 7] = [
        (
            "[link]\nmax_rate_hz = 1e-300\n",
            &["run"],
            &["[link] max_rate_hz", "0 or [0.1, 10000]"],
        ),
        (
            "[run]\nvehicle_pose_timeout_s = 1e300\n",
            &["run", "--vehicle-pose", "mavlink"],
            &["[run] vehicle_pose_timeout_s", "(0, 86400]"],
        ),
        (
            "[log]\nretry_after_error_s = 9223372036854775807\n",
            &["run"],
            &["[log] retry_after_error_s", "[1, 86400]"],
        ),
        (
            "[fit]\nadaptive_subsets = 0\n",
            &["run"],
            &["[fit] adaptive_subsets", "[1, 1000]"],
        ),
        (
            "[fit]\nadaptive_confidence = nan\n",
            &["run"],
            &["[fit] adaptive_confidence", "(0, 1)"],
        ),
        (
            "[detect]\nthreshold_fractions = []\n",
            &["run"],
            &["threshold_fractions", "1 to 16"],
        ),
        (
            "[detect]\nmax_candidates = 0\n",
            &["run"],
            &["[detect] max_candidates", "[1, 100]"],
        ),
    ];
    for (text, command, words) in cases {
        let cfg = write(d, "r.toml", text);
        let cfg = cfg.to_str().unwrap();
        let mut args = command.to_vec();
        args.extend(["--config", cfg, "--max-frames", "2", "--log-dir", "logs"]);
        let o = run(&args, d, SHORT);
        let mut all = words.to_vec();
        all.push(cfg);
        assert_refused(&o, &all);
    }
}

#[test]
fn scenario_reproducers_exit_2_naming_file_key_and_range() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: [(&str, &[&str]); 5] = [
        (
            "[drogue]\nstruts = 4294967295\n",
            &["drogue.struts", "[0, 64]"],
        ),
        (
            "[drogue]\ntrail_offset_m = [1e300, 0.0, 0.0]\n",
            &["drogue.trail_offset_m", "[-1000, 1000]"],
        ),
        ("[tanker]\naltitude_m = nan\n", &["tanker.altitude_m"]),
        ("[tanker]\nheading_deg = nan\n", &["tanker.heading_deg"]),
        (
            "[mount]\npitch_deg = nan\n",
            &["mount.pitch_deg", "[-360, 360]"],
        ),
    ];
    for (text, words) in cases {
        let s = write(d, "s.toml", text);
        let s = s.to_str().unwrap();
        let o = run(
            &["sim", "--scenario", s, "--out", "out", "--frames", "2"],
            d,
            SHORT,
        );
        let mut all = words.to_vec();
        all.push(s);
        assert_refused(&o, &all);
    }
}

/// A camera file for `process`.
fn camera_yaml(w: u32, h: u32, d0: &str) -> String {
    format!(
        "image_width: {w}\nimage_height: {h}\ncamera_name: t\ncamera_matrix:\n  rows: 3\n  cols: 3\n  \
         data: [500.0, 0.0, {cx}, 0.0, 500.0, {cy}, 0.0, 0.0, 1.0]\ndistortion_model: plumb_bob\n\
         distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [{d0}, 0.0, 0.0, 0.0, 0.0]\n",
        cx = w / 2,
        cy = h / 2
    )
}

#[test]
fn a_camera_file_with_absurd_distortion_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("frames")).unwrap();
    write(d, "cam.yaml", &camera_yaml(64, 48, "1.0e300"));
    let o = run(
        &[
            "process", "frames", "--camera", "cam.yaml", "--out", "o.jsonl",
        ],
        d,
        SHORT,
    );
    assert_refused(
        &o,
        &["cam.yaml", "distortion_coefficients.data[0]", "[-100, 100]"],
    );
}

/// The simulator's first frame, as a JPEG, with its camera file.
fn sim_frame(d: &Path) -> image::GrayImage {
    let o = run(
        &[
            "sim",
            "--scenario",
            "approach",
            "--out",
            "sim",
            "--frames",
            "1",
        ],
        d,
        SHORT,
    );
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let png = std::fs::read_dir(d.join("sim"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "png"))
        .unwrap();
    image::open(png).unwrap().into_luma8()
}

/// A JPEG cut short is an unreadable frame (an error record), while the
/// whole JPEG of the same frame is detected.
#[test]
fn a_truncated_jpeg_is_an_unreadable_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let frame = sim_frame(d);
    std::fs::create_dir(d.join("jpg")).unwrap();
    let mut jpeg = std::io::Cursor::new(Vec::new());
    frame.write_to(&mut jpeg, image::ImageFormat::Jpeg).unwrap();
    let jpeg = jpeg.into_inner();
    std::fs::write(d.join("jpg/a_whole.jpg"), &jpeg).unwrap();
    std::fs::write(d.join("jpg/b_cut.jpg"), &jpeg[..jpeg.len() * 3 / 5]).unwrap();
    let o = run(
        &[
            "process",
            "jpg",
            "--camera",
            "sim/camera.yaml",
            "--out",
            "o.jsonl",
            "--independent",
        ],
        d,
        SHORT,
    );
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let r = read_json_lines(&d.join("o.jsonl"));
    assert_eq!(r.len(), 2);
    assert!(r[0]["detected"].as_bool().unwrap_or(false), "{}", r[0]);
    let e = r[1]["error"].as_str().unwrap_or_default();
    assert!(e.contains("ends early"), "{}", r[1]);
}

/// A frame of another size than the camera file's, after one of the right
/// size, is unreadable, refused from its header. (When the first frame is
/// of another size the calibration is wrong: exit 2, `tests/run_calibration.rs`.)
#[test]
fn a_frame_of_the_wrong_size_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("frames")).unwrap();
    image::GrayImage::new(64, 48)
        .save(d.join("frames/0.png"))
        .unwrap();
    image::GrayImage::new(80, 60)
        .save(d.join("frames/a.png"))
        .unwrap();
    write(d, "cam.yaml", &camera_yaml(64, 48, "0.0"));
    let o = run(
        &[
            "process", "frames", "--camera", "cam.yaml", "--out", "o.jsonl",
        ],
        d,
        SHORT,
    );
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let r = read_json_lines(&d.join("o.jsonl"));
    let e = r[1]["error"].as_str().unwrap_or_default();
    assert!(e.contains("80x60") && e.contains("64x48"), "{}", r[1]);
}

/// A valid 20000 x 20000 gray PNG of a few hundred KB (zeros compress).
fn png_bomb(path: &Path) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = png::Encoder::new(file, 20_000, 20_000);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header().unwrap();
    let mut s = w.stream_writer().unwrap();
    let row = vec![0u8; 20_000];
    for _ in 0..20_000 {
        s.write_all(&row).unwrap();
    }
    s.finish().unwrap();
}

/// The largest peak memory the bombs may cost `process`, KiB (64 MB).
const PEAK_LIMIT_KIB: i64 = 64 * 1000;

#[test]
fn image_bombs_and_a_lying_mcap_stay_under_64_mb() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("bomb")).unwrap();
    // A frame of the right size first (a first frame of another size is a
    // wrong calibration: exit 2 before anything else is read).
    image::GrayImage::new(1280, 960)
        .save(d.join("bomb/0.png"))
        .unwrap();
    png_bomb(&d.join("bomb/bomb.png"));
    assert!(std::fs::metadata(d.join("bomb/bomb.png")).unwrap().len() < 5 << 20);
    write(d, "cam.yaml", &camera_yaml(1280, 960, "0.0"));
    // With the camera's size known: refused from the header.
    let o = run(
        &[
            "process", "bomb", "--camera", "cam.yaml", "--out", "o.jsonl",
        ],
        d,
        SHORT,
    );
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let r = read_json_lines(&d.join("o.jsonl"));
    let e = r[1]["error"].as_str().unwrap_or_default();
    assert!(e.contains("20000"), "{e}");
    println!("png bomb: peak {} KiB", o.max_rss_kib);
    assert!(o.max_rss_kib < PEAK_LIMIT_KIB, "{} KiB", o.max_rss_kib);

    // 109 bytes: the MCAP magic, a header, and a message record claiming
    // 400 MiB.
    let mut lying = Vec::new();
    lying.extend_from_slice(b"\x89MCAP0\r\n");
    lying.push(0x01); // Header
    lying.extend_from_slice(&8u64.to_le_bytes());
    lying.extend_from_slice(&0u32.to_le_bytes()); // profile ""
    lying.extend_from_slice(&0u32.to_le_bytes()); // library ""
    lying.push(0x05); // Message
    lying.extend_from_slice(&(400u64 << 20).to_le_bytes());
    lying.resize(109, 0xAB);
    std::fs::write(d.join("lying.mcap"), &lying).unwrap();
    for args in [
        &["process", "lying.mcap", "--out", "o2.jsonl"][..],
        &[
            "process",
            "lying.mcap",
            "--camera",
            "cam.yaml",
            "--out",
            "o3.jsonl",
        ][..],
        &["recover", "lying.mcap", "--out", "fixed.mcap"][..],
    ] {
        let o = run(args, d, SHORT);
        println!(
            "lying mcap {args:?}: exit {:?}, peak {} KiB",
            o.code, o.max_rss_kib
        );
        assert!(matches!(o.code, Some(0..=2)), "{}", o.stderr);
        assert!(o.max_rss_kib < PEAK_LIMIT_KIB, "{} KiB", o.max_rss_kib);
    }
}

/// A log of 64x48 raw frames with sequence numbers 1, 2, 4, 5 (and a
/// calibration first), unchunked so each message is a top-level record; with
/// `big` > 0, a `/camera/image` message of `big` bytes (sequence 3) between
/// frames 2 and 4. Returns the number of messages written.
fn log_with_a_big_record(path: &Path, big: usize) -> u64 {
    use drogue_vision::frame::{Frame, FrameOrigin};
    use drogue_vision::log::{ImageEncoding, png_gray::GrayPngEncoder, topics};
    let k = nalgebra::Matrix3::new(60.0, 0.0, 32.0, 0.0, 60.0, 24.0, 0.0, 0.0, 1.0);
    let camera = drogue_vision::camera::CameraModel::new("t", 64, 48, k, [0.0; 5]).unwrap();
    let options = mcap::WriteOptions::new().use_chunks(false);
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut w = mcap::Writer::with_options(file, options).unwrap();
    let mut channel = |topic: &str| {
        let spec = topics::channel_spec(topic, ImageEncoding::Raw).unwrap();
        let schema = &spec.schema;
        let s = w
            .add_schema(&schema.name, &schema.encoding, &schema.data)
            .unwrap();
        w.add_channel(s, topic, spec.message_encoding, &Default::default())
            .unwrap()
    };
    let (cal, img) = (channel(topics::CALIBRATION), channel(topics::IMAGE));
    let header = |channel_id, sequence: u32| mcap::records::MessageHeader {
        channel_id,
        sequence,
        log_time: u64::from(sequence) * 1_000_000,
        publish_time: u64::from(sequence) * 1_000_000,
    };
    let mut buf = Vec::new();
    topics::encode(&topics::calibration(&camera, 0), &mut buf).unwrap();
    w.write_to_known_channel(&header(cal, 0), &buf).unwrap();
    let mut n = 1;
    for seq in [1u32, 2, 3, 4, 5] {
        if seq == 3 {
            if big > 0 {
                w.write_to_known_channel(&header(img, 3), &vec![0u8; big])
                    .unwrap();
                n += 1;
            }
            continue;
        }
        let frame = Frame {
            seq: u64::from(seq),
            capture_time_ns: u64::from(seq) * 1_000_000,
            image: image::GrayImage::from_pixel(64, 48, image::Luma([seq as u8 * 40])),
            origin: FrameOrigin::File(PathBuf::new()),
        };
        topics::image(
            &frame,
            ImageEncoding::Raw,
            75,
            &mut GrayPngEncoder::default(),
            &mut buf,
        )
        .unwrap();
        w.write_to_known_channel(&header(img, seq), &buf).unwrap();
        n += 1;
    }
    w.finish().unwrap();
    n
}

/// A record above the 32 MiB bound between good ones is skipped unread and
/// counted: the frames before and after it are all read (replay, `process`,
/// `recover`), and reading the log costs no more peak memory than the same
/// log without it (far less than the record).
#[test]
fn an_oversized_mcap_record_is_skipped_and_counted() {
    use drogue_vision::log::recover;
    use drogue_vision::source::replay;
    const BIG: usize = 48 << 20;
    const { assert!(BIG > drogue_vision::log::oversized::RECORD_LIMIT_BYTES) };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let written = log_with_a_big_record(&d.join("big.mcap"), BIG);
    let written_small = log_with_a_big_record(&d.join("small.mcap"), 0);
    assert_eq!((written, written_small), (6, 5));
    assert!(std::fs::metadata(d.join("big.mcap")).unwrap().len() > BIG as u64);

    // Replay: every frame but the oversized one, in order, and no error.
    let mut reader = replay::open(&d.join("big.mcap")).unwrap();
    let seqs: Vec<u64> = reader.by_ref().map(|f| f.unwrap().seq).collect();
    assert_eq!(seqs, [1, 2, 4, 5]);
    assert_eq!(reader.oversized_skipped(), 1);
    let cam = replay::ReplayReader::first_camera(&d.join("big.mcap")).unwrap();
    assert_eq!((cam.width, cam.height), (64, 48));

    // Recover: the 5 good messages copied, the skip counted and reported.
    let report = recover::recover(&d.join("big.mcap"), &d.join("rec.mcap")).unwrap();
    assert_eq!(report.oversized_records, 1, "{report}");
    assert_eq!(report.messages, 5, "{report}");
    assert!(
        report.to_string().contains("1 records above the 32 MiB"),
        "{report}"
    );
    let seqs: Vec<u64> = replay::open(&d.join("rec.mcap"))
        .unwrap()
        .map(|f| f.unwrap().seq)
        .collect();
    assert_eq!(seqs, [1, 2, 4, 5]);

    // Through the binary: the same frames, the count in the warning, and
    // the peak memory of the log without the record, within a quarter of
    // the record's size (reading it would cost all of it).
    let base = run(&["process", "small.mcap", "--out", "s.jsonl"], d, SHORT);
    assert_eq!(base.code, Some(0), "{}", base.stderr);
    let o = run(&["process", "big.mcap", "--out", "b.jsonl"], d, SHORT);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let frames: Vec<String> = read_json_lines(&d.join("b.jsonl"))
        .iter()
        .map(|r| r["frame"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(frames, ["1", "2", "4", "5"]);
    // The record's body: the data and the message header (channel id 2,
    // sequence 4, log and publish times 8 + 8 bytes, per the MCAP spec).
    let warning = format!(
        "1 MCAP record(s) ({} bytes) above the 32 MiB record bound skipped in all",
        BIG + 22
    );
    assert!(o.stderr.contains(&warning), "{}", o.stderr);
    let rec = run(&["recover", "big.mcap", "--out", "rec2.mcap"], d, SHORT);
    assert_eq!(rec.code, Some(0), "{}", rec.stderr);
    println!(
        "oversized record: process peak {} KiB (without it {} KiB), recover peak {} KiB",
        o.max_rss_kib, base.max_rss_kib, rec.max_rss_kib
    );
    let margin = (BIG / 4 / 1024) as i64;
    assert!(
        o.max_rss_kib < base.max_rss_kib + margin,
        "{} KiB",
        o.max_rss_kib
    );
    assert!(rec.max_rss_kib < PEAK_LIMIT_KIB, "{} KiB", rec.max_rss_kib);
    assert!(o.max_rss_kib < PEAK_LIMIT_KIB, "{} KiB", o.max_rss_kib);
}

/// Random values for random numbers of the config, through the binary: exit
/// 0 or 2, each within a bounded time (the in-process property tests in
/// `config.rs` cover every key with many more values).
#[test]
fn random_configs_through_the_binary_exit_0_or_2() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(16);
    let numbers: Vec<(&str, f64)> = drogue_vision::config::RANGES
        .iter()
        .map(|(k, r)| (*k, r.hi))
        .collect();
    let specials = [f64::NAN, f64::INFINITY, -1.0, 0.0, 1e300, 1e-300];
    for i in 0..6 {
        let (key, hi) = numbers[rng.random_range(0..numbers.len())];
        let x = if i % 2 == 0 {
            specials[rng.random_range(0..specials.len())]
        } else {
            rng.random_range(0.0..=hi.min(1e6))
        };
        let (section, name) = key.split_once('.').unwrap();
        let default = drogue_vision::config::DEFAULT_TOML
            .parse::<toml::Table>()
            .unwrap();
        let value = toml::Value::Float(x).to_string();
        let value = match default[section][name].as_array() {
            Some(a) => format!("[{}]", vec![value; a.len()].join(", ")),
            None => value,
        };
        let text = format!("[{section}]\n{name} = {value}\n");
        write(d, "r.toml", &text);
        let o = run(
            &[
                "run",
                "--config",
                "r.toml",
                "--max-frames",
                "3",
                "--fast",
                "--log-dir",
                "logs",
            ],
            d,
            SHORT,
        );
        assert!(
            matches!(o.code, Some(0 | 2)),
            "{text}: exit {:?}: {}",
            o.code,
            o.stderr
        );
    }
}
