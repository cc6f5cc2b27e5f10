//! Capture times and sequence numbers from the driver's buffer metadata.
//!
//! V4L2 drivers stamp each buffer with CLOCK_MONOTONIC (flag
//! `V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC`; UVC: the start or end of the frame's
//! readout). The pipeline wants Unix-epoch nanoseconds, so the source measures
//! the offset CLOCK_REALTIME - CLOCK_MONOTONIC when it opens the camera (and
//! again every few seconds, so NTP corrections are followed): it reads
//! MONOTONIC, REALTIME, MONOTONIC in a row, several times, and keeps the read
//! with the narrowest MONOTONIC bracket, taking REALTIME against its middle.

/// `V4L2_BUF_FLAG_TIMESTAMP_MASK` and the one type we convert.
pub const TIMESTAMP_TYPE_MASK: u32 = 0x0000_e000;
/// `V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC`: the driver's time is CLOCK_MONOTONIC.
pub const TIMESTAMP_MONOTONIC: u32 = 0x0000_2000;
/// `V4L2_BUF_FLAG_ERROR`: the driver says the buffer's data may be corrupt.
pub const BUFFER_FLAG_ERROR: u32 = 0x0000_0040;

/// A driver time farther than this from the dequeue time is not believed.
const MAX_DRIVER_TIME_ERROR_NS: i128 = 1_000_000_000;

/// One read of the two clocks, nanoseconds: MONOTONIC, REALTIME, MONOTONIC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockRead {
    /// MONOTONIC before the REALTIME read.
    pub monotonic_before_ns: i128,
    /// REALTIME (Unix time).
    pub realtime_ns: i128,
    /// MONOTONIC after the REALTIME read.
    pub monotonic_after_ns: i128,
}

/// REALTIME - MONOTONIC, nanoseconds, with the half-width of the bracket it
/// was read in (its uncertainty).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockOffset {
    /// REALTIME - MONOTONIC, against the bracket's middle.
    pub realtime_minus_monotonic_ns: i128,
    /// Half-width of the MONOTONIC bracket.
    pub uncertainty_ns: i128,
}

impl ClockOffset {
    /// The offset from the read with the narrowest bracket; `None` when no
    /// read is usable (a bracket that runs backwards).
    pub fn from_reads(reads: &[ClockRead]) -> Option<Self> {
        reads
            .iter()
            .filter(|r| r.monotonic_after_ns >= r.monotonic_before_ns)
            .min_by_key(|r| r.monotonic_after_ns - r.monotonic_before_ns)
            .map(|r| {
                let middle =
                    r.monotonic_before_ns + (r.monotonic_after_ns - r.monotonic_before_ns) / 2;
                Self {
                    realtime_minus_monotonic_ns: r.realtime_ns - middle,
                    uncertainty_ns: (r.monotonic_after_ns - r.monotonic_before_ns + 1) / 2,
                }
            })
    }

    /// Measured now on this machine (10 reads).
    #[cfg(feature = "v4l")]
    pub fn measure() -> Option<Self> {
        fn now(clock: libc::clockid_t) -> Option<i128> {
            let mut ts = libc::timespec {
                tv_sec: 0,
                tv_nsec: 0,
            };
            // SAFETY: clock_gettime writes one timespec, which `ts` is.
            let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
            (rc == 0).then(|| i128::from(ts.tv_sec) * 1_000_000_000 + i128::from(ts.tv_nsec))
        }
        let reads: Option<Vec<ClockRead>> = (0..10)
            .map(|_| {
                Some(ClockRead {
                    monotonic_before_ns: now(libc::CLOCK_MONOTONIC)?,
                    realtime_ns: now(libc::CLOCK_REALTIME)?,
                    monotonic_after_ns: now(libc::CLOCK_MONOTONIC)?,
                })
            })
            .collect();
        Self::from_reads(&reads?)
    }
}

/// Where a frame's capture time came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeSource {
    /// The driver's CLOCK_MONOTONIC buffer timestamp, converted.
    Driver,
    /// The time the buffer was dequeued: the driver's stamp is missing, of
    /// another clock (`COPY`, unknown), or more than a second off.
    Dequeue,
}

/// The capture time of a buffer, Unix ns, from the driver's timestamp
/// (`seconds`, `microseconds` as in `struct timeval`) and `flags`.
pub fn capture_time_ns(
    flags: u32,
    seconds: i64,
    microseconds: i64,
    offset: &ClockOffset,
    dequeued_unix_ns: u64,
) -> (u64, TimeSource) {
    let fallback = (dequeued_unix_ns, TimeSource::Dequeue);
    let stamped = seconds != 0 || microseconds != 0;
    if flags & TIMESTAMP_TYPE_MASK != TIMESTAMP_MONOTONIC || !stamped {
        return fallback;
    }
    let unix_ns = i128::from(seconds) * 1_000_000_000
        + i128::from(microseconds) * 1_000
        + offset.realtime_minus_monotonic_ns;
    if (unix_ns - i128::from(dequeued_unix_ns)).abs() > MAX_DRIVER_TIME_ERROR_NS {
        return fallback;
    }
    match u64::try_from(unix_ns) {
        Ok(t) => (t, TimeSource::Driver),
        Err(_) => fallback,
    }
}

