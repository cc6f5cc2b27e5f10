//! The bounded, drop-oldest queue of decoded messages for the MCAP log
//! (`/mavlink/out`, `/mavlink/in`). The link never waits for the logger: when
//! the consumer falls behind, the oldest events go and are counted.
//!
//! Received messages have their own budget ([`EventSender::push_incoming`]):
//! at most a configured number a second are queued, so a flood of valid
//! MAVLink from the network cannot fill the flight log (nor cost the CPU of
//! decoding every message's fields); the consumer also skips them while the
//! log is busy ([`EventReceiver::skip_incoming`]). Both are counted
//! (`LinkStats::unlogged_incoming`).

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// One MAVLink message sent or received, decoded.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkEvent {
    /// When the write to the transport started / the read returned, ns since
    /// the Unix epoch, on the run's clock (`run --fast`: the source's, see
    /// [`crate::clock`]).
    pub time_ns: u64,
    /// Sent by us (`/mavlink/out`) or received (`/mavlink/in`).
    pub outgoing: bool,
    /// MAVLink message name, e.g. `LANDING_TARGET`.
    pub name: String,
    /// Capture time of the frame a pose message was built from.
    pub capture_time_ns: Option<u64>,
    /// The message's fields (plus `sysid`, `compid`, `seq` of the frame).
    pub fields: serde_json::Value,
}

struct Queue {
    events: Mutex<VecDeque<LinkEvent>>,
    ready: Condvar,
    capacity: usize,
    dropped: AtomicU64,
    /// Received messages not logged (over budget, or skipped by the consumer).
    unlogged_incoming: AtomicU64,
    /// Token bucket of the incoming budget: tokens left, and when last filled.
    incoming_budget: Mutex<(f64, Option<std::time::Instant>)>,
    incoming_per_s: f64,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The producing side, held by the link tasks.
#[derive(Clone)]
pub(crate) struct EventSender(Arc<Queue>);

/// The consuming side, handed out by `LinkHandle::events()`. Meant for one
/// consumer (the logger); clones share the same queue.
#[derive(Clone)]
pub struct EventReceiver(Arc<Queue>);

/// A queue holding at most `capacity` (>= 1) events, of which at most
/// `incoming_per_s` received messages a second (bursts of one second's worth).
pub(crate) fn event_queue(capacity: usize, incoming_per_s: f64) -> (EventSender, EventReceiver) {
    let incoming_per_s = incoming_per_s.max(1.0);
    let q = Arc::new(Queue {
        events: Mutex::new(VecDeque::with_capacity(capacity.clamp(1, 4096))),
        ready: Condvar::new(),
        capacity: capacity.max(1),
        dropped: AtomicU64::new(0),
        unlogged_incoming: AtomicU64::new(0),
        incoming_budget: Mutex::new((incoming_per_s, None)),
        incoming_per_s,
    });
    (EventSender(q.clone()), EventReceiver(q))
}

impl EventSender {
    /// Queues `e`, dropping the oldest event when full. Never blocks for long.
    pub fn push(&self, e: LinkEvent) {
        let mut q = lock(&self.0.events);
        if q.len() >= self.0.capacity {
            q.pop_front();
            self.0.dropped.fetch_add(1, Ordering::Relaxed);
        }
        q.push_back(e);
        drop(q);
        self.0.ready.notify_one();
    }

    /// Queues the received message `make()` builds, if the incoming budget
    /// allows one now; otherwise counts it (and never builds it).
    pub fn push_incoming(&self, make: impl FnOnce() -> LinkEvent) {
        let now = std::time::Instant::now();
        let allowed = {
            let mut b = lock(&self.0.incoming_budget);
            let rate = self.0.incoming_per_s;
            if let Some(last) = b.1 {
                b.0 = (b.0 + now.saturating_duration_since(last).as_secs_f64() * rate).min(rate);
            }
            b.1 = Some(now);
            let ok = b.0 >= 1.0;
            if ok {
                b.0 -= 1.0;
            }
            ok
        };
        if allowed {
            self.push(make());
        } else {
            self.0.unlogged_incoming.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl EventReceiver {
    /// The oldest queued event, if any, without waiting.
    pub fn try_recv(&self) -> Option<LinkEvent> {
        lock(&self.0.events).pop_front()
    }

    /// The oldest event, waiting up to `timeout` for one.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<LinkEvent> {
        let q = lock(&self.0.events);
        let (mut q, _) = self
            .0
            .ready
            .wait_timeout_while(q, timeout, |q| q.is_empty())
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        q.pop_front()
    }

    /// Everything queued now, oldest first.
    pub fn drain(&self) -> Vec<LinkEvent> {
        lock(&self.0.events).drain(..).collect()
    }

    /// Events dropped so far because this consumer was too slow.
    pub fn dropped(&self) -> u64 {
        self.0.dropped.load(Ordering::Relaxed)
    }

    /// The consumer did not log this received message (its log was busy):
    /// counted with those over the budget.
    pub fn skip_incoming(&self) {
        self.0.unlogged_incoming.fetch_add(1, Ordering::Relaxed);
    }

    /// Received messages not logged so far (over budget or skipped).
    pub fn unlogged_incoming(&self) -> u64 {
        self.0.unlogged_incoming.load(Ordering::Relaxed)
    }

    /// Events waiting now (for the run's queue statistics).
    pub fn len(&self) -> usize {
        lock(&self.0.events).len()
    }

    /// No events waiting.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(i: u64) -> LinkEvent {
        LinkEvent {
            time_ns: i,
            outgoing: true,
            name: "X".into(),
            capture_time_ns: None,
            fields: serde_json::Value::Null,
        }
    }

    #[test]
    fn full_queue_drops_oldest_and_counts() {
        let (tx, rx) = event_queue(3, 1000.0);
        for i in 0..5 {
            tx.push(ev(i));
        }
        let got: Vec<u64> = rx.drain().iter().map(|e| e.time_ns).collect();
        assert_eq!(got, vec![2, 3, 4]);
        assert_eq!(rx.dropped(), 2);
        assert!(rx.try_recv().is_none());
        assert!(rx.recv_timeout(Duration::from_millis(5)).is_none());
    }

    #[test]
    fn incoming_messages_stay_within_their_budget() {
        let (tx, rx) = event_queue(100_000, 50.0);
        let started = std::time::Instant::now();
        let mut built = 0u64;
        for i in 0..10_000 {
            tx.push_incoming(|| {
                built += 1;
                ev(i)
            });
        }
        let elapsed = started.elapsed().as_secs_f64();
        // One second's burst plus what the elapsed time earned.
        let most = 50.0 * (1.0 + elapsed) + 1.0;
        assert!((rx.len() as f64) <= most, "{} queued", rx.len());
        assert_eq!(built, rx.len() as u64, "an event over budget was built");
        assert_eq!(rx.unlogged_incoming() + rx.len() as u64, 10_000);
        rx.skip_incoming();
        assert_eq!(rx.unlogged_incoming() + rx.len() as u64, 10_001);
    }
}
