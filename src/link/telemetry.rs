//! The autopilot's own pose, as reported on the link: a short time-indexed
//! buffer of ATTITUDE and LOCAL_POSITION_NED, and the clock offset that puts
//! their `time_boot_ms` on our clock (Unix epoch, like capture times).
//!
//! Clock: the offset comes from TIMESYNC. Our own requests (tc1 = 0, ts1 =
//! our ns) are answered with the autopilot's clock in tc1; the sample with
//! the shortest round trip gives offset = tc1 - (ts1 + now) / 2. Until a
//! reply arrives, the autopilot's own requests give a one-way estimate
//! (ts1 - now, off by the link latency). Without any TIMESYNC a sample is
//! stamped with its arrival time.

use crate::spatial::{LocalNed, Point};
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::VecDeque;

/// The vehicle's pose at one time, in the autopilot's local NED.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehiclePose {
    /// The time it is for, ns since the Unix epoch.
    pub time_ns: u64,
    /// Body origin, metres.
    pub position_ned_m: Point<LocalNed>,
    /// Attitude: body → NED.
    pub q_ned_body: UnitQuaternion<f64>,
}

/// Most samples kept per stream (an autopilot streams at most ~50 Hz).
const MAX_SAMPLES: usize = 256;
/// A jump of the clock offset beyond this is a reboot or a new clock: restart.
const OFFSET_JUMP_NS: i64 = 1_000_000_000;
const SYNC_WINDOW: usize = 8;
/// Replies to our own TIMESYNC requests before the offset counts as converged.
pub const CONVERGED_REPLIES: usize = 4;

/// Estimates autopilot clock minus our clock, ns.
#[derive(Default)]
pub struct TimeSync {
    pending: VecDeque<i64>,
    /// (round trip, offset) of recent replies to our requests.
    replies: VecDeque<(i64, i64)>,
    /// One-way estimates from the autopilot's requests.
    one_way: VecDeque<i64>,
}

impl TimeSync {
    /// We sent a request with ts1 = `ts1_ns` (our clock).
    pub fn request_sent(&mut self, ts1_ns: i64) {
        if self.pending.len() >= SYNC_WINDOW {
            self.pending.pop_front();
        }
        self.pending.push_back(ts1_ns);
    }

    /// A reply (tc1 != 0) arrived at `now_ns`; true if it answered one of ours.
    pub fn reply(&mut self, tc1_ns: i64, ts1_ns: i64, now_ns: i64) -> bool {
        let Some(i) = self.pending.iter().position(|&t| t == ts1_ns) else {
            return false;
        };
        self.pending.remove(i);
        let rtt = now_ns - ts1_ns;
        if rtt < 0 {
            return false;
        }
        let offset = tc1_ns - (ts1_ns + rtt / 2);
        if let Some(current) = self.offset_ns()
            && (offset - current).abs() > OFFSET_JUMP_NS
        {
            self.replies.clear();
            self.one_way.clear();
        }
        if self.replies.len() >= SYNC_WINDOW {
            self.replies.pop_front();
        }
        self.replies.push_back((rtt, offset));
        true
    }

    /// The autopilot asked (tc1 == 0) with its clock `ts1_ns`, seen at `now_ns`.
    pub fn request_seen(&mut self, ts1_ns: i64, now_ns: i64) {
        let offset = ts1_ns - now_ns;
        if let Some(&last) = self.one_way.back()
            && (offset - last).abs() > OFFSET_JUMP_NS
        {
            self.one_way.clear();
        }
        if self.one_way.len() >= SYNC_WINDOW {
            self.one_way.pop_front();
        }
        self.one_way.push_back(offset);
    }

    /// The offset once our own requests have had [`CONVERGED_REPLIES`]
    /// answers in the window (the one-way estimate from the autopilot's
    /// requests is off by the link latency and does not count).
    pub fn converged_offset_ns(&self) -> Option<i64> {
        if self.replies.len() < CONVERGED_REPLIES {
            return None;
        }
        self.replies
            .iter()
            .min_by_key(|(rtt, _)| *rtt)
            .map(|&(_, offset)| offset)
    }

    /// Autopilot clock minus our clock, ns, if known.
    pub fn offset_ns(&self) -> Option<i64> {
        if let Some(&(_, offset)) = self.replies.iter().min_by_key(|(rtt, _)| *rtt) {
            return Some(offset);
        }
        // The least delayed one-way sample has the largest ts1 - now.
        self.one_way.iter().copied().max()
    }
}

