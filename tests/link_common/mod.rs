//! Shared helpers for the link integration tests: hand-built measurements
//! with known values (the fixtures of `drogue_vision::testing`), and a
//! MAVLink peer that frames and parses with the `mavlink` crate's own reader
//! and writer (independent of `link::frame`).
#![allow(dead_code)]

use drogue_vision::config::Config;
use drogue_vision::link::{LinkConfig, LinkHandle};
use drogue_vision::measure::{Detection, Measurement};
use drogue_vision::testing;
use mavlink::dialects::ardupilotmega::{LANDING_TARGET_DATA, MavMessage};
use mavlink::{MavHeader, MavlinkVersion, SigningData};
use std::io::Read;
use std::net::{SocketAddr, TcpListener, UdpSocket};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The embedded default `[link]`, for the test to adjust.
pub fn link_config() -> LinkConfig {
    Config::embedded().link
}

// Not every test uses every helper (as `dead_code` above).
#[allow(unused_imports)]
pub use drogue_vision::{
    clock::unix_now_ns,
    testing::{detection, heartbeat},
};

/// [`testing::measurement`], shared as the link takes it.
pub fn measurement(
    seq: u64,
    capture_time_ns: u64,
    detection: Option<Detection>,
) -> Arc<Measurement> {
    Arc::new(testing::measurement(seq, capture_time_ns, detection))
}

/// An ArduPilot quadrotor's HEARTBEAT (flight mode 4, GUIDED).
pub fn autopilot_heartbeat() -> MavMessage {
    testing::autopilot_heartbeat(4)
}

/// Submits a detection `range_m` straight ahead, its axis back at the
/// vehicle, captured now; returns the capture time (ns since the epoch).
pub fn submit_ahead(link: &LinkHandle, seq: u64, range_m: f64, track_epoch: u32) -> u64 {
    let capture = unix_now_ns();
    let ahead = detection([range_m, 0.0, 0.0], [-1.0, 0.0, 0.0], track_epoch);
    link.submit(measurement(seq, capture, Some(ahead)));
    capture
}

/// A loopback UDP port nobody listens on (bound, then released).
pub fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A loopback TCP port nobody listens on (bound, then released).
pub fn free_tcp_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Every LANDING_TARGET among `msgs`, in order.
pub fn landing_targets_in(msgs: &[MavMessage]) -> Vec<LANDING_TARGET_DATA> {
    msgs.iter()
        .filter_map(|m| match m {
            MavMessage::LANDING_TARGET(l) => Some(l.clone()),
            _ => None,
        })
        .collect()
}

/// The `time_usec` of every LANDING_TARGET among `msgs`, in order.
pub fn landing_target_times(msgs: &[MavMessage]) -> Vec<u64> {
    landing_targets_in(msgs)
        .iter()
        .map(|l| l.time_usec)
        .collect()
}

pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// ATTITUDE at boot time 1 s.
pub fn attitude(roll: f32, pitch: f32, yaw: f32) -> MavMessage {
    testing::attitude(1000, [roll, pitch, yaw])
}

/// LOCAL_POSITION_NED at boot time 1 s, at rest.
pub fn local_position(x: f32, y: f32, z: f32) -> MavMessage {
    testing::local_position_ned(1000, [x, y, z])
}

/// One message as the peer saw it.
#[derive(Clone, Debug)]
pub struct Got {
    pub at: Instant,
    pub header: MavHeader,
    pub message: MavMessage,
}

/// Frames `msg` with the crate's writer, as the autopilot (sysid 1, compid 1).
pub fn encode(msg: &MavMessage, seq: u8, signing: Option<&SigningData>) -> Vec<u8> {
    let mut v = Vec::new();
    let h = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: seq,
    };
    mavlink::write_v2_msg_signed(&mut v, h, msg, signing).unwrap();
    v
}

/// Parses every MAVLink 2 message in `bytes` with the crate's reader
/// (checking CRC and, with `signing`, signatures).
pub fn parse_all(bytes: &[u8], signing: Option<&SigningData>) -> Vec<(MavHeader, MavMessage)> {
    let mut r = mavlink::MavlinkReader::new(bytes);
    let mut out = Vec::new();
    while let Ok(m) = r.read_message_signed::<MavMessage>(MavlinkVersion::V2, signing) {
        out.push(m);
    }
    out
}

