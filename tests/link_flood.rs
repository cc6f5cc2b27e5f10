//! A link an attacker on the network can neither take nor starve (issue 16),
//! on 127.0.0.1 only, with bounded counts and times: `udpin` keeps the
//! autopilot as its peer while garbage and unsigned frames arrive from other
//! ports, and LANDING_TARGET keeps >= 95 % of its rate under floods of 0xFE
//! datagrams and of valid frames sent as fast as this test can send them.
//! The peer parses with the `mavlink` crate's own reader (link_common).

mod link_common;

use drogue_vision::link::Link;
use link_common::*;
use mavlink::{SigningConfig, SigningData};
use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::sleep;
use std::time::{Duration, Instant};

/// Garbage from another port, a while: one byte, 0xFE runs, a frame with a
/// bad CRC and a truncated one; none of it may take the peer.
fn send_garbage(to: std::net::SocketAddr, extra: &[Vec<u8>]) -> UdpSocket {
    let attacker = UdpSocket::bind("127.0.0.1:0").unwrap();
    let good = encode(&autopilot_heartbeat(), 0, None);
    let mut bad_crc = good.clone();
    let k = bad_crc.len() - 1;
    bad_crc[k] ^= 0x77;
    let mut datagrams = vec![vec![0x42u8], vec![0xFE; 1400], bad_crc, good[..8].to_vec()];
    datagrams.extend_from_slice(extra);
    for _ in 0..50 {
        for d in &datagrams {
            attacker.send_to(d, to).unwrap();
        }
        sleep(Duration::from_millis(2));
    }
    attacker
}

/// The autopilot says hello until the link answers (its socket may not be
/// bound yet when the first heartbeat goes out); whether it answered.
fn introduce(autopilot: &mut UdpPeer, sign: Option<&SigningData>) -> bool {
    for _ in 0..20 {
        autopilot.send_with(&autopilot_heartbeat(), sign);
        let got =
            autopilot.collect_until(Duration::from_millis(250), |g| count(g, "HEARTBEAT") >= 1);
        if count(&got, "HEARTBEAT") >= 1 {
            return true;
        }
    }
    false
}

/// Whether `socket` received anything within `limit`.
fn received_any(socket: &UdpSocket, limit: Duration) -> bool {
    socket.set_read_timeout(Some(limit)).unwrap();
    let mut buf = [0u8; 2048];
    socket.recv_from(&mut buf).is_ok()
}

#[test]
fn udpin_keeps_the_autopilot_while_garbage_arrives_from_another_port() {
    let rt = runtime();
    let port = free_udp_port();
    let to = ([127, 0, 0, 1], port).into();
    let link = Link::start(
        &link_config(),
        Some(&format!("udpin:127.0.0.1:{port}")),
        rt.handle(),
    )
    .unwrap();
    let mut autopilot = UdpPeer::bind();
    autopilot.link = Some(to);
    assert!(introduce(&mut autopilot, None));

    let attacker = send_garbage(to, &[]);
    let capture = submit_ahead(&link, 1, 6.0, 1);
    let got = autopilot.collect_until(Duration::from_secs(2), |g| !landing_targets(g).is_empty());
    assert_eq!(landing_targets(&got)[0].time_usec, capture / 1000);
    assert!(
        !received_any(&attacker, Duration::from_millis(1200)),
        "the attacker got our traffic"
    );
    let s = link.stats();
    assert_eq!(s.peer_changes, 0, "{s:?}");
    assert!(s.bad_bytes > 50 * 1400, "{s:?}");

    // A well-formed MAVLink 2 frame from a new port is a new peer (the
    // autopilot moved): followed, and counted as a change.
    let moved = UdpPeer::bind();
    moved
        .socket
        .send_to(&encode(&autopilot_heartbeat(), 9, None), to)
        .unwrap();
    assert!(wait_for(Duration::from_secs(2), || link
        .stats()
        .peer_changes
        == 1));
    assert!(received_any(&moved.socket, Duration::from_secs(2)));
    link.shutdown();
}

#[test]
fn udpin_with_signing_follows_only_a_signed_frame() {
    let rt = runtime();
    let port = free_udp_port();
    let to = ([127, 0, 0, 1], port).into();
    let mut cfg = link_config();
    cfg.signing_passphrase = "drogue".into();
    cfg.signing_require = false; // unsigned frames are read, but never trusted
    let link = Link::start(&cfg, Some(&format!("udpin:127.0.0.1:{port}")), rt.handle()).unwrap();
    let key: [u8; 32] = {
        use sha2::{Digest, Sha256};
        Sha256::digest(b"drogue").into()
    };
    let sign = SigningData::from_config(SigningConfig::new(key, 1, true, false));
    let mut autopilot = UdpPeer::bind();
    autopilot.link = Some(to);
    autopilot.signing = Some(SigningData::from_config(SigningConfig::new(
        key, 0, true, false,
    )));
    assert!(introduce(&mut autopilot, Some(&sign)));
    // Valid but unsigned frames from another port: read, not followed.
    let unsigned = encode(&autopilot_heartbeat(), 3, None);
    let attacker = send_garbage(to, &[unsigned]);
    assert!(!received_any(&attacker, Duration::from_millis(1200)));
    let got = autopilot.collect_until(Duration::from_millis(1500), |g| count(g, "HEARTBEAT") >= 1);
    assert!(count(&got, "HEARTBEAT") >= 1);
    assert_eq!(link.stats().peer_changes, 0);
    link.shutdown();
}

