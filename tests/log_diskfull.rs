//! Disk full: the writer's storage fails with StorageFull part-way through.
//! The error is reported (tracing and, once space is back, `/log`), the
//! caller carries on, what was written stays readable, and logging resumes in
//! a new numbered file when the disk has room again.

mod log_support;

use drogue_vision::log::{reader, recover};
use drogue_vision::source::replay;
use log_support as s;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use tracing_subscriber::layer::SubscriberExt;

/// Collects the messages of ERROR events from every thread.
struct Errors(Arc<Mutex<Vec<String>>>);

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for Errors {
    fn on_event(&self, e: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
        if *e.metadata().level() == tracing::Level::ERROR {
            struct V(String);
            impl tracing::field::Visit for V {
                fn record_debug(&mut self, _: &tracing::field::Field, v: &dyn std::fmt::Debug) {
                    self.0 += &format!("{v:?}");
                }
            }
            let mut v = V(String::new());
            e.record(&mut v);
            self.0.lock().unwrap().push(v.0);
        }
    }
}

#[test]
fn a_full_disk_is_reported_the_caller_carries_on_and_the_file_stays_readable() {
    let errors = Arc::new(Mutex::new(Vec::new()));
    tracing::subscriber::set_global_default(
        tracing_subscriber::registry().with(Errors(errors.clone())),
    )
    .unwrap();

    let dir = tempfile::tempdir().unwrap();
    // Room for about 4 frames.
    let (log, free) = s::log_on_small_disk(dir.path(), 5_000_000, None);

    // 10 frames: the disk fills during the fifth. The caller never notices.
    for seq in 0..10 {
        s::log_frame(&log, seq, false);
    }
    // Wait for the writer to hit the full disk (its error is reported), however
    // slowly a loaded machine runs it; then room again, and after the retry
    // delay logging resumes in part 001.
    let reported = || {
        errors
            .lock()
            .unwrap()
            .iter()
            .any(|e| e.contains("no space left on device (test disk)"))
    };
    let start = std::time::Instant::now();
    while !reported() && start.elapsed() < std::time::Duration::from_secs(30) {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(reported(), "the full disk was never reported");
    free.store(u64::MAX / 2, Ordering::SeqCst);
    std::thread::sleep(std::time::Duration::from_millis(1200));
    for seq in 10..15 {
        log.frame(Arc::new(s::frame(seq, false)));
    }
    let summary = log.finish().unwrap();
    println!("{summary:?}");

    assert!(summary.write_errors >= 1);
    assert!(summary.dropped_write_error >= 1);
    assert_eq!(summary.files.len(), 2, "{:?}", summary.files);
    assert!(
        errors
            .lock()
            .unwrap()
            .iter()
            .any(|e| e.contains("no space left on device (test disk)")),
        "{:?}",
        errors.lock().unwrap()
    );

    // The full file reads back in order up to the cut, and recovers.
    let first: Vec<u64> = replay::open(&summary.files[0])
        .unwrap()
        .map_while(Result::ok)
        .map(|f| f.seq)
        .collect();
    assert!(first.len() >= 3, "{first:?}");
    assert_eq!(first, (0..first.len() as u64).collect::<Vec<_>>());
    let fixed = dir.path().join("fixed.mcap");
    assert!(
        recover::recover(&summary.files[0], &fixed)
            .unwrap()
            .messages
            > 0
    );

    // The second part is complete: the frames after the disk had room, and
    // the write error in /log.
    assert!(reader::is_complete(&summary.files[1]).unwrap());
    let second: Vec<u64> = replay::open(&summary.files[1])
        .unwrap()
        .map(|f| f.unwrap().seq)
        .collect();
    assert_eq!(second, (10..15).collect::<Vec<_>>());
    let bytes = std::fs::read(&summary.files[1]).unwrap();
    let logged_error = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == "/log")
        .any(|m| String::from_utf8_lossy(&m.data).contains("no space left on device"));
    assert!(logged_error);
}
