//! What can go wrong starting, finishing, recovering or reading a log, and
//! the check every command makes of an MCAP input before it creates
//! anything.

use std::path::{Path, PathBuf};

/// Why the log could not be started, finished, recovered or read.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// A `[log]` setting (or a review's output folder) is unusable.
    #[error("log config: {0}")]
    Config(String),
    /// A file or folder could not be read, created or written.
    #[error("{path}: {message}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        message: String,
    },
    /// The input is not an MCAP log, or is damaged beyond reading.
    #[error("{path}: not a readable MCAP log: {message}")]
    Format {
        /// The input file.
        path: PathBuf,
        /// What the reader found wrong.
        message: String,
    },
    /// The writer thread failed: it could not start, panicked, or the log
    /// was already finished.
    #[error("log writer: {0}")]
    Writer(String),
    /// `recover` would have written less than the input holds.
    #[error("refused: {0}")]
    Refused(String),
}

impl LogError {
    pub(crate) fn io(path: &Path, e: impl std::fmt::Display) -> Self {
        LogError::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
    pub(crate) fn format(path: &Path, e: impl std::fmt::Display) -> Self {
        LogError::Format {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

/// Checks that `path` is a file starting with the MCAP magic, before a
/// command creates anything: a missing, unreadable or foreign input is
/// [`LogError::Format`] (exit status 2), and nothing is left behind.
pub fn check_mcap_input(path: &Path) -> Result<(), LogError> {
    use std::io::Read;
    let not_readable = |why: String| Err(LogError::format(path, why));
    if path.is_dir() {
        return not_readable("a folder, not a file".into());
    }
    let mut file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) => return not_readable(format!("cannot open it: {e}")),
    };
    let mut magic = [0u8; 8];
    if file.read_exact(&mut magic).is_err() || magic.as_slice() != mcap::MAGIC {
        return not_readable("no MCAP magic at the start".into());
    }
    Ok(())
}

/// An error with its causes ("I/O error: No space left on device"): the
/// `mcap` crate's errors hide the io::Error in `source()`.
pub(crate) fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let c_text = c.to_string();
        if !text.contains(&c_text) {
            text.push_str(": ");
            text.push_str(&c_text);
        }
        cause = c.source();
    }
    text
}
