//! The connection task: owns the transport for the life of the link (opens,
//! reconnects with back-off), sends the queued pose messages, HEARTBEAT and
//! TIMESYNC, and reads what the autopilot sends (telemetry, its heartbeat,
//! TIMESYNC replies), checking every frame before use.

use super::super::events::LinkEvent;
use super::super::frame::{DecodeCounts, FrameDecoder, FrameEncoder, Incoming};
use super::super::messages::{self, Outbound};
use super::super::stats::bump;
use super::super::transport::Transport;
use super::{Context, Outgoing, READ_CHUNK, lock, unix_now_ns};
use mavlink::dialects::ardupilotmega::{HEARTBEAT_DATA, MavAutopilot, MavMessage, MavType};
use mavlink::{Message, SigningConfig, SigningData};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use tokio::time::{MissedTickBehavior, interval, sleep_until, timeout};

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

/// Why a connection ended.
pub(super) enum End {
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
                () = sleep_until(wake) => break,
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

pub(super) struct Connection {
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
