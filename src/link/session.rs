//! The link's two tasks: the pose task (measurements → pose messages) and the
//! connection task (transport, reconnection, heartbeat, TIMESYNC, telemetry).
//! Each task has its file (`session/pose.rs`, `session/connection.rs`); here
//! is what the two share.

use super::Settings;
use super::events::EventSender;
use super::handoff::Handoff;
use super::messages::Outbound;
use super::stats::Counters;
use super::telemetry::Telemetry;
use crate::clock::RunClock;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

mod connection;
mod pose;

pub(crate) use connection::connection_task;
pub(crate) use pose::pose_task;

/// Most bytes read from a stream transport per turn of the connection loop
/// (a datagram is read whole, up to this size: MAVLink frames are smaller).
const READ_CHUNK: usize = 4096;

/// What both tasks share.
#[derive(Clone)]
pub(crate) struct Context {
    pub settings: Arc<Settings>,
    pub counters: Arc<Counters>,
    pub telemetry: Arc<Mutex<Telemetry>>,
    pub events: EventSender,
    pub stopped: Arc<AtomicBool>,
    /// The run's clock: staleness and the events' times (module docs of
    /// [`super`]).
    pub clock: RunClock,
    pub handoff: Arc<Handoff>,
}

/// A pose message on its way to the connection task.
pub(crate) struct Outgoing {
    pub message: Outbound,
    pub capture_time_ns: u64,
    /// The last message of its measurement: once it is written or dropped,
    /// the link is done with that measurement ([`Handoff`]).
    pub last: bool,
}

/// The wall clock, ns since the Unix epoch: TIMESYNC's and the telemetry's
/// clock (the protocol's times are always real).
pub(crate) fn unix_now_ns() -> u64 {
    crate::clock::unix_now_ns()
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Context {
    /// Older than `max_age_ms` now, on the run's clock?
    fn is_stale(&self, capture_time_ns: u64) -> bool {
        let max_age_ms = self.settings.cfg.max_age_ms;
        max_age_ms > 0
            && self.clock.now_ns().saturating_sub(capture_time_ns) > max_age_ms * 1_000_000
    }

    /// The time of a message sent or received at `wall_ns`, on the run's
    /// clock (the log's).
    fn event_time_ns(&self, wall_ns: u64) -> u64 {
        if self.clock.is_source() {
            self.clock.now_ns()
        } else {
            wall_ns
        }
    }
}

#[cfg(test)]
mod tests {
    use super::pose::{RateLimit, build_pose_messages};
    use super::*;
    use crate::config::Config;
    use crate::link::messages::tests::detection;
    use crate::link::telemetry::CONVERGED_REPLIES;
    use crate::link::{PoseMessage, TimeClock};
    use crate::measure::Measurement;
    use crate::measure::StageTimes;
    use mavlink::dialects::development as dev;
    use nalgebra::Vector3;

    const CAPTURE_NS: u64 = 1_700_000_000_123_456_789;
    /// The autopilot's clock (µs since its boot, as ns) minus ours.
    const AUTOPILOT_MINUS_OURS_NS: i64 = -1_699_999_000_000_000_000;

    fn context(cfg: &super::super::LinkConfig) -> Context {
        Context {
            settings: Arc::new(super::super::validate(cfg, None).unwrap()),
            counters: Arc::default(),
            telemetry: Arc::new(Mutex::new(Telemetry::new(50_000_000))),
            events: super::super::events::event_queue(8, 10.0).0,
            stopped: Arc::default(),
            clock: RunClock::wall(),
            handoff: Arc::default(),
        }
    }

    /// Our TIMESYNC requests answered by the autopilot (1 ms each way).
    fn converge(ctx: &Context) {
        let mut tm = lock(&ctx.telemetry);
        for k in 0..CONVERGED_REPLIES as i64 {
            let ts1 = 1_700_000_000_000_000_000 + k * 1_000_000_000;
            tm.timesync.request_sent(ts1);
            assert!(tm.timesync.reply(
                ts1 + 1_000_000 + AUTOPILOT_MINUS_OURS_NS,
                ts1,
                ts1 + 2_000_000
            ));
        }
    }

    fn target_relative_timestamp_us(ctx: &Context) -> u64 {
        let m = Measurement {
            seq: 1,
            capture_time_ns: CAPTURE_NS,
            detection: Some(detection(
                Vector3::new(6.0, 0.5, -0.3),
                Vector3::new(-1.0, 0.0, 0.0),
            )),
            miss: None,
            tracked: false,
            times: StageTimes::default(),
        };
        let mut out = Vec::new();
        build_pose_messages(ctx, &m, &mut out);
        match out.as_slice() {
            [Outbound::Development(dev::MavMessage::TARGET_RELATIVE(t))] => t.timestamp,
            other => panic!("not one TARGET_RELATIVE: {}", other.len()),
        }
    }

    /// PX4's receiver maps a companion's stamp with its own timesync
    /// (`Timesync::sync_stamp`: the stamp plus the offset PX4 measured
    /// against our TIMESYNC replies once converged, else its arrival time),
    /// and the message defines `timestamp` as Unix time (README, "PX4:
    /// TARGET_RELATIVE"). So by default it is the capture time on our Unix
    /// clock, also once our own TIMESYNC has converged; "autopilot" moves it
    /// onto the autopilot's clock only then.
    #[test]
    fn target_relative_timestamp_is_our_clock_by_default_even_once_converged() {
        let mut cfg = Config::embedded().link;
        assert_eq!(cfg.target_relative_clock, TimeClock::Own);
        cfg.messages = vec![PoseMessage::TargetRelative];
        let ours_us = CAPTURE_NS / 1000;
        let own = context(&cfg);
        assert_eq!(target_relative_timestamp_us(&own), ours_us);
        converge(&own);
        assert_eq!(target_relative_timestamp_us(&own), ours_us);

        cfg.target_relative_clock = TimeClock::Autopilot;
        let autopilot = context(&cfg);
        // Not converged: our clock, PX4 maps it as for "own".
        assert_eq!(target_relative_timestamp_us(&autopilot), ours_us);
        converge(&autopilot);
        let want_us = (CAPTURE_NS as i64 + AUTOPILOT_MINUS_OURS_NS) as u64 / 1000;
        assert_eq!(target_relative_timestamp_us(&autopilot), want_us);
        assert_eq!(
            want_us, 1_000_123_456,
            "the autopilot's clock: 1000.1 s since boot"
        );
    }

    #[test]
    fn the_rate_limit_passes_a_source_at_its_rate_and_thins_a_faster_one() {
        // 30 fps capture times against a 30 Hz limit: all pass (a hair of
        // rounding is not a missing token); 60 fps against 30 Hz: half.
        for (fps, limit_hz, want) in [(30.0, 30.0, 300), (30.0, 50.0, 300), (60.0, 30.0, 151)] {
            let mut limit = RateLimit::new(limit_hz);
            let mut sent = 0;
            for k in 0..300u64 {
                let now_s = k as f64 / fps;
                if limit.wait_s(now_s).is_none() {
                    limit.spend(now_s);
                    sent += 1;
                }
            }
            assert_eq!(sent, want, "{fps} fps at {limit_hz} Hz");
        }
    }
}
