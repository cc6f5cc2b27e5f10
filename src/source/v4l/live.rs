//! A live camera as a frame source: capture times, sequence numbers, dropped
//! frames, and the camera lost and reopened with back-off while the run goes
//! on. Written against two small traits, so that all of it is tested with a
//! scripted camera; the V4L2 device implements them (`device.rs`).

use super::Backoff;
use super::clock::{ClockOffset, SequenceTracker, TimeSource, capture_time_ns};
use crate::camera::CameraModel;
use crate::frame::{Frame, FrameOrigin};
use crate::measure::mount::MountConfig;
use crate::source::{Captured, FrameSource, SourceItem};
use image::GrayImage;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::{Duration, Instant};

/// How often the clock offset is measured again while streaming.
const CLOCK_REFRESH: Duration = Duration::from_secs(10);
/// Dropped-frame warnings at most this often (the count is cumulative).
const DROP_REPORT_INTERVAL: Duration = Duration::from_secs(5);

/// One dequeued buffer: the frame (or why it is unreadable) and the driver's
/// metadata, copied out of the driver's memory.
#[derive(Clone, Debug)]
pub struct RawBuffer {
    /// The frame, or why the buffer does not make one.
    pub image: Result<GrayImage, String>,
    /// V4L2 buffer flags (timestamp type, error).
    pub flags: u32,
    /// The driver's timestamp, as in `struct timeval`.
    pub seconds: i64,
    /// The microseconds part of the driver's timestamp.
    pub microseconds: i64,
    /// The driver's frame counter.
    pub sequence: u32,
    /// When the buffer was dequeued, Unix ns (the fallback capture time).
    pub dequeued_unix_ns: u64,
}

/// An open, streaming camera.
pub trait Camera: Send {
    /// The next buffer; an error means the camera is lost (unplugged,
    /// stalled past the timeout) and must be reopened.
    fn next_buffer(&mut self) -> Result<RawBuffer, String>;
    /// What the driver granted, for the log.
    fn description(&self) -> String;
    /// The granted frame rate, when the driver says.
    fn fps(&self) -> Option<f64>;
    /// The exposure time, when the camera's is fixed (manual exposure).
    fn exposure(&self) -> Option<Duration> {
        None
    }
}

/// Opens the camera (again).
pub trait CameraOpener: Send {
    /// The camera it opens.
    type Camera: Camera;
    /// Opens the device and starts streaming; an error leaves it for a later attempt.
    fn open(&mut self) -> Result<Self::Camera, String>;
    /// REALTIME - MONOTONIC now, to convert the driver's timestamps.
    fn clock_offset(&self) -> Option<ClockOffset>;
}

/// Figures of a live source, logged when it closes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LiveStats {
    /// Frames delivered.
    pub frames: u64,
    /// Frames the driver dropped (gaps in its sequence numbers).
    pub dropped_by_driver: u64,
    /// Buffers that did not make a frame (reported and skipped).
    pub unreadable: u64,
    /// Times the camera was lost (an error or no frame within the timeout).
    pub losses: u64,
    /// Times it was opened again after a loss.
    pub reopens: u64,
    /// Frames stamped with the dequeue time, the driver's time not being usable.
    pub stamped_at_dequeue: u64,
}

/// A live camera as a frame source.
pub struct LiveSource<O: CameraOpener> {
    name: String,
    opener: O,
    camera: Option<O::Camera>,
    fps: Option<f64>,
    /// The granted settings still to be logged (after an open, with the
    /// first frame, so that they reach the MCAP `/log` as well as stderr).
    announce: bool,
    sequence: SequenceTracker,
    clock: ClockOffset,
    clock_measured: Instant,
    backoff: Backoff,
    next_attempt: Instant,
    stats: LiveStats,
    last_drop_report: Option<Instant>,
}

/// Drops a camera; a panic in a driver binding while closing a vanished
/// device (STREAMOFF, munmap) is contained.
fn close<C>(camera: C) {
    let _ = catch_unwind(AssertUnwindSafe(move || drop(camera)));
}

