//! Errors of the core layer.
//!
//! Every error that comes from user input names where it came from: the file, the
//! 1-based line (as a text editor counts it, metadata lines included) and the column
//! (1-based field index and its header name).

use std::path::PathBuf;

/// Where in an input file a problem sits.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The file (or a name such as `<memory>` for in-memory input).
    pub file: PathBuf,
    /// 1-based line number in the file.
    pub line: u64,
    /// 1-based column (field) number and the column's header name, when known.
    pub column: Option<(usize, String)>,
}

impl std::fmt::Display for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.file.display(), self.line)?;
        if let Some((col, name)) = &self.column {
            write!(f, ":{col} (column `{name}`)")?;
        }
        Ok(())
    }
}

/// The core error type.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The CSV text itself is malformed (wrong number of fields, bad quoting, …).
    #[error("{at}: {message}")]
    Malformed {
        /// Where.
        at: Location,
        /// What is wrong.
        message: String,
    },
    /// A required column is missing from the header.
    #[error("{file}:{line}: missing required column `{column}` (header has: {header})")]
    MissingColumn {
        /// The file.
        file: PathBuf,
        /// Line of the header.
        line: u64,
        /// The missing column.
        column: String,
        /// The header as read.
        header: String,
    },
    /// A cell is not a number, or is NaN or infinite.
    #[error("{at}: {message}")]
    BadValue {
        /// Where.
        at: Location,
        /// What is wrong, with the offending text.
        message: String,
    },
    /// Time is not strictly increasing.
    #[error("{at}: time t = {t} is not after the previous sample t = {previous}")]
    TimeNotIncreasing {
        /// Where (column `t`).
        at: Location,
        /// The value on this line.
        t: f64,
        /// The value on the line before.
        previous: f64,
    },
    /// Too few samples for the requested processing (e.g. the filter's padding).
    #[error("{file}: {samples} samples, but {needed} are needed ({why})")]
    TooShort {
        /// The file or recording name.
        file: PathBuf,
        /// Samples present.
        samples: usize,
        /// Samples needed.
        needed: usize,
        /// Why that many are needed.
        why: String,
    },
    /// A setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),
    /// Columns of different lengths were handed to a constructor.
    #[error("column `{column}` has {len} samples, `t` has {expected}")]
    LengthMismatch {
        /// The column.
        column: String,
        /// Its length.
        len: usize,
        /// The length of `t`.
        expected: usize,
    },
}

/// Result alias for the core crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