#[derive(Clone, Copy)]
struct Sample<T> {
    time_ns: u64,
    value: T,
}

/// Samples of one quantity, sorted by time, bounded.
struct Series<T> {
    samples: VecDeque<Sample<T>>,
}

impl<T: Copy> Series<T> {
    fn new() -> Self {
        Self {
            samples: VecDeque::with_capacity(MAX_SAMPLES),
        }
    }

    fn push(&mut self, time_ns: u64, value: T) {
        if let Some(last) = self.samples.back()
            && last.time_ns > time_ns.saturating_add(OFFSET_JUMP_NS as u64)
        {
            // Time went back by more than a second: a new clock. Start over.
            self.samples.clear();
        }
        let at = self.samples.partition_point(|s| s.time_ns <= time_ns);
        self.samples.insert(at, Sample { time_ns, value });
        while self.samples.len() > MAX_SAMPLES {
            self.samples.pop_front();
        }
    }

    /// The samples around `t` within `tol` of it: (before, after), either may
    /// be missing.
    fn around(&self, t: u64, tol: u64) -> (Option<Sample<T>>, Option<Sample<T>>) {
        let i = self.samples.partition_point(|s| s.time_ns <= t);
        let before = i
            .checked_sub(1)
            .and_then(|j| self.samples.get(j))
            .filter(|s| t - s.time_ns <= tol)
            .copied();
        let after = self
            .samples
            .get(i)
            .filter(|s| s.time_ns - t <= tol)
            .copied();
        (before, after)
    }
}

fn fraction(t: u64, a: u64, b: u64) -> f64 {
    if b > a {
        (t - a) as f64 / (b - a) as f64
    } else {
        0.0
    }
}

/// The vehicle telemetry buffer.
pub struct Telemetry {
    tolerance_ns: u64,
    attitude: Series<UnitQuaternion<f64>>,
    position: Series<Vector3<f64>>,
    /// The autopilot's clock offset from ours (TIMESYNC).
    pub timesync: TimeSync,
}

impl Telemetry {
    /// Samples farther than `tolerance_ns` from a requested time are not used.
    pub fn new(tolerance_ns: u64) -> Self {
        Self {
            tolerance_ns,
            attitude: Series::new(),
            position: Series::new(),
            timesync: TimeSync::default(),
        }
    }

    /// The Unix time of an autopilot `time_boot_ms`, or the arrival time
    /// without clock sync.
    fn sample_time(&self, time_boot_ms: u32, received_ns: u64) -> u64 {
        match self.timesync.offset_ns() {
            Some(offset) => {
                let t = i128::from(time_boot_ms) * 1_000_000 - i128::from(offset);
                u64::try_from(t).unwrap_or(received_ns)
            }
            None => received_ns,
        }
    }

    /// ATTITUDE: roll, pitch, yaw (radians, body → NED, ZYX).
    pub fn push_attitude(&mut self, time_boot_ms: u32, rpy: [f32; 3], received_ns: u64) {
        let [r, p, y] = rpy.map(f64::from);
        if !(r.is_finite() && p.is_finite() && y.is_finite()) {
            return;
        }
        let t = self.sample_time(time_boot_ms, received_ns);
        self.attitude
            .push(t, UnitQuaternion::from_euler_angles(r, p, y));
    }

    /// LOCAL_POSITION_NED: x, y, z, metres.
    pub fn push_position(&mut self, time_boot_ms: u32, ned_m: [f32; 3], received_ns: u64) {
        let v = Vector3::from(ned_m.map(f64::from));
        if !v.iter().all(|c| c.is_finite()) {
            return;
        }
        let t = self.sample_time(time_boot_ms, received_ns);
        self.position.push(t, v);
    }

    /// The attitude (body → NED) at `t` (ns, Unix), as [`Telemetry::pose_at`]
    /// finds it, without needing a position.
    pub fn attitude_at(&self, t: u64) -> Option<UnitQuaternion<f64>> {
        match self.attitude.around(t, self.tolerance_ns) {
            (Some(a), Some(b)) => Some(
                a.value
                    .try_slerp(&b.value, fraction(t, a.time_ns, b.time_ns), 1e-9)
                    .unwrap_or(a.value),
            ),
            (Some(a), None) | (None, Some(a)) => Some(a.value),
            (None, None) => None,
        }
    }

