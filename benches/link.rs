//! Cost of one pose on the link: building the MAVLink messages from a
//! measurement, framing (and signing) them, writing them to a UDP socket and
//! the decoded event for the log; and the submit → on-the-wire latency
//! through the running link.

use criterion::{Criterion, criterion_group, criterion_main};
use drogue_vision::config::Config;
use drogue_vision::link::frame::FrameEncoder;
use drogue_vision::link::messages::{self, DroguePose};
use drogue_vision::link::{Link, PoseMessage};
use drogue_vision::measure::Measurement;
use drogue_vision::testing;
use mavlink::{SigningConfig, SigningData};
use nalgebra::Vector3;
use std::hint::black_box;
use std::net::UdpSocket;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

fn measurement() -> Measurement {
    let p = Vector3::new(8.0, 0.4, -0.2);
    let n = Vector3::new(-0.98, 0.1, 0.17).normalize();
    let mut detection = testing::detection(p, n, 1);
    detection.ellipse_px.theta = 0.1;
    Measurement {
        tracked: true,
        ..testing::measurement(1, 1_700_000_000_000_000_000, Some(detection))
    }
}

fn bench_encode_send(c: &mut Criterion) {
    let m = measurement();
    let det = m.detection.clone().unwrap();
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = sink.local_addr().unwrap();
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut enc = FrameEncoder::new(1, 197);
    let signing = SigningData::from_config(SigningConfig::new([7; 32], 0, true, false));

    c.bench_function("link/landing_target build+encode", |b| {
        b.iter(|| {
            let pose = DroguePose::new(black_box(&det)).unwrap();
            let msg = messages::landing_target_body(&m, &pose, &det);
            black_box(enc.encode(&msg, None));
        });
    });
    c.bench_function("link/landing_target build+encode+udp send+event", |b| {
        b.iter(|| {
            let pose = DroguePose::new(black_box(&det)).unwrap();
            let msg = messages::landing_target_body(&m, &pose, &det);
            let raw = enc.encode(&msg, None);
            socket.send_to(raw.raw_bytes(), to).unwrap();
            black_box(messages::fields_json(&msg));
        });
    });
    c.bench_function(
        "link/landing_target signed build+encode+udp send+event",
        |b| {
            b.iter(|| {
                let pose = DroguePose::new(black_box(&det)).unwrap();
                let msg = messages::landing_target_body(&m, &pose, &det);
                let raw = enc.encode(&msg, Some(&signing));
                socket.send_to(raw.raw_bytes(), to).unwrap();
                black_box(messages::fields_json(&msg));
            });
        },
    );
    c.bench_function(
        "link/3 messages (LT+VPE+ODOMETRY) build+encode+udp send",
        |b| {
            b.iter(|| {
                let pose = DroguePose::new(black_box(&det)).unwrap();
                for msg in [
                    messages::landing_target_body(&m, &pose, &det),
                    messages::vision_position_estimate(&m, &pose, &det),
                    messages::odometry(&m, &pose, &det),
                ] {
                    let raw = enc.encode(&msg, None);
                    socket.send_to(raw.raw_bytes(), to).unwrap();
                }
            });
        },
    );
}

/// submit() → the datagram arriving at a loopback peer, through the running
/// link (tasks, channels, framing, socket): the capture → send latency the
/// link adds on top of the measurement.
fn bench_submit_to_wire(c: &mut Criterion) {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    let mut cfg = Config::embedded().link;
    cfg.messages = vec![PoseMessage::LandingTarget];
    cfg.max_rate_hz = 0.0;
    cfg.max_age_ms = 0;
    cfg.timesync_interval_ms = 0;
    let addr = format!("udpout:{}", peer.local_addr().unwrap());
    let link = Link::start(&cfg, Some(&addr), rt.handle()).unwrap();
    let base = measurement();
    let mut buf = [0u8; 512];
    let mut seq = 0u64;
    c.bench_function("link/submit to wire (loopback UDP)", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                seq += 1;
                let mut m = base.clone();
                m.seq = seq;
                m.capture_time_ns = SystemTime::now()
                    .duration_since(UNIX_EPOCH)
                    .unwrap()
                    .as_nanos() as u64;
                let t0 = Instant::now();
                link.submit(Arc::new(m));
                // Skip heartbeats: wait for the LANDING_TARGET (id 149).
                while let Ok((n, _)) = peer.recv_from(&mut buf) {
                    if n > 10 && buf[7] == 149 && buf[8] == 0 {
                        break;
                    }
                }
                total += t0.elapsed();
            }
            total
        });
    });
    link.shutdown();
}

criterion_group!(benches, bench_encode_send, bench_submit_to_wire);
criterion_main!(benches);
