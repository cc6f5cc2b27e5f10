//! The companion-computer deployment files: `config/companion.toml` is a valid
//! config (the loader rejects unknown keys and wrong types, so loading it
//! proves it), and the systemd unit runs it the way the config expects.

use drogue_vision::config::Config;
use drogue_vision::link::address::Address;
use drogue_vision::source::SourceSpec;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

fn repo_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(name)
}

fn companion() -> Config {
    Config::load(Some(&repo_file("config/companion.toml"))).expect("companion.toml loads")
}

/// The unit's `Key=value` lines (a repeated key keeps every value).
fn unit() -> HashMap<String, Vec<String>> {
    let text = std::fs::read_to_string(repo_file("config/drogue-vision.service")).unwrap();
    let mut keys: HashMap<String, Vec<String>> = HashMap::new();
    for line in text.lines().map(str::trim) {
        if line.starts_with('#') || line.starts_with('[') || line.is_empty() {
            continue;
        }
        let (k, v) = line.split_once('=').expect("Key=value");
        keys.entry(k.to_string()).or_default().push(v.to_string());
    }
    keys
}

#[test]
fn companion_config_is_valid_and_says_what_it_should() {
    let c = companion();
    assert_eq!(
        c.run.source.parse::<SourceSpec>().unwrap(),
        SourceSpec::V4l("/dev/video0".into())
    );
    assert_eq!(
        Address::parse(&c.link.connection).unwrap(),
        Address::Serial {
            device: "/dev/ttyAMA0".into(),
            baud: 921_600
        }
    );
    c.v4l.validate().unwrap();
    c.log.validate().unwrap();
    // The service runs from its state folder: every path must be absolute.
    for path in [&c.camera.file, &c.link.signing_key_file, &c.log.dir] {
        assert!(path.is_absolute(), "{} is relative", path.display());
    }
    assert!(c.link.signing_require);
    assert!((1..=99).contains(&c.run.realtime_priority));
    // Files on an SD card: small, frequent enough to lose little.
    assert!(c.log.rotate_size_mib > 0 && c.log.rotate_size_mib <= 1024);
    assert!(c.log.rotate_duration_s > 0 && c.log.rotate_duration_s <= 600);
}

#[test]
fn service_runs_the_companion_config_and_stops_cleanly() {
    let c = companion();
    let u = unit();
    let one = |k: &str| -> String {
        let v = u.get(k).unwrap_or_else(|| panic!("no {k}="));
        assert_eq!(v.len(), 1, "{k} given {} times", v.len());
        v[0].clone()
    };
    assert_eq!(
        one("ExecStart"),
        "/usr/local/bin/drogue-vision run --config /etc/drogue-vision/companion.toml"
    );
    // SIGINT is the clean stop that finishes the MCAP file.
    assert_eq!(one("KillSignal"), "SIGINT");
    // The service user may take the configured real-time priority.
    assert_eq!(
        one("LimitRTPRIO").parse::<u8>().ok(),
        Some(c.run.realtime_priority)
    );
    assert_eq!(one("Restart"), "on-failure");
    assert!(one("RestartSec").parse::<u32>().unwrap() > 0);
    // Long enough for a frame wait to end and the log to be finished.
    let stop_s: u64 = one("TimeoutStopSec").parse().unwrap();
    assert!(stop_s * 1000 >= c.v4l.frame_timeout_ms + 5_000, "{stop_s}");
    // A dedicated user, allowed the camera and the serial port.
    assert_ne!(one("User"), "root");
    let groups = one("SupplementaryGroups");
    assert!(groups.split_whitespace().any(|g| g == "video"), "{groups}");
    assert!(
        groups.split_whitespace().any(|g| g == "dialout"),
        "{groups}"
    );
    // The log folder is inside what the service may write.
    let state = Path::new("/var/lib").join(one("StateDirectory"));
    assert!(c.log.dir.starts_with(&state), "{}", c.log.dir.display());
    assert!(c.log.dir.starts_with(one("ReadWritePaths")));
    assert_eq!(Path::new(&one("WorkingDirectory")), state);
    // The camera the unit waits for is the one the config opens.
    let SourceSpec::V4l(device) = c.run.source.parse::<SourceSpec>().unwrap() else {
        panic!("not a camera source");
    };
    let device_unit = format!(
        "{}.device",
        device.trim_start_matches('/').replace('/', "-")
    );
    assert_eq!(one("After"), device_unit);
}

#[test]
fn run_with_the_companion_config_reports_the_camera_clearly() {
    // No camera on a build machine (and no libclang-built v4l support in a
    // default build): `run` must stop at setup with status 2 and say why.
    let out = Command::new(BIN)
        .args(["run", "--max-frames", "1", "--config"])
        .arg(repo_file("config/companion.toml"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    if cfg!(feature = "v4l") {
        // A machine with a camera gets further (to the missing camera file).
        if !Path::new("/dev/video0").exists() {
            assert!(stderr.contains("v4l:/dev/video0"), "{stderr}");
            assert!(stderr.contains("No such file"), "{stderr}");
        }
    } else {
        assert!(stderr.contains("v4l:/dev/video0"), "{stderr}");
        assert!(stderr.contains("--features v4l"), "{stderr}");
    }
}

#[test]
fn unit_stops_restarting_on_a_configuration_error() {
    let u = unit();
    assert_eq!(u["Restart"], vec!["on-failure".to_string()]);
    // Exit status 2 (drogue-vision --help: bad config, camera, arguments).
    assert_eq!(u["RestartPreventExitStatus"], vec!["2".to_string()]);
}

#[test]
fn deployment_files_point_only_at_readme_sections_that_exist() {
    let readme = std::fs::read_to_string(repo_file("README.md")).unwrap();
    let headings: Vec<String> = readme
        .lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| l.trim_start_matches('#').trim().to_string())
        .collect();
    let mut seen = 0;
    for file in ["config/companion.toml", "config/drogue-vision.service"] {
        // A pointer may wrap over two comment lines: join them first.
        let text: String = std::fs::read_to_string(repo_file(file))
            .unwrap()
            .lines()
            .map(|l| l.trim_start_matches('#').trim())
            .collect::<Vec<_>>()
            .join(" ");
        for (i, _) in text.match_indices("README: \"") {
            let rest = &text[i + "README: \"".len()..];
            let name = &rest[..rest.find('"').expect("closing quote")];
            assert!(
                headings.iter().any(|h| h == name),
                "{file} points at README section \"{name}\", which does not exist"
            );
            seen += 1;
        }
    }
    assert!(seen >= 3, "only {seen} README pointers found");
}
