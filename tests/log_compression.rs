//! Compressed logs: every chunk compression the writer offers (zstd, lz4,
//! none) round-trips through every reader we have (the `mcap` crate's
//! validating reader, replay, review, recover), and recover never loses or
//! launders data: a zstd log cut at 20 random offsets keeps every complete
//! chunk's messages, flipped bytes are reported, a non-MCAP file gives an
//! error and no output.
//!
//! What a cut file must still hold is counted independently of `recover`:
//! the chunk boundaries come from the complete file's own chunk index (the
//! `mcap` crate's summary reader), and a chunk is complete in a cut file when
//! it ends before the cut.

mod log_support;

use drogue_vision::log::recover::{self, RECOVER_METADATA};
use drogue_vision::log::{ChunkCompression, FlightLog, LogConfig, LogError, metadata, reader};
use drogue_vision::source::replay;
use log_support as s;
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};

const FRAMES: u64 = 24;

/// Writes FRAMES frames with everything derived; small chunks so a cut
/// falls between many of them.
fn write_log(dir: &Path, cfg: &LogConfig) -> PathBuf {
    let log = FlightLog::start(cfg, dir, &s::camera()).unwrap();
    log.metadata(
        "test.meta",
        [("k".to_string(), "v".to_string())].into_iter().collect(),
    );
    for seq in 0..FRAMES {
        s::log_frame(&log, seq, true);
        log.mavlink(s::link_event(seq, true));
    }
    let summary = log.finish().unwrap();
    assert_eq!(summary.dropped_queue_full, 0);
    summary.files[0].clone()
}

fn config(compression: ChunkCompression) -> LogConfig {
    let mut cfg = s::config();
    cfg.compression = compression;
    cfg.chunk_size_kib = 256;
    cfg
}

/// (topic, sequence, log time) of every message the crate's validating
/// reader reads, and whether it stopped on an error.
fn read_all(path: &Path) -> (Vec<(String, u32, u64)>, bool) {
    let mut out = Vec::new();
    for m in reader::message_reader(path).unwrap() {
        match m {
            Ok(m) => out.push((m.channel.topic.clone(), m.sequence, m.log_time)),
            Err(_) => return (out, true),
        }
    }
    (out, false)
}

#[test]
fn every_compression_round_trips_through_every_reader() {
    for compression in [
        ChunkCompression::Zstd,
        ChunkCompression::Lz4,
        ChunkCompression::None,
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = write_log(dir.path(), &config(compression));
        let bytes = std::fs::read(&path).unwrap();
        // The chunks carry the codec asked for (the crate's summary reader).
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let want = match compression {
            ChunkCompression::Zstd => "zstd",
            ChunkCompression::Lz4 => "lz4",
            ChunkCompression::None => "",
        };
        assert!(summary.chunk_indexes.len() > 1, "{compression:?}");
        for c in &summary.chunk_indexes {
            assert_eq!(c.compression, want, "{compression:?}");
        }
        let (messages, failed) = read_all(&path);
        assert!(!failed, "{compression:?}");
        assert_eq!(
            messages.len() as u64,
            summary.stats.as_ref().unwrap().message_count
        );

        // Replay: every frame, pixel for pixel.
        let frames: Vec<_> = replay::open(&path).unwrap().map(|f| f.unwrap()).collect();
        assert_eq!(frames.len() as u64, FRAMES);
        for f in &frames {
            assert_eq!(f.image, s::image(f.seq, s::WIDTH, s::HEIGHT));
        }

        // Review: complete, not cut, not damaged; the metadata is read.
        let review = drogue_vision::log::review::review(&path, &dir.path().join("rev")).unwrap();
        assert_eq!(review.cut, None, "{compression:?}");
        assert_eq!(review.damaged, None, "{compression:?}");
        assert_eq!(review.frames, FRAMES);
        assert!(review.metadata.iter().any(|(n, _)| n == "test.meta"));

        // Recover of a complete file: the same messages, nothing reported.
        let out = dir.path().join("copy.mcap");
        let r = recover::recover(&path, &out).unwrap();
        assert_eq!((r.cut.as_deref(), r.damaged.len()), (None, 0), "{r}");
        assert_eq!(read_all(&out), (messages, false));
        assert!(
            metadata::read_metadata(&out)
                .unwrap()
                .iter()
                .any(|(n, _)| n == "test.meta")
        );
    }
}

#[test]
fn a_zstd_log_cut_at_20_random_offsets_keeps_every_complete_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_log(dir.path(), &config(ChunkCompression::Zstd));
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let (all, _) = read_all(&path);
    // Messages per chunk, in file order, from the index (the crate's reader).
    let mut chunks: Vec<(u64, u64, usize)> = Vec::new();
    for c in &summary.chunk_indexes {
        let n = summary.stream_chunk(&bytes, c).unwrap().count();
        chunks.push((
            c.chunk_start_offset,
            c.chunk_start_offset + c.chunk_length,
            n,
        ));
    }
    chunks.sort_unstable();
    let data_end = chunks.last().unwrap().1;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
    for _ in 0..20 {
        let cut = rng.random_range(8..data_end + 20);
        let cut_path = dir.path().join("cut.mcap");
        std::fs::write(&cut_path, &bytes[..cut as usize]).unwrap();
        let complete: usize = chunks
            .iter()
            .filter(|(_, end, _)| *end <= cut)
            .map(|c| c.2)
            .sum();
        let out = dir.path().join("fixed.mcap");
        let _ = std::fs::remove_file(&out);
        let r = recover::recover(&cut_path, &out).unwrap();
        assert!(r.cut.is_some(), "cut at {cut}: {r}");
        assert!(r.damaged.is_empty(), "cut at {cut}: {r}");
        let (got, failed) = read_all(&out);
        assert!(!failed);
        assert!(
            got.len() >= complete,
            "cut at {cut}: {} messages recovered, {complete} in complete chunks",
            got.len()
        );
        // What it recovered is exactly the start of the original, in order.
        assert_eq!(got[..], all[..got.len()], "cut at {cut}");
        assert!(reader::is_complete(&out).unwrap());
    }
}

