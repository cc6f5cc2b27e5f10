//! MAVLink link to the autopilot (ARCHITECTURE.md section 6).
//!
//! [`Link::start`] spawns two tasks on a tokio runtime:
//! - the *pose* task takes the newest [`Measurement`] (latest-wins, never
//!   blocking the measurement thread), drops it when it has no detection or is
//!   older than `max_age_ms`, applies the rate limit and builds the configured
//!   pose messages ([`messages`]);
//! - the *connection* task owns the transport ([`address`]: `udpout`, `udpin`
//!   / `udp`, `udpbcast`, `tcpout` / `tcp`, `tcpin`, `serial`), writes MAVLink 2 frames (signed when a key is set),
//!   sends HEARTBEAT and TIMESYNC, reads and validates everything that comes
//!   back ([`frame`]), keeps the autopilot's attitude and position in a short
//!   time-indexed buffer ([`telemetry`]) and rebuilds the transport with
//!   back-off when it fails.
//!
//! Nothing on the link can stop the process: every fault is logged, counted
//! ([`LinkStats`]) and retried.
//!
//! The link's "now" (a pose's age for `max_age_ms`, the time stamped on each
//! sent or received message for the log) is the run's [`RunClock`]: the
//! wall clock, or with `run --fast` the source's clock, the capture time of
//! the newest measurement handed to the link, so that a replay as fast as
//! possible still sends its poses. There `max_rate_hz` is kept on the
//! source's clock too (a measurement over the budget is not sent, counted
//! as `rate_limited`), and [`LinkHandle::wait_handled`] lets the measurement
//! wait until the link is done with each one (`handoff`) instead of
//! handing over latest-wins. The protocol's own times (TIMESYNC, the
//! autopilot's telemetry) stay on the wall clock.

pub mod address;
pub(crate) mod events;
pub mod frame;
mod handoff;
pub mod messages;
mod session;
pub(crate) mod signing;
pub(crate) mod stats;
pub mod telemetry;
mod transport;

pub use events::{EventReceiver, LinkEvent};
pub use stats::LinkStats;
pub use telemetry::VehiclePose;

use crate::clock::RunClock;
use crate::measure::Measurement;
use address::Address;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::{mpsc, watch};

/// The pose messages the link can send (config `[link] messages`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseMessage {
    /// LANDING_TARGET in MAV_FRAME_BODY_FRD (ArduPilot precision landing, a
    /// fixed-wing docking script).
    LandingTarget,
    /// LANDING_TARGET in MAV_FRAME_LOCAL_NED, absolute (PX4).
    LandingTargetNed,
    /// VISION_POSITION_ESTIMATE: the receiver's pose in the drogue frame.
    VisionPositionEstimate,
    /// ODOMETRY with the same pose and covariance.
    Odometry,
    /// TARGET_RELATIVE (id 511, `development` dialect) for PX4's
    /// vision_target_estimator: the drogue relative to the vehicle with its
    /// standard deviations (see [`messages`]).
    TargetRelative,
}

/// Which clock TARGET_RELATIVE's `timestamp` is on (`[link]
/// target_relative_clock`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeClock {
    /// Our Unix clock, µs: the receiver maps it with its own TIMESYNC (PX4's
    /// `sync_stamp`), as for every other message.
    Own,
    /// The autopilot's clock (µs since its boot), once our TIMESYNC requests
    /// have converged; our Unix clock until then.
    Autopilot,
}

