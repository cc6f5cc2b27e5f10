//! Errors of the simulator: each names the file and the key at fault.

/// Why a scenario could not be loaded or a simulation set up.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// No builtin scenario of that name and no such file.
    #[error("scenario `{name}`: not a builtin ({builtins}) and not a readable file: {message}")]
    NotFound {
        /// The name asked for.
        name: String,
        /// The builtin scenarios' names, comma-separated.
        builtins: String,
        /// Why it could not be read as a file.
        message: String,
    },
    /// The scenario file could not be read.
    #[error("{file}: {message}")]
    Io {
        /// The scenario file.
        file: String,
        /// The I/O error.
        message: String,
    },
    /// A key of the scenario is malformed, unknown or out of range.
    #[error("{file}: key `{key}`: {message}")]
    Scenario {
        /// The scenario file.
        file: String,
        /// The dotted key at fault.
        key: String,
        /// What is wrong with its value.
        message: String,
    },
    /// The scenario's camera file is unusable.
    #[error("camera file {file}: key `{key}`: {message}")]
    Camera {
        /// The camera file.
        file: String,
        /// The key at fault.
        key: String,
        /// What is wrong with its value.
        message: String,
    },
}
