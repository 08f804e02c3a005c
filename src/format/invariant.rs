//! The numbered invariants of a valid file (`format-spec/container.md` §9), and [`Violation`]:
//! what a decoder reports when bytes break one.
//!
//! The decoders of this module work on byte slices and know no file name, so they report a
//! [`Violation`] (invariant, where, what). The store, which knows which file the bytes came
//! from, turns it into [`crate::Error::Corrupt`] with [`Violation::in_file`]. So every
//! corruption error names its file, and no decoder carries a placeholder path.

use std::fmt;
use std::path::Path;

use serde::Serialize;

use crate::error::Error;

/// One numbered invariant. The validator reports one check per invariant, and
/// [`crate::Error::Corrupt`] names the one a file broke.
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
