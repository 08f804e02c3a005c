//! The one error type of the crate.
//!
//! Errors say *whose fault* they are, in the SQLite spirit of keeping "your input is bad" apart
//! from "this program is wrong": [`Error::Input`] and [`Error::Unsupported`] name a file and
//! what is wrong with it, [`Error::Corrupt`] names a container and the invariant it breaks,
//! [`Error::TooLarge`] refuses a size before anything is allocated, [`Error::InvalidArgument`]
//! is a bad option value, [`Error::Io`] is the operating system saying no, and
//! [`Error::Internal`] is fmrh itself being wrong. Nothing in this crate reports a malformed
//! file by panicking, and an I/O failure while reading is never reported as corruption.
//!
//! A corrupt file names the numbered invariant it breaks ([`Invariant`],
//! `format-spec/container.md` §9 and `dataset.md` §6). The format's decoders work on byte
//! slices and know no file name, so they report a [`Violation`] (invariant, where, what); the
//! store, which knows which file the bytes came from, turns it into [`Error::Corrupt`] with
//! [`Violation::in_file`]. So every corruption error names its file, and no decoder carries a
//! placeholder path.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Serialize;

/// Everything that can go wrong in fmrh.
///
/// ```
/// use fmrh::Error;
///
/// let damaged = fmrh::Terrain::open("/no/such/file.fmrh").unwrap_err();
/// assert!(matches!(damaged, Error::Io { .. }));
/// let not_a_dem = fmrh::Heightfield::new(2, 2, vec![0.0; 3]).unwrap_err();
/// assert_eq!(not_a_dem.kind(), "invalid_argument");
/// ```
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
    /// The file or object no longer holds the state this reader opened, and no newer state
    /// of it took that one's place: it was replaced underneath the reader (an object
    /// re-uploaded, a file copied over in place). Nothing of the other version was returned
    /// as data; open it again.
    #[error("{}: changed underneath this reader ({detail}); open it again", path.display())]
    Changed {
        /// The file, object or dataset.
        path: PathBuf,
        /// How the change was seen.
        detail: String,
    },
    /// A state fmrh's own code should never reach: a bug, to be reported, never a property of
    /// the input.
    #[error("internal error (a bug in fmrh): {0}")]
    Internal(String),
}

/// The payload of an [`std::io::Error`] that a source returns when the object it reads is no
/// longer the version it opened (an ETag that no longer matches, another length):
/// [`Error::io`] turns it into [`Error::Changed`].
#[derive(Debug)]
pub(crate) struct ObjectChanged(pub String);

impl fmt::Display for ObjectChanged {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ObjectChanged {}

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
    /// `corrupt`, `poisoned`, `superseded`, `changed` or `internal`.
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
            Error::Changed { .. } => "changed",
            Error::Internal(_) => "internal",
        }
    }

    /// An I/O error about `path`; [`Error::Changed`] when the source said the object it reads
    /// changed underneath.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        if let Some(changed) = source
            .get_ref()
            .and_then(|e| e.downcast_ref::<ObjectChanged>())
        {
            return Error::Changed {
                path: path.into(),
                detail: changed.0.clone(),
            };
        }
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// One numbered invariant. The validator reports one check per invariant, and
/// [`Error::Corrupt`] names the one a file broke.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Invariant {
    /// I-1: a commit record is valid: magic, CRC, fields in range, zero tail.
    CommitRecord,
    /// I-2: the major version is one this reader knows.
    Version,
    /// I-3: page size allowed; file length equals the record's and is whole pages.
    FileLength,
    /// I-4: the inactive commit slot is zero or an older valid record.
    InactiveSlot,
    /// I-5: every structured page: tag, own page number, CRC, zero tail.
    Page,
    /// I-6: the dataset header parses and is self-consistent.
    DatasetHeader,
    /// I-7: every table is a well-formed B+-tree.
    TreeShape,
    /// I-8: every page belongs to exactly one structure.
    PageOwnership,
    /// I-9: payloads: inside the file, aligned, disjoint, CRC, zero gaps, implied lengths.
    Payload,
    /// I-10: the node table is the FMRH in Hilbert pre-order.
    NodeTable,
    /// I-11: the block table holds every physical block, row-major.
    BlockTable,
    /// I-12: the cluster directory: thresholds and summaries.
    ClusterDirectory,
    /// I-13: each cluster index is its cut, sorted by Hilbert key.
    ClusterIndex,
    /// I-14: adjacency lists list each cut's edge nodes in order.
    Adjacency,
    /// I-15: errors, ranges and node grids equal their recomputation from the blocks.
    Measured,
    /// I-16: the free list names free pages only.
    FreeList,
    /// D-1 (datasets, `format-spec/dataset.md`): a manifest commit record is valid.
    ManifestRecord,
    /// D-2: the manifest head and its tile pages: inside the file, checksummed, in order.
    ManifestPages,
    /// D-3: the tile records: names, placement, order, the tiling.
    TileRecords,
    /// D-4: every tile file holds its pinned state, of the size and heights its record says,
    /// and neighbours agree on their shared edges.
    TilePins,
    /// D-5: each tile's adjacent-cluster tables are the merges of its and its east and
    /// south neighbours' edge lists.
    AdjacentClusters,
}

