//! Failed commands as a user meets them (issue 15, item 8): `review`,
//! `recover` and `process` of a missing file, of a folder and of a file that
//! is not an MCAP log exit with status 2 as their `--help` says, name the
//! input in the message (no placeholder such as `(file)`), and leave no file
//! or folder behind, not even the output folders they were asked for.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

/// Every path under `dir`, recursively.
fn tree(dir: &Path) -> BTreeSet<PathBuf> {
    let mut out = BTreeSet::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p.clone());
            }
            out.insert(p);
        }
    }
    out
}

/// Runs `args` in `dir` and checks the failure: status 2, `input` named in
/// the message, no placeholder, nothing new in `dir`.
fn fails_cleanly(dir: &Path, args: &[&str], input: &str) {
    let before = tree(dir);
    let out = Command::new(BIN)
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    assert!(
        stderr.contains(input),
        "{args:?} does not name {input}: {stderr}"
    );
    for placeholder in ["(file)", "(path)", "{}"] {
        assert!(!stderr.contains(placeholder), "{args:?}: {stderr}");
    }
    assert_eq!(tree(dir), before, "{args:?} left files behind: {stderr}");
}

#[test]
fn review_recover_and_process_of_bad_inputs_exit_2_and_leave_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("text.mcap"), b"this is not an MCAP file at all").unwrap();
    std::fs::write(dir.join("empty.mcap"), b"").unwrap();
    std::fs::create_dir(dir.join("folder.mcap")).unwrap();
    for input in ["missing.mcap", "text.mcap", "empty.mcap", "folder.mcap"] {
        // Default outputs beside the input, and outputs in folders that do
        // not exist yet (which must not be made for a failed command).
        fails_cleanly(dir, &["review", input], input);
        fails_cleanly(dir, &["review", input, "--out", "new/deeper/rev"], input);
        fails_cleanly(dir, &["recover", input], input);
        if input != "folder.mcap" {
            // `process` takes a folder as a folder of images (tested below).
            fails_cleanly(
                dir,
                &[
                    "process",
                    input,
                    "--out",
                    "new/out.jsonl",
                    "--log",
                    "new/out.mcap",
                ],
                input,
            );
        }
    }
    // A folder of images without --camera, and with a camera file that is
    // missing: refused before any output.
    fails_cleanly(
        dir,
        &["process", "folder.mcap", "--out", "new/out.jsonl"],
        "--camera",
    );
    fails_cleanly(
        dir,
        &[
            "process",
            "folder.mcap",
            "--camera",
            "nope.yaml",
            "--out",
            "o.jsonl",
        ],
        "nope.yaml",
    );
}

#[test]
fn recover_into_a_missing_folder_is_an_output_failure_and_leaves_nothing() {
    // The input is a real (tiny) MCAP file; the output's folder does not
    // exist: exit status 1 (the output could not be written), nothing made.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let log = dir.join("ok.mcap");
    {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&log).unwrap(),
        ))
        .unwrap();
        w.finish().unwrap();
    }
    let before = tree(dir);
    let out = Command::new(BIN)
        .current_dir(dir)
        .args(["recover", "ok.mcap", "--out", "no/such/dir/fixed.mcap"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("fixed.mcap"), "{stderr}");
    assert_eq!(tree(dir), before, "{stderr}");
}
