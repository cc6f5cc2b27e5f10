//! The measurement stage both pipelines run for every frame: measure, hand
//! the result to the link (when there is one), log it (when there is a log),
//! and give back the `process` record of it.

use crate::clock::RunClock;
use crate::frame::Frame;
use crate::link::LinkHandle;
use crate::log::LogHandle;
use crate::measure::mount::Mount;
use crate::measure::{Measurement, Measurer};
use crate::record::DetectionRecord;
use crate::source::dir::unix_now_ns;
use std::sync::Arc;
use std::time::Duration;

/// `--fast`: longest the measurement waits for the link to be done with a
/// frame (a transport write stuck that long is a fault the link reports).
pub const HANDOFF_TIMEOUT: Duration = Duration::from_secs(2);

/// One frame measured and passed on.
pub struct Measured {
    pub measurement: Arc<Measurement>,
    pub record: DetectionRecord,
    /// `--fast`: the link was not done with the frame within
    /// [`HANDOFF_TIMEOUT`] (its pose may not have been sent).
    pub link_timed_out: bool,
}

/// The measurer and where its results go.
pub struct MeasureStage {
    measurer: Measurer,
    mount: Mount,
    link: Option<LinkHandle>,
    log: Option<LogHandle>,
    clock: RunClock,
    handoff_timeouts: u64,
}

impl MeasureStage {
    pub fn new(
        measurer: Measurer,
        mount: Mount,
        link: Option<LinkHandle>,
        log: Option<LogHandle>,
        clock: RunClock,
    ) -> Self {
        Self {
            measurer,
            mount,
            link,
            log,
            clock,
            handoff_timeouts: 0,
        }
    }

    pub fn measurer_mut(&mut self) -> &mut Measurer {
        &mut self.measurer
    }

    /// Measures `frame`, hands the result to the link and the log, and
    /// returns it with its record, named `name`.
    ///
    /// On the source's clock (`--fast`, `process`) the clock reaches the
    /// frame as it goes to the link, which is then waited for, so that every
    /// detected frame's pose is sent. On the wall clock the link takes the
    /// newest measurement (latest wins) and the log's record carries the
    /// frame's capture and measurement times (`latency_ns`).
    pub fn measure(&mut self, frame: &Frame, name: String) -> Measured {
        let measurement = Arc::new(self.measurer.measure(frame));
        let measured_ns = unix_now_ns();
        self.clock.advance_to(frame.capture_time_ns);
        let source_clock = self.clock.is_source();
        let mut link_timed_out = false;
        if let Some(link) = &self.link {
            link.submit(Arc::clone(&measurement));
            link_timed_out =
                source_clock && !link.wait_handled(frame.capture_time_ns, HANDOFF_TIMEOUT);
            if link_timed_out {
                self.handoff_timeouts += 1;
                if self.handoff_timeouts.is_power_of_two() {
                    tracing::warn!(
                        seq = frame.seq,
                        timeouts = self.handoff_timeouts,
                        "--fast: the link was not done with a frame within {HANDOFF_TIMEOUT:?}"
                    );
                }
            }
        }
        let record = DetectionRecord::from_measurement(name, &measurement);
        if let Some(log) = &self.log {
            let mut json = serde_json::to_value(&record).unwrap_or_default();
            // Latency stamps are wall-clock times from the capture on: not
            // on the source's clock.
            if !source_clock {
                json["latency_ns"] = serde_json::json!({
                    "captured": frame.capture_time_ns,
                    "measured": measured_ns,
                });
            }
            log.measurement(Arc::clone(&measurement), json, &self.mount);
        }
        Measured {
            measurement,
            record,
            link_timed_out,
        }
    }
}
