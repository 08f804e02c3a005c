//! The fixed-size table records, as `zerocopy` structs of little-endian fields, and the plain
//! values they encode and decode to.
//!
//! Every struct is `#[repr(C)]` with alignment 1 (all fields are byte arrays underneath), so a
//! record is read straight out of any byte slice, mapped or not, on any host, and its size is
//! pinned by a compile-time assertion. Offsets and meanings are tabulated in
//! `format-spec/container.md` §6. Each record has a plain counterpart ([`StoredNode`],
//! [`StoredBlock`], [`ScanEntry`], [`FreePage`]) with native fields, which is what the
//! store's API hands out; the conversions both ways live here and nowhere else.

use zerocopy::byteorder::little_endian::{F32, F64, U16, U32, U64};

use super::payload::PayloadRef;
use crate::curve::HilbertKey;

/// `parent` of the root in the node table.
pub const ROOT_PARENT: u32 = u32::MAX;

/// [`NodeRecord::flags`]: the grid has void or padding samples (a bitmap follows the heights).
pub const NODE_GRID_HAS_VOIDS: u16 = 1;

/// [`NodeRecord::flags`] (format 5): the grid is coded against its parent node's grid, so
/// decoding it needs that grid first.
pub const NODE_GRID_AGAINST_PARENT: u16 = 2;

/// [`NodeRecord::flags`] (format 5): the grid's void bitmap follows a void flag
/// ([`crate::codec::voids`]: raw or as runs) instead of lying raw; set only with
/// [`NODE_GRID_HAS_VOIDS`]. A grid kept from an older state keeps its raw bitmap.
pub const NODE_GRID_BITMAP_FLAGGED: u16 = 4;

/// [`NodeRecord::flags`] (format 6): bits 3 to 6 hold `log₂ k`, the factor the coarse grid
/// is thinned by east-west (thinning by area, [`crate::model::thinning`]); 0 for a square
/// grid. The payload then stores only the kept columns (format §7).
pub const NODE_GRID_THIN_MASK: u16 = 0x78;

/// The shift of [`NODE_GRID_THIN_MASK`].
pub const NODE_GRID_THIN_SHIFT: u32 = 3;

on_disk! {
    /// One node of the FMRH.
    pub struct NodeRecord {
        /// The node's [`HilbertKey`].
        pub key: U64,
        /// 0 = root, `L` = physical blocks.
        pub level: u8,
        /// Kept children: bit `dy * 2 + dx`.
        pub child_mask: u8,
        /// Bit 0 ([`NODE_GRID_HAS_VOIDS`]): the coarse grid has void or padding samples, and its
        /// payload carries the void bitmap. Bit 1 ([`NODE_GRID_AGAINST_PARENT`], format 5): the
        /// grid is coded against its parent's. Bit 2 ([`NODE_GRID_BITMAP_FLAGGED`], format 5):
        /// the bitmap follows a void flag. Bits 3 to 6 ([`NODE_GRID_THIN_MASK`], format 6):
        /// `log₂` of the grid's thinning factor.
        pub flags: U16,
        /// Column among the level's nodes.
        pub x: U32,
        /// Row among the level's nodes, from the north.
        pub y: U32,
        /// Index of the parent; [`ROOT_PARENT`] for the root.
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
}

/// A node of the FMRH as a store holds it: the tree node, and where its payload is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StoredNode {
    /// Place on the multiresolution Hilbert curve.
    pub key: HilbertKey,
    /// Level: 0 is the root, `L` the physical blocks.
    pub level: u8,
    /// Column among the level's nodes.
    pub x: u32,
    /// Row among the level's nodes, from the north.
    pub y: u32,
    /// Kept children: bit `dy * 2 + dx` for the child in quadrant `(dx, dy)`.
    pub child_mask: u8,
    /// Index of the parent in the node table; `None` for the root.
    pub parent: Option<u32>,
    /// Nodes in its subtree, itself included: its descendants are the next
    /// `subtree_len - 1` nodes of the table.
    pub subtree_len: u32,
    /// The measured static error of its own grid, in height units.
    pub static_error: f64,
    /// `e*`: the largest static error in its subtree; never grows from parent to child.
    pub monotone_error: f64,
    /// Least mended height over the footprint.
    pub min_height: f32,
    /// Greatest mended height over the footprint.
    pub max_height: f32,
    /// Valid samples in the footprint.
    pub valid_samples: u64,
    /// Its payload: the coarse grid, or at the finest level the physical block.
    pub payload: PayloadRef,
    /// Whether its coarse grid carries a void bitmap.
    pub grid_has_voids: bool,
    /// Whether its coarse grid is coded against its parent's grid (format 5).
    pub grid_against_parent: bool,
    /// Whether its coarse grid's void bitmap follows a void flag (format 5).
    pub grid_bitmap_flagged: bool,
    /// `log₂` of the factor its coarse grid is thinned by east-west (format 6); 0: square.
    pub grid_thin: u8,
}