impl<O: CameraOpener> LiveSource<O> {
    /// Opens the camera; failing here is a setup error (wrong device, no
    /// permission), reported before anything runs.
    pub fn open(name: &str, mut opener: O, backoff: Backoff) -> Result<Self, String> {
        let clock = opener.clock_offset().ok_or(
            "cannot read CLOCK_MONOTONIC/CLOCK_REALTIME to convert the driver's timestamps",
        )?;
        let camera = opener.open()?;
        tracing::info!(device = name, "camera opened: {}", camera.description());
        Ok(Self {
            name: name.to_string(),
            fps: camera.fps(),
            camera: Some(camera),
            opener,
            announce: true,
            sequence: SequenceTracker::default(),
            clock,
            clock_measured: Instant::now(),
            backoff,
            next_attempt: Instant::now(),
            stats: LiveStats::default(),
            last_drop_report: None,
        })
    }

    /// The figures so far.
    pub fn stats(&self) -> LiveStats {
        LiveStats {
            dropped_by_driver: self.sequence.dropped(),
            ..self.stats
        }
    }

    /// Closes a failed camera; the next frame request reopens it.
    fn lose_camera(&mut self, why: &str) -> String {
        if let Some(camera) = self.camera.take() {
            close(camera);
        }
        self.stats.losses += 1;
        // The back-off goes on growing until a frame comes through, so a
        // camera that opens but never delivers is not reopened in a tight loop.
        let wait = self.backoff.failed();
        self.next_attempt = Instant::now() + wait;
        tracing::warn!(
            device = %self.name,
            "camera lost ({why}); the run goes on, reopening with back-off"
        );
        format!(
            "camera {}: {why}; reopening in {} ms",
            self.name,
            wait.as_millis()
        )
    }

    /// One attempt to reopen a lost camera, after the back-off.
    fn try_reopen(&mut self) -> Result<(), String> {
        if let Some(wait) = self.next_attempt.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        match self.opener.open() {
            Ok(camera) => {
                self.stats.reopens += 1;
                self.sequence.restart();
                self.fps = camera.fps();
                self.camera = Some(camera);
                self.announce = true;
                self.refresh_clock();
                tracing::info!(device = %self.name, reopens = self.stats.reopens, "camera reopened");
                Ok(())
            }
            Err(e) => {
                let wait = self.backoff.failed();
                self.next_attempt = Instant::now() + wait;
                Err(format!(
                    "camera {} unavailable ({e}); next attempt in {} ms",
                    self.name,
                    wait.as_millis()
                ))
            }
        }
    }

    fn refresh_clock(&mut self) {
        if let Some(c) = self.opener.clock_offset() {
            self.clock = c;
        }
        self.clock_measured = Instant::now();
    }

    fn report_drops(&mut self, dropped_now: u64) {
        let due = self
            .last_drop_report
            .is_none_or(|t| t.elapsed() >= DROP_REPORT_INTERVAL);
        if dropped_now > 0 && due {
            self.last_drop_report = Some(Instant::now());
            tracing::warn!(
                device = %self.name,
                dropped_total = self.sequence.dropped(),
                "camera driver dropped frames (gaps in its sequence numbers)"
            );
        }
    }
}

