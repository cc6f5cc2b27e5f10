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

/// Why the calling thread could not be made real-time.
#[derive(Debug, thiserror::Error)]
pub enum RealtimeError {
    /// The priority asked for is not within 1-99.
    #[error("real-time priority {0} is outside 1-99")]
    OutOfRange(u8),
    /// The system refused SCHED_FIFO (no privilege or RLIMIT_RTPRIO).
    #[error(
        "SCHED_FIFO priority {priority} refused ({source}): run as root, give the \
         binary CAP_SYS_NICE, or raise RLIMIT_RTPRIO (systemd: LimitRTPRIO={priority})"
    )]
    Refused {
        /// The priority asked for.
        priority: u8,
        /// The system's refusal.
        source: std::io::Error,
    },
    /// Not on Linux.
    #[error("real-time scheduling is only supported on Linux")]
    Unsupported,
}

/// Puts the calling thread in SCHED_FIFO at `priority` (1-99): it then runs
/// as soon as it is ready, ahead of every normal thread of the machine.
/// Only for a thread that sleeps most of the time (the measurement: about
/// a millisecond per frame); the kernel's RT throttling still caps it.
pub fn make_this_thread_realtime(priority: u8) -> Result<(), RealtimeError> {
    if !(1..=99).contains(&priority) {
        return Err(RealtimeError::OutOfRange(priority));
    }
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param {
            sched_priority: i32::from(priority),
        };
        // SAFETY: `param` is a valid sched_param that outlives the call;
        // pid 0 is the calling thread.
        let r = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &raw const param) };
        if r != 0 {
            return Err(RealtimeError::Refused {
                priority,
                source: std::io::Error::last_os_error(),
            });
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(RealtimeError::Unsupported)
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

    fn policy_of_this_thread() -> i32 {
        // SAFETY: sched_getscheduler takes a pid (0: the caller) only.
        unsafe { libc::sched_getscheduler(0) }
    }

    #[test]
    fn realtime_is_set_on_the_calling_thread_or_refused_with_the_remedy() {
        assert!(matches!(
            make_this_thread_realtime(0),
            Err(RealtimeError::OutOfRange(0))
        ));
        assert!(matches!(
            make_this_thread_realtime(100),
            Err(RealtimeError::OutOfRange(100))
        ));
        let before = policy_of_this_thread();
        let (result, policy) = std::thread::spawn(|| {
            let r = make_this_thread_realtime(5);
            (r, policy_of_this_thread())
        })
        .join()
        .unwrap();
        match result {
            // Root or CAP_SYS_NICE: the thread is SCHED_FIFO now.
            Ok(()) => assert_eq!(policy, libc::SCHED_FIFO),
            // Otherwise the error says what to grant, and nothing changed.
            Err(e) => {
                assert_eq!(policy, before);
                assert!(e.to_string().contains("LimitRTPRIO=5"), "{e}");
            }
        }
        assert_eq!(
            policy_of_this_thread(),
            before,
            "the caller's thread changed"
        );
    }
}
