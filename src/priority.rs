//! Thread priorities: the threads that only need throughput (the log writer,
//! the simulator's renderer) step back for the measurement and the link.
//!
//! On a two-core companion computer three busy threads compete right after a
//! frame arrives: the renderer or decoder, the log writer (copying the frame)
//! and the measurement. Without a hint the scheduler may let the measurement
//! wait several milliseconds for a core. Lowering the nice value of a thread
//! needs no privilege (raising the measurement's would).

/// Nice value for throughput-only threads (0 is normal, 19 the lowest).
const BACKGROUND_NICE: i32 = 10;

/// Lowers the calling thread's scheduling priority. On Linux the nice value
/// is per thread, and `setpriority(PRIO_PROCESS, 0, ..)` sets the caller's.
/// Elsewhere it does nothing. A refusal is only reported.
pub fn make_this_thread_background(what: &str) {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: setpriority takes plain integers and touches no memory of ours.
        let r = unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, BACKGROUND_NICE) };
        if r != 0 {
            tracing::debug!(
                "{what}: cannot lower the thread's priority: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (what, BACKGROUND_NICE);
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn nice_of_this_thread() -> i32 {
        // SAFETY: as above; getpriority returns the caller's nice value.
        unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }
    }

    #[test]
    fn lowers_only_the_calling_thread() {
        let before = nice_of_this_thread();
        let inside = std::thread::spawn(|| {
            make_this_thread_background("test");
            nice_of_this_thread()
        })
        .join()
        .unwrap();
        assert_eq!(inside, BACKGROUND_NICE.max(before));
        assert_eq!(nice_of_this_thread(), before, "the caller's thread changed");
    }
}
