//! The one error type of the core. Every failure on user input is an `Error`, never a panic.

/// Errors of the rtloop core. Messages name the offending field, e.g. `objects[1].normal: zero-length normal`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The scene description is malformed or physically invalid.
    #[error("{0}")]
    Scene(String),
    /// A call was given inconsistent arguments (options, budgets).
    #[error("{0}")]
    Invalid(String),
    /// An argument has the wrong shape or value (an array's shape, a count; Python's `ValueError`).
    #[error("{0}")]
    Value(String),
    /// Reading or writing a file failed.
    #[error("{path}: {message}")]
    Io { path: String, message: String },
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub(crate) fn scene(field: impl std::fmt::Display, message: impl std::fmt::Display) -> Self {
        Error::Scene(format!("{field}: {message}"))
    }
}
