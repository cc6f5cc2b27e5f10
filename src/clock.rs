//! The run's clock: what "now" is for a pose's staleness and for the flight
//! log's timestamps.
//!
//! A live run (a camera, or a recorded timeline paced on the wall clock)
//! uses the wall clock, ns since the Unix epoch: the frames' capture times
//! are on it, so age = now - capture is the real latency.
//!
//! `run --fast` replays a recorded timeline (a simulation, an MCAP log, a
//! folder) as fast as the pipeline goes. Its capture times are the source's
//! (a replayed log's are in the past), so the wall clock would call every
//! pose stale and spread the log over the replay's date and today. There the
//! run uses the *source's* clock: "now" is the capture time of the newest
//! frame the measurement has handed to the link (so a pose's age is how far
//! the pipeline has moved on along the source's timeline since its frame),
//! and every log topic (camera, detection, pose, MAVLink traffic, `/log`,
//! `/drogue/stats`) is stamped with it. The log then spans the source's
//! first to last capture time, the run's real length, whatever the replay's
//! speed.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

/// Now on the wall clock, ns since the Unix epoch.
pub fn unix_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// The run's clock (see the module docs). Cheap to clone; clones share the
/// source's time.
#[derive(Clone, Debug, Default)]
pub struct RunClock {
    /// `None`: the wall clock. `Some`: the source's newest time handed on,
    /// ns since the Unix epoch (0 until the first frame).
    source_ns: Option<Arc<AtomicU64>>,
}

impl RunClock {
    /// The wall clock (every run without `--fast`).
    pub fn wall() -> Self {
        Self { source_ns: None }
    }

    /// The source's clock, starting at the capture time `start_ns` of the
    /// source's first frame (0: not known yet, the first
    /// [`RunClock::advance_to`] sets it).
    pub fn source(start_ns: u64) -> Self {
        Self {
            source_ns: Some(Arc::new(AtomicU64::new(start_ns))),
        }
    }

    /// Whether this is the source's clock.
    pub fn is_source(&self) -> bool {
        self.source_ns.is_some()
    }

    /// Now: the wall clock, or the source's newest time. Before the source's
    /// first frame (only when its first item was unreadable) the wall clock.
    pub fn now_ns(&self) -> u64 {
        match &self.source_ns {
            None => unix_now_ns(),
            Some(t) => match t.load(Ordering::Acquire) {
                0 => unix_now_ns(),
                t => t,
            },
        }
    }

    /// Starts the source's clock at `time_ns` if no frame has set it yet
    /// (the source's first item was unreadable). No effect otherwise.
    pub fn start_at(&self, time_ns: u64) {
        if let Some(t) = &self.source_ns {
            let _ = t.compare_exchange(0, time_ns, Ordering::AcqRel, Ordering::Acquire);
        }
    }

    /// Moves the source's clock on to `time_ns` (never back: a source's
    /// capture times only grow, and a late one must not rewind the log). No
    /// effect on the wall clock.
    pub fn advance_to(&self, time_ns: u64) {
        if let Some(t) = &self.source_ns {
            t.fetch_max(time_ns, Ordering::AcqRel);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_source_clock_follows_the_frames_and_never_goes_back() {
        let c = RunClock::source(1_000);
        let shared = c.clone();
        assert_eq!(c.now_ns(), 1_000);
        shared.advance_to(5_000);
        assert_eq!(c.now_ns(), 5_000);
        shared.advance_to(2_000);
        assert_eq!(c.now_ns(), 5_000);
        assert!(c.is_source());
        // start_at only sets a clock no frame has set.
        c.start_at(9_000);
        assert_eq!(c.now_ns(), 5_000);
        let late = RunClock::source(0);
        late.start_at(7_000);
        assert_eq!(late.now_ns(), 7_000);
    }

    #[test]
    fn the_wall_clock_is_now_and_ignores_the_frames() {
        let c = RunClock::wall();
        c.advance_to(1_000);
        let (before, now, after) = (unix_now_ns(), c.now_ns(), unix_now_ns());
        assert!(before <= now && now <= after);
        assert!(!c.is_source());
        // A source clock before its first frame is the wall clock too.
        let unset = RunClock::source(0);
        let (before, now) = (unix_now_ns(), unset.now_ns());
        assert!(now >= before);
    }
}
