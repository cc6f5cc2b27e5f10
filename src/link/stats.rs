//! Link counters: cheap to bump from the link tasks, snapshotted by `stats()`.

use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// A snapshot of the link's health, for logs, `review` and tests.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LinkStats {
    /// Messages written to the transport, by MAVLink message name.
    pub sent: BTreeMap<String, u64>,
    /// Valid MAVLink 2 messages accepted from the link.
    pub received: u64,
    /// Valid frames refused by signing (unsigned when signing is required,
    /// bad signature, replayed timestamp).
    pub rejected_signature: u64,
    /// MAVLink 1 frames (valid CRC) ignored: this link speaks MAVLink 2 only.
    pub rejected_mavlink1: u64,
    /// Frames whose CRC matched but whose payload did not decode.
    pub rejected_payload: u64,
    /// Bytes skipped while hunting for a frame: garbage, bad CRC, truncated
    /// frames, unknown message ids.
    pub bad_bytes: u64,
    /// Times the autopilot's heartbeat went missing for longer than the timeout.
    pub heartbeat_losses: u64,
    /// Transport (re)connections after the first.
    pub reconnects: u64,
    /// Transport errors (open, read, write).
    pub io_errors: u64,
    /// Measurements handed to the link without a detection (nothing sent).
    pub no_detection: u64,
    /// Measurements dropped because they were older than `max_age_ms` when
    /// their turn to be sent came.
    pub stale: u64,
    /// `--fast`: detected measurements not sent because they came faster
    /// than `max_rate_hz` on the source's clock (live runs wait instead).
    pub rate_limited: u64,
    /// Measurements superseded by a newer one before the pose task looked at
    /// them (latest-wins and the rate limit; includes one still pending).
    pub superseded: u64,
    /// `landing_target_ned` skipped: no vehicle pose near the capture time.
    pub no_vehicle_pose: u64,
    /// Measurements with non-finite or degenerate values (nothing sent).
    pub invalid_measurement: u64,
    /// Outgoing messages dropped: queue full, no peer yet (`udpin`),
    /// disconnected, or write timeout.
    pub dropped_outgoing: u64,
    /// Events dropped because the `events()` consumer was too slow.
    pub dropped_events: u64,
    /// Received messages not logged: over `[link] log_incoming_max_hz`, or
    /// skipped while the flight log's queue was busy (frames come first).
    pub unlogged_incoming: u64,
    /// `udpin`: times the peer changed after the first (each is logged).
    pub peer_changes: u64,
    /// Age of the last autopilot heartbeat, seconds; negative: never seen.
    /// Only a HEARTBEAT of the configured system id that names an autopilot
    /// and is not a ground station's or an onboard controller's counts.
    pub last_heartbeat_age_s: f64,
    /// Whether the transport is currently open.
    pub connected: bool,
    /// Whether the transport was ever open (`tcpin` before a client, a
    /// serial port that never opened: false).
    pub opened: bool,
    /// Estimated autopilot clock minus own clock (Unix), ns; 0 when unknown.
    pub timesync_offset_ns: i64,
}

/// The live counters behind [`LinkStats`].
#[derive(Default)]
pub(crate) struct Counters {
    sent: Mutex<BTreeMap<String, u64>>,
    pub received: AtomicU64,
    pub rejected_signature: AtomicU64,
    pub rejected_mavlink1: AtomicU64,
    pub rejected_payload: AtomicU64,
    pub bad_bytes: AtomicU64,
    pub heartbeat_losses: AtomicU64,
    pub reconnects: AtomicU64,
    pub io_errors: AtomicU64,
    pub no_detection: AtomicU64,
    pub stale: AtomicU64,
    pub rate_limited: AtomicU64,
    /// Measurements handed to `submit()`.
    pub submitted: AtomicU64,
    /// Measurements the pose task looked at (the rest were superseded).
    pub considered: AtomicU64,
    pub no_vehicle_pose: AtomicU64,
    pub invalid_measurement: AtomicU64,
    pub dropped_outgoing: AtomicU64,
    pub peer_changes: AtomicU64,
    pub connected: std::sync::atomic::AtomicBool,
    pub opened: std::sync::atomic::AtomicBool,
    pub timesync_offset_ns: std::sync::atomic::AtomicI64,
    last_heartbeat: Mutex<Option<Instant>>,
}

/// Adds `n` to a counter.
pub(crate) fn bump(c: &AtomicU64, n: u64) {
    c.fetch_add(n, Ordering::Relaxed);
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic while holding these short locks cannot leave the data
    // inconsistent (plain counters), so a poisoned lock is still usable.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl LinkStats {
    /// Whether an autopilot heartbeat was ever heard.
    pub fn autopilot_heard(&self) -> bool {
        self.last_heartbeat_age_s >= 0.0
    }

    /// One phrase for the link's state: `not open`, `open, autopilot never
    /// heard`, `open, autopilot heard 0.4 s ago`, `closed (reopening), ...`.
    pub fn state(&self) -> String {
        let transport = match (self.opened, self.connected) {
            (false, _) => return "never opened".to_string(),
            (true, true) => "open",
            (true, false) => "down (reopening)",
        };
        if self.autopilot_heard() {
            format!(
                "{transport}, autopilot heard {:.1} s ago",
                self.last_heartbeat_age_s
            )
        } else {
            format!("{transport}, autopilot never heard")
        }
    }
}

impl Counters {
    pub fn count_sent(&self, name: &str) {
        let mut sent = lock(&self.sent);
        match sent.get_mut(name) {
            Some(n) => *n += 1,
            None => {
                sent.insert(name.to_string(), 1);
            }
        }
    }

    pub fn heartbeat_seen(&self, at: Instant) {
        *lock(&self.last_heartbeat) = Some(at);
    }

    pub fn last_heartbeat(&self) -> Option<Instant> {
        *lock(&self.last_heartbeat)
    }

    pub fn snapshot(&self, dropped_events: u64, unlogged_incoming: u64) -> LinkStats {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        LinkStats {
            sent: lock(&self.sent).clone(),
            received: get(&self.received),
            rejected_signature: get(&self.rejected_signature),
            rejected_mavlink1: get(&self.rejected_mavlink1),
            rejected_payload: get(&self.rejected_payload),
            bad_bytes: get(&self.bad_bytes),
            heartbeat_losses: get(&self.heartbeat_losses),
            reconnects: get(&self.reconnects),
            io_errors: get(&self.io_errors),
            no_detection: get(&self.no_detection),
            stale: get(&self.stale),
            rate_limited: get(&self.rate_limited),
            superseded: get(&self.submitted).saturating_sub(get(&self.considered)),
            no_vehicle_pose: get(&self.no_vehicle_pose),
            invalid_measurement: get(&self.invalid_measurement),
            dropped_outgoing: get(&self.dropped_outgoing),
            dropped_events,
            unlogged_incoming,
            peer_changes: get(&self.peer_changes),
            last_heartbeat_age_s: self
                .last_heartbeat()
                .map_or(-1.0, |t| t.elapsed().as_secs_f64()),
            connected: self.connected.load(Ordering::Relaxed),
            opened: self.opened.load(Ordering::Relaxed),
            timesync_offset_ns: self.timesync_offset_ns.load(Ordering::Relaxed),
        }
    }
}
