//! Errors of the simulator: each names the file and the key at fault.

/// Why a scenario could not be loaded or a simulation set up.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// No builtin scenario of that name and no such file.
    #[error("scenario `{name}`: not a builtin ({builtins}) and not a readable file: {message}")]
    NotFound {
        name: String,
        builtins: String,
        message: String,
    },
    /// The scenario file could not be read.
    #[error("{file}: {message}")]
    Io { file: String, message: String },
    /// A key of the scenario is malformed, unknown or out of range.
    #[error("{file}: key `{key}`: {message}")]
    Scenario {
        file: String,
        key: String,
        message: String,
    },
    /// The scenario's camera file is unusable.
    #[error("camera file {file}: key `{key}`: {message}")]
    Camera {
        file: String,
        key: String,
        message: String,
    },
}
