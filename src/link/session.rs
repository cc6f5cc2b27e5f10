//! The link's two tasks: the pose task (measurements → pose messages) and the
//! connection task (transport, reconnection, heartbeat, TIMESYNC, telemetry).

use super::events::{EventSender, LinkEvent};
use super::frame::{DecodeCounts, FrameDecoder, FrameEncoder, Incoming};
use super::handoff::Handoff;
use super::messages::{self, DroguePose, Outbound, TargetRelativeInputs};
use super::stats::{Counters, bump};
use super::telemetry::Telemetry;
use super::transport::Transport;
use super::{PoseMessage, Settings, TimeClock};
use crate::clock::RunClock;
use crate::measure::Measurement;
use mavlink::dialects::ardupilotmega::{HEARTBEAT_DATA, MavAutopilot, MavMessage, MavType};
use mavlink::{Message, SigningConfig, SigningData};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use tokio::time::{MissedTickBehavior, interval, sleep_until, timeout};

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
    m.lock().unwrap_or_else(|p| p.into_inner())
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
                out.push(messages::landing_target_body(m, &pose, det).into())
            }
            PoseMessage::LandingTargetNed => {
                let vehicle = lock(&ctx.telemetry).pose_at(m.capture_time_ns);
                match vehicle.and_then(|v| messages::landing_target_ned(m, &pose, det, &v)) {
                    Some(msg) => out.push(msg.into()),
                    None => bump(&ctx.counters.no_vehicle_pose, 1),
                }
            }
            PoseMessage::VisionPositionEstimate => {
                out.push(messages::vision_position_estimate(m, &pose, det).into())
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

/// Whether a HEARTBEAT (from the configured system id) is the autopilot's:
/// a ground station (MAV_TYPE_GCS), a companion or router
/// (MAV_TYPE_ONBOARD_CONTROLLER) or any component that names no autopilot
/// (MAV_AUTOPILOT_INVALID: cameras, gimbals, ...) may share the system id
/// and must not keep "autopilot heard" alive.
pub(crate) fn is_autopilot_heartbeat(h: &HEARTBEAT_DATA) -> bool {
    h.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID
        && !matches!(
            h.mavtype,
            MavType::MAV_TYPE_GCS | MavType::MAV_TYPE_ONBOARD_CONTROLLER
        )
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
                    _ = sleep_until(now + wait) => {}
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
struct RateLimit {
    rate_hz: f64,
    tokens: f64,
    last_s: Option<f64>,
}

impl RateLimit {
    const BURST: f64 = 2.0;

    fn new(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            tokens: Self::BURST,
            last_s: None,
        }
    }

    fn refill(&mut self, now_s: f64) {
        if let Some(last) = self.last_s {
            let earned = (now_s - last).max(0.0) * self.rate_hz;
            self.tokens = (self.tokens + earned).min(Self::BURST);
        }
        self.last_s = Some(now_s);
    }

    /// How long until the next send may go, if not now; `None` without a
    /// limit.
    fn wait_s(&mut self, now_s: f64) -> Option<Duration> {
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

    fn spend(&mut self, now_s: f64) {
        if self.rate_hz > 0.0 {
            self.refill(now_s);
            self.tokens = (self.tokens - 1.0).max(0.0);
        }
    }
}

/// Why a connection ended.
enum End {
    Shutdown,
    Fault(String),
}

/// Owns the transport for the life of the link: opens it, runs it, and
/// reopens it with back-off after any fault.
pub(crate) async fn connection_task(
    ctx: Context,
    mut out: mpsc::Receiver<Outgoing>,
    mut shutdown: watch::Receiver<bool>,
) {
    let cfg = &ctx.settings.cfg;
    let address = ctx.settings.address.clone();
    let signing = ctx.settings.signing_key.map(|key| {
        SigningData::from_config(SigningConfig::new(
            key,
            cfg.signing_link_id,
            true,
            !cfg.signing_require,
        ))
    });
    let mut conn = Connection {
        ctx: ctx.clone(),
        encoder: FrameEncoder::new(cfg.system_id, cfg.component_id),
        signing,
        heartbeat_lost: false,
    };
    let min_backoff = Duration::from_millis(cfg.reconnect_min_ms);
    let max_backoff = Duration::from_millis(cfg.reconnect_max_ms);
    let mut backoff = min_backoff;
    let mut opened_before = false;
    let mut failures_in_a_row = 0u64;
    loop {
        if ctx.stopped.load(Ordering::SeqCst) {
            return;
        }
        // `tcpin` waits for a client inside `open`: a shutdown must end it.
        let opened = tokio::select! {
            r = Transport::open(&address) => r,
            _ = shutdown.changed() => return,
        };
        match opened {
            Ok(transport) => {
                if opened_before {
                    bump(&ctx.counters.reconnects, 1);
                    tracing::warn!(%address, "mavlink link reconnected");
                } else {
                    tracing::info!(%address, "mavlink link open");
                }
                opened_before = true;
                failures_in_a_row = 0;
                backoff = min_backoff;
                ctx.counters.connected.store(true, Ordering::Relaxed);
                ctx.counters.opened.store(true, Ordering::Relaxed);
                let end = conn.run(transport, &mut out, &mut shutdown).await;
                ctx.counters.connected.store(false, Ordering::Relaxed);
                match end {
                    End::Shutdown => return,
                    End::Fault(why) => {
                        bump(&ctx.counters.io_errors, 1);
                        tracing::warn!(%address, "mavlink link lost: {why}; reopening");
                    }
                }
            }
            Err(e) => {
                bump(&ctx.counters.io_errors, 1);
                failures_in_a_row += 1;
                // Log the first failure and then every 10th, not every retry.
                if failures_in_a_row % 10 == 1 {
                    tracing::warn!(%address, attempts = failures_in_a_row, "cannot open mavlink link: {e}");
                }
            }
        }
        // Wait, dropping what the pose task queues meanwhile: nothing stale
        // may go out once the link is back.
        let wake = tokio::time::Instant::now() + backoff;
        loop {
            tokio::select! {
                _ = sleep_until(wake) => break,
                _ = shutdown.changed() => return,
                o = out.recv() => match o {
                    Some(o) => {
                        bump(&ctx.counters.dropped_outgoing, 1);
                        if o.last {
                            ctx.handoff.done(o.capture_time_ns);
                        }
                    }
                    None => return,
                },
            }
        }
        backoff = (backoff * 2).min(max_backoff);
    }
}

struct Connection {
    ctx: Context,
    encoder: FrameEncoder,
    signing: Option<SigningData>,
    heartbeat_lost: bool,
}

impl Connection {
    async fn run(
        &mut self,
        mut transport: Transport,
        out: &mut mpsc::Receiver<Outgoing>,
        shutdown: &mut watch::Receiver<bool>,
    ) -> End {
        let cfg = self.ctx.settings.cfg.clone();
        let mut heartbeat = interval(Duration::from_millis(cfg.heartbeat_interval_ms));
        heartbeat.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let mut timesync = interval(Duration::from_millis(cfg.timesync_interval_ms.max(1)));
        timesync.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let mut watchdog = interval(Duration::from_millis(100));
        watchdog.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let heartbeat_timeout = Duration::from_millis(cfg.heartbeat_timeout_ms);
        let opened_at = Instant::now();
        let datagram = transport.is_datagram();
        let is_serial = matches!(transport, Transport::Serial(_));
        let mut decoder = FrameDecoder::new();
        let mut incoming = Vec::new();
        let mut buf = vec![0u8; READ_CHUNK];
        loop {
            // Biased, with the input last: each turn of this loop reads at
            // most one datagram or READ_CHUNK bytes, and the pose messages,
            // heartbeat and TIMESYNC are served before it, so no inbound
            // flood can hold the output back.
            tokio::select! {
                biased;
                _ = shutdown.changed() => return End::Shutdown,
                o = out.recv() => match o {
                    Some(o) => {
                        if self.ctx.is_stale(o.capture_time_ns) {
                            bump(&self.ctx.counters.stale, 1);
                        } else {
                            let sent = self.send(&mut transport, &o.message, Some(o.capture_time_ns)).await;
                            if let Err(e) = sent {
                                if o.last {
                                    self.ctx.handoff.done(o.capture_time_ns);
                                }
                                return e;
                            }
                        }
                        if o.last {
                            self.ctx.handoff.done(o.capture_time_ns);
                        }
                    }
                    None => return End::Shutdown,
                },
                _ = heartbeat.tick() => {
                    if let Err(e) = self.send(&mut transport, &messages::heartbeat().into(), None).await {
                        return e;
                    }
                }
                _ = timesync.tick(), if cfg.timesync_interval_ms > 0 => {
                    let now = i64::try_from(unix_now_ns()).unwrap_or(i64::MAX);
                    lock(&self.ctx.telemetry).timesync.request_sent(now);
                    if let Err(e) = self.send(&mut transport, &messages::timesync_request(now).into(), None).await {
                        return e;
                    }
                }
                _ = watchdog.tick() => {
                    let last = self.ctx.counters.last_heartbeat();
                    let lost = last.is_some_and(|t| t.elapsed() > heartbeat_timeout);
                    if lost && !self.heartbeat_lost {
                        self.heartbeat_lost = true;
                        bump(&self.ctx.counters.heartbeat_losses, 1);
                        tracing::warn!("autopilot heartbeat lost (none for {} ms)", cfg.heartbeat_timeout_ms);
                    }
                    // A serial port may hang without an error (a USB adapter
                    // half gone): once the autopilot spoke on this port and
                    // then fell silent, rebuild the port.
                    if lost && is_serial && last.is_some_and(|t| t > opened_at) {
                        return End::Fault("autopilot heartbeat lost on the serial port".into());
                    }
                }
                r = transport.read(&mut buf) => match r {
                    Ok((0, _)) if !datagram => return End::Fault("peer closed the connection".into()),
                    Ok((n, from)) => {
                        let mut counts = DecodeCounts::default();
                        decoder.feed(&buf[..n], datagram, self.signing.as_ref(), &mut counts, &mut incoming);
                        self.count(&counts);
                        if let Some(from) = from {
                            self.follow_peer(&mut transport, from, &incoming);
                        }
                        for msg in incoming.drain(..) {
                            if let Err(e) = self.handle(&mut transport, msg).await {
                                return e;
                            }
                        }
                    }
                    // A UDP error (e.g. ICMP unreachable) is not fatal: keep the socket.
                    Err(e) if datagram => {
                        bump(&self.ctx.counters.io_errors, 1);
                        tracing::debug!("mavlink udp receive: {e}");
                    }
                    Err(e) => return End::Fault(format!("read: {e}")),
                },
            }
        }
    }

    /// `udpin`: follows `from` when its datagram held a frame the decoder
    /// accepted, and that frame was signed (and verified) if signing is on;
    /// each change of peer is logged.
    fn follow_peer(&self, transport: &mut Transport, from: std::net::SocketAddr, got: &[Incoming]) {
        let trusted = got.iter().any(|m| m.signed || self.signing.is_none());
        if !trusted {
            return;
        }
        match transport.follow(from) {
            Some(None) => tracing::info!(peer = %from, "mavlink udpin: replying to {from}"),
            Some(Some(old)) => {
                bump(&self.ctx.counters.peer_changes, 1);
                tracing::warn!(peer = %from, previous = %old, "mavlink udpin: peer changed from {old} to {from}");
            }
            None => {}
        }
    }

    fn count(&self, c: &DecodeCounts) {
        let k = &self.ctx.counters;
        bump(&k.received, c.accepted);
        bump(&k.bad_bytes, c.bad_bytes);
        bump(&k.rejected_mavlink1, c.mavlink1);
        bump(&k.rejected_signature, c.bad_signature);
        bump(&k.rejected_payload, c.bad_payload);
    }

    /// Encodes, signs and writes one message; logs it as an event.
    async fn send(
        &mut self,
        transport: &mut Transport,
        message: &Outbound,
        capture_time_ns: Option<u64>,
    ) -> Result<(), End> {
        if self.ctx.stopped.load(Ordering::SeqCst) {
            return Err(End::Shutdown);
        }
        let raw = match message {
            Outbound::Ardupilot(m) => self.encoder.encode(m, self.signing.as_ref()),
            Outbound::Development(m) => self.encoder.encode(m, self.signing.as_ref()),
        };
        let limit = Duration::from_millis(self.ctx.settings.cfg.write_timeout_ms);
        let datagram = transport.is_datagram();
        // Stamped as the write starts: a stamp taken after it returns could
        // land after the peer already has the message (a busy machine may
        // preempt this thread right after the system call).
        let write_started_ns = unix_now_ns();
        match timeout(limit, transport.write(raw.raw_bytes())).await {
            Ok(Ok(true)) => {
                self.ctx.counters.count_sent(message.name());
                self.ctx.events.push(LinkEvent {
                    time_ns: self.ctx.event_time_ns(write_started_ns),
                    outgoing: true,
                    name: message.name().to_string(),
                    capture_time_ns,
                    fields: message.fields_json(),
                });
                Ok(())
            }
            Ok(Ok(false)) => {
                bump(&self.ctx.counters.dropped_outgoing, 1);
                Ok(())
            }
            Ok(Err(e)) if datagram => {
                // Nobody listening, or the network is down: UDP keeps going.
                bump(&self.ctx.counters.dropped_outgoing, 1);
                bump(&self.ctx.counters.io_errors, 1);
                tracing::debug!("mavlink udp send: {e}");
                Ok(())
            }
            Ok(Err(e)) => {
                bump(&self.ctx.counters.dropped_outgoing, 1);
                Err(End::Fault(format!("write: {e}")))
            }
            Err(_) => {
                bump(&self.ctx.counters.dropped_outgoing, 1);
                if datagram {
                    Ok(())
                } else {
                    Err(End::Fault(format!("write blocked for more than {limit:?}")))
                }
            }
        }
    }

    /// Reacts to one accepted message from the link.
    async fn handle(&mut self, transport: &mut Transport, m: Incoming) -> Result<(), End> {
        let cfg = &self.ctx.settings.cfg;
        let now_ns = unix_now_ns();
        let from_system = m.header.system_id;
        let from_component = m.header.component_id;
        // Our own frames echoed back by a router: not the autopilot.
        if from_system == u32::from(cfg.system_id) && from_component == cfg.component_id {
            return Ok(());
        }
        let event_ns = self.ctx.event_time_ns(now_ns);
        self.ctx.events.push_incoming(|| {
            let mut fields = messages::fields_json(&m.message);
            if let Some(obj) = fields.as_object_mut() {
                obj.insert("sysid".into(), from_system.into());
                obj.insert("compid".into(), from_component.into());
                obj.insert("seq".into(), m.header.sequence.into());
                obj.insert("signed".into(), m.signed.into());
            }
            LinkEvent {
                time_ns: event_ns,
                outgoing: false,
                name: m.message.message_name().to_string(),
                capture_time_ns: None,
                fields,
            }
        });
        let from_autopilot = from_system == u32::from(cfg.system_id);
        match &m.message {
            MavMessage::HEARTBEAT(h) if from_autopilot && is_autopilot_heartbeat(h) => {
                self.ctx.counters.heartbeat_seen(Instant::now());
                if self.heartbeat_lost {
                    self.heartbeat_lost = false;
                    tracing::info!("autopilot heartbeat back");
                }
            }
            MavMessage::ATTITUDE(a) if from_autopilot => {
                lock(&self.ctx.telemetry).push_attitude(
                    a.time_boot_ms,
                    [a.roll, a.pitch, a.yaw],
                    now_ns,
                );
            }
            MavMessage::LOCAL_POSITION_NED(p) if from_autopilot => {
                lock(&self.ctx.telemetry).push_position(p.time_boot_ms, [p.x, p.y, p.z], now_ns);
            }
            MavMessage::TIMESYNC(t) => {
                let now = i64::try_from(now_ns).unwrap_or(i64::MAX);
                if t.tc1 == 0 {
                    // A request: answer at once, then learn from it.
                    let reply = messages::timesync_reply(
                        now,
                        t.ts1,
                        u8::try_from(from_system).unwrap_or(0),
                        from_component,
                    );
                    self.send(transport, &reply.into(), None).await?;
                    if from_autopilot {
                        lock(&self.ctx.telemetry).timesync.request_seen(t.ts1, now);
                    }
                } else if from_autopilot {
                    let mut tm = lock(&self.ctx.telemetry);
                    tm.timesync.reply(t.tc1, t.ts1, now);
                    if let Some(off) = tm.timesync.offset_ns() {
                        self.ctx
                            .counters
                            .timesync_offset_ns
                            .store(off, Ordering::Relaxed);
                    }
                }
            }
            _ => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::link::messages::tests::detection;
    use crate::link::telemetry::CONVERGED_REPLIES;
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
