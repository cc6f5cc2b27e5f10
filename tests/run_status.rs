//! `run` that talks: on a terminal (a tmux pane) a status line with frames,
//! detections, range, latency, link state and log size; piped, no escape
//! codes at all, and with `NO_COLOR` none on a terminal either.

use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

fn have_tmux() -> bool {
    Command::new("tmux")
        .arg("-V")
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn a_piped_run_has_no_escape_codes() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(BIN)
        .args(["run", "--source", "sim:approach", "--max-frames", "45"])
        .args(["--mavlink", "udpout:127.0.0.1:9", "--log-dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        !err.contains('\x1b'),
        "escape codes in a piped run:\n{err:?}"
    );
    assert!(err.contains("run ended: 45 frames"), "{err}");
}

/// Runs `run` in a detached tmux session (a real terminal) and returns what
/// the pane showed while it ran; `None` without tmux, unless
/// `DROGUE_REQUIRE_TMUX` is set (`.ci/run` sets it after installing tmux),
/// where a missing tmux fails the test instead of passing it unrun.
fn pane_while_running(extra_env: &str) -> Option<String> {
    if !have_tmux() {
        assert!(
            std::env::var_os("DROGUE_REQUIRE_TMUX").is_none(),
            "DROGUE_REQUIRE_TMUX is set but tmux is not installed (apt-get install tmux)"
        );
        eprintln!("tmux not installed: skipped (apt-get install tmux)");
        return None;
    }
    let dir = tempfile::tempdir().unwrap();
    // One tmux server per call (its own socket, `-L`): the tests run in
    // parallel threads of one process, and two calls starting the default
    // server at once failed one of them now and then ("server exited
    // unexpectedly"; before that, "duplicate session").
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    let session = format!("dv-status-{}-{call}", std::process::id());
    let tmux = |args: &[&str]| {
        let mut c = Command::new("tmux");
        c.args(["-L", &session]).args(args);
        c
    };
    let cmd = format!(
        "{extra_env} {BIN} run --source sim:approach --max-frames 150 \
         --mavlink udpout:127.0.0.1:9 --log-dir {}; sleep 30",
        dir.path().display()
    );
    let ok = tmux(&[
        "new-session",
        "-d",
        "-x",
        "200",
        "-y",
        "30",
        "-s",
        &session,
        &cmd,
    ])
    .status()
    .unwrap()
    .success();
    assert!(ok, "tmux new-session -s {session} failed");
    // The line appears after about a second; poll the pane for it.
    let end = Instant::now() + Duration::from_secs(20);
    let mut seen = String::new();
    while Instant::now() < end {
        std::thread::sleep(Duration::from_millis(300));
        let cap = tmux(&["capture-pane", "-p", "-e", "-t", &session])
            .output()
            .unwrap();
        seen = String::from_utf8_lossy(&cap.stdout).into_owned();
        if seen.contains("frames ") && seen.contains(", link ") && seen.contains(" MB") {
            break;
        }
    }
    let _ = tmux(&["kill-server"]).status();
    Some(seen)
}

#[test]
fn a_terminal_shows_the_status_line() {
    let Some(pane) = pane_while_running("") else {
        return;
    };
    let line = pane
        .lines()
        .find(|l| l.contains("frames ") && l.contains(", link "))
        .unwrap_or_else(|| panic!("no status line in the pane:\n{pane}"));
    for part in ["detected ", "range ", "latency ", "log "] {
        assert!(line.contains(part), "{part} missing: {line}");
    }
    // Nobody listens on port 9: the autopilot is never heard, in yellow.
    assert!(line.contains("autopilot never heard"), "{line}");
    assert!(
        line.contains("\x1b[33m"),
        "no colour on a terminal: {line:?}"
    );
}

#[test]
fn no_color_turns_colours_off_on_a_terminal() {
    let Some(pane) = pane_while_running("NO_COLOR=1") else {
        return;
    };
    let line = pane
        .lines()
        .find(|l| l.contains("frames ") && l.contains(", link "))
        .unwrap_or_else(|| panic!("no status line in the pane:\n{pane}"));
    assert!(
        !pane.contains("\x1b[3"),
        "colours despite NO_COLOR: {line:?}"
    );
}
