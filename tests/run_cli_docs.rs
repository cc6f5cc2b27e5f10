//! Shell completions and man pages come from the command line's own
//! definition: every subcommand and `run`'s options appear in them.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

#[test]
fn completions_know_every_subcommand_and_run_option() {
    for shell in ["bash", "zsh", "fish"] {
        let out = Command::new(BIN)
            .args(["completions", shell])
            .output()
            .unwrap();
        assert!(out.status.success(), "{shell}");
        let text = String::from_utf8_lossy(&out.stdout);
        // (fish spells long options `-l mavlink`, the others `--mavlink`.)
        for word in [
            "run", "process", "review", "recover", "sim", "mavlink", "fast",
        ] {
            assert!(text.contains(word), "{shell} completion lacks {word}");
        }
    }
    let bad = Command::new(BIN)
        .args(["completions", "cmd.exe"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
}

#[test]
fn man_pages_to_stdout_and_one_per_command() {
    let out = Command::new(BIN).arg("man").output().unwrap();
    assert!(out.status.success());
    let page = String::from_utf8_lossy(&out.stdout);
    assert!(
        page.starts_with(".ie") || page.contains(".TH drogue-vision 1"),
        "{page}"
    );
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(BIN)
        .args(["man", "--dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success());
    for name in [
        "drogue-vision.1",
        "drogue-vision-run.1",
        "drogue-vision-sim.1",
    ] {
        let text = std::fs::read_to_string(dir.path().join(name)).unwrap();
        assert!(text.contains(".SH"), "{name}");
    }
    let run = std::fs::read_to_string(dir.path().join("drogue-vision-run.1")).unwrap();
    assert!(run.contains("mavlink"), "run's page lacks --mavlink");
}