/// Extends the driver's 32-bit frame counter into the pipeline's sequence
/// numbers and counts the frames the driver dropped (gaps in its counter).
/// The numbers keep increasing across a reopen of the camera (where the
/// driver starts again from 0), so a log never sees a sequence go back.
#[derive(Clone, Debug, Default)]
pub struct SequenceTracker {
    last_driver: Option<u32>,
    next_seq: u64,
    dropped: u64,
}

impl SequenceTracker {
    /// The sequence number of a frame with the driver's counter `driver`,
    /// and how many frames were dropped just before it.
    pub fn observe(&mut self, driver: u32) -> (u64, u64) {
        let step = match self.last_driver {
            None => 1,
            Some(last) => match driver.wrapping_sub(last) {
                // A driver that does not count (always 0), or one that went
                // backwards: no drop information, count on by one.
                0 => 1,
                d if d > u32::MAX / 2 => 1,
                d => u64::from(d),
            },
        };
        self.last_driver = Some(driver);
        let dropped_now = step - 1;
        self.dropped += dropped_now;
        let seq = self.next_seq + dropped_now;
        self.next_seq = seq + 1;
        (seq, dropped_now)
    }

    /// The camera was reopened: its driver counts from anew.
    pub fn restart(&mut self) {
        self.last_driver = None;
    }

    /// Frames dropped by the driver so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OFFSET: ClockOffset = ClockOffset {
        realtime_minus_monotonic_ns: 1_700_000_000_000_000_000 - 5_000_000_000,
        uncertainty_ns: 100,
    };

    #[test]
    fn offset_from_the_narrowest_bracket() {
        let reads = [
            ClockRead {
                monotonic_before_ns: 1_000,
                realtime_ns: 10_000_600,
                monotonic_after_ns: 2_000,
            },
            ClockRead {
                monotonic_before_ns: 5_000,
                realtime_ns: 10_005_100,
                monotonic_after_ns: 5_200,
            },
            // Backwards: unusable.
            ClockRead {
                monotonic_before_ns: 9_000,
                realtime_ns: 0,
                monotonic_after_ns: 8_000,
            },
        ];
        assert_eq!(
            ClockOffset::from_reads(&reads),
            Some(ClockOffset {
                realtime_minus_monotonic_ns: 10_005_100 - 5_100,
                uncertainty_ns: 100,
            })
        );
        assert_eq!(ClockOffset::from_reads(&reads[2..]), None);
        assert_eq!(ClockOffset::from_reads(&[]), None);
    }

    #[test]
    fn driver_time_converted_to_unix() {
        // Driver stamp 5.25 s after boot = Unix 1.7e18 ns + 0.25 s.
        let unix = 1_700_000_000_250_000_000u64;
        let (t, src) = capture_time_ns(
            TIMESTAMP_MONOTONIC | 0x1,
            5,
            250_000,
            &OFFSET,
            unix + 3_000_000,
        );
        assert_eq!((t, src), (unix, TimeSource::Driver));
    }

    #[test]
    fn other_clocks_and_bad_stamps_fall_back_to_dequeue_time() {
        let dequeued = 1_700_000_000_250_000_000u64;
        // COPY (0x4000) and unknown (0) timestamp types.
        for flags in [0x4000, 0] {
            assert_eq!(
                capture_time_ns(flags, 5, 250_000, &OFFSET, dequeued),
                (dequeued, TimeSource::Dequeue)
            );
        }
        // No stamp; a stamp 3 s off; a stamp that is not a Unix time.
        for (s, us) in [(0, 0), (2, 0), (-9_000_000_000_000, 0)] {
            assert_eq!(
                capture_time_ns(TIMESTAMP_MONOTONIC, s, us, &OFFSET, dequeued),
                (dequeued, TimeSource::Dequeue)
            );
        }
        let extreme = capture_time_ns(TIMESTAMP_MONOTONIC, i64::MAX, i64::MAX, &OFFSET, dequeued);
        assert_eq!(extreme, (dequeued, TimeSource::Dequeue));
    }

    #[test]
    fn sequence_gaps_count_dropped_frames() {
        let mut t = SequenceTracker::default();
        assert_eq!(t.observe(100), (0, 0));
        assert_eq!(t.observe(101), (1, 0));
        assert_eq!(t.observe(104), (4, 2));
        assert_eq!(t.dropped(), 2);
        // The 32-bit counter wraps.
        let mut w = SequenceTracker::default();
        w.observe(u32::MAX - 1);
        assert_eq!(w.observe(u32::MAX), (1, 0));
        assert_eq!(w.observe(1), (3, 1));
        assert_eq!(w.dropped(), 1);
    }

    #[test]
    fn sequence_keeps_increasing_across_a_reopen_and_odd_drivers() {
        let mut t = SequenceTracker::default();
        t.observe(7);
        t.observe(8);
        t.restart();
        assert_eq!(t.observe(0), (2, 0));
        assert_eq!(t.observe(1), (3, 0));
        // A driver that never counts.
        assert_eq!(t.observe(1), (4, 0));
        // A driver counter that jumps back.
        assert_eq!(t.observe(0), (5, 0));
        assert_eq!(t.dropped(), 0);
    }
}