impl NodeRecord {
    /// The plain node.
    #[inline]
    pub fn decode(&self) -> StoredNode {
        StoredNode {
            key: HilbertKey(self.key.get()),
            level: self.level,
            x: self.x.get(),
            y: self.y.get(),
            child_mask: self.child_mask,
            parent: Some(self.parent.get()).filter(|&p| p != ROOT_PARENT),
            subtree_len: self.subtree_len.get(),
            static_error: self.static_error.get(),
            monotone_error: self.monotone_error.get(),
            min_height: self.min_height.get(),
            max_height: self.max_height.get(),
            valid_samples: self.valid_samples.get(),
            payload: self.payload(),
            grid_has_voids: self.flags.get() & NODE_GRID_HAS_VOIDS != 0,
            grid_against_parent: self.flags.get() & NODE_GRID_AGAINST_PARENT != 0,
            grid_bitmap_flagged: self.flags.get() & NODE_GRID_BITMAP_FLAGGED != 0,
            // Four bits.
            grid_thin: ((self.flags.get() & NODE_GRID_THIN_MASK) >> NODE_GRID_THIN_SHIFT) as u8,
        }
    }

    /// The record of `node`.
    pub fn encode(node: &StoredNode) -> NodeRecord {
        NodeRecord {
            key: U64::new(node.key.0),
            level: node.level,
            child_mask: node.child_mask,
            flags: U16::new(
                if node.grid_has_voids {
                    NODE_GRID_HAS_VOIDS
                } else {
                    0
                } | if node.grid_against_parent {
                    NODE_GRID_AGAINST_PARENT
                } else {
                    0
                } | if node.grid_bitmap_flagged {
                    NODE_GRID_BITMAP_FLAGGED
                } else {
                    0
                } | (u16::from(node.grid_thin) << NODE_GRID_THIN_SHIFT) & NODE_GRID_THIN_MASK,
            ),
            x: U32::new(node.x),
            y: U32::new(node.y),
            parent: U32::new(node.parent.unwrap_or(ROOT_PARENT)),
            subtree_len: U32::new(node.subtree_len),
            payload_crc: U32::new(node.payload.crc),
            static_error: F64::new(node.static_error),
            monotone_error: F64::new(node.monotone_error),
            min_height: F32::new(node.min_height),
            max_height: F32::new(node.max_height),
            valid_samples: U64::new(node.valid_samples),
            payload_offset: U64::new(node.payload.offset),
            payload_len: U32::new(node.payload.len),
            reserved: U32::new(0),
        }
    }

    /// Where its payload is.
    #[inline]
    pub fn payload(&self) -> PayloadRef {
        PayloadRef {
            offset: self.payload_offset.get(),
            len: self.payload_len.get(),
            crc: self.payload_crc.get(),
        }
    }
}

on_disk! {
    /// One physical block: the full-resolution samples of a finest-level footprint, clipped to
    /// the data rectangle.
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
        /// Format 4: the node whose coarse grid the samples are coded against, as its index in
        /// the node table plus one; 0 when the block is coded alone. Zero (reserved) before 4.0.
        pub against: U32,
    }
}

