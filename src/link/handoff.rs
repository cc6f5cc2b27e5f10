//! How far the link has got with the measurements handed to it, so that
//! `run --fast` can wait for each one before measuring the next.
//!
//! The link takes measurements latest-wins: a live pipeline must never wait
//! for it. A replay as fast as possible would then overwrite most of them
//! before they are sent, so there the measurement thread waits
//! ([`Handoff::wait`]) until the link is done with its measurement: sent,
//! or dropped for a reason the link counts (no detection, stale, rate
//! limited, queue full, transport down). Measurements are named by their
//! capture time, which grows along a source.

use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// Capture times (ns) of the newest measurement the pose task took, and of
/// the newest one the link is done with.
#[derive(Debug, Default)]
pub(crate) struct Handoff {
    state: Mutex<Progress>,
    changed: Condvar,
}

#[derive(Clone, Copy, Debug, Default)]
struct Progress {
    taken_ns: u64,
    done_ns: u64,
}

/// How often a wait looks at the transport's state.
const POLL: Duration = Duration::from_millis(20);

impl Handoff {
    fn update(&self, f: impl FnOnce(&mut Progress)) {
        let mut p = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f(&mut p);
        drop(p);
        self.changed.notify_all();
    }

    /// The pose task took the measurement captured at `capture_ns`.
    pub fn taken(&self, capture_ns: u64) {
        self.update(|p| p.taken_ns = p.taken_ns.max(capture_ns));
    }

    /// The link is done with the measurement captured at `capture_ns`.
    pub fn done(&self, capture_ns: u64) {
        self.update(|p| {
            p.taken_ns = p.taken_ns.max(capture_ns);
            p.done_ns = p.done_ns.max(capture_ns);
        });
    }

    /// Waits until the link is done with the measurement captured at
    /// `capture_ns`, or it was taken while `connected()` says the transport
    /// is down (its messages wait for a transport that may take long to
    /// come, as `tcpin` waiting for a client), or `stopped()`, or `timeout`.
    /// Whether the link got that far.
    pub fn wait(
        &self,
        capture_ns: u64,
        timeout: Duration,
        connected: impl Fn() -> bool,
        stopped: impl Fn() -> bool,
    ) -> bool {
        let deadline = Instant::now() + timeout;
        let mut p = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        loop {
            if p.done_ns >= capture_ns || (p.taken_ns >= capture_ns && !connected()) {
                return true;
            }
            let now = Instant::now();
            if now >= deadline || stopped() {
                return false;
            }
            let slice = POLL.min(deadline - now);
            p = self
                .changed
                .wait_timeout(p, slice)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn a_wait_ends_when_the_link_is_done_or_the_transport_is_down() {
        let h = Arc::new(Handoff::default());
        let worker = Arc::clone(&h);
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(30));
            worker.done(2_000);
        });
        assert!(h.wait(2_000, Duration::from_secs(5), || true, || false));
        t.join().unwrap();
        // An earlier capture time is done too.
        assert!(h.wait(1_000, Duration::ZERO, || true, || false));
        // Taken but not done: only a transport that is down ends the wait.
        h.taken(3_000);
        assert!(!h.wait(3_000, Duration::from_millis(30), || true, || false));
        assert!(h.wait(3_000, Duration::from_millis(30), || false, || false));
        // Never taken: a stopped link ends it.
        assert!(!h.wait(4_000, Duration::from_secs(5), || false, || true));
    }
}