impl<O: CameraOpener> FrameSource for LiveSource<O> {
    fn camera(&self) -> Option<CameraModel> {
        None
    }
    fn mount(&self) -> Option<MountConfig> {
        None
    }
    fn fps(&self) -> Option<f64> {
        self.fps
    }
    fn exposure(&self) -> Option<Duration> {
        self.camera.as_ref().and_then(Camera::exposure)
    }
    fn live(&self) -> bool {
        true
    }
    /// The next frame; an `Err` item for a frame that cannot be read and for
    /// each failed attempt to reopen a lost camera (so the run stays
    /// responsive to a stop request). Never `None`: a camera does not end.
    fn next_frame(&mut self) -> Option<SourceItem> {
        if self.camera.is_none()
            && let Err(e) = self.try_reopen()
        {
            return Some(Err(e));
        }
        if self.clock_measured.elapsed() >= CLOCK_REFRESH {
            self.refresh_clock();
        }
        let buffer = match self.camera.as_mut().map(Camera::next_buffer) {
            Some(Ok(b)) => b,
            Some(Err(e)) => return Some(Err(self.lose_camera(&e))),
            None => return Some(Err(format!("camera {} is not open", self.name))),
        };
        let (seq, dropped_now) = self.sequence.observe(buffer.sequence);
        self.report_drops(dropped_now);
        let (capture_time_ns, time_source) = capture_time_ns(
            buffer.flags,
            buffer.seconds,
            buffer.microseconds,
            &self.clock,
            buffer.dequeued_unix_ns,
        );
        if time_source == TimeSource::Dequeue {
            if self.stats.stamped_at_dequeue == 0 {
                tracing::warn!(
                    device = %self.name,
                    "the driver's buffer timestamps are not CLOCK_MONOTONIC (or are off by \
                     more than 1 s): capture time = dequeue time"
                );
            }
            self.stats.stamped_at_dequeue += 1;
        }
        if self.announce {
            self.announce = false;
            let granted = self.camera.as_ref().map(Camera::description);
            tracing::info!(
                device = %self.name,
                clock_offset_uncertainty_ns = self.clock.uncertainty_ns as i64,
                "camera streaming: {}",
                granted.unwrap_or_default()
            );
        }
        self.backoff.reset();
        match buffer.image {
            Ok(image) => {
                self.stats.frames += 1;
                Some(Ok(Captured::from(Frame {
                    seq,
                    capture_time_ns,
                    image,
                    origin: FrameOrigin::Camera {
                        device: self.name.clone(),
                    },
                })))
            }
            Err(e) => {
                self.stats.unreadable += 1;
                Some(Err(format!("camera {} frame {seq}: {e}", self.name)))
            }
        }
    }
}