/// `[link]` in the config. Every key is documented in `config/default.toml`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkConfig {
    /// One of [`address::FORMS`].
    pub connection: String,
    /// Our system id: the autopilot's (its telemetry is read from this id too).
    pub system_id: u8,
    /// Our component id (197 = MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY).
    pub component_id: u8,
    /// Pose messages to send for each detection, any combination.
    pub messages: Vec<PoseMessage>,
    /// Most pose updates per second; 0: every measurement.
    pub max_rate_hz: f64,
    /// A pose older than this (capture to send) is never sent; 0: no limit.
    pub max_age_ms: u64,
    /// HEARTBEAT period.
    pub heartbeat_interval_ms: u64,
    /// The autopilot's heartbeat is lost after this long without one.
    pub heartbeat_timeout_ms: u64,
    /// Period of our own TIMESYNC requests; 0: only answer the autopilot's.
    pub timesync_interval_ms: u64,
    /// Telemetry farther than this from a capture time is not used for it.
    pub telemetry_tolerance_ms: u64,
    /// First wait before reopening a failed transport.
    pub reconnect_min_ms: u64,
    /// Longest wait between reopening attempts (the back-off doubles up to it).
    pub reconnect_max_ms: u64,
    /// A write blocked longer than this is a transport fault.
    pub write_timeout_ms: u64,
    /// File with the 32-byte signing key; empty: none.
    pub signing_key_file: PathBuf,
    /// Passphrase whose SHA-256 is the signing key; empty: none.
    pub signing_passphrase: String,
    /// Signing link id stamped on our signed frames.
    pub signing_link_id: u8,
    /// Reject incoming unsigned frames (badly signed ones are always rejected
    /// once a key is set).
    pub signing_require: bool,
    /// Capacity of the `events()` queue (drop-oldest beyond it).
    pub event_queue: usize,
    /// TARGET_RELATIVE: factor on the reported standard deviations.
    pub target_relative_std_scale: f64,
    /// TARGET_RELATIVE: smallest reported position standard deviation, m.
    pub target_relative_std_floor_m: f64,
    /// TARGET_RELATIVE: the clock of `timestamp`.
    pub target_relative_clock: TimeClock,
    /// Most received messages logged per second; the rest are counted.
    pub log_incoming_max_hz: f64,
}

/// A link that could not be started (bad address or configuration). Faults
/// after the start are never errors: they are logged, counted and retried.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The MAVLink address does not parse.
    #[error("mavlink connection {0}")]
    Address(String),
    /// A `[link]` setting is unusable.
    #[error("[link] config: {0}")]
    Config(String),
    /// The signing settings are unusable (a key file and a passphrase
    /// both, or a key file that cannot be read).
    #[error("[link] signing: {0}")]
    Signing(String),
}

/// Starts links; see [`Link::start`].
pub struct Link;

/// Shared between the handle and the tasks.
struct Shared {
    latest: watch::Sender<Option<Arc<Measurement>>>,
    shutdown_tx: watch::Sender<bool>,
    stopped: Arc<AtomicBool>,
    counters: Arc<stats::Counters>,
    telemetry: Arc<Mutex<telemetry::Telemetry>>,
    events: EventReceiver,
    handoff: Arc<handoff::Handoff>,
}

impl Drop for Shared {
    fn drop(&mut self) {
        self.stopped.store(true, Ordering::SeqCst);
        self.shutdown_tx.send_replace(true);
    }
}

/// The running link. Cheap to clone; the link stops when the last clone is
/// dropped or [`LinkHandle::shutdown`] is called.
#[derive(Clone)]
pub struct LinkHandle {
    shared: Arc<Shared>,
}

/// Validated settings derived from [`LinkConfig`].
pub(crate) struct Settings {
    pub cfg: LinkConfig,
    pub address: Address,
    pub signing_key: Option<[u8; 32]>,
}

