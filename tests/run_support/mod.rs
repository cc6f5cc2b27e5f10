//! Shared helpers of the `run` end-to-end and closed-loop tests: a scripted
//! autopilot on UDP that frames and parses with the `mavlink` crate (not the
//! link's own framing), the `run` child process, and MCAP reading with the
//! `mcap` crate's stream reader.
#![allow(dead_code)]

use drogue_vision::testing;
use mavlink::dialects::ardupilotmega::{LANDING_TARGET_DATA, MavMessage, TIMESYNC_DATA};
use mavlink::{MavHeader, MavlinkVersion};
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_drogue-vision");

// Not every test uses every helper (as `dead_code` above).
#[allow(unused_imports)]
pub use drogue_vision::clock::unix_now_ns;

/// The vehicle's pose as the scripted autopilot reports it: LOCAL_POSITION_NED
/// (metres) and ATTITUDE (roll, pitch, yaw, radians), in the f32 the wire
/// carries, so that expectations use exactly what was sent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReportedPose {
    pub position_ned_m: [f32; 3],
    pub rpy_rad: [f32; 3],
}

/// What the scripted autopilot reports at a Unix time (ns); `None`: silent
/// (a telemetry gap).
pub type Script = Arc<dyn Fn(u64) -> Option<ReportedPose> + Send + Sync>;

/// One LANDING_TARGET as the peer received it.
#[derive(Clone, Debug)]
pub struct Received {
    pub arrival_ns: u64,
    pub target: LANDING_TARGET_DATA,
}

/// A scripted autopilot (sysid 1, compid 1) on 127.0.0.1 UDP: HEARTBEAT at
/// 1 Hz, ATTITUDE and LOCAL_POSITION_NED at `rate_hz` from `script`, answers
/// the link's TIMESYNC requests with its own boot clock, and keeps every
/// LANDING_TARGET it receives.
pub struct Autopilot {
    pub port: u16,
    stop: Arc<AtomicBool>,
    received: Arc<Mutex<Vec<Received>>>,
    thread: Option<JoinHandle<()>>,
}

impl Autopilot {
    pub fn start(script: Option<Script>, rate_hz: f64) -> Self {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(2)))
            .unwrap();
        let port = socket.local_addr().unwrap().port();
        let stop = Arc::new(AtomicBool::new(false));
        let received = Arc::new(Mutex::new(Vec::new()));
        let (s, r) = (stop.clone(), received.clone());
        let thread = std::thread::spawn(move || peer_loop(socket, script, rate_hz, s, r));
        Self {
            port,
            stop,
            received,
            thread: Some(thread),
        }
    }

    /// The `--mavlink` address for `run` (it sends to us).
    pub fn address(&self) -> String {
        format!("udpout:127.0.0.1:{}", self.port)
    }

    /// Stops the peer and returns every LANDING_TARGET it received.
    pub fn finish(mut self) -> Vec<Received> {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
        std::mem::take(&mut *self.received.lock().unwrap())
    }
}

fn encode(msg: &MavMessage, seq: &mut u8) -> Vec<u8> {
    let mut v = Vec::new();
    let h = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: *seq,
    };
    *seq = seq.wrapping_add(1);
    mavlink::write_v2_msg(&mut v, h, msg).unwrap();
    v
}

