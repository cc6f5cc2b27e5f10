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
    use drogue_vision::log::{recover, replay};
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