/// What a flood run measured.
struct FloodResult {
    submitted: u64,
    landing_targets: usize,
    datagrams: u64,
    bytes: u64,
    seconds: f64,
}

/// Submits a detection at 30 Hz for `seconds` while another thread sends
/// `datagram` to the link's port as fast as it can; counts LANDING_TARGET.
fn flood_run(datagram: Vec<u8>, seconds: f64) -> FloodResult {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let link = Arc::new(Link::start(&link_config(), Some(&peer.address()), rt.handle()).unwrap());
    peer.wait_for_link();
    let link_addr = peer.link.unwrap();

    let stop = Arc::new(AtomicBool::new(false));
    let (datagrams, bytes) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let flood = {
        let (stop, datagrams, bytes) = (stop.clone(), datagrams.clone(), bytes.clone());
        std::thread::spawn(move || {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            while !stop.load(Ordering::Relaxed) {
                if s.send_to(&datagram, link_addr).is_ok() {
                    datagrams.fetch_add(1, Ordering::Relaxed);
                    bytes.fetch_add(datagram.len() as u64, Ordering::Relaxed);
                }
            }
        })
    };
    let started = Instant::now();
    let submitter = {
        let (stop, link) = (stop.clone(), link.clone());
        std::thread::spawn(move || {
            let mut n = 0u64;
            let period = Duration::from_nanos(1_000_000_000 / 30);
            let mut next = Instant::now();
            while !stop.load(Ordering::Relaxed) {
                n += 1;
                link.submit(measurement(
                    n,
                    unix_now_ns(),
                    Some(detection([6.0, 0.1, 0.0], [-1.0, 0.0, 0.0], 1)),
                ));
                next += period;
                sleep(next.saturating_duration_since(Instant::now()));
            }
            n
        })
    };
    let got = peer.collect_until(Duration::from_secs_f64(seconds), |_| false);
    stop.store(true, Ordering::Relaxed);
    let submitted = submitter.join().unwrap();
    flood.join().unwrap();
    let elapsed = started.elapsed().as_secs_f64();
    // The last submission may still be on its way: collect briefly.
    let tail = peer.collect_until(Duration::from_millis(300), |_| false);
    let r = FloodResult {
        submitted,
        landing_targets: landing_targets(&got).len() + landing_targets(&tail).len(),
        datagrams: datagrams.load(Ordering::Relaxed),
        bytes: bytes.load(Ordering::Relaxed),
        seconds: elapsed,
    };
    println!(
        "flood of {}-byte datagrams: {:.0} datagrams/s ({:.1} MB/s); LANDING_TARGET {} of {} submitted ({:.1} %); link {:?}",
        datagram_len(&r),
        r.datagrams as f64 / r.seconds,
        r.bytes as f64 / r.seconds / 1e6,
        r.landing_targets,
        r.submitted,
        100.0 * r.landing_targets as f64 / r.submitted as f64,
        link.stats()
    );
    link.shutdown();
    r
}

fn datagram_len(r: &FloodResult) -> u64 {
    r.bytes.checked_div(r.datagrams).unwrap_or(0)
}

fn assert_rate_kept(r: &FloodResult) {
    assert!(r.datagrams > 1000, "the flood did not run");
    assert!(
        r.landing_targets as f64 >= 0.95 * r.submitted as f64,
        "{} LANDING_TARGET for {} submitted",
        r.landing_targets,
        r.submitted
    );
}

#[test]
fn landing_target_keeps_its_rate_under_a_flood_of_0xfe() {
    let r = flood_run(vec![0xFE; 1400], 3.0);
    assert_rate_kept(&r);
}

#[test]
fn landing_target_keeps_its_rate_under_a_flood_of_valid_frames() {
    // Valid ATTITUDE frames from the autopilot, packed into one datagram.
    let mut datagram = Vec::new();
    let mut seq = 0u8;
    while datagram.len() < 1300 {
        datagram.extend(encode(&attitude(0.1, 0.0, 0.2), seq, None));
        seq = seq.wrapping_add(1);
    }
    let r = flood_run(datagram, 3.0);
    assert_rate_kept(&r);
}