fn peer_loop(
    socket: UdpSocket,
    script: Option<Script>,
    rate_hz: f64,
    stop: Arc<AtomicBool>,
    received: Arc<Mutex<Vec<Received>>>,
) {
    let boot = Instant::now();
    let boot_unix_ns = unix_now_ns();
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let mut link: Option<SocketAddr> = None;
    let mut seq = 0u8;
    let mut next_telemetry = Instant::now();
    let mut next_heartbeat = Instant::now();
    let mut buf = [0u8; 2048];
    while !stop.load(Ordering::SeqCst) {
        let mut out: Vec<MavMessage> = Vec::new();
        if let Ok((n, from)) = socket.recv_from(&mut buf) {
            link = Some(from);
            let arrival_ns = unix_now_ns();
            let mut reader = mavlink::MavlinkReader::new(&buf[..n]);
            while let Ok((_, msg)) =
                reader.read_message_signed::<MavMessage>(MavlinkVersion::V2, None)
            {
                match msg {
                    MavMessage::LANDING_TARGET(target) => {
                        received
                            .lock()
                            .unwrap()
                            .push(Received { arrival_ns, target });
                    }
                    // The link asks for our clock: tc1 = our boot clock, ns.
                    MavMessage::TIMESYNC(t) if t.tc1 == 0 => {
                        out.push(MavMessage::TIMESYNC(TIMESYNC_DATA {
                            tc1: boot.elapsed().as_nanos() as i64,
                            ts1: t.ts1,
                            target_system: 0,
                            target_component: 0,
                        }));
                    }
                    _ => {}
                }
            }
        }
        let now = Instant::now();
        if now >= next_heartbeat {
            next_heartbeat += Duration::from_secs(1);
            out.push(testing::autopilot_heartbeat(0));
        }
        if now >= next_telemetry {
            next_telemetry += period;
            // The pose at exactly the (whole millisecond) time it is stamped with.
            let time_boot_ms = boot.elapsed().as_millis() as u32;
            let stamp_unix_ns = boot_unix_ns + u64::from(time_boot_ms) * 1_000_000;
            if let Some(pose) = script.as_ref().and_then(|s| s(stamp_unix_ns)) {
                out.push(testing::attitude(time_boot_ms, pose.rpy_rad));
                out.push(testing::local_position_ned(
                    time_boot_ms,
                    pose.position_ned_m,
                ));
            }
        }
        if let Some(to) = link {
            for m in &out {
                let _ = socket.send_to(&encode(m, &mut seq), to);
            }
        }
    }
}

/// `drogue-vision run` with `args`, stderr into `stderr_file`.
pub fn spawn_run(args: &[String], stderr_file: &Path) -> Child {
    Command::new(BIN)
        .arg("run")
        .args(args)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(stderr_file).unwrap())
        .spawn()
        .expect("start run")
}

/// What a `run` against a scripted peer ended with.
pub struct PeerRun {
    pub status: std::process::ExitStatus,
    /// The LANDING_TARGETs the peer received.
    pub received: Vec<Received>,
    pub stderr: String,
}

/// `drogue-vision run` talking MAVLink to `peer`, logging to `logs`, with
/// `config` laid over the default and `args` before those; ends the peer
/// once the run has ended (within 60 s) and its last datagrams are in.
pub fn run_with_peer(
    args: &[String],
    peer: Autopilot,
    logs: &Path,
    config: &Path,
    stderr_file: &Path,
) -> PeerRun {
    let mut all = args.to_vec();
    all.extend([
        "--mavlink".into(),
        peer.address(),
        "--log-dir".into(),
        logs.display().to_string(),
        "--config".into(),
        config.display().to_string(),
    ]);
    let mut child = spawn_run(&all, stderr_file);
    let status = wait_with_limit(&mut child, Duration::from_secs(60));
    // Stragglers still in flight.
    std::thread::sleep(Duration::from_millis(100));
    PeerRun {
        status,
        received: peer.finish(),
        stderr: std::fs::read_to_string(stderr_file).unwrap(),
    }
}

/// Waits for the child, killing it after `limit`.
pub fn wait_with_limit(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let end = Instant::now() + limit;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if Instant::now() > end {
            let _ = child.kill();
            panic!("run did not end by itself within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The only MCAP file in `dir`.
pub fn only_log(dir: &Path) -> PathBuf {
    let logs: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("log dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    assert_eq!(logs.len(), 1, "{logs:?}");
    logs[0].clone()
}

/// One logged message: topic, log time, payload.
pub struct Logged {
    pub topic: String,
    /// The MCAP sequence (the frame's for everything derived from a frame).
    pub sequence: u32,
    pub log_time_ns: u64,
    pub data: Vec<u8>,
}

/// Every message of an MCAP file, read with the `mcap` crate's stream reader.
pub fn read_log(path: &Path) -> Vec<Logged> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| {
            let m = m.expect("a readable message");
            Logged {
                topic: m.channel.topic.clone(),
                sequence: m.sequence,
                log_time_ns: m.log_time,
                data: m.data.to_vec(),
            }
        })
        .collect()
}

/// `run ended: N frames` from the summary on stderr.
pub fn frames_in_summary(stderr: &str) -> u64 {
    let line = stderr
        .lines()
        .find(|l| l.starts_with("run ended:"))
        .unwrap_or_else(|| panic!("no summary line in:\n{stderr}"));
    line["run ended:".len()..]
        .split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap()
}
