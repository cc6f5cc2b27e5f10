//! Inputs the cargo fuzz targets (fuzz/) found crashing, each run through
//! the same code as its target, with the outcome it has now. The inputs are
//! also in the targets' seeds (fuzz/seeds/TARGET/), so the fuzz regression
//! run in CI replays them too; here they run in every `cargo test`, on
//! stable, with overflow checks off as in the release build, so each test
//! checks the outcome, not only the absence of a panic.

use std::path::{Path, PathBuf};

fn seed(target: &str, name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/seeds")
        .join(target)
        .join(name)
}

/// mcap_reader: a message record inside an uncompressed chunk, longer than
/// the chunk's records. The `mcap` crate's reader (0.26) subtracted its
/// length from the chunk's bytes left without a check (an overflow panic
/// under the fuzz build's overflow checks; in release the count wrapped and
/// the bytes after the chunk were read as its records). Now the reading
/// ends with an error naming the problem, and recover copies what the
/// input's records before it hold.
#[test]
fn mcap_a_record_running_past_its_chunk_is_an_error() {
    // The second: the same inside a chunk whose own length runs past the end
    // of the file (the reader streams such a chunk up to the cut).
    for name in [
        "chunk_record_past_end.mcap",
        "chunk_record_past_end_in_cut_chunk.mcap",
    ] {
        a_record_running_past_its_chunk(&seed("mcap_reader", name));
    }
}

fn a_record_running_past_its_chunk(input: &Path) {
    use drogue_vision::log::recover;
    use drogue_vision::source::replay;
    let items: Vec<_> = replay::open(input).unwrap().collect();
    let last = items.last().expect("an error at least");
    let Err(e) = last else {
        panic!("the reading ends with an error");
    };
    assert!(
        e.to_string()
            .contains("runs past the end of the chunk's records"),
        "{}: {e}",
        input.display()
    );
    let dir = tempfile::tempdir().unwrap();
    // Whatever recover decides (a copy or a refusal), it decides it cleanly.
    let _ = recover::recover(input, &dir.path().join("out.mcap"));
}

/// image_measure (found after 805,075 executions of its campaign): a frame
/// on which a candidate's rim is projected from a pose far off, so that the
/// rim search's sample count did not fit a usize (`rim::profile`, and the
/// count the canopy check expects): an overflow panic under the fuzz build's
/// overflow checks, an empty profile where it wrapped. Counts now saturate
/// (`measure::detect::rim` unit test for the outcome); here the frame runs
/// through the target's code and is measured.
#[test]
fn image_a_rim_range_too_long_to_count_is_measured() {
    use drogue_vision::camera::CameraModel;
    use drogue_vision::config::Config;
    use drogue_vision::frame::{Frame, FrameOrigin};
    use drogue_vision::image_io::decode_gray8;
    use drogue_vision::measure::Measurer;
    let data = std::fs::read(seed("image_measure", "rim_range_overflow.pnm")).unwrap();
    let image = decode_gray8(&data, None, Some((64, 48))).unwrap();
    let k = nalgebra::Matrix3::new(60.0, 0.0, 32.0, 0.0, 60.0, 24.0, 0.0, 0.0, 1.0);
    let camera = CameraModel::new("fuzz", 64, 48, k, [-0.1, 0.01, 0.0, 0.0, 0.0]).unwrap();
    let mut m = Measurer::new(camera, &Config::embedded().measure()).unwrap();
    let frame = Frame {
        seq: 0,
        capture_time_ns: 0,
        image,
        origin: FrameOrigin::File(Default::default()),
    };
    let measurement = m.measure(&frame);
    assert_eq!(measurement.seq, 0);
}

/// mcap_reader (found after 567,798 executions of its campaign): an
/// attachment record whose body ends less than 4 bytes after its header and
/// data length. The `mcap` crate's `parse_record` (0.26) slices it at its
/// length less 4 without a check (a panic in every build). Replay (the
/// frames, the first camera) no longer parses attachments; recover counts
/// such a record as unreadable and copies the rest.
#[test]
fn mcap_an_attachment_without_room_for_its_crc() {
    use drogue_vision::log::recover;
    use drogue_vision::source::replay;
    let input = seed("mcap_reader", "attachment_without_crc.mcap");
    let frames: Vec<_> = replay::open(&input).unwrap().collect();
    let _ = replay::ReplayReader::first_camera(&input);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.mcap");
    match recover::recover(&input, &out) {
        Ok(report) => {
            assert!(report.unreadable_records >= 1, "{report}");
            let copied = replay::open(&out).unwrap().flatten().count();
            let read = frames.iter().filter(|f| f.is_ok()).count();
            assert!(copied >= read, "{copied} frames copied, {read} read");
        }
        Err(e) => panic!("recover: {e}"),
    }
}
