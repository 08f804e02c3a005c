//! The fixed-size on-disk structures, as `zerocopy` structs of little-endian fields.
//!
//! Every struct is `#[repr(C)]` with alignment 1 (all fields are byte arrays underneath), so a
//! record is read straight out of any byte slice, mapped or not, on any host, and its size is
//! pinned by a compile-time assertion. Offsets and meanings are tabulated in
//! `format-spec/container.md`. Comments here say why a field exists.

use zerocopy::byteorder::little_endian::{F32, F64, U16, U32, U64};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

use super::{COMMIT_RECORD_LEN, PAGE_HEADER_LEN};

/// Where a blob lives: pages `first_page ..` holding `length` content bytes.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    FromBytes,
    IntoBytes,
    KnownLayout,
    Immutable,
    Unaligned,
)]
#[repr(C)]
pub struct BlobRef {
    /// First page of the run.
    pub first_page: U64,
    /// Content bytes (the pages hold `P - 24` content bytes each).
    pub length: U64,
}

/// Where a B+-tree lives. An empty tree has root, records and depth zero (and still names
/// its record size).
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    FromBytes,
    IntoBytes,
    KnownLayout,
    Immutable,
    Unaligned,
)]
#[repr(C)]
pub struct TreeRef {
    /// The root page; 0 for an empty tree.
    pub root_page: U64,
    /// Records in the leaves.
    pub records: U64,
    /// Page levels: 1 when the root is a leaf, 0 for an empty tree.
    pub depth: U16,
    /// Bytes per leaf record (pins the record layout the writer used).
    pub record_size: U16,
    /// Zero.
    pub reserved: U32,
}

/// A commit record: the first [`COMMIT_RECORD_LEN`] bytes of page 0 or page 1.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct CommitRecord {
    /// [`super::MAGIC`].
    pub magic: [u8; 8],
    /// [`super::FORMAT_MAJOR`] of the writer.
    pub major: U16,
    /// [`super::FORMAT_MINOR`] of the writer.
    pub minor: U16,
    /// Bytes per page.
    pub page_size: U32,
    /// Transaction id: the valid record with the higher id is the current state.
    pub txn_id: U64,
    /// The file's length in bytes when this record was written; a shorter file is truncated.
    pub file_length: U64,
    /// Reserved for flags (recovery state); zero.
    pub flags: U32,
    /// Zero.
    pub reserved0: U32,
    /// The dataset header blob.
    pub dataset_header: BlobRef,
    /// The cluster directory blob.
    pub cluster_directory: BlobRef,
    /// The node table ([`NodeRecord`]s in Hilbert pre-order).
    pub node_table: TreeRef,
    /// The block table ([`BlockRecord`]s, row-major over the finest level).
    pub block_table: TreeRef,
    /// The free list ([`FreeEntry`]s); empty in a freshly built file.
    pub free_list: TreeRef,
    /// The adjacency table: every cluster's edge lists ([`AdjacencyEntry`]s), back to back
    /// in the order the cluster directory's [`EdgeRange`]s give.
    pub adjacency: TreeRef,
    /// Zero.
    pub reserved: [u8; 84],
    /// CRC-32 of bytes `0..252` of the record.
    pub crc: U32,
}

/// The header that opens every structured page.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct PageHeader {
    /// What the page is (see [`super::tag`]).
    pub tag: [u8; 4],
    /// CRC-32 of bytes `8..P` of the page.
    pub crc: U32,
    /// The page's own number: a page written to the wrong place is caught.
    pub page_no: U64,
    /// Tree pages: 0 for a leaf, else the height above the leaves. Blob pages: 0.
    pub level: U16,
    /// Zero.
    pub reserved: U16,
    /// Tree pages: records or branch entries in the page. Blob pages: content bytes.
    pub count: U32,
}

impl PageHeader {
    /// The header at the start of `bytes`, if there are enough of them.
    pub fn read(bytes: &[u8]) -> Option<PageHeader> {
        PageHeader::read_from_prefix(bytes).ok().map(|(h, _)| h)
    }
}

/// One child of a B+-tree branch page.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct BranchEntry {
    /// The key of the first record under the child (the ordinal, for unkeyed tables).
    pub first_key: U64,
    /// The ordinal of the first record under the child.
    pub first_ordinal: U64,
    /// The child page.
    pub child: U64,
}