#[test]
fn flipped_bytes_are_reported_and_the_rest_salvaged_not_laundered() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_log(dir.path(), &config(ChunkCompression::None));
    let mut bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let (all, _) = read_all(&path);
    // Flip bytes inside the data of the third chunk (past its header).
    let mut idx: Vec<_> = summary.chunk_indexes.clone();
    idx.sort_by_key(|c| c.chunk_start_offset);
    let target = &idx[2];
    let start = (target.chunk_start_offset + 9 + 60) as usize;
    let n_in_chunk = summary.stream_chunk(&bytes, target).unwrap().count();
    for i in 0..300 {
        bytes[start + 1000 + i * 97] ^= 0x5a;
    }
    let bad = dir.path().join("flipped.mcap");
    std::fs::write(&bad, &bytes).unwrap();

    // The validating reader stops at the damage; review says DAMAGED, not cut.
    let (_, failed) = read_all(&bad);
    assert!(failed);
    let review = drogue_vision::log::review::review(&bad, &dir.path().join("rev")).unwrap();
    assert!(review.damaged.is_some() && review.cut.is_none());
    assert!(review.to_string().contains("DAMAGED"));

    // Recover: the damaged chunk is reported and recorded in the copy, every
    // other chunk's messages are all there.
    let out = dir.path().join("fixed.mcap");
    let r = recover::recover(&bad, &out).unwrap();
    assert_eq!(r.damaged.len(), 1, "{r}");
    let d = &r.damaged[0];
    assert_eq!(d.offset, target.chunk_start_offset);
    assert_eq!(d.salvaged + d.dropped.unwrap(), n_in_chunk as u64, "{r}");
    let (got, failed) = read_all(&out);
    assert!(!failed);
    assert_eq!(got.len() as u64, all.len() as u64 - d.dropped.unwrap());
    let meta = metadata::read_metadata(&out).unwrap();
    let rec = meta
        .iter()
        .find(|(n, _)| n == RECOVER_METADATA)
        .expect("the damage is recorded in the copy");
    assert!(rec.1["report"].contains("DAMAGED chunk"), "{:?}", rec.1);
    // And review of the copy prints it.
    let review = drogue_vision::log::review::review(&out, &dir.path().join("rev2")).unwrap();
    assert!(review.to_string().contains(RECOVER_METADATA));
}

#[test]
fn a_damaged_zstd_chunk_costs_only_that_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_log(dir.path(), &config(ChunkCompression::Zstd));
    let mut bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let (all, _) = read_all(&path);
    let mut idx: Vec<_> = summary.chunk_indexes.clone();
    idx.sort_by_key(|c| c.chunk_start_offset);
    let target = &idx[1];
    let n_in_chunk = summary.stream_chunk(&bytes, target).unwrap().count();
    let mid = (target.chunk_start_offset + target.chunk_length / 2) as usize;
    for b in &mut bytes[mid..mid + 300] {
        *b ^= 0xa5;
    }
    let bad = dir.path().join("flipped.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    let out = dir.path().join("fixed.mcap");
    let r = recover::recover(&bad, &out).unwrap();
    assert_eq!(r.damaged.len(), 1, "{r}");
    assert_eq!(r.damaged[0].offset, target.chunk_start_offset);
    let (got, failed) = read_all(&out);
    assert!(!failed);
    assert!(got.len() >= all.len() - n_in_chunk, "{r}");
    assert!(r.to_string().contains("DAMAGED"));
}

#[test]
fn recover_of_a_non_mcap_file_fails_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("notes.mcap");
    std::fs::write(&input, b"this is not an MCAP file at all, just text\n").unwrap();
    let out = dir.path().join("out.mcap");
    let e = recover::recover(&input, &out).unwrap_err();
    assert!(matches!(e, LogError::Format { .. }), "{e}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(left.len(), 1, "only the input is left: {left:?}");

    // The binary: non-zero exit, no output.
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_drogue-vision"))
        .args(["recover"])
        .arg(&input)
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(!status.success());
    assert!(!out.exists());
}

#[test]
fn recover_never_overwrites_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_log(dir.path(), &config(ChunkCompression::Zstd));
    let before = std::fs::read(&path).unwrap();
    let e = recover::recover(&path, &path).unwrap_err();
    assert!(matches!(e, LogError::Config(_)), "{e}");
    // Through another name for the same file, too.
    let alias = dir.path().join("sub/../").join(path.file_name().unwrap());
    std::fs::create_dir_all(dir.path().join("sub")).unwrap();
    assert!(recover::recover(&path, &alias).is_err());
    assert_eq!(std::fs::read(&path).unwrap(), before);
}

#[test]
fn review_leaves_no_folder_behind_when_it_fails() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("junk.mcap");
    std::fs::write(&input, b"junk").unwrap();
    let out = dir.path().join("rev");
    assert!(drogue_vision::log::review::review(&input, &out).is_err());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(left.len(), 1, "{left:?}");
}
