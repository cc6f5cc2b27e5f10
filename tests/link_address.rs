//! The address forms MAVProxy and pymavlink read (`tcpin:`, `udpbcast:`,
//! `udp:` = listen) and the link's health (only an autopilot's heartbeat
//! counts), on 127.0.0.0/8 only, against a peer that frames and parses with
//! the `mavlink` crate's own reader and writer.

mod link_common;

use drogue_vision::link::Link;
use link_common::*;
use mavlink::dialects::ardupilotmega::{MavAutopilot, MavMessage, MavType};
use std::io::Write;
use std::net::{TcpStream, UdpSocket};
use std::time::{Duration, Instant};

/// Connects to the link's `tcpin` listener, retrying while it binds.
fn connect(port: u16) -> TcpStream {
    let end = Instant::now() + Duration::from_secs(5);
    loop {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => {
                s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
                return s;
            }
            Err(e) if Instant::now() > end => panic!("cannot connect to tcpin: {e}"),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// Reads until `n` messages named `name` arrived (or 3 s passed).
fn read_until(stream: &mut TcpStream, name: &str, n: usize) -> Vec<MavMessage> {
    use mavlink::Message;
    collect_stream(stream, &mut Vec::new(), Duration::from_secs(3), |msgs| {
        msgs.iter().filter(|m| m.message_name() == name).count() >= n
    })
}

#[test]
fn tcpin_serves_one_client_then_the_next() {
    let rt = runtime();
    let port = free_tcp_port();
    let mut cfg = link_config();
    cfg.heartbeat_interval_ms = 100;
    let link = Link::start(&cfg, Some(&format!("tcpin:127.0.0.1:{port}")), rt.handle()).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    // Listening, no client yet: not open, and the state says so.
    let s = link.stats();
    assert!(!s.opened && !s.connected, "{s:?}");
    assert_eq!(s.state(), "never opened");

    let mut first = connect(port);
    let got = read_until(&mut first, "HEARTBEAT", 2);
    assert!(got.len() >= 2, "first client got {got:?}");
    first
        .write_all(&encode(&autopilot_heartbeat(), 0, None))
        .unwrap();
    assert!(wait_for(Duration::from_secs(2), || link
        .stats()
        .autopilot_heard()));
    assert!(link.stats().opened);
    drop(first);

    // The link notices the hang-up, listens again, and serves the next one.
    let mut second = connect(port);
    let got = read_until(&mut second, "HEARTBEAT", 1);
    assert!(!got.is_empty(), "second client got nothing");
    assert!(wait_for(Duration::from_secs(2), || link.stats().reconnects >= 1));
    link.shutdown();
}

#[test]
fn udp_means_listen_as_in_mavproxy() {
    let rt = runtime();
    let port = free_udp_port();
    let link = Link::start(
        &link_config(),
        Some(&format!("udp:127.0.0.1:{port}")),
        rt.handle(),
    )
    .unwrap();
    // A listener on that port: a peer that speaks to it is answered (as
    // `udpout:` the link would have sent from an ephemeral port instead).
    let mut peer = UdpPeer::bind();
    std::thread::sleep(Duration::from_millis(300));
    peer.link = Some(([127, 0, 0, 1], port).into());
    peer.send(&autopilot_heartbeat());
    let got = peer.collect_until(Duration::from_millis(2500), |g| count(g, "HEARTBEAT") >= 1);
    assert!(count(&got, "HEARTBEAT") >= 1);
    link.shutdown();
}

#[test]
fn udpbcast_broadcasts_then_locks_on_the_first_peer() {
    let rt = runtime();
    // A socket on the loopback broadcast address receives what is sent to it;
    // sending there at all needs SO_BROADCAST (EACCES without it).
    let bcast = UdpSocket::bind("127.255.255.255:0").unwrap();
    let port = bcast.local_addr().unwrap().port();
    let mut listener = UdpPeer::on(bcast);
    let mut cfg = link_config();
    cfg.heartbeat_interval_ms = 100;
    let link = Link::start(
        &cfg,
        Some(&format!("udpbcast:127.255.255.255:{port}")),
        rt.handle(),
    )
    .unwrap();
    let got = listener.collect_until(Duration::from_secs(3), |g| count(g, "HEARTBEAT") >= 2);
    assert!(count(&got, "HEARTBEAT") >= 2, "nothing broadcast: {got:?}");
    let link_addr = listener.link.expect("the link's address");

    // A peer answers from its own (unicast) socket: the link now sends there.
    let mut peer = UdpPeer::bind();
    peer.link = Some(link_addr);
    peer.send(&autopilot_heartbeat());
    let got = peer.collect_until(Duration::from_secs(3), |g| count(g, "HEARTBEAT") >= 2);
    assert!(count(&got, "HEARTBEAT") >= 2, "no lock-on: {got:?}");
    assert!(link.stats().autopilot_heard());
    // ... and no longer to the broadcast address (a frame in flight at the
    // switch may still arrive: drain first).
    let _ = listener.collect_until(Duration::from_millis(150), |_| false);
    let after = listener.collect_until(Duration::from_millis(600), |g| !g.is_empty());
    assert!(after.is_empty(), "still broadcasting after lock-on");
    link.shutdown();
}

#[test]
fn a_ground_station_heartbeat_is_not_the_autopilot() {
    let rt = runtime();
    let mut peer = UdpPeer::bind();
    let mut cfg = link_config();
    cfg.heartbeat_timeout_ms = 300;
    let link = Link::start(&cfg, Some(&peer.address()), rt.handle()).unwrap();
    peer.wait_for_link();
    let s = link.stats();
    assert!(s.opened && !s.autopilot_heard(), "{s:?}");
    assert_eq!(s.state(), "open, autopilot never heard");

    // Same system id (1), but a ground station, a router/companion, and a
    // camera that names no autopilot: none of them is the autopilot, even
    // with an autopilot field set (a GCS that copies the vehicle's).
    for hb in [
        heartbeat(
            MavType::MAV_TYPE_GCS,
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            0,
        ),
        heartbeat(
            MavType::MAV_TYPE_GCS,
            MavAutopilot::MAV_AUTOPILOT_INVALID,
            0,
        ),
        heartbeat(
            MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            MavAutopilot::MAV_AUTOPILOT_PX4,
            0,
        ),
        heartbeat(
            MavType::MAV_TYPE_CAMERA,
            MavAutopilot::MAV_AUTOPILOT_INVALID,
            0,
        ),
    ] {
        peer.send(&hb);
    }
    // They were received (so the link did read them) but did not count.
    assert!(wait_for(Duration::from_secs(2), || link.stats().received >= 4));
    std::thread::sleep(Duration::from_millis(100));
    let s = link.stats();
    assert!(
        !s.autopilot_heard(),
        "a non-autopilot heartbeat counted: {s:?}"
    );
    assert_eq!(s.heartbeat_losses, 0);

    // A fixed-wing PX4 is an autopilot.
    peer.send(&heartbeat(
        MavType::MAV_TYPE_FIXED_WING,
        MavAutopilot::MAV_AUTOPILOT_PX4,
        0,
    ));
    assert!(wait_for(Duration::from_secs(2), || link
        .stats()
        .autopilot_heard()));
    assert!(link.stats().state().starts_with("open, autopilot heard"));
    // Then only the ground station keeps talking: the autopilot is lost.
    let end = Instant::now() + Duration::from_millis(800);
    while Instant::now() < end {
        peer.send(&heartbeat(
            MavType::MAV_TYPE_GCS,
            MavAutopilot::MAV_AUTOPILOT_INVALID,
            0,
        ));
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(wait_for(Duration::from_secs(2), || link
        .stats()
        .heartbeat_losses
        == 1));
    link.shutdown();
}

#[test]
fn a_link_that_never_opened_says_so() {
    let rt = runtime();
    let link = Link::start(
        &link_config(),
        Some("serial:/nonexistent/ttyDROGUE:57600"),
        rt.handle(),
    )
    .unwrap();
    assert!(wait_for(Duration::from_secs(2), || link.stats().io_errors >= 1));
    let s = link.stats();
    assert!(!s.opened && !s.connected);
    assert_eq!(s.state(), "never opened");
    link.shutdown();
}

#[test]
fn unknown_forms_are_refused_with_the_list() {
    let rt = runtime();
    for bad in ["udpx:127.0.0.1:14550", "file:/tmp/x.tlog", "/dev/ttyACM0"] {
        let e = Link::start(&link_config(), Some(bad), rt.handle())
            .err()
            .unwrap_or_else(|| panic!("{bad} accepted"))
            .to_string();
        assert!(e.contains("udpbcast:") && e.contains("tcpin:"), "{e}");
    }
}
