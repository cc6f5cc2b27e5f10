//! The threads of `run` besides the capture loop: the measurement thread
//! and the logger of the link's events.

use super::meters::PipelineMeters;
use super::signals::realtime_if_asked;
use super::stage::MeasureStage;
use crate::frame::Frame;
use crate::link::LinkHandle;
use crate::log::LogHandle;
use crate::log::review::Histogram;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::time::{Duration, Instant};

/// The measurement thread: every frame it gets is measured, handed to the
/// link (latest-wins) and logged ([`MeasureStage`]), and counted in
/// `meters`. With `handed_to_link`, it says when each frame is done.
pub fn spawn_measurement(
    mut stage: MeasureStage,
    meters: Arc<PipelineMeters>,
    handed_to_link: Option<std::sync::mpsc::Sender<u64>>,
    realtime_priority: u8,
) -> (SyncSender<Arc<Frame>>, std::thread::JoinHandle<()>) {
    // Capacity 1: at most one frame waits; a newer one finding it full is
    // skipped for measurement (still logged), so latency never builds up.
    let (tx, rx) = sync_channel::<Arc<Frame>>(1);
    let handle = std::thread::spawn(move || {
        realtime_if_asked("measurement", realtime_priority);
        for frame in rx {
            let measured = stage.measure(&frame, frame.seq.to_string());
            if let Some(done) = &handed_to_link {
                let _ = done.send(frame.seq);
            }
            if measured.link_timed_out {
                meters.link_handoff_timeouts.fetch_add(1, Ordering::Relaxed);
            }
            let range = measured
                .measurement
                .detection
                .as_ref()
                .map(|d| d.position_body_m.norm());
            meters.frame_measured(range);
            meters.set_last_miss(measured.measurement.miss.as_ref().map(|m| m.reason.code()));
        }
    });
    (tx, handle)
}

/// Longest a rendering source waits for the measurement of its last frame.
const MAX_YIELD: Duration = Duration::from_millis(20);

/// Waits (at most [`MAX_YIELD`]) until frame `seq` has been handed to the link.
pub fn wait_until_handed_to_link(handed: &std::sync::mpsc::Receiver<u64>, seq: u64) {
    let deadline = Instant::now() + MAX_YIELD;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match handed.recv_timeout(left) {
            Ok(done) if done >= seq => return,
            Ok(_) => {}
            Err(_) => return,
        }
    }
}

/// The link's events (sent and received messages) go to the log; the
/// capture → send latency of each frame's first pose message is counted on
/// the way. Received messages wait while the log's queue is half full:
/// camera frames and measurements are never dropped for them (counted in the
/// link stats as unlogged_incoming).
pub fn spawn_event_logger(
    link: &LinkHandle,
    log: LogHandle,
    meters: Arc<PipelineMeters>,
    busy_depth: u64,
    measure_latency: bool,
    done: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Histogram> {
    let events = link.events();
    std::thread::spawn(move || {
        let mut latency_ms = Histogram::default();
        let mut last_sent_capture = None;
        loop {
            match events.recv_timeout(Duration::from_millis(100)) {
                Some(ev) => {
                    if let (true, true, Some(captured)) =
                        (measure_latency, ev.outgoing, ev.capture_time_ns)
                        && last_sent_capture != Some(captured)
                    {
                        last_sent_capture = Some(captured);
                        let ms = ev.time_ns.saturating_sub(captured) as f64 * 1e-6;
                        latency_ms.add(ms);
                        meters.set_latency_ms(ms.max(1e-6));
                    }
                    if !ev.outgoing && log.queue_depth() >= busy_depth {
                        events.skip_incoming();
                        continue;
                    }
                    log.mavlink(ev);
                }
                None if done.load(Ordering::SeqCst) => break,
                None => {}
            }
        }
        latency_ms
    })
}