impl Invariant {
    /// Every invariant, in id order.
    pub const ALL: [Invariant; 16] = [
        Invariant::CommitRecord,
        Invariant::Version,
        Invariant::FileLength,
        Invariant::InactiveSlot,
        Invariant::Page,
        Invariant::DatasetHeader,
        Invariant::TreeShape,
        Invariant::PageOwnership,
        Invariant::Payload,
        Invariant::NodeTable,
        Invariant::BlockTable,
        Invariant::ClusterDirectory,
        Invariant::ClusterIndex,
        Invariant::Adjacency,
        Invariant::Measured,
        Invariant::FreeList,
    ];

    /// The invariants of a dataset's manifest (`format-spec/dataset.md` §6), in id order.
    pub const DATASET: [Invariant; 5] = [
        Invariant::ManifestRecord,
        Invariant::ManifestPages,
        Invariant::TileRecords,
        Invariant::TilePins,
        Invariant::AdjacentClusters,
    ];

    /// Its number in the spec: 1 for I-1; the dataset invariants follow, from 17 for D-1.
    pub fn number(self) -> u8 {
        // The variants are declared in id order, from 0.
        self as u8 + 1
    }

    /// `I-1`, `I-2`, ...
    pub fn id(self) -> &'static str {
        const IDS: [&str; 21] = [
            "I-1", "I-2", "I-3", "I-4", "I-5", "I-6", "I-7", "I-8", "I-9", "I-10", "I-11", "I-12",
            "I-13", "I-14", "I-15", "I-16", "D-1", "D-2", "D-3", "D-4", "D-5",
        ];
        IDS[self as usize]
    }

    /// What the invariant is about, in a few words.
    pub fn name(self) -> &'static str {
        match self {
            Invariant::CommitRecord => "commit record",
            Invariant::Version => "format version",
            Invariant::FileLength => "file length",
            Invariant::InactiveSlot => "inactive commit slot",
            Invariant::Page => "page headers and checksums",
            Invariant::DatasetHeader => "dataset header",
            Invariant::TreeShape => "table shape",
            Invariant::PageOwnership => "page ownership",
            Invariant::Payload => "payloads",
            Invariant::NodeTable => "node table",
            Invariant::BlockTable => "block table",
            Invariant::ClusterDirectory => "cluster directory",
            Invariant::ClusterIndex => "cluster indexes and cuts",
            Invariant::Adjacency => "adjacency lists",
            Invariant::Measured => "measured content",
            Invariant::FreeList => "free list",
            Invariant::ManifestRecord => "manifest record",
            Invariant::ManifestPages => "manifest pages",
            Invariant::TileRecords => "tile records",
            Invariant::TilePins => "tile pins",
            Invariant::AdjacentClusters => "adjacent-cluster tables",
        }
    }
}

impl fmt::Display for Invariant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.id())
    }
}

impl Serialize for Invariant {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.id())
    }
}

/// Bytes that break an invariant: which one, where, and what was found. Decoders return it;
/// [`Violation::in_file`] makes it an error that names the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Violation {
    /// The invariant broken.
    pub invariant: Invariant,
    /// Where: a page number, a byte offset, a node index.
    pub location: String,
    /// What was found, for a person.
    pub detail: String,
}

impl Violation {
    /// A violation of `invariant` at `location`.
    pub fn new(
        invariant: Invariant,
        location: impl Into<String>,
        detail: impl Into<String>,
    ) -> Violation {
        Violation {
            invariant,
            location: location.into(),
            detail: detail.into(),
        }
    }

    /// The corruption error of the file at `path`.
    pub fn in_file(self, path: &Path) -> Error {
        Error::Corrupt {
            path: path.to_path_buf(),
            invariant: self.invariant,
            location: self.location,
            detail: self.detail,
        }
    }
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} violated at {}: {}",
            self.invariant, self.location, self.detail
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_follow_the_declaration_order() {
        for (i, inv) in Invariant::ALL.iter().enumerate() {
            assert_eq!(usize::from(inv.number()), i + 1);
            assert_eq!(inv.id(), format!("I-{}", i + 1));
        }
        for (i, inv) in Invariant::DATASET.iter().enumerate() {
            assert_eq!(usize::from(inv.number()), Invariant::ALL.len() + i + 1);
            assert_eq!(inv.id(), format!("D-{}", i + 1));
        }
    }
}