    /// Attitude and position at `t` (ns, Unix): interpolated between the
    /// samples around it (slerp for the attitude), or the nearest one, as long
    /// as they are within the tolerance; `None` otherwise.
    pub fn pose_at(&self, t: u64) -> Option<VehiclePose> {
        let tol = self.tolerance_ns;
        let q = self.attitude_at(t)?;
        let p = match self.position.around(t, tol) {
            (Some(a), Some(b)) => a.value.lerp(&b.value, fraction(t, a.time_ns, b.time_ns)),
            (Some(a), None) | (None, Some(a)) => a.value,
            (None, None) => return None,
        };
        Some(VehiclePose {
            time_ns: t,
            position_ned_m: Point::new(p),
            q_ned_body: q,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn interpolates_between_samples_and_refuses_far_times() {
        let mut tm = Telemetry::new(100 * MS);
        let t0 = 1_700_000_000_000 * MS;
        // No TIMESYNC: samples are stamped with their arrival time.
        tm.push_position(0, [0.0, 0.0, -10.0], t0);
        tm.push_position(0, [2.0, -4.0, -12.0], t0 + 100 * MS);
        tm.push_attitude(0, [0.0, 0.0, 0.0], t0);
        tm.push_attitude(0, [0.0, 0.0, 0.2], t0 + 100 * MS);
        let p = tm.pose_at(t0 + 25 * MS).unwrap();
        // Linear interpolation a quarter of the way.
        let expect = [0.5, -1.0, -10.5];
        for (got, want) in p.position_ned_m.iter().zip(expect) {
            assert!((got - want).abs() < 1e-9);
        }
        // Slerp of a pure yaw: a quarter of 0.2 rad about down.
        let q = crate::spatial::quaternion_to_wxyz(&p.q_ned_body);
        let yaw = 2.0 * q[3].atan2(q[0]);
        assert!((yaw - 0.05).abs() < 1e-9, "{yaw}");
        // Held within the tolerance past the last sample, refused beyond.
        assert!(tm.pose_at(t0 + 150 * MS).is_some());
        assert!(tm.pose_at(t0 + 250 * MS).is_none());
        assert!(tm.pose_at(t0 - 150 * MS).is_none());
    }

    #[test]
    fn timesync_puts_boot_time_on_the_unix_clock() {
        let mut ts = TimeSync::default();
        assert_eq!(ts.offset_ns(), None);
        // Autopilot clock = Unix - 1e18 ns; replies take 10 ms and 2 ms round trips.
        let off = -1_000_000_000_000_000_000i64;
        let unix0 = 1_700_000_000_000_000_000i64;
        ts.request_sent(unix0);
        assert!(ts.reply(
            unix0 + off + 5 * MS as i64 + 3 * MS as i64,
            unix0,
            unix0 + 10 * MS as i64
        ));
        ts.request_sent(unix0 + 1000 * MS as i64);
        let t1 = unix0 + 1000 * MS as i64;
        assert!(ts.reply(t1 + off + MS as i64, t1, t1 + 2 * MS as i64));
        // The shorter round trip wins: exact offset.
        assert_eq!(ts.offset_ns(), Some(off));
        // Two replies are not yet a converged exchange; four are.
        assert_eq!(ts.converged_offset_ns(), None);
        let mut converged = TimeSync::default();
        for k in 0..CONVERGED_REPLIES as i64 {
            let t = unix0 + k * 1000 * MS as i64;
            converged.request_sent(t);
            assert!(converged.reply(t + off + MS as i64, t, t + 2 * MS as i64));
        }
        assert_eq!(converged.converged_offset_ns(), Some(off));
        // A reply to someone else's request is ignored.
        assert!(!ts.reply(123, 456, t1));

        let mut tm = Telemetry::new(50 * MS);
        tm.timesync = ts;
        let boot_ms = 5_000u32;
        let unix_of_boot = (i64::from(boot_ms) * MS as i64 - off) as u64;
        tm.push_position(boot_ms, [1.0, 2.0, 3.0], 0);
        tm.push_attitude(boot_ms, [0.0, 0.0, 0.0], 0);
        let p = tm.pose_at(unix_of_boot).unwrap();
        assert_eq!(p.position_ned_m.to_array(), [1.0, 2.0, 3.0]);
    }

    #[test]
    fn buffer_is_bounded_and_restarts_on_a_clock_jump() {
        let mut s = Series::new();
        for i in 0..10 * MAX_SAMPLES as u64 {
            s.push(1_000_000 * MS + i * MS, i);
        }
        assert_eq!(s.samples.len(), MAX_SAMPLES);
        s.push(5 * MS, 0);
        assert_eq!(s.samples.len(), 1);
    }
}