/// One node of the FMRH.
#[derive(
    Clone, Copy, Debug, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned,
)]
#[repr(C)]
pub struct NodeRecord {
    /// The node's [`crate::curve::HilbertKey`].
    pub key: U64,
    /// 0 = root, `L` = physical blocks.
    pub level: u8,
    /// Kept children: bit `dy * 2 + dx`.
    pub child_mask: u8,
    /// Bit 0 ([`NODE_GRID_HAS_VOIDS`]): the coarse grid has void or padding samples, and its
    /// payload carries the void bitmap.
    pub flags: U16,
    /// Column among the level's nodes.
    pub x: U32,
    /// Row among the level's nodes, from the north.
    pub y: U32,
    /// Index of the parent; `u32::MAX` for the root.
    pub parent: U32,
    /// Nodes in the subtree, itself included.
    pub subtree_len: U32,
    /// CRC-32 of the payload.
    pub payload_crc: U32,
    /// The node's own measured static error.
    pub static_error: F64,
    /// `e*`: the largest static error in the node's subtree of the full quadtree.
    pub monotone_error: F64,
    /// Least mended height over the footprint.
    pub min_height: F32,
    /// Greatest mended height over the footprint.
    pub max_height: F32,
    /// Valid samples in the footprint.
    pub valid_samples: U64,
    /// Byte offset of the payload: the coarse grid, or at level `L` the physical block.
    pub payload_offset: U64,
    /// Payload bytes.
    pub payload_len: U32,
    /// Zero.
    pub reserved: U32,
}

/// [`NodeRecord::flags`]: the grid has void or padding samples (a bitmap follows the heights).
pub const NODE_GRID_HAS_VOIDS: u16 = 1;

/// One physical block: the full-resolution samples of a finest-level footprint, clipped to
/// the data rectangle.
#[derive(
    Clone, Copy, Debug, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned,
)]
#[repr(C)]
pub struct BlockRecord {
    /// Byte offset of the payload.
    pub payload_offset: U64,
    /// Payload bytes: `4 * (width * height + void_count)`.
    pub payload_len: U32,
    /// CRC-32 of the payload.
    pub payload_crc: U32,
    /// Samples along a row (the footprint clipped to the data).
    pub width: U32,
    /// Samples down a column.
    pub height: U32,
    /// Void samples; their mended stand-ins follow the samples.
    pub void_count: U32,
    /// Zero.
    pub reserved: U32,
}

/// One node of a cluster, in the cluster's index.
#[derive(
    Clone, Copy, Debug, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned,
)]
#[repr(C)]
pub struct IndexEntry {
    /// The node's Hilbert key (the index's sort key; unique within a cut).
    pub key: U64,
    /// The node's index in the node table.
    pub node: U32,
    /// The node's level.
    pub level: u8,
    /// Zero.
    pub reserved: [u8; 3],
}

/// One node touching an edge of the data, in the adjacency table.
#[derive(
    Clone, Copy, Debug, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned,
)]
#[repr(C)]
pub struct AdjacencyEntry {
    /// The node's index in the node table.
    pub node: U32,
}

/// One free page (reserved for copy-on-write updates; a fresh file has none).
#[derive(
    Clone, Copy, Debug, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned,
)]
#[repr(C)]
pub struct FreeEntry {
    /// The page.
    pub page: U64,
    /// The transaction that freed it: reusable once no reader holds an older snapshot.
    pub freed_txn: U64,
}

/// One cluster in the cluster directory.
#[derive(
    Clone, Copy, Debug, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned,
)]
#[repr(C)]
pub struct ClusterRecord {
    /// δ.
    pub threshold: F64,
    /// The largest `e*` in the cut.
    pub max_error: F64,
    /// The index: [`IndexEntry`]s keyed by Hilbert key.
    pub index: TreeRef,
    /// Where this cluster's north, east, south and west edge lists lie in the adjacency
    /// table.
    pub adjacency: [EdgeRange; 4],
}

/// A run of the adjacency table: records `first .. first + count`.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    FromBytes,
    IntoBytes,
    KnownLayout,
    Immutable,
    Unaligned,
)]
#[repr(C)]
pub struct EdgeRange {
    /// Ordinal of the first record.
    pub first: U64,
    /// Records in the run.
    pub count: U64,
}

/// Bytes before the cluster records in the cluster directory: `count: u32, reserved: u32`.
pub const CLUSTER_DIRECTORY_PREFIX: usize = 8;

const _: () = {
    assert!(size_of::<BlobRef>() == 16);
    assert!(size_of::<TreeRef>() == 24);
    assert!(size_of::<CommitRecord>() == COMMIT_RECORD_LEN);
    assert!(size_of::<PageHeader>() == PAGE_HEADER_LEN);
    assert!(size_of::<BranchEntry>() == 24);
    assert!(size_of::<NodeRecord>() == 80);
    assert!(size_of::<BlockRecord>() == 32);
    assert!(size_of::<IndexEntry>() == 16);
    assert!(size_of::<AdjacencyEntry>() == 4);
    assert!(size_of::<FreeEntry>() == 16);
    assert!(size_of::<ClusterRecord>() == 104);
    assert!(size_of::<EdgeRange>() == 16);
};