fn validate(cfg: &LinkConfig, connection: Option<&str>) -> Result<Settings, LinkError> {
    let conn = connection.unwrap_or(&cfg.connection);
    let address = Address::parse(conn).map_err(LinkError::Address)?;
    let bad = |m: String| Err(LinkError::Config(m));
    if !(cfg.max_rate_hz >= 0.0 && cfg.max_rate_hz.is_finite()) {
        return bad(format!("max_rate_hz = {} must be >= 0", cfg.max_rate_hz));
    }
    if cfg.heartbeat_interval_ms == 0 || cfg.heartbeat_timeout_ms == 0 {
        return bad("heartbeat_interval_ms and heartbeat_timeout_ms must be > 0".into());
    }
    if cfg.reconnect_min_ms == 0 || cfg.reconnect_max_ms < cfg.reconnect_min_ms {
        return bad(format!(
            "need 0 < reconnect_min_ms ({}) <= reconnect_max_ms ({})",
            cfg.reconnect_min_ms, cfg.reconnect_max_ms
        ));
    }
    if cfg.write_timeout_ms == 0 {
        return bad("write_timeout_ms must be > 0".into());
    }
    if !(cfg.target_relative_std_scale.is_finite() && cfg.target_relative_std_scale >= 1.0) {
        return bad(format!(
            "target_relative_std_scale = {} must be >= 1 (a covariance is never shrunk)",
            cfg.target_relative_std_scale
        ));
    }
    if !(cfg.target_relative_std_floor_m.is_finite() && cfg.target_relative_std_floor_m >= 0.0) {
        return bad(format!(
            "target_relative_std_floor_m = {} must be >= 0",
            cfg.target_relative_std_floor_m
        ));
    }
    if cfg.event_queue == 0 {
        return bad("event_queue must be > 0".into());
    }
    if cfg.system_id == 0 {
        return bad("system_id 0 is the broadcast id; use the autopilot's (1)".into());
    }
    let from_file = !cfg.signing_key_file.as_os_str().is_empty();
    let from_pass = !cfg.signing_passphrase.is_empty();
    let signing_key = match (from_file, from_pass) {
        (true, true) => {
            return Err(LinkError::Signing(
                "set signing_key_file or signing_passphrase, not both".into(),
            ));
        }
        (true, false) => {
            Some(signing::key_from_file(&cfg.signing_key_file).map_err(LinkError::Signing)?)
        }
        (false, true) => Some(signing::key_from_passphrase(&cfg.signing_passphrase)),
        (false, false) => None,
    };
    if cfg.signing_require && signing_key.is_none() {
        return Err(LinkError::Signing(
            "signing_require needs signing_key_file or signing_passphrase".into(),
        ));
    }
    Ok(Settings {
        cfg: cfg.clone(),
        address,
        signing_key,
    })
}

impl Link {
    /// Parses the address and spawns the link tasks on `rt`. `connection`
    /// (the `--mavlink` option) overrides `cfg.connection`. Opening the
    /// transport happens in the background and is retried; only a bad address
    /// or configuration fails here.
    pub fn start(
        cfg: &LinkConfig,
        connection: Option<&str>,
        rt: &tokio::runtime::Handle,
    ) -> Result<LinkHandle, LinkError> {
        Self::start_with_clock(cfg, connection, rt, RunClock::wall())
    }

    /// [`Link::start`] on the run's clock (the source's for `run --fast`,
    /// see the module docs).
    pub fn start_with_clock(
        cfg: &LinkConfig,
        connection: Option<&str>,
        rt: &tokio::runtime::Handle,
        clock: RunClock,
    ) -> Result<LinkHandle, LinkError> {
        let settings = Arc::new(validate(cfg, connection)?);
        let (latest, latest_rx) = watch::channel(None);
        let (shutdown_tx, shutdown_rx) = watch::channel(false);
        let stopped = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(stats::Counters::default());
        let telemetry = Arc::new(Mutex::new(telemetry::Telemetry::new(
            cfg.telemetry_tolerance_ms.saturating_mul(1_000_000),
        )));
        let (events_tx, events_rx) = events::event_queue(cfg.event_queue, cfg.log_incoming_max_hz);
        // A few pose messages at most wait here: the connection task drains
        // it at once, and drops what is stale when it was away.
        let (out_tx, out_rx) = mpsc::channel(16);
        let handoff = Arc::new(handoff::Handoff::default());
        let ctx = session::Context {
            settings,
            counters: counters.clone(),
            telemetry: telemetry.clone(),
            events: events_tx,
            stopped: stopped.clone(),
            clock,
            handoff: handoff.clone(),
        };
        rt.spawn(session::pose_task(
            ctx.clone(),
            latest_rx,
            out_tx,
            shutdown_rx.clone(),
        ));
        rt.spawn(session::connection_task(ctx, out_rx, shutdown_rx));
        tracing::info!(connection = %connection.unwrap_or(&cfg.connection), "mavlink link started");
        Ok(LinkHandle {
            shared: Arc::new(Shared {
                latest,
                shutdown_tx,
                stopped,
                counters,
                telemetry,
                events: events_rx,
                handoff,
            }),
        })
    }
}

