//! The link over a serial line: a pseudo-terminal pair stands in for the
//! UART. The link opens the device through a symlink, so the test can make
//! the device disappear and reappear (a USB adapter unplugged and back).

mod link_common;

use drogue_vision::link::Link;
use link_common::*;
use mavlink::dialects::ardupilotmega::MavMessage;
use serialport::{SerialPort, TTYPort};
use std::io::Write;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::sleep;
use std::time::{Duration, Instant};

/// A fresh pty; the symlink `link` points at its device.
fn plug(link: &Path) -> TTYPort {
    let (mut master, slave) = TTYPort::pair().unwrap();
    let name = slave.name().unwrap();
    drop(slave);
    master.set_timeout(Duration::from_millis(20)).unwrap();
    let _ = std::fs::remove_file(link);
    std::os::unix::fs::symlink(name, link).unwrap();
    master
}

#[test]
fn serial_sends_poses_and_resumes_after_the_device_comes_back() {
    let rt = runtime();
    let dir = tempfile::tempdir().unwrap();
    let dev = dir.path().join("ttyDROGUE");
    let mut master = plug(&dev);
    let mut cfg = link_config();
    cfg.reconnect_min_ms = 100;
    cfg.reconnect_max_ms = 500;
    cfg.max_rate_hz = 20.0;
    let addr = format!("serial:{}:921600", dev.display());
    let link = Link::start(&cfg, Some(&addr), rt.handle()).unwrap();

    // A camera at 30 Hz, all along.
    let running = Arc::new(AtomicBool::new(true));
    let camera = {
        let link = link.clone();
        let running = running.clone();
        std::thread::spawn(move || {
            let mut seq = 0;
            while running.load(Ordering::Relaxed) {
                let det = detection([10.0, 0.25, -0.5], [-1.0, 0.0, 0.0], 1);
                link.submit(measurement(seq, unix_now_ns(), Some(det)));
                seq += 1;
                sleep(Duration::from_millis(33));
            }
        })
    };

    // Autopilot heartbeats in (once the link has the port open), poses out.
    let mut bytes = Vec::new();
    collect_stream(&mut master, &mut bytes, Duration::from_secs(3), |m| {
        !m.is_empty()
    });
    master
        .write_all(&encode(&autopilot_heartbeat(), 0, None))
        .unwrap();
    let msgs = collect_stream(&mut master, &mut bytes, Duration::from_secs(3), |m| {
        landing_target_times(m).len() >= 5
    });
    assert!(
        landing_target_times(&msgs).len() >= 5,
        "{} poses",
        landing_target_times(&msgs).len()
    );
    let lt = landing_targets_in(&msgs).swap_remove(0);
    assert_eq!((lt.x, lt.y, lt.z), (10.0, 0.25, -0.5));
    assert!(msgs.iter().any(|m| matches!(m, MavMessage::HEARTBEAT(_))));
    assert!(link.stats().last_heartbeat_age_s >= 0.0);

    // Unplugged: the device node goes away.
    drop(master);
    std::fs::remove_file(&dev).unwrap();
    sleep(Duration::from_millis(1500));
    assert!(
        wait_for(Duration::from_secs(2), || link.stats().io_errors >= 1),
        "{:?}",
        link.stats()
    );

    // Plugged back in: poses flow again within 2 s, and only fresh ones.
    let mut master = plug(&dev);
    let back = Instant::now();
    let mut bytes = Vec::new();
    let msgs = collect_stream(&mut master, &mut bytes, Duration::from_secs(3), |m| {
        !landing_target_times(m).is_empty()
    });
    let resumed = back.elapsed();
    let times = landing_target_times(&msgs);
    assert!(!times.is_empty(), "no pose after the device came back");
    assert!(
        resumed < Duration::from_secs(2),
        "resumed after {resumed:?}"
    );
    let now_us = unix_now_ns() / 1000;
    for t in &times {
        assert!(
            now_us - t < 300_000,
            "a pose {} ms old",
            (now_us - t) / 1000
        );
    }
    let s = link.stats();
    assert!(s.reconnects >= 1, "{s:?}");
    eprintln!("serial link resumed {resumed:?} after the device came back");

    running.store(false, Ordering::Relaxed);
    camera.join().unwrap();
    link.shutdown();
}

#[test]
fn serial_garbage_does_not_stop_the_stream() {
    let rt = runtime();
    let dir = tempfile::tempdir().unwrap();
    let dev = dir.path().join("ttyGARBAGE");
    let mut master = plug(&dev);
    let cfg = link_config();
    let addr = format!("serial:{}:57600", dev.display());
    let link = Link::start(&cfg, Some(&addr), rt.handle()).unwrap();
    let mut bytes = Vec::new();
    collect_stream(&mut master, &mut bytes, Duration::from_secs(2), |m| {
        !m.is_empty()
    });
    // Noise on the line, a frame cut short, then a good heartbeat.
    let good = encode(&autopilot_heartbeat(), 1, None);
    let mut noise: Vec<u8> = (0..5000u32).map(|i| (i * 7919 % 251) as u8).collect();
    noise.extend_from_slice(&good[..good.len() / 2]);
    master.write_all(&noise).unwrap();
    master.write_all(&vec![0u8; 300]).unwrap();
    master.write_all(&good).unwrap();
    wait_for(Duration::from_secs(2), || {
        link.stats().last_heartbeat_age_s >= 0.0
    });
    let s = link.stats();
    assert!(s.bad_bytes >= 5000, "{s:?}");
    assert!(s.last_heartbeat_age_s >= 0.0, "{s:?}");
    let capture = submit_ahead(&link, 1, 4.0, 1);
    let mut bytes = Vec::new();
    let msgs = collect_stream(&mut master, &mut bytes, Duration::from_secs(2), |m| {
        !landing_target_times(m).is_empty()
    });
    assert_eq!(landing_target_times(&msgs), vec![capture / 1000]);
    link.shutdown();
}
