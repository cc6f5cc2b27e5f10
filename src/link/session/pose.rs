//! The pose task: takes the newest measurement (older ones are dropped:
//! latest wins), drops it when too old, holds the configured rate with a
//! token bucket, builds the configured messages and queues them for the
//! connection task.

use super::super::messages::{self, DroguePose, Outbound, TargetRelativeInputs};
use super::super::stats::bump;
use super::super::{PoseMessage, TimeClock};
use super::{Context, Outgoing, lock};
use crate::measure::Measurement;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio::time::sleep_until;

/// Builds the configured messages for one measurement; empty when nothing
/// may be sent (no detection, degenerate values, no vehicle pose for NED).
pub(crate) fn build_pose_messages(ctx: &Context, m: &Measurement, out: &mut Vec<Outbound>) {
    let Some(det) = m.detection.as_ref() else {
        bump(&ctx.counters.no_detection, 1);
        return;
    };
    let Some(pose) = DroguePose::new(det) else {
        bump(&ctx.counters.invalid_measurement, 1);
        return;
    };
    for kind in &ctx.settings.cfg.messages {
        match kind {
            PoseMessage::LandingTarget => {
                out.push(messages::landing_target_body(m, &pose, det).into());
            }
            PoseMessage::LandingTargetNed => {
                let vehicle = lock(&ctx.telemetry).pose_at(m.capture_time_ns);
                match vehicle.and_then(|v| messages::landing_target_ned(m, &pose, det, &v)) {
                    Some(msg) => out.push(msg.into()),
                    None => bump(&ctx.counters.no_vehicle_pose, 1),
                }
            }
            PoseMessage::VisionPositionEstimate => {
                out.push(messages::vision_position_estimate(m, &pose, det).into());
            }
            PoseMessage::Odometry => out.push(messages::odometry(m, &pose, det).into()),
            PoseMessage::TargetRelative => {
                let cfg = &ctx.settings.cfg;
                let inputs = {
                    let tm = lock(&ctx.telemetry);
                    TargetRelativeInputs {
                        q_ned_body: tm.attitude_at(m.capture_time_ns),
                        autopilot_offset_ns: match cfg.target_relative_clock {
                            TimeClock::Own => None,
                            TimeClock::Autopilot => tm.timesync.converged_offset_ns(),
                        },
                        std_scale: cfg.target_relative_std_scale,
                        std_floor_m: cfg.target_relative_std_floor_m,
                    }
                };
                match messages::target_relative(m, &pose, det, &inputs) {
                    Some(msg) => out.push(Outbound::Development(msg)),
                    None => bump(&ctx.counters.invalid_measurement, 1),
                }
            }
        }
    }
}

/// Takes the newest measurement, applies the rate limit and staleness, and
/// queues its messages for the connection task.
pub(crate) async fn pose_task(
    ctx: Context,
    mut latest: watch::Receiver<Option<Arc<Measurement>>>,
    out: mpsc::Sender<Outgoing>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut limit = RateLimit::new(ctx.settings.cfg.max_rate_hz);
    let on_source_clock = ctx.clock.is_source();
    // The rate limit's time, s: since the start (wall clock), or the
    // capture times since the first (the source's clock).
    let wall_start = tokio::time::Instant::now();
    let mut source_start_ns = None;
    let mut built = Vec::with_capacity(4);
    loop {
        tokio::select! {
            changed = latest.changed() => if changed.is_err() { return },
            _ = shutdown.changed() => return,
        }
        // Live: wait for the budget, then take the newest measurement.
        if !on_source_clock {
            let now = tokio::time::Instant::now();
            if let Some(wait) = limit.wait_s(now.duration_since(wall_start).as_secs_f64()) {
                tokio::select! {
                    () = sleep_until(now + wait) => {}
                    _ = shutdown.changed() => return,
                }
            }
        }
        if ctx.stopped.load(Ordering::SeqCst) {
            return;
        }
        let Some(m) = latest.borrow_and_update().clone() else {
            continue;
        };
        let capture = m.capture_time_ns;
        ctx.handoff.taken(capture);
        bump(&ctx.counters.considered, 1);
        if m.detection.is_some() && ctx.is_stale(capture) {
            bump(&ctx.counters.stale, 1);
            ctx.handoff.done(capture);
            continue;
        }
        built.clear();
        build_pose_messages(&ctx, &m, &mut built);
        if built.is_empty() {
            ctx.handoff.done(capture);
            continue;
        }
        let now_s = if on_source_clock {
            let start = *source_start_ns.get_or_insert(capture);
            capture.saturating_sub(start) as f64 * 1e-9
        } else {
            tokio::time::Instant::now()
                .duration_since(wall_start)
                .as_secs_f64()
        };
        // The source's clock cannot be waited for: over the budget on it,
        // the measurement is not sent (a live run waits instead, above).
        if on_source_clock && limit.wait_s(now_s).is_some() {
            bump(&ctx.counters.rate_limited, 1);
            ctx.handoff.done(capture);
            continue;
        }
        let count = built.len();
        for (i, message) in built.drain(..).enumerate() {
            let last = i + 1 == count;
            let o = Outgoing {
                message,
                capture_time_ns: capture,
                last,
            };
            if out.try_send(o).is_err() {
                bump(&ctx.counters.dropped_outgoing, 1);
                if last {
                    ctx.handoff.done(capture);
                }
            }
        }
        limit.spend(now_s);
    }
}

/// A token bucket: on average at most `rate` pose sets a second, with a
/// burst of [`RateLimit::BURST`], so that a camera running at the limit rate
/// with some jitter is never held back or thinned out (a plain minimum
/// interval drops frames that arrive a little early, and drifts).
///
/// Times are seconds on any clock that only grows (see `pose_task`).
pub(super) struct RateLimit {
    rate_hz: f64,
    tokens: f64,
    last_s: Option<f64>,
}

impl RateLimit {
    const BURST: f64 = 2.0;

    pub(super) fn new(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            tokens: Self::BURST,
            last_s: None,
        }
    }

    pub(super) fn refill(&mut self, now_s: f64) {
        if let Some(last) = self.last_s {
            let earned = (now_s - last).max(0.0) * self.rate_hz;
            self.tokens = (self.tokens + earned).min(Self::BURST);
        }
        self.last_s = Some(now_s);
    }

    /// How long until the next send may go, if not now; `None` without a
    /// limit.
    pub(super) fn wait_s(&mut self, now_s: f64) -> Option<Duration> {
        if self.rate_hz <= 0.0 {
            return None;
        }
        self.refill(now_s);
        // A hair below one token is a whole one: the capture times of a
        // source at exactly the limit rate must not be thinned by rounding.
        // The config keeps the rate within [0.1, 10000] Hz; the wait is
        // bounded anyway, so no rate can make this overflow (issue 16).
        (self.tokens < 1.0 - 1e-9).then(|| {
            Duration::try_from_secs_f64((1.0 - self.tokens) / self.rate_hz)
                .unwrap_or(Duration::MAX)
                .min(Duration::from_secs(10))
        })
    }

    pub(super) fn spend(&mut self, now_s: f64) {
        if self.rate_hz > 0.0 {
            self.refill(now_s);
            self.tokens = (self.tokens - 1.0).max(0.0);
        }
    }
}