/// Reads a byte stream from the link (a TCP connection, a serial port's
/// master end; with a read timeout, so that `limit` holds) into `bytes`
/// until the messages parsed from all of it satisfy `done` or `limit`
/// passes, and returns those messages.
pub fn collect_stream(
    stream: &mut impl Read,
    bytes: &mut Vec<u8>,
    limit: Duration,
    mut done: impl FnMut(&[MavMessage]) -> bool,
) -> Vec<MavMessage> {
    let end = Instant::now() + limit;
    let mut buf = [0u8; 4096];
    loop {
        let msgs: Vec<MavMessage> = parse_all(bytes, None).into_iter().map(|m| m.1).collect();
        if done(&msgs) || Instant::now() > end {
            return msgs;
        }
        if let Ok(n) = stream.read(&mut buf) {
            bytes.extend_from_slice(&buf[..n]);
        }
    }
}

/// The autopilot end of a UDP link, on 127.0.0.1.
pub struct UdpPeer {
    pub socket: UdpSocket,
    /// Where the link sends from (learnt from its first datagram).
    pub link: Option<SocketAddr>,
    pub signing: Option<SigningData>,
    seq: u8,
}

impl UdpPeer {
    pub fn bind() -> Self {
        Self::on(UdpSocket::bind("127.0.0.1:0").unwrap())
    }

    pub fn on(socket: UdpSocket) -> Self {
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        Self {
            socket,
            link: None,
            signing: None,
            seq: 0,
        }
    }

    pub fn address(&self) -> String {
        format!("udpout:{}", self.socket.local_addr().unwrap())
    }

    /// Collects messages until `done` says so or `limit` passes.
    pub fn collect_until(
        &mut self,
        limit: Duration,
        mut done: impl FnMut(&[Got]) -> bool,
    ) -> Vec<Got> {
        let end = Instant::now() + limit;
        let mut got = Vec::new();
        let mut buf = [0u8; 2048];
        while Instant::now() < end && !done(&got) {
            if let Ok((n, from)) = self.socket.recv_from(&mut buf) {
                self.link = Some(from);
                let at = Instant::now();
                for (header, message) in parse_all(&buf[..n], self.signing.as_ref()) {
                    got.push(Got {
                        at,
                        header,
                        message,
                    });
                }
            }
        }
        got
    }

    /// Waits for the link's first datagram, so the peer knows where it is.
    pub fn wait_for_link(&mut self) {
        let got = self.collect_until(Duration::from_secs(3), |g| !g.is_empty());
        assert!(!got.is_empty(), "the link sent nothing within 3 s");
    }

    pub fn send(&mut self, msg: &MavMessage) {
        self.send_with(msg, None);
    }

    pub fn send_with(&mut self, msg: &MavMessage, signing: Option<&SigningData>) {
        let bytes = encode(msg, self.seq, signing);
        self.seq = self.seq.wrapping_add(1);
        self.send_raw(&bytes);
    }

    pub fn send_raw(&self, bytes: &[u8]) {
        let to = self.link.expect("link address not known yet");
        self.socket.send_to(bytes, to).unwrap();
    }
}

pub fn landing_targets(got: &[Got]) -> Vec<LANDING_TARGET_DATA> {
    got.iter()
        .filter_map(|g| match &g.message {
            MavMessage::LANDING_TARGET(d) => Some(d.clone()),
            _ => None,
        })
        .collect()
}

pub fn count(got: &[Got], name: &str) -> usize {
    use mavlink::Message;
    got.iter()
        .filter(|g| g.message.message_name() == name)
        .count()
}

/// Polls `cond` until it holds or `limit` passes; returns whether it held.
/// (Loaded CI machines: never assume a fixed sleep was long enough.)
pub fn wait_for(limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let end = Instant::now() + limit;
    loop {
        if cond() {
            return true;
        }
        if Instant::now() > end {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}
