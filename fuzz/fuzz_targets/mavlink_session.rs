//! What the link's session does with received bytes, without the network:
//! frames found (signed with a fixed key, or not), then every accepted
//! ATTITUDE, LOCAL_POSITION_NED and TIMESYNC handed to the telemetry and
//! clock-sync state as the session does, and the vehicle pose asked for.
#![no_main]

use drogue_vision::link::frame::{DecodeCounts, FrameDecoder};
use drogue_vision::link::telemetry::Telemetry;
use libfuzzer_sys::fuzz_target;
use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{SigningConfig, SigningData};

fuzz_target!(|data: &[u8]| {
    let Some((&mode, bytes)) = data.split_first() else {
        return;
    };
    let signing = (mode & 1 == 1).then(|| {
        SigningData::from_config(SigningConfig::new([7u8; 32], 0, true, mode & 2 == 2))
    });
    let mut d = FrameDecoder::new();
    let (mut out, mut counts) = (Vec::new(), DecodeCounts::default());
    d.feed(bytes, mode & 4 == 4, signing.as_ref(), &mut counts, &mut out);
    let mut t = Telemetry::new(100_000_000);
    let mut now: u64 = 1_000_000_000;
    for m in out {
        now += 10_000_000;
        match m.message {
            MavMessage::ATTITUDE(a) => t.push_attitude(a.time_boot_ms, [a.roll, a.pitch, a.yaw], now),
            MavMessage::LOCAL_POSITION_NED(p) => t.push_position(p.time_boot_ms, [p.x, p.y, p.z], now),
            MavMessage::TIMESYNC(s) => {
                let now = now as i64;
                if s.tc1 == 0 {
                    t.timesync.request_seen(s.ts1, now);
                } else {
                    t.timesync.reply(s.tc1, s.ts1, now);
                }
                let _ = t.timesync.offset_ns();
            }
            _ => {}
        }
        let _ = t.pose_at(now);
    }
});
