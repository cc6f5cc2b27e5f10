//! MCAP records above the 32 MiB record bound *inside chunks* (issue 16:
//! "MCAP records larger than a bound are skipped and counted"): replay,
//! `process`, `review` and `recover` skip them without holding them, count
//! them in their summaries, and read every other record of the same chunks.
//!
//! The logs are built here byte by byte from the MCAP specification (record
//! framing, chunk header, CRC-32 of the records, zstd from the `zstd` crate,
//! image and calibration messages from the `foxglove` crate's encoders), not
//! with the project's log writer nor the `mcap` crate's.

use foxglove::Encode;
use foxglove::messages::{CameraCalibration, RawImage};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");
/// Above the bound (32 MiB), by a little.
const BIG: usize = (32 << 20) + 1000;
/// Peak resident memory allowed to the commands reading the log: less than
/// one of its records above the bound (holding one would cost all of it;
/// they run in about 12 MB).
const PEAK_LIMIT_KIB: i64 = 32 * 1024;

// Opcodes (MCAP spec).
const HEADER: u8 = 0x01;
const FOOTER: u8 = 0x02;
const SCHEMA: u8 = 0x03;
const CHANNEL: u8 = 0x04;
const MESSAGE: u8 = 0x05;
const CHUNK: u8 = 0x06;
const DATA_END: u8 = 0x0F;
const MAGIC: &[u8] = b"\x89MCAP0\r\n";

fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![opcode];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