impl LinkHandle {
    /// Latest-wins hand-over of a new measurement; never blocks.
    pub fn submit(&self, m: Arc<Measurement>) {
        if self.shared.stopped.load(Ordering::SeqCst) {
            return;
        }
        stats::bump(&self.shared.counters.submitted, 1);
        self.shared.latest.send_replace(Some(m));
    }

    /// `run --fast`: waits (at most `timeout`) until the link is done with
    /// the measurement captured at `capture_time_ns` that was just
    /// submitted: its messages written, or dropped and counted. Returns early
    /// while the transport is down (nothing would be written) or after a
    /// shutdown; `false` when the link did not get that far in time.
    pub fn wait_handled(&self, capture_time_ns: u64, timeout: std::time::Duration) -> bool {
        let counters = &self.shared.counters;
        self.shared.handoff.wait(
            capture_time_ns,
            timeout,
            || counters.connected.load(Ordering::Relaxed),
            || self.shared.stopped.load(Ordering::SeqCst),
        )
    }

    /// Every message sent or received, decoded, for the MCAP `/mavlink/out`
    /// and `/mavlink/in` topics. Bounded (`event_queue`), drop-oldest; meant
    /// for one consumer.
    pub fn events(&self) -> EventReceiver {
        self.shared.events.clone()
    }

    /// The vehicle pose the autopilot reported (LOCAL_POSITION_NED +
    /// ATTITUDE) interpolated to `time_ns` (ns since the Unix epoch); `None`
    /// without telemetry within `telemetry_tolerance_ms` of that time.
    pub fn vehicle_pose_at(&self, time_ns: u64) -> Option<VehiclePose> {
        self.shared
            .telemetry
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .pose_at(time_ns)
    }

    /// Counters and health, see [`LinkStats`].
    pub fn stats(&self) -> LinkStats {
        self.shared.counters.snapshot(
            self.shared.events.dropped(),
            self.shared.events.unlogged_incoming(),
        )
    }

    /// Stops sending at once (nothing is written after this returns) and ends
    /// the link tasks.
    pub fn shutdown(&self) {
        self.shared.stopped.store(true, Ordering::SeqCst);
        self.shared.shutdown_tx.send_replace(true);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn start(cfg: &LinkConfig, conn: Option<&str>) -> Result<LinkHandle, LinkError> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let r = Link::start(cfg, conn, rt.handle());
        if let Ok(h) = &r {
            h.shutdown();
        }
        r
    }

    #[test]
    fn bad_addresses_and_configs_fail_at_start() {
        let cfg = Config::embedded().link;
        assert!(matches!(
            start(&cfg, Some("udpout:nowhere")),
            Err(LinkError::Address(_))
        ));
        let mut c = cfg.clone();
        c.signing_require = true;
        assert!(matches!(start(&c, None), Err(LinkError::Signing(_))));
        c.signing_passphrase = "x".into();
        c.signing_key_file = "/nonexistent/key".into();
        assert!(matches!(start(&c, None), Err(LinkError::Signing(_))));
        c.signing_key_file = "".into();
        assert!(start(&c, None).is_ok());
        let mut c = cfg.clone();
        c.reconnect_max_ms = c.reconnect_min_ms - 1;
        assert!(matches!(start(&c, None), Err(LinkError::Config(_))));
        let mut c = cfg.clone();
        c.max_rate_hz = f64::NAN;
        assert!(matches!(start(&c, None), Err(LinkError::Config(_))));
        let mut c = cfg;
        c.system_id = 0;
        assert!(matches!(start(&c, None), Err(LinkError::Config(_))));
    }

    #[test]
    fn every_pose_message_name_parses_from_config() {
        let c = Config::from_toml_str(
            "[link]\nmessages = [\"landing_target\", \"landing_target_ned\", \"vision_position_estimate\", \"odometry\", \"target_relative\"]\n",
            "u.toml",
        )
        .unwrap();
        assert_eq!(c.link.messages.len(), 5);
        assert!(Config::from_toml_str("[link]\nmessages = [\"pose\"]\n", "u.toml").is_err());
    }
}
