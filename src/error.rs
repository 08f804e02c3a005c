//! The one error type of the crate.
//!
//! Errors say *whose fault* they are, in the SQLite spirit of keeping "your input is bad" apart
//! from "this program is wrong": [`Error::Input`] and [`Error::Unsupported`] name a file and
//! what is wrong with it, [`Error::Corrupt`] names a container and the invariant it breaks,
//! [`Error::TooLarge`] refuses a size before anything is allocated, [`Error::InvalidArgument`]
//! is a bad option value, [`Error::Io`] is the operating system saying no, and
//! [`Error::Internal`] is fmrh itself being wrong. Nothing in this crate reports a malformed
//! file by panicking, and an I/O failure while reading is never reported as corruption.

use std::path::PathBuf;

use crate::format::Invariant;

/// Everything that can go wrong in fmrh.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed at the operating-system level.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file involved.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The input file is malformed: truncated, inconsistent or not what it claims to be.
    #[error("{}: {reason}", path.display())]
    Input {
        /// The offending file.
        path: PathBuf,
        /// What is wrong with it, for a person.
        reason: String,
    },
    /// The input is well formed but uses a feature fmrh does not read (a sample type, a
    /// compression, a colour model).
    #[error("{}: unsupported: {reason}", path.display())]
    Unsupported {
        /// The offending file.
        path: PathBuf,
        /// Which feature, for a person.
        reason: String,
    },
    /// A size beyond fmrh's documented limits; refused before any allocation.
    #[error("{what} is too large: {detail}")]
    TooLarge {
        /// What was too large (a raster, a header field, a threshold list...).
        what: String,
        /// The size and the limit.
        detail: String,
    },
    /// An option or argument value that cannot be used.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A container breaks one of the numbered invariants of `format-spec/container.md`: the
    /// file is damaged (or was written by a buggy writer), which is never a bug of the reader.
    #[error("{}: corrupt container: {invariant} violated at {location}: {detail}", path.display())]
    Corrupt {
        /// The container.
        path: PathBuf,
        /// The invariant broken.
        invariant: Invariant,
        /// Where: a page number, a byte offset, a node index.
        location: String,
        /// What was found, for a person.
        detail: String,
    },
    /// An earlier write, sync or length change of this container failed, so what the file
    /// holds past its last commit is unknown; open it again to go on (recovery runs then).
    #[error(
        "{}: the container had an I/O failure and refuses further use; open it again",
        path.display()
    )]
    Poisoned {
        /// The container.
        path: PathBuf,
    },
    /// The state this reader holds was superseded, and a later commit reused pages it
    /// reaches: the file is sound, but this reader's view of it is gone (a reader that did
    /// not register its state, format §11.6). Open the file again.
    #[error(
        "{}: the state this reader holds (txn {txn}) was superseded by txn {latest}, which \
         reused its pages ({detail}); open the file again",
        path.display()
    )]
    Superseded {
        /// The container.
        path: PathBuf,
        /// The txn id of the state the reader holds.
        txn: u64,
        /// The txn id of the file's latest state when this was found.
        latest: u64,
        /// What the reader found: which page or payload no longer holds its state's bytes.
        detail: String,
    },
    /// A state fmrh's own code should never reach: a bug, to be reported, never a property of
    /// the input.
    #[error("internal error (a bug in fmrh): {0}")]
    Internal(String),
}

impl Error {
    /// A malformed-input error about `path`.
    pub fn input(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::Input {
            path: path.into(),
            reason: reason.into(),
        }
    }

    /// An unsupported-feature error about `path`.
    pub fn unsupported(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::Unsupported {
            path: path.into(),
            reason: reason.into(),
        }
    }

    /// What kind of error this is, as a stable lowercase word for machine-readable output
    /// (`fmrh --json`): `io`, `input`, `unsupported`, `too_large`, `invalid_argument`,
    /// `corrupt`, `poisoned`, `superseded` or `internal`.
    pub fn kind(&self) -> &'static str {
        match self {
            Error::Io { .. } => "io",
            Error::Input { .. } => "input",
            Error::Unsupported { .. } => "unsupported",
            Error::TooLarge { .. } => "too_large",
            Error::InvalidArgument(_) => "invalid_argument",
            Error::Corrupt { .. } => "corrupt",
            Error::Poisoned { .. } => "poisoned",
            Error::Superseded { .. } => "superseded",
            Error::Internal(_) => "internal",
        }
    }

    /// An I/O error about `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
