//! One error type for the library; binaries print it on one line and exit non-zero.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A URDF that cannot be read or that does not describe a usable serial chain.
    #[error("URDF {origin}: {message}")]
    Urdf { origin: String, message: String },
    /// A scenario file that does not parse or whose values make no sense.
    #[error("scenario {origin}: {message}")]
    Scenario { origin: String, message: String },
    /// A data file (CSV, JSON) with missing columns, bad cells or NaN.
    #[error("data {origin}: {message}")]
    Data { origin: String, message: String },
    /// A target or region the robot cannot reach.
    #[error("unreachable: {0}")]
    Unreachable(String),
    /// The physics reference did not settle or could not be built.
    #[error("physics: {0}")]
    Physics(String),
    /// Any other argument out of its domain (wrong length, NaN, empty set).
    #[error("invalid input: {0}")]
    Invalid(String),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// The message for a caller that wraps it in its own context (a field, a region): without the prefix of
    /// an invalid argument or an unreachable target, which the context replaces; every other kind keeps its
    /// own words (a file's error names the file).
    pub fn detail(&self) -> String {
        match self {
            Error::Invalid(message) | Error::Unreachable(message) => message.clone(),
            other => other.to_string(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}
