//! The link over UDP and TCP loopback (127.0.0.1 only), against a peer that
//! frames and parses with the `mavlink` crate's own reader and writer.
//! Expected values are worked out by hand from the measurement, not by the
//! link's code.

mod link_common;

use drogue_vision::link::{Link, PoseMessage};
use link_common::*;
use mavlink::dialects::ardupilotmega::{
    LandingTargetType, MavAutopilot, MavBool, MavFrame, MavMessage, MavType, TIMESYNC_DATA,
};
use mavlink::{MavlinkVersion, SigningConfig, SigningData};
use sha2::{Digest, Sha256};
use std::net::{TcpListener, UdpSocket};
use std::thread::sleep;
use std::time::{Duration, Instant};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn udp_every_pose_message_matches_the_measurement() {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let mut cfg = link_config();
    cfg.messages = vec![
        PoseMessage::LandingTarget,
        PoseMessage::LandingTargetNed,
        PoseMessage::VisionPositionEstimate,
        PoseMessage::Odometry,
    ];
    cfg.max_rate_hz = 0.0;
    cfg.telemetry_tolerance_ms = 1000;
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    peer.wait_for_link();

    // The autopilot: heading east (yaw +90 deg), at N 100, E 20, 50 m up.
    peer.send(&autopilot_heartbeat());
    peer.send(&attitude(0.0, 0.0, std::f32::consts::FRAC_PI_2));
    peer.send(&local_position(100.0, 20.0, -50.0));
    assert!(wait_for(Duration::from_secs(2), || link
        .vehicle_pose_at(unix_now_ns())
        .is_some()));
    let capture = unix_now_ns();
    // Drogue 8 m ahead, 0.4 m right, 0.2 m up, square on (normal toward us).
    let det = detection([8.0, 0.4, -0.2], [-1.0, 0.0, 0.0], 3);
    link.submit(measurement(1, capture, Some(det)));

    let got = peer.collect_until(Duration::from_secs(2), |g| {
        landing_targets(g).len() >= 2
            && count(g, "VISION_POSITION_ESTIMATE") >= 1
            && count(g, "ODOMETRY") >= 1
    });
    for g in &got {
        assert_eq!((g.header.system_id, g.header.component_id), (1, 197));
    }
    let lts = landing_targets(&got);
    let body = lts
        .iter()
        .find(|l| l.frame == MavFrame::MAV_FRAME_BODY_FRD)
        .expect("LANDING_TARGET body");
    assert_eq!(body.time_usec, capture / 1000);
    assert_eq!((body.x, body.y, body.z), (8.0, 0.4, -0.2));
    let range = (64.0f64 + 0.16 + 0.04).sqrt();
    assert!(close(f64::from(body.distance), range, 1e-5));
    // Line of sight in the image: camera x = body y, camera y = body z.
    assert!(close(f64::from(body.angle_x), (0.4f64 / 8.0).atan(), 1e-6));
    assert!(close(f64::from(body.angle_y), (-0.2f64 / 8.0).atan(), 1e-6));
    assert_eq!(body.q, [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(body.position_valid, MavBool::MAV_BOOL_TRUE);
    assert_eq!(
        body.mavtype,
        LandingTargetType::LANDING_TARGET_TYPE_VISION_OTHER
    );

    // NED: forward is east, right is south, down is down.
    let ned = lts
        .iter()
        .find(|l| l.frame == MavFrame::MAV_FRAME_LOCAL_NED)
        .expect("LANDING_TARGET NED");
    assert!(close(f64::from(ned.x), 99.6, 1e-4), "{}", ned.x);
    assert!(close(f64::from(ned.y), 28.0, 1e-4), "{}", ned.y);
    assert!(close(f64::from(ned.z), -50.2, 1e-4), "{}", ned.z);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let q = ned.q.map(f64::from);
    assert!(close(q[0], h, 1e-6) && close(q[3], h, 1e-6) && q[1].abs() < 1e-6 && q[2].abs() < 1e-6);

    // The receiver in the drogue frame (= body axes here): 8 m behind it.
    let vpe = got
        .iter()
        .find_map(|g| match &g.message {
            MavMessage::VISION_POSITION_ESTIMATE(v) => Some(v.clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!(vpe.usec, capture / 1000);
    assert_eq!((vpe.x, vpe.y, vpe.z), (-8.0, -0.4, 0.2));
    assert_eq!((vpe.roll, vpe.pitch, vpe.yaw), (0.0, 0.0, 0.0));
    assert_eq!(vpe.reset_counter, 3);
    // Covariance, upper triangle row by row: (0,0) x, (1,1) at 6, (2,2) at 11,
    // (3,3) at 15, (4,4) at 18, (5,5) at 20. Lateral: + (range * sigma)^2.
    let lateral = (range * 0.02).powi(2);
    let c = vpe.covariance.map(f64::from);
    assert!(close(c[0], 4e-4, 1e-9));
    assert!(close(c[6], 1e-5 + lateral, 1e-8));
    assert!(close(c[11], 2e-5 + lateral, 1e-8));
    for k in [15, 18, 20] {
        assert!(close(c[k], 4e-4, 1e-9));
    }
    for k in [1, 2, 3, 4, 5, 7, 8, 9, 10, 12, 13, 14, 16, 17, 19] {
        assert_eq!(c[k], 0.0, "off-diagonal {k}");
    }
    let odo = got
        .iter()
        .find_map(|g| match &g.message {
            MavMessage::ODOMETRY(o) => Some(o.clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!((odo.x, odo.y, odo.z), (-8.0, -0.4, 0.2));
    assert_eq!(odo.q, [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(odo.frame_id, MavFrame::MAV_FRAME_LOCAL_FRD);
    assert_eq!(odo.child_frame_id, MavFrame::MAV_FRAME_BODY_FRD);
    assert_eq!(odo.pose_covariance, vpe.covariance);
    assert_eq!(odo.time_usec, capture / 1000);

    // The vehicle pose the link heard, at the capture time; none far from it.
    let v = link.vehicle_pose_at(capture).expect("vehicle pose");
    assert_eq!(v.position_ned_m.to_array(), [100.0, 20.0, -50.0]);
    let q = drogue_vision::spatial::quaternion_to_wxyz(&v.q_ned_body);
    assert!(close(q[0], h, 1e-6) && close(q[3], h, 1e-6));
    assert!(link.vehicle_pose_at(capture + 10_000_000_000).is_none());

    // Every message is also an event for the log.
    let events = link.events().drain();
    let out_lt = events
        .iter()
        .find(|e| e.outgoing && e.name == "LANDING_TARGET")
        .expect("LANDING_TARGET event");
    assert_eq!(out_lt.capture_time_ns, Some(capture));
    assert!(out_lt.time_ns >= capture);
    assert!(events.iter().any(|e| !e.outgoing
        && e.name == "HEARTBEAT"
        && e.fields["sysid"] == 1
        && e.fields["autopilot"] == "MAV_AUTOPILOT_ARDUPILOTMEGA"));
    let s = link.stats();
    assert_eq!(s.sent.get("LANDING_TARGET"), Some(&2));
    assert!(s.received >= 3 && s.connected);
    assert!(s.last_heartbeat_age_s >= 0.0);
    link.shutdown();
}

#[test]
fn udp_heartbeat_at_1hz_and_timesync_answered() {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let cfg = link_config();
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    let got = peer.collect_until(Duration::from_millis(2600), |g| count(g, "HEARTBEAT") >= 3);
    let beats: Vec<_> = got
        .iter()
        .filter_map(|g| match &g.message {
            MavMessage::HEARTBEAT(h) => Some((g.at, g.header, h.clone())),
            _ => None,
        })
        .collect();
    assert!(beats.len() >= 3, "{} heartbeats", beats.len());
    for (_, header, h) in &beats {
        assert_eq!((header.system_id, header.component_id), (1, 197));
        assert_eq!(h.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
        assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
    }
    for w in beats.windows(2) {
        let dt = w[1].0 - w[0].0;
        assert!(
            dt > Duration::from_millis(700) && dt < Duration::from_millis(1300),
            "{dt:?}"
        );
    }
    // Our own TIMESYNC requests go out too (tc1 = 0, ts1 = the link's clock).
    assert!(got.iter().any(|g| matches!(&g.message,
        MavMessage::TIMESYNC(t) if t.tc1 == 0 && t.ts1 > 0)));

    // The autopilot asks: tc1 = the link's clock in ns, ts1 echoed.
    let before = unix_now_ns() as i64;
    peer.send(&MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1: 123_456_789,
        target_system: 0,
        target_component: 0,
    }));
    let got = peer.collect_until(Duration::from_secs(1), |g| {
        g.iter()
            .any(|x| matches!(&x.message, MavMessage::TIMESYNC(t) if t.ts1 == 123_456_789))
    });
    let after = unix_now_ns() as i64;
    let reply = got
        .iter()
        .find_map(|g| match &g.message {
            MavMessage::TIMESYNC(t) if t.ts1 == 123_456_789 => Some(t.clone()),
            _ => None,
        })
        .expect("TIMESYNC reply");
    assert!(reply.tc1 >= before && reply.tc1 <= after);
    assert_eq!((reply.target_system, reply.target_component), (1, 1));
    link.shutdown();
    // Nothing at all after shutdown.
    sleep(Duration::from_millis(50));
    let late = peer.collect_until(Duration::from_millis(1300), |_| false);
    assert!(late.is_empty(), "{} messages after shutdown", late.len());
}

#[test]
fn udp_rate_limit_latest_wins_staleness_and_no_detection() {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let mut cfg = link_config();
    cfg.max_rate_hz = 10.0;
    cfg.max_age_ms = 200;
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    peer.wait_for_link();

    // 60 measurements at 100 Hz: on average at most one pose per 100 ms goes out.
    let mut captures = Vec::new();
    let start = Instant::now();
    for i in 0..60u64 {
        let t = unix_now_ns();
        captures.push(t / 1000);
        let det = detection([6.0 + i as f64 * 0.01, 0.0, 0.0], [-1.0, 0.0, 0.0], 1);
        link.submit(measurement(i, t, Some(det)));
        sleep(Duration::from_millis(10));
    }
    let elapsed = start.elapsed().as_secs_f64();
    let got = peer.collect_until(Duration::from_millis(300), |_| false);
    let lts = landing_targets(&got);
    // A token bucket (burst 2) sends at most 2 + rate * T in any window T;
    // the window runs until the last pending pose may go, 100 ms after.
    let max_expected = ((elapsed + 0.1) * 10.0).ceil() as usize + 2;
    assert!(
        lts.len() >= 4 && lts.len() <= max_expected,
        "{} poses in {elapsed:.2} s",
        lts.len()
    );
    for l in &lts {
        assert!(
            captures.contains(&l.time_usec),
            "pose not from a submitted frame"
        );
    }
    for w in lts.windows(2) {
        assert!(w[1].time_usec > w[0].time_usec);
    }
    // Latest wins: after the wait, the newest measurement is the one sent.
    assert_eq!(lts.last().map(|l| l.time_usec), captures.last().copied());
    assert!(link.stats().superseded > 40);

    // Too old: never sent.
    sleep(Duration::from_millis(150));
    let det = detection([6.0, 0.0, 0.0], [-1.0, 0.0, 0.0], 1);
    link.submit(measurement(100, unix_now_ns() - 1_000_000_000, Some(det)));
    // No detection: nothing sent.
    sleep(Duration::from_millis(150));
    link.submit(measurement(101, unix_now_ns(), None));
    let got = peer.collect_until(Duration::from_millis(400), |_| false);
    assert!(landing_targets(&got).is_empty());
    let s = link.stats();
    assert!(s.stale >= 1 && s.no_detection >= 1, "{s:?}");
    link.shutdown();
}

fn signing_data(key: [u8; 32], allow_unsigned: bool) -> SigningData {
    SigningData::from_config(SigningConfig::new(key, 0, true, allow_unsigned))
}

#[test]
fn udp_signing_required_accepts_good_and_rejects_the_rest() {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let mut cfg = link_config();
    cfg.signing_passphrase = "drogue-test-passphrase".into();
    cfg.signing_link_id = 7;
    cfg.signing_require = true;
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    // MAVProxy's convention, computed here independently: key = SHA-256(passphrase).
    let key: [u8; 32] = Sha256::digest(b"drogue-test-passphrase").into();
    peer.signing = Some(signing_data(key, false));

    // The link's frames verify with the key (the crate reader rejects bad ones).
    let mut raw = [0u8; 512];
    let mut first = None;
    assert!(wait_for(Duration::from_secs(3), || {
        first = peer.socket.recv_from(&mut raw).ok();
        first.is_some()
    }));
    let (n, from) = first.unwrap();
    peer.link = Some(from);
    assert_eq!(raw[0], 0xFD, "MAVLink 2");
    assert_eq!(raw[2] & 0x01, 0x01, "signed flag");
    let sig_link_id = raw[n - 13];
    assert_eq!(sig_link_id, 7);
    let verified = parse_all(&raw[..n], peer.signing.as_ref());
    assert_eq!(verified.len(), 1);
    let wrong = signing_data([9u8; 32], false);
    assert!(parse_all(&raw[..n], Some(&wrong)).is_empty());

    // Unsigned and wrongly signed heartbeats are rejected.
    for _ in 0..3 {
        peer.send_with(&autopilot_heartbeat(), None);
    }
    for _ in 0..2 {
        peer.send_with(&autopilot_heartbeat(), Some(&wrong));
    }
    wait_for(Duration::from_secs(2), || {
        link.stats().rejected_signature >= 5
    });
    let s = link.stats();
    assert_eq!(s.rejected_signature, 5, "{s:?}");
    assert!(s.last_heartbeat_age_s < 0.0, "unsigned heartbeat accepted");
    // A correctly signed one is accepted.
    let good = signing_data(key, false);
    peer.send_with(&autopilot_heartbeat(), Some(&good));
    wait_for(Duration::from_secs(2), || {
        link.stats().last_heartbeat_age_s >= 0.0
    });
    let s = link.stats();
    assert!(
        s.last_heartbeat_age_s >= 0.0,
        "signed heartbeat refused: {s:?}"
    );
    assert_eq!(s.rejected_signature, 5);
    link.shutdown();
}

#[test]
fn udp_garbage_and_a_flood_are_counted_and_do_not_harm_the_stream() {
    use rand::{RngCore, SeedableRng};
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let cfg = link_config();
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    peer.wait_for_link();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);

    let good = encode(&autopilot_heartbeat(), 0, None);
    let mut v1 = Vec::new();
    let h = mavlink::MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    mavlink::write_versioned_msg(&mut v1, MavlinkVersion::V1, h, &autopilot_heartbeat()).unwrap();
    let mut bad_crc = good.clone();
    let k = bad_crc.len() - 2;
    bad_crc[k] ^= 0x5A;
    for _ in 0..20 {
        peer.send_raw(&v1);
        peer.send_raw(&bad_crc);
        peer.send_raw(&good[..good.len() - 4]);
        let mut junk = vec![0u8; 300];
        rng.fill_bytes(&mut junk);
        peer.send_raw(&junk);
        sleep(Duration::from_millis(2));
    }
    wait_for(Duration::from_secs(2), || {
        link.stats().rejected_mavlink1 >= 20
    });
    let s = link.stats();
    assert_eq!(s.rejected_mavlink1, 20, "{s:?}");
    assert!(
        s.bad_bytes >= (20 * (bad_crc.len() + good.len() - 4)) as u64,
        "{s:?}"
    );
    assert!(s.last_heartbeat_age_s < 0.0, "no valid heartbeat was sent");

    // A flood of random datagrams for ~1.5 s; the link keeps its heartbeat.
    let flood_end = Instant::now() + Duration::from_millis(1500);
    let mut junk = vec![0u8; 1200];
    let mut sent = 0u64;
    while Instant::now() < flood_end {
        rng.fill_bytes(&mut junk);
        peer.send_raw(&junk);
        sent += 1;
    }
    assert!(sent > 1000);
    // Valid traffic right after the flood is understood at once.
    peer.send(&autopilot_heartbeat());
    let capture = unix_now_ns();
    link.submit(measurement(
        1,
        capture,
        Some(detection([7.0, 0.0, 0.5], [-1.0, 0.0, 0.0], 1)),
    ));
    let got = peer.collect_until(Duration::from_secs(2), |g| !landing_targets(g).is_empty());
    let lt = landing_targets(&got);
    assert_eq!(lt.len(), 1);
    assert_eq!(lt[0].time_usec, capture / 1000);
    // The link serves its output before the flood's backlog of input: the
    // heartbeat sent after the flood is read once the backlog is drained.
    wait_for(Duration::from_secs(5), || {
        link.stats().last_heartbeat_age_s >= 0.0
    });
    let s = link.stats();
    assert!(s.last_heartbeat_age_s >= 0.0, "{s:?}");
    assert!(s.bad_bytes > 1_000_000, "{s:?}");
    assert!(*s.sent.get("HEARTBEAT").unwrap_or(&0) >= 2, "{s:?}");
    link.shutdown();
}

#[test]
fn udpout_keeps_sending_with_nobody_listening() {
    let rt = runtime();
    let port = free_udp_port();
    let cfg = link_config();
    let link = Link::start(&cfg, Some(&format!("udpout:127.0.0.1:{port}")), rt.handle()).unwrap();
    sleep(Duration::from_millis(1300));
    let s = link.stats();
    assert!(*s.sent.get("HEARTBEAT").unwrap_or(&0) >= 2, "{s:?}");
    // Someone starts listening: heartbeats and poses arrive.
    let mut peer = UdpPeer::on(UdpSocket::bind(("127.0.0.1", port)).unwrap());
    peer.wait_for_link();
    let capture = submit_ahead(&link, 1, 5.0, 1);
    let got = peer.collect_until(Duration::from_secs(2), |g| !landing_targets(g).is_empty());
    assert_eq!(landing_targets(&got)[0].time_usec, capture / 1000);
    link.shutdown();
}

#[test]
fn udpin_answers_whoever_speaks() {
    let rt = runtime();
    let port = free_udp_port();
    let cfg = link_config();
    let link = Link::start(&cfg, Some(&format!("udpin:127.0.0.1:{port}")), rt.handle()).unwrap();
    sleep(Duration::from_millis(300));
    // Nobody to send to yet: the heartbeat is dropped, not an error.
    assert!(link.stats().dropped_outgoing >= 1);
    let mut peer = UdpPeer::bind();
    peer.link = Some(([127, 0, 0, 1], port).into());
    peer.send(&autopilot_heartbeat());
    let got = peer.collect_until(Duration::from_millis(1500), |g| count(g, "HEARTBEAT") >= 1);
    assert!(count(&got, "HEARTBEAT") >= 1);
    link.shutdown();
}

/// Reads from a TCP peer connection until `done` or `limit`.
fn tcp_collect(
    stream: &mut std::net::TcpStream,
    bytes: &mut Vec<u8>,
    limit: Duration,
    done: impl FnMut(&[MavMessage]) -> bool,
) -> Vec<MavMessage> {
    stream
        .set_read_timeout(Some(Duration::from_millis(20)))
        .unwrap();
    collect_stream(stream, bytes, limit, done)
}

fn accept_within(listener: &TcpListener, limit: Duration) -> Option<std::net::TcpStream> {
    listener.set_nonblocking(true).unwrap();
    let end = Instant::now() + limit;
    while Instant::now() < end {
        if let Ok((s, _)) = listener.accept() {
            s.set_nonblocking(false).unwrap();
            return Some(s);
        }
        sleep(Duration::from_millis(5));
    }
    None
}

#[test]
fn tcp_poses_flow_and_survive_a_peer_restart() {
    use std::io::Write;
    let rt = runtime();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let mut cfg = link_config();
    cfg.reconnect_min_ms = 100;
    cfg.reconnect_max_ms = 400;
    cfg.max_age_ms = 200;
    let link = Link::start(&cfg, Some(&format!("tcpout:127.0.0.1:{port}")), rt.handle()).unwrap();
    let mut stream = accept_within(&listener, Duration::from_secs(2)).expect("link connects");
    stream
        .write_all(&encode(&autopilot_heartbeat(), 0, None))
        .unwrap();
    let capture = unix_now_ns();
    let det = detection([9.0, -0.3, 0.1], [-1.0, 0.0, 0.0], 1);
    link.submit(measurement(1, capture, Some(det)));
    let mut bytes = Vec::new();
    let msgs = tcp_collect(&mut stream, &mut bytes, Duration::from_secs(2), |m| {
        !landing_target_times(m).is_empty()
    });
    let lt = landing_targets_in(&msgs).swap_remove(0);
    assert_eq!(
        (lt.x, lt.y, lt.z, lt.time_usec),
        (9.0, -0.3, 0.1, capture / 1000)
    );
    // The link serves its output before its input (issue 16), so the pose
    // may go out before the heartbeat sent ahead of it is read.
    assert!(wait_for(Duration::from_secs(2), || link
        .stats()
        .last_heartbeat_age_s
        >= 0.0));

    // The peer goes away; a pose measured meanwhile must never arrive later.
    drop(stream);
    drop(listener);
    sleep(Duration::from_millis(100));
    let old_capture = submit_ahead(&link, 2, 9.0, 1);
    sleep(Duration::from_millis(600));
    let listener = TcpListener::bind(("127.0.0.1", port)).unwrap();
    let back = Instant::now();
    let mut stream = accept_within(&listener, Duration::from_secs(3)).expect("link reconnects");
    let reconnect_s = back.elapsed().as_secs_f64();
    assert!(reconnect_s < 1.5, "reconnected after {reconnect_s:.2} s");
    let capture2 = submit_ahead(&link, 3, 8.0, 2);
    let mut bytes = Vec::new();
    let msgs = tcp_collect(&mut stream, &mut bytes, Duration::from_secs(2), |m| {
        landing_target_times(m).contains(&(capture2 / 1000))
            && m.iter().any(|x| matches!(x, MavMessage::HEARTBEAT(_)))
    });
    let times = landing_target_times(&msgs);
    assert!(
        times.contains(&(capture2 / 1000)),
        "no pose after reconnect"
    );
    assert!(
        !times.contains(&(old_capture / 1000)),
        "a stale pose went out"
    );
    assert!(msgs.iter().any(|m| matches!(m, MavMessage::HEARTBEAT(_))));
    let s = link.stats();
    assert!(s.reconnects >= 1 && s.io_errors >= 1, "{s:?}");
    link.shutdown();
}

#[test]
fn udp_telemetry_is_placed_on_our_clock_by_timesync() {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let cfg = link_config();
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    // The autopilot booted an hour ago: its clock = Unix - boot.
    let boot_unix_ns = unix_now_ns() - 3_600_000_000_000;
    let got = peer.collect_until(Duration::from_secs(3), |g| {
        g.iter()
            .any(|x| matches!(&x.message, MavMessage::TIMESYNC(t) if t.tc1 == 0))
    });
    let ts1 = got
        .iter()
        .find_map(|g| match &g.message {
            MavMessage::TIMESYNC(t) if t.tc1 == 0 => Some(t.ts1),
            _ => None,
        })
        .expect("the link asks for TIMESYNC");
    let autopilot_ns = (unix_now_ns() - boot_unix_ns) as i64;
    peer.send(&MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: autopilot_ns,
        ts1,
        target_system: 1,
        target_component: 197,
    }));
    wait_for(Duration::from_secs(2), || {
        link.stats().timesync_offset_ns != 0
    });
    let offset = link.stats().timesync_offset_ns;
    let expect = -(boot_unix_ns as i64);
    assert!(
        (offset - expect).abs() < 50_000_000,
        "offset {offset} vs {expect}"
    );

    // Telemetry from 5 s ago (by the autopilot's clock), arriving now.
    let t1_ms = ((unix_now_ns() - boot_unix_ns) / 1_000_000 - 5000) as u32;
    for (dt, north) in [(0u32, 10.0f32), (100, 12.0)] {
        let mut att = attitude(0.0, 0.0, 0.0);
        let mut pos = local_position(north, 0.0, -5.0);
        if let MavMessage::ATTITUDE(a) = &mut att {
            a.time_boot_ms = t1_ms + dt;
        }
        if let MavMessage::LOCAL_POSITION_NED(p) = &mut pos {
            p.time_boot_ms = t1_ms + dt;
        }
        peer.send(&att);
        peer.send(&pos);
    }
    let mid = boot_unix_ns + (u64::from(t1_ms) + 50) * 1_000_000;
    wait_for(Duration::from_secs(2), || {
        link.vehicle_pose_at(mid)
            .is_some_and(|v| v.position_ned_m[0] > 10.5)
    });
    let v = link
        .vehicle_pose_at(mid)
        .expect("pose at the autopilot's time");
    // Halfway between the two samples, to within the sync error (< 50 ms of
    // a 20 m/s motion).
    assert!(
        close(v.position_ned_m[0], 11.0, 0.3),
        "{:?}",
        v.position_ned_m
    );
    assert_eq!(v.position_ned_m[2], -5.0);
    // Arrival time means nothing here: there is no pose at "now".
    assert!(link.vehicle_pose_at(unix_now_ns()).is_none());
    link.shutdown();
}