/// A physical block as the block table describes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StoredBlock {
    /// Its payload.
    pub payload: PayloadRef,
    /// Samples along a row (its footprint clipped to the data).
    pub width: u32,
    /// Samples down a column.
    pub height: u32,
    /// Void samples.
    pub void_count: u32,
    /// The node (its index in the node table) whose coarse grid the samples are coded
    /// against; `None` when the block is coded alone.
    pub against: Option<u32>,
}

impl BlockRecord {
    /// The plain block description.
    #[inline]
    pub fn decode(&self) -> StoredBlock {
        StoredBlock {
            payload: self.payload(),
            width: self.width.get(),
            height: self.height.get(),
            void_count: self.void_count.get(),
            against: self.against.get().checked_sub(1),
        }
    }

    /// The record of `block`.
    pub fn encode(block: &StoredBlock) -> BlockRecord {
        BlockRecord {
            payload_offset: U64::new(block.payload.offset),
            payload_len: U32::new(block.payload.len),
            payload_crc: U32::new(block.payload.crc),
            width: U32::new(block.width),
            height: U32::new(block.height),
            void_count: U32::new(block.void_count),
            // A node table holds fewer than 2^32 - 1 nodes (checked where it is written).
            against: U32::new(block.against.map_or(0, |n| n.saturating_add(1))),
        }
    }

    /// Where its payload is.
    #[inline]
    pub fn payload(&self) -> PayloadRef {
        PayloadRef {
            offset: self.payload_offset.get(),
            len: self.payload_len.get(),
            crc: self.payload_crc.get(),
        }
    }
}

on_disk! {
    /// One node of a cluster, in the cluster's index.
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
}

/// An entry of a cluster index, as a scan returns it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ScanEntry {
    /// The node's Hilbert key.
    pub key: HilbertKey,
    /// The node's level.
    pub level: u8,
    /// The node's index in the node table.
    pub node: u32,
}

impl IndexEntry {
    /// The plain entry.
    #[inline]
    pub fn decode(&self) -> ScanEntry {
        ScanEntry {
            key: HilbertKey(self.key.get()),
            level: self.level,
            node: self.node.get(),
        }
    }

    /// The record of `entry`.
    pub fn encode(entry: &ScanEntry) -> IndexEntry {
        IndexEntry {
            key: U64::new(entry.key.0),
            node: U32::new(entry.node),
            level: entry.level,
            reserved: [0; 3],
        }
    }
}

on_disk! {
    /// One node touching an edge of the data, in the adjacency table.
    pub struct AdjacencyEntry {
        /// The node's index in the node table.
        pub node: U32,
    }
}

on_disk! {
    /// One free page.
    pub struct FreeEntry {
        /// The page.
        pub page: U64,
        /// The transaction that freed it: reusable once no reader holds an older snapshot.
        pub freed_txn: U64,
    }
}

/// A page no structure of a state uses, and the first state that stopped using it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct FreePage {
    /// The page number.
    pub page: u64,
    /// The txn id of the first state that no longer reaches it.
    pub freed_txn: u64,
}

impl FreeEntry {
    /// The plain entry.
    #[inline]
    pub fn decode(&self) -> FreePage {
        FreePage {
            page: self.page.get(),
            freed_txn: self.freed_txn.get(),
        }
    }

    /// The record of `free`.
    pub fn encode(free: &FreePage) -> FreeEntry {
        FreeEntry {
            page: U64::new(free.page),
            freed_txn: U64::new(free.freed_txn),
        }
    }
}

const _: () = {
    assert!(size_of::<NodeRecord>() == 80);
    assert!(size_of::<BlockRecord>() == 32);
    assert!(size_of::<IndexEntry>() == 16);
    assert!(size_of::<AdjacencyEntry>() == 4);
    assert!(size_of::<FreeEntry>() == 16);
};