impl<O: CameraOpener> Drop for LiveSource<O> {
    fn drop(&mut self) {
        let s = self.stats();
        tracing::info!(
            device = %self.name,
            frames = s.frames,
            dropped_by_driver = s.dropped_by_driver,
            unreadable = s.unreadable,
            losses = s.losses,
            reopens = s.reopens,
            stamped_at_dequeue = s.stamped_at_dequeue,
            "camera closed"
        );
        if let Some(camera) = self.camera.take() {
            close(camera);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::v4l::V4lConfig;
    use crate::source::v4l::clock::TIMESTAMP_MONOTONIC;
    use std::collections::VecDeque;
    use std::sync::{Arc, Mutex};

    /// What the scripted camera does next.
    #[derive(Clone, Debug)]
    enum Step {
        /// A good buffer: driver sequence and timestamp (µs after boot).
        Frame { sequence: u32, stamp_us: i64 },
        /// A buffer that does not decode.
        Corrupt { sequence: u32 },
        /// The camera is lost (dequeue fails).
        Lost,
    }

    /// REALTIME - MONOTONIC of the scripted machine: boot at Unix 1.7e9 s.
    const BOOT_UNIX_NS: i128 = 1_700_000_000_000_000_000;

    struct ScriptedCamera {
        steps: Arc<Mutex<VecDeque<Step>>>,
    }

    impl Camera for ScriptedCamera {
        fn next_buffer(&mut self) -> Result<RawBuffer, String> {
            let step = self.steps.lock().unwrap().pop_front();
            let buffer = |sequence: u32, stamp_us: i64, image: Result<GrayImage, String>| {
                RawBuffer {
                    image,
                    flags: TIMESTAMP_MONOTONIC,
                    seconds: stamp_us / 1_000_000,
                    microseconds: stamp_us % 1_000_000,
                    sequence,
                    // Dequeued 2 ms after the driver's stamp.
                    dequeued_unix_ns: (BOOT_UNIX_NS + i128::from(stamp_us) * 1000) as u64
                        + 2_000_000,
                }
            };
            match step {
                Some(Step::Frame { sequence, stamp_us }) => Ok(buffer(
                    sequence,
                    stamp_us,
                    Ok(GrayImage::from_pixel(4, 3, image::Luma([sequence as u8]))),
                )),
                Some(Step::Corrupt { sequence }) => Ok(buffer(
                    sequence,
                    1_000_000,
                    Err("MJPG frame does not decode".into()),
                )),
                Some(Step::Lost) | None => Err("No such device (os error 19)".into()),
            }
        }
        fn description(&self) -> String {
            "scripted GREY 4x3".into()
        }
        fn fps(&self) -> Option<f64> {
            Some(30.0)
        }
        fn exposure(&self) -> Option<Duration> {
            // Manual exposure, 40 x 100 us.
            Some(Duration::from_millis(4))
        }
    }

    /// Opens fail while `failures` is above zero (each attempt takes one).
    struct ScriptedOpener {
        steps: Arc<Mutex<VecDeque<Step>>>,
        failures: Arc<Mutex<u32>>,
        opens: Arc<Mutex<u32>>,
    }

    impl CameraOpener for ScriptedOpener {
        type Camera = ScriptedCamera;
        fn open(&mut self) -> Result<ScriptedCamera, String> {
            let mut failures = self.failures.lock().unwrap();
            if *failures > 0 {
                *failures -= 1;
                return Err("No such file or directory (os error 2)".into());
            }
            *self.opens.lock().unwrap() += 1;
            Ok(ScriptedCamera {
                steps: Arc::clone(&self.steps),
            })
        }
        fn clock_offset(&self) -> Option<ClockOffset> {
            Some(ClockOffset {
                realtime_minus_monotonic_ns: BOOT_UNIX_NS,
                uncertainty_ns: 50,
            })
        }
    }

    fn source(
        steps: Vec<Step>,
        failures: u32,
    ) -> (LiveSource<ScriptedOpener>, Arc<Mutex<u32>>, Arc<Mutex<u32>>) {
        let failures = Arc::new(Mutex::new(failures));
        let opens = Arc::new(Mutex::new(0));
        let opener = ScriptedOpener {
            steps: Arc::new(Mutex::new(steps.into())),
            failures: Arc::clone(&failures),
            opens: Arc::clone(&opens),
        };
        let config = V4lConfig {
            reopen_min_ms: 1,
            reopen_max_ms: 4,
            ..crate::config::Config::embedded().v4l
        };
        let s = LiveSource::open("/dev/video9", opener, Backoff::new(&config)).unwrap();
        (s, failures, opens)
    }

    #[test]
    fn frames_carry_driver_time_and_sequence() {
        let (mut s, _, _) = source(
            vec![
                Step::Frame {
                    sequence: 10,
                    stamp_us: 5_000_000,
                },
                Step::Frame {
                    sequence: 11,
                    stamp_us: 5_033_333,
                },
                Step::Frame {
                    sequence: 14,
                    stamp_us: 5_133_333,
                },
            ],
            0,
        );
        let f: Vec<Frame> = (0..3)
            .map(|_| s.next_frame().unwrap().unwrap().frame)
            .collect();
        assert_eq!(f.iter().map(|f| f.seq).collect::<Vec<_>>(), [0, 1, 4]);
        assert_eq!(f[0].capture_time_ns, 1_700_000_005_000_000_000);
        assert_eq!(f[2].capture_time_ns, 1_700_000_005_133_333_000);
        assert_eq!(f[1].image.get_pixel(0, 0)[0], 11);
        assert_eq!(
            f[0].origin,
            FrameOrigin::Camera {
                device: "/dev/video9".into()
            }
        );
        assert_eq!(s.stats().dropped_by_driver, 2);
        assert_eq!(s.fps(), Some(30.0));
        assert!(s.live());
    }

    #[test]
    fn unreadable_frame_is_an_error_item_and_the_stream_goes_on() {
        let (mut s, _, opens) = source(
            vec![
                Step::Corrupt { sequence: 0 },
                Step::Frame {
                    sequence: 1,
                    stamp_us: 1_000_000,
                },
            ],
            0,
        );
        let e = s.next_frame().unwrap().unwrap_err();
        assert!(
            e.contains("/dev/video9") && e.contains("does not decode"),
            "{e}"
        );
        assert_eq!(s.next_frame().unwrap().unwrap().frame.seq, 1);
        assert_eq!(s.stats().unreadable, 1);
        assert_eq!(*opens.lock().unwrap(), 1, "a bad frame must not reopen");
    }

    #[test]
    fn lost_camera_is_reopened_with_backoff_and_numbering_goes_on() {
        let (mut s, failures, opens) = source(
            vec![
                Step::Frame {
                    sequence: 2,
                    stamp_us: 1_000_000,
                },
                Step::Lost,
                // After the reopen the driver's counter is a new one (here
                // from 40): no frames count as dropped across the reopen.
                Step::Frame {
                    sequence: 40,
                    stamp_us: 9_000_000,
                },
                Step::Frame {
                    sequence: 41,
                    stamp_us: 9_033_333,
                },
            ],
            0,
        );
        assert_eq!(s.next_frame().unwrap().unwrap().frame.seq, 0);
        *failures.lock().unwrap() = 3;
        let lost = s.next_frame().unwrap().unwrap_err();
        assert!(lost.contains("reopening in 1 ms"), "{lost}");
        // Three failed attempts, each an error item with its wait: 2, 4, 4 ms
        // (doubling from the loss's 1 ms, capped at 4).
        let waits: Vec<String> = (0..3)
            .map(|_| s.next_frame().unwrap().unwrap_err())
            .collect();
        for (e, ms) in waits.iter().zip([2, 4, 4]) {
            assert!(e.contains(&format!("next attempt in {ms} ms")), "{e}");
        }
        // The open camera's exposure time is the source's; none while it
        // is lost.
        assert_eq!(s.exposure(), None);
        let back = s.next_frame().unwrap().unwrap().frame;
        assert_eq!(s.exposure(), Some(Duration::from_millis(4)));
        assert_eq!(back.seq, 1, "sequence numbers never go back");
        assert_eq!(back.capture_time_ns, 1_700_000_009_000_000_000);
        assert_eq!(s.next_frame().unwrap().unwrap().frame.seq, 2);
        let st = s.stats();
        assert_eq!((st.losses, st.reopens, st.frames), (1, 1, 3));
        assert_eq!(st.dropped_by_driver, 0);
        assert_eq!(*opens.lock().unwrap(), 2);
    }

    #[test]
    fn a_camera_that_opens_but_never_delivers_is_retried_ever_more_slowly() {
        let (mut s, _, opens) = source(vec![Step::Lost; 4], 0);
        let errors: Vec<String> = (0..4)
            .map(|_| s.next_frame().unwrap().unwrap_err())
            .collect();
        for (e, ms) in errors.iter().zip([1, 2, 4, 4]) {
            assert!(e.contains(&format!("reopening in {ms} ms")), "{e}");
        }
        assert_eq!(*opens.lock().unwrap(), 4);
        assert_eq!(s.stats().losses, 4);
    }

    #[test]
    fn a_camera_missing_at_start_is_a_setup_error() {
        let failures = Arc::new(Mutex::new(1));
        let opener = ScriptedOpener {
            steps: Arc::new(Mutex::new(VecDeque::new())),
            failures,
            opens: Arc::new(Mutex::new(0)),
        };
        let backoff = Backoff::new(&crate::config::Config::embedded().v4l);
        let Err(e) = LiveSource::open("/dev/video9", opener, backoff) else {
            panic!("opened a missing camera");
        };
        assert!(e.contains("No such file"), "{e}");
    }
}
