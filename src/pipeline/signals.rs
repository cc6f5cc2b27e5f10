//! Signals (SIGINT, SIGTERM: a clean stop) and real-time priority of the
//! threads on the capture → send path.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A stop request from SIGINT / SIGTERM.
pub fn watch_signals(rt: &tokio::runtime::Runtime, stop: Arc<AtomicBool>) {
    rt.spawn(async move {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let (Ok(mut int), Ok(mut term)) = (
                signal(SignalKind::interrupt()),
                signal(SignalKind::terminate()),
            ) else {
                tracing::warn!("cannot watch SIGINT/SIGTERM; stop with --max-frames");
                return;
            };
            tokio::select! {
                _ = int.recv() => tracing::info!("SIGINT: finishing the run"),
                _ = term.recv() => tracing::info!("SIGTERM: finishing the run"),
            }
        }
        #[cfg(not(unix))]
        {
            let _ = tokio::signal::ctrl_c().await;
        }
        stop.store(true, Ordering::SeqCst);
    });
}

/// Makes the calling thread real-time (`[run] realtime_priority`, 0: off).
/// A refusal is a warning: the run goes on at normal priority.
pub fn realtime_if_asked(thread: &str, priority: u8) {
    if priority == 0 {
        return;
    }
    match crate::priority::make_this_thread_realtime(priority) {
        Ok(()) => tracing::info!("{thread} thread: SCHED_FIFO priority {priority}"),
        Err(e) => tracing::warn!("{thread} thread stays at normal priority: {e}"),
    }
}
