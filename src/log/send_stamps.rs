//! Puts the "sent" stamp into a frame's `/drogue/detection` record.
//!
//! The measurement is logged right after it is handed to the link, and the
//! link sends it a few microseconds later on its own task; its send event
//! reaches the log through a different path, so it may come before or after
//! the record. The writer holds a detected frame's record back for a short
//! while until its first pose message is seen going out (or a newer frame's
//! is, or the wait is over: not sent), then writes it with
//! `latency_ns.sent` set.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Longest a record waits for its send event. Sends happen within
/// milliseconds; this only bounds the wait when nothing is sent (stale pose,
/// link down).
pub(crate) const HOLD: Duration = Duration::from_millis(250);
/// Records held at most (beyond it the oldest is written unsent).
const MAX_HELD: usize = 32;
/// Send events remembered for records that arrive after their event.
const MAX_RECENT_SENDS: usize = 32;

/// A record ready to be written, with its sent stamp filled in.
pub(crate) struct ReadyRecord {
    pub seq: u64,
    pub capture_time_ns: u64,
    pub json: serde_json::Value,
}

struct Held {
    since: Instant,
    record: ReadyRecord,
}

/// Matches detection records with the send events of their frames.
#[derive(Default)]
pub(crate) struct SendStamps {
    held: VecDeque<Held>,
    /// (capture time, first send time) of recent pose messages.
    recent_sends: VecDeque<(u64, u64)>,
}

/// `record` with `latency_ns.sent` set (null: not sent).
pub(crate) fn stamp(mut record: ReadyRecord, sent_ns: Option<u64>) -> ReadyRecord {
    if let Some(latency) = record
        .json
        .get_mut("latency_ns")
        .and_then(|v| v.as_object_mut())
    {
        latency.insert("sent".into(), sent_ns.into());
    }
    record
}

impl SendStamps {
    /// A detected frame's record: ready now if its pose was already seen
    /// going out, else held.
    pub fn hold(&mut self, record: ReadyRecord, now: Instant) -> Vec<ReadyRecord> {
        let capture = record.capture_time_ns;
        if let Some(&(_, sent)) = self.recent_sends.iter().find(|(c, _)| *c == capture) {
            return vec![stamp(record, Some(sent))];
        }
        self.held.push_back(Held { since: now, record });
        let mut ready = Vec::new();
        while self.held.len() > MAX_HELD {
            if let Some(h) = self.held.pop_front() {
                ready.push(stamp(h.record, None));
            }
        }
        ready
    }

    /// An outgoing pose message built from the frame captured at
    /// `capture_time_ns`, written at `sent_ns`. Releases that frame's record
    /// and any older one (the link only sends the newest pose, so an older
    /// frame will not be sent any more).
    pub fn sent(&mut self, capture_time_ns: u64, sent_ns: u64) -> Vec<ReadyRecord> {
        if self.recent_sends.iter().any(|(c, _)| *c == capture_time_ns) {
            return Vec::new();
        }
        self.recent_sends.push_back((capture_time_ns, sent_ns));
        if self.recent_sends.len() > MAX_RECENT_SENDS {
            self.recent_sends.pop_front();
        }
        let mut ready = Vec::new();
        while let Some(h) = self
            .held
            .front()
            .filter(|h| h.record.capture_time_ns <= capture_time_ns)
        {
            let matched = h.record.capture_time_ns == capture_time_ns;
            if let Some(h) = self.held.pop_front() {
                ready.push(stamp(h.record, matched.then_some(sent_ns)));
            }
        }
        ready
    }

    /// Records that waited [`HOLD`] without a send: not sent.
    pub fn expired(&mut self, now: Instant) -> Vec<ReadyRecord> {
        let mut ready = Vec::new();
        while self
            .held
            .front()
            .is_some_and(|h| now.duration_since(h.since) >= HOLD)
        {
            if let Some(h) = self.held.pop_front() {
                ready.push(stamp(h.record, None));
            }
        }
        ready
    }

    /// Everything still held (the log is finishing): not sent.
    pub fn drain(&mut self) -> Vec<ReadyRecord> {
        self.held.drain(..).map(|h| stamp(h.record, None)).collect()
    }

    /// When the oldest held record gives up waiting.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.held.front().map(|h| h.since + HOLD)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(capture: u64) -> ReadyRecord {
        ReadyRecord {
            seq: capture,
            capture_time_ns: capture,
            json: serde_json::json!({"latency_ns": {"captured": capture}}),
        }
    }

    fn sent_of(r: &ReadyRecord) -> serde_json::Value {
        r.json["latency_ns"]["sent"].clone()
    }

    #[test]
    fn record_then_send_event() {
        let mut s = SendStamps::default();
        let t0 = Instant::now();
        assert!(s.hold(record(100), t0).is_empty());
        let ready = s.sent(100, 150);
        assert_eq!(ready.len(), 1);
        assert_eq!(sent_of(&ready[0]), 150);
        // The frame's second and third messages change nothing.
        assert!(s.sent(100, 160).is_empty());
        assert!(s.next_deadline().is_none());
    }

    #[test]
    fn send_event_before_record() {
        let mut s = SendStamps::default();
        assert!(s.sent(100, 150).is_empty());
        let ready = s.hold(record(100), Instant::now());
        assert_eq!(ready.len(), 1);
        assert_eq!(sent_of(&ready[0]), 150);
    }

    #[test]
    fn superseded_and_expired_records_are_not_sent() {
        let mut s = SendStamps::default();
        let t0 = Instant::now();
        s.hold(record(100), t0);
        s.hold(record(200), t0);
        let ready = s.sent(200, 250);
        assert_eq!(ready.len(), 2);
        assert_eq!(sent_of(&ready[0]), serde_json::Value::Null);
        assert_eq!(sent_of(&ready[1]), 250);

        s.hold(record(300), t0);
        assert!(s.expired(t0 + HOLD / 2).is_empty());
        let ready = s.expired(t0 + HOLD);
        assert_eq!(ready.len(), 1);
        assert_eq!(sent_of(&ready[0]), serde_json::Value::Null);
    }

    #[test]
    fn bounded() {
        let mut s = SendStamps::default();
        let t0 = Instant::now();
        let released: usize = (0..100).map(|c| s.hold(record(c), t0).len()).sum();
        assert_eq!(released, 100 - MAX_HELD);
        assert_eq!(s.drain().len(), MAX_HELD);
    }
}
