//! Pacing: a recorded timeline (a simulation, a log) replayed on the wall
//! clock at its own frame rate, as a camera would deliver it.

use crate::source::dir::unix_now_ns;
use std::time::{Duration, Instant};

/// Replays a source's timeline on the wall clock: a frame's capture time
/// becomes the run's start plus its time on the timeline (exact, so truth
/// and messages line up). A source that falls more than [`MAX_SOURCE_LAG`]
/// behind (a simulator on a busy machine) is re-anchored, like a camera
/// dropping frames; otherwise its frames would all arrive stale.
pub struct Pacer {
    started: Instant,
    started_ns: u64,
    lag: Duration,
    first_ns: Option<u64>,
    /// Times the source fell behind and was re-anchored.
    pub late: u64,
}

const MAX_SOURCE_LAG: Duration = Duration::from_millis(100);

impl Pacer {
    pub fn start() -> Self {
        Self {
            started: Instant::now(),
            started_ns: unix_now_ns(),
            lag: Duration::ZERO,
            first_ns: None,
            late: 0,
        }
    }

    /// Sleeps until the frame at `timeline_ns` (the source's clock) is due;
    /// returns its capture time, ns since the Unix epoch.
    pub fn wait_until_due(&mut self, timeline_ns: u64, seq: u64) -> u64 {
        let first = *self.first_ns.get_or_insert(timeline_ns);
        let offset = Duration::from_nanos(timeline_ns.saturating_sub(first));
        let now = Instant::now();
        let due = self.started + offset + self.lag;
        if now > due + MAX_SOURCE_LAG {
            self.lag += now - due;
            self.late += 1;
            tracing::warn!(seq, "source behind its frame rate: timeline moved on");
        } else if let Some(wait) = due.checked_duration_since(now) {
            std::thread::sleep(wait);
        }
        self.started_ns + (offset + self.lag).as_nanos() as u64
    }

    /// Like [`Pacer::wait_until_due`] but the timeline never moves: `None`
    /// when the frame is more than [`MAX_SOURCE_LAG`] late (the caller drops
    /// it). For the closed loop, whose scenario clock must stay on the
    /// autopilot's (wall) clock.
    pub fn wait_until_due_or_drop(&mut self, timeline_ns: u64) -> Option<u64> {
        let first = *self.first_ns.get_or_insert(timeline_ns);
        let offset = Duration::from_nanos(timeline_ns.saturating_sub(first));
        let now = Instant::now();
        let due = self.started + offset;
        if now > due + MAX_SOURCE_LAG {
            return None;
        }
        if let Some(wait) = due.checked_duration_since(now) {
            std::thread::sleep(wait);
        }
        Some(self.started_ns + offset.as_nanos() as u64)
    }
}
