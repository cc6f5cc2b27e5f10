//! Shared helpers for the link integration tests: hand-built measurements
//! with known values, and a MAVLink peer that frames and parses with the
//! `mavlink` crate's own reader and writer (independent of `link::frame`).
#![allow(dead_code)]

use drogue_vision::config::Config;
use drogue_vision::link::LinkConfig;
use drogue_vision::measure::ellipse::Ellipse;
use drogue_vision::measure::{
    CirclePose, Detection, Disambiguation, FitQuality, Measurement, StageTimes,
};
use drogue_vision::spatial::{Direction, Point};
use mavlink::dialects::ardupilotmega::{
    ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavMessage, MavModeFlag,
    MavState, MavType,
};
use mavlink::{MavHeader, MavlinkVersion, SigningData};
use nalgebra::{Matrix3, Vector3};
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

pub fn unix_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

/// The embedded default `[link]`, for the test to adjust.
pub fn link_config() -> LinkConfig {
    Config::embedded().link
}

pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// A detection with the given drogue centre and normal (body FRD), the
/// default forward-looking mount (camera x = body y, y = body z, z = body x).
pub fn detection(position_body_m: [f64; 3], normal_body: [f64; 3], epoch: u32) -> Detection {
    let p = Vector3::from(position_body_m);
    let n = Vector3::from(normal_body);
    Detection {
        ellipse_px: Ellipse {
            cx: 640.0,
            cy: 480.0,
            a: 40.0,
            b: 38.0,
            theta: 0.0,
        },
        pose_camera: CirclePose {
            centre_camera_m: Vector3::new(p.y, p.z, p.x),
            normal_camera: Vector3::new(n.y, n.z, n.x),
        },
        alt_pose_camera: None,
        disambiguation: Disambiguation::CanopyRim,
        position_body_m: Point::new(p),
        normal_body: Direction::new(n),
        position_from_probe_body_m: Point::new(p),
        position_cov_body_m2: Matrix3::from_diagonal(&Vector3::new(4e-4, 1e-5, 2e-5)),
        normal_sigma_rad: 0.02,
        quality: FitQuality {
            points: 200,
            inliers: 180,
            rms_residual_px: 0.3,
            score: 0.8,
        },
        track_epoch: epoch,
        rim_points_px: vec![],
        inliers: vec![],
    }
}

pub fn measurement(
    seq: u64,
    capture_time_ns: u64,
    detection: Option<Detection>,
) -> Arc<Measurement> {
    Arc::new(Measurement {
        seq,
        capture_time_ns,
        detection,
        tracked: false,
        times: StageTimes::default(),
    })
}

pub fn autopilot_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 4,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

pub fn attitude(roll: f32, pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms: 1000,
        roll,
        pitch,
        yaw,
        rollspeed: 0.0,
        pitchspeed: 0.0,
        yawspeed: 0.0,
    })
}

pub fn local_position(x: f32, y: f32, z: f32) -> MavMessage {
    MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms: 1000,
        x,
        y,
        z,
        vx: 0.0,
        vy: 0.0,
        vz: 0.0,
    })
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

pub fn landing_targets(got: &[Got]) -> Vec<mavlink::dialects::ardupilotmega::LANDING_TARGET_DATA> {
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
