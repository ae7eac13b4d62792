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
    /// A robot description (URDF or DH table) that cannot be read or that does not describe a usable serial chain.
    #[error("robot {origin}: {message}")]
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

/// The longest error line a binary prints: two screen lines of message name a file, a field and a value.
pub const MAX_LINE_CHARS: usize = 400;

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

    /// The error as a binary prints it: one line (line breaks of a wrapped parser message become spaces)
    /// of at most [`MAX_LINE_CHARS`] characters, so that no input, however large, is echoed whole.
    pub fn line(&self) -> String {
        let text: String = self
            .to_string()
            .split(['\n', '\r'])
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join(" ");
        let n = text.chars().count();
        if n <= MAX_LINE_CHARS {
            text
        } else {
            let head: String = text.chars().take(MAX_LINE_CHARS).collect();
            format!("{head}… ({n} characters in all)")
        }
    }

    /// A runtime error of work on the data file `origin` (registration, a fit), attributed to it:
    /// `data FILE: DOING: detail`. An error that already names its file is kept as it is.
    pub fn in_data(self, origin: &str, doing: &str) -> Error {
        match self {
            Error::Invalid(_) | Error::Unreachable(_) | Error::Physics(_) => Error::Data {
                origin: origin.to_string(),
                message: format!("{doing}: {}", self.detail()),
            },
            named => named,
        }
    }

    /// The same for the scenario `origin`: a region that cannot be reached, a physics reference that does
    /// not settle, are the scenario's.
    pub fn in_scenario(self, origin: &str) -> Error {
        match self {
            Error::Invalid(_) | Error::Unreachable(_) | Error::Physics(_) => Error::Scenario {
                origin: origin.to_string(),
                message: self.to_string(),
            },
            named => named,
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}