fn string(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

fn schema(id: u16, name: &str) -> Vec<u8> {
    let mut b = id.to_le_bytes().to_vec();
    string(&mut b, name);
    string(&mut b, "protobuf");
    b.extend_from_slice(&0u32.to_le_bytes()); // no schema data
    record(SCHEMA, &b)
}

fn channel(id: u16, schema_id: u16, topic: &str) -> Vec<u8> {
    let mut b = id.to_le_bytes().to_vec();
    b.extend_from_slice(&schema_id.to_le_bytes());
    string(&mut b, topic);
    string(&mut b, "protobuf");
    b.extend_from_slice(&0u32.to_le_bytes()); // empty metadata map
    record(CHANNEL, &b)
}

/// The head (9 bytes) and message header (22 bytes) of a message whose data
/// is `data_len` bytes.
fn message_head(channel_id: u16, seq: u32, data_len: usize) -> Vec<u8> {
    let mut r = vec![MESSAGE];
    r.extend_from_slice(&((22 + data_len) as u64).to_le_bytes());
    r.extend_from_slice(&channel_id.to_le_bytes());
    r.extend_from_slice(&seq.to_le_bytes());
    let t = u64::from(seq) * 1_000_000;
    r.extend_from_slice(&t.to_le_bytes()); // log time
    r.extend_from_slice(&t.to_le_bytes()); // publish time
    r
}

fn message(channel_id: u16, seq: u32, data: &[u8]) -> Vec<u8> {
    let mut r = message_head(channel_id, seq, data.len());
    r.extend_from_slice(data);
    r
}

/// A 64x48 mono8 frame of one grey level, as `foxglove.RawImage`.
fn frame(level: u8) -> Vec<u8> {
    let img = RawImage {
        width: 64,
        height: 48,
        encoding: "mono8".into(),
        step: 64,
        data: vec![level; 64 * 48].into(),
        ..Default::default()
    };
    let mut buf = Vec::new();
    img.encode(&mut buf).unwrap();
    buf
}

fn calibration() -> Vec<u8> {
    let cal = CameraCalibration {
        width: 64,
        height: 48,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: vec![60.0, 0.0, 32.0, 0.0, 60.0, 24.0, 0.0, 0.0, 1.0],
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![
            60.0, 0.0, 32.0, 0.0, 0.0, 60.0, 24.0, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
        ..Default::default()
    };
    let mut buf = Vec::new();
    cal.encode(&mut buf).unwrap();
    buf
}

/// A chunk's records: bytes, and runs of one byte (never held whole, so
/// that this test process stays small: a child's peak memory as wait4
/// reports it starts from its parent's at the spawn).
enum Part {
    Bytes(Vec<u8>),
    Fill(u8, usize),
}

fn for_each_piece(parts: &[Part], mut f: impl FnMut(&[u8])) {
    for p in parts {
        match p {
            Part::Bytes(b) => f(b),
            Part::Fill(v, n) => {
                let piece = [*v; 1 << 16];
                let mut left = *n;
                while left > 0 {
                    let k = left.min(piece.len());
                    f(&piece[..k]);
                    left -= k;
                }
            }
        }
    }
}

/// Writes a chunk record holding `parts` as its records (its uncompressed
/// size and CRC-32 are theirs), uncompressed (`zstd` false) or zstd.
fn write_chunk(out: &mut impl Write, parts: &[Part], zstd: bool) {
    let mut size = 0u64;
    let mut crc = crc32fast::Hasher::new();
    for_each_piece(parts, |b| {
        size += b.len() as u64;
        crc.update(b);
    });
    let compressed = zstd.then(|| {
        let mut e = zstd::stream::Encoder::new(Vec::new(), 3).unwrap();
        for_each_piece(parts, |b| e.write_all(b).unwrap());
        e.finish().unwrap()
    });
    let compression = if zstd { "zstd" } else { "" };
    let data_len = compressed.as_ref().map_or(size, |c| c.len() as u64);
    let mut b = Vec::new();
    b.extend_from_slice(&0u64.to_le_bytes()); // message start time
    b.extend_from_slice(&u64::MAX.to_le_bytes()); // message end time
    b.extend_from_slice(&size.to_le_bytes());
    b.extend_from_slice(&crc.finalize().to_le_bytes());
    string(&mut b, compression);
    b.extend_from_slice(&data_len.to_le_bytes());
    out.write_all(&[CHUNK]).unwrap();
    out.write_all(&(b.len() as u64 + data_len).to_le_bytes())
        .unwrap();
    out.write_all(&b).unwrap();
    match compressed {
        Some(c) => out.write_all(&c).unwrap(),
        None => for_each_piece(parts, |p| out.write_all(p).unwrap()),
    }
}

/// The log: a zstd chunk [schemas, channels, calibration, frames 1, 2 (a
/// message of BIG bytes of data), 3], then an uncompressed chunk [frames
/// 4, 5 (BIG), 6], then the data end and the footer (no summary). Frame n
/// is grey level 10 n. Two records above the bound, both in chunks.
fn log_with_big_records_in_chunks(path: &Path) {
    let (cal, img) = (1u16, 2u16);
    let mut head = Vec::new();
    head.extend(schema(1, "foxglove.CameraCalibration"));
    head.extend(schema(2, "foxglove.RawImage"));
    head.extend(channel(cal, 1, "/camera/calibration"));
    head.extend(channel(img, 2, "/camera/image"));
    head.extend(message(cal, 0, &calibration()));
    head.extend(message(img, 1, &frame(10)));
    head.extend(message_head(img, 2, BIG));
    let first = [
        Part::Bytes(head),
        Part::Fill(0x5A, BIG),
        Part::Bytes(message(img, 3, &frame(30))),
    ];
    let mut head = message(img, 4, &frame(40));
    head.extend(message_head(img, 5, BIG));
    let second = [
        Part::Bytes(head),
        Part::Fill(0xA5, BIG),
        Part::Bytes(message(img, 6, &frame(60))),
    ];

    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    file.write_all(MAGIC).unwrap();
    let mut header = Vec::new();
    string(&mut header, ""); // profile
    string(&mut header, "hand-built test log"); // library
    file.write_all(&record(HEADER, &header)).unwrap();
    write_chunk(&mut file, &first, true);
    write_chunk(&mut file, &second, false);
    file.write_all(&record(DATA_END, &0u32.to_le_bytes()))
        .unwrap();
    // Footer: no summary (start 0, offset start 0, CRC 0).
    file.write_all(&record(FOOTER, &[0u8; 20])).unwrap();
    file.write_all(MAGIC).unwrap();
    file.flush().unwrap();
}

/// Runs the binary in `cwd`; its exit code, stderr and stdout, and peak
/// resident memory (wait4's rusage of this child).
#[allow(clippy::zombie_processes)]
fn run(args: &[&str], cwd: &Path) -> (Option<i32>, String, String, i64) {
    let out_path = cwd.join("stdout.txt");
    let err_path = cwd.join("stderr.txt");
    let child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .unwrap();
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: a zeroed rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: pid is our own child, the pointers are to live locals; reaps it.
    let r = unsafe { libc::wait4(pid, &raw mut status, 0, &raw mut usage) };
    assert_eq!(r, pid, "wait4");
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    (
        code,
        std::fs::read_to_string(&err_path).unwrap_or_default(),
        std::fs::read_to_string(&out_path).unwrap_or_default(),
        usage.ru_maxrss,
    )
}

fn log_in(dir: &Path) -> PathBuf {
    let path = dir.join("big.mcap");
    log_with_big_records_in_chunks(&path);
    path
}

/// Replay reads frames 1, 3, 4 and 6 (their grey levels), counts the two
/// records skipped, and ends without an error.
#[test]
fn replay_skips_and_counts_records_above_the_bound_in_chunks() {
    use drogue_vision::source::replay;
    let dir = tempfile::tempdir().unwrap();
    let path = log_in(dir.path());
    let mut reader = replay::open(&path).unwrap();
    let frames: Vec<(u64, u8)> = reader
        .by_ref()
        .map(|f| {
            let f = f.unwrap();
            (f.seq, f.image.get_pixel(0, 0)[0])
        })
        .collect();
    assert_eq!(frames, [(1, 10), (3, 30), (4, 40), (6, 60)]);
    assert_eq!(reader.oversized_skipped(), 2);
    assert_eq!(reader.oversized().bytes(), 2 * (22 + BIG as u64));
    let cam = replay::ReplayReader::first_camera(&path).unwrap();
    assert_eq!((cam.width, cam.height), (64, 48));
}

/// `recover` copies the calibration and the four frames, counts the two
/// records in its report (and its summary line), and the copy replays the
/// same frames.
#[test]
fn recover_skips_and_counts_records_above_the_bound_in_chunks() {
    use drogue_vision::log::recover;
    use drogue_vision::source::replay;
    let dir = tempfile::tempdir().unwrap();
    let path = log_in(dir.path());
    let out = dir.path().join("rec.mcap");
    let report = recover::recover(&path, &out).unwrap();
    assert_eq!(report.messages, 5, "{report}");
    assert_eq!(report.oversized_records, 2, "{report}");
    assert!(report.damaged.is_empty(), "{report}");
    assert!(report.cut.is_none(), "{report}");
    assert!(
        report
            .to_string()
            .contains("SKIPPED: 2 records above the 32 MiB record bound"),
        "{report}"
    );
    let seqs: Vec<u64> = replay::open(&out)
        .unwrap()
        .map(|f| f.unwrap().seq)
        .collect();
    assert_eq!(seqs, [1, 3, 4, 6]);
}

/// Through the binary: `process`, `review` and `recover` say how many
/// records they skipped in the summaries they print, read every other
/// frame, and stay below 32 MiB of peak memory (each record is larger).
#[test]
fn the_summaries_count_records_above_the_bound_and_memory_stays_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    log_in(d);

    let (code, err, _, rss) = run(&["process", "big.mcap", "--out", "p.jsonl"], d);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("4 frames")
            && err.contains("2 MCAP records above the 32 MiB record bound skipped unread"),
        "{err}"
    );
    let frames: Vec<String> = std::fs::read_to_string(d.join("p.jsonl"))
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            v["frame"].as_str().unwrap().to_string()
        })
        .collect();
    assert_eq!(frames, ["1", "3", "4", "6"]);
    assert!(rss < PEAK_LIMIT_KIB, "process: peak {rss} KiB");

    let (code, err, out, rss) = run(&["review", "big.mcap", "--out", "rev"], d);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("frames     4 logged"), "{out}");
    let skipped = format!(
        "SKIPPED: 2 MCAP record(s) ({} bytes) above the 32 MiB record bound",
        2 * (22 + BIG)
    );
    assert!(out.contains(&skipped), "{out}");
    assert!(
        !out.contains("DAMAGED") && !out.contains("CUT SHORT"),
        "{out}"
    );
    assert!(rss < PEAK_LIMIT_KIB, "review: peak {rss} KiB");

    let (code, err, _, rss) = run(&["recover", "big.mcap", "--out", "rec.mcap"], d);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("5 messages") && err.contains("SKIPPED: 2 records above the 32 MiB"),
        "{err}"
    );
    assert!(rss < PEAK_LIMIT_KIB, "recover: peak {rss} KiB");
}

/// A log without records above the bound says nothing of them.
#[test]
fn review_of_a_log_without_big_records_says_nothing_of_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut file = MAGIC.to_vec();
    let mut header = Vec::new();
    string(&mut header, "");
    string(&mut header, "hand-built test log");
    file.extend(record(HEADER, &header));
    let mut records = schema(2, "foxglove.RawImage");
    records.extend(channel(2, 2, "/camera/image"));
    records.extend(message(2, 1, &frame(10)));
    write_chunk(&mut file, &[Part::Bytes(records)], false);
    file.extend(record(DATA_END, &0u32.to_le_bytes()));
    file.extend(record(FOOTER, &[0u8; 20]));
    file.extend_from_slice(MAGIC);
    std::fs::write(d.join("small.mcap"), file).unwrap();
    let (code, err, out, _) = run(&["review", "small.mcap", "--out", "rev"], d);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("frames     1 logged"), "{out}");
    assert!(!out.contains("SKIPPED"), "{out}");
}
