//! The `.fmrh` container format: byte layouts, constants and the numbered invariants, with
//! no I/O.
//!
//! This module is the code side of `format-spec/container.md`, and the only code that knows
//! where a byte of a container goes. It says what the bytes mean and nothing about where they
//! come from: each on-disk structure is encoded and decoded in one file here, on plain byte
//! slices, and every decoder returns either a typed value or a [`Violation`] naming the
//! invariant it broke. The store (`src/store/`) decides which bytes to read and write.
//!
//! | file | structure | spec |
//! |---|---|---|
//! | [`commit`] | commit records, the slot choice | §3 |
//! | [`page`] | the page header, tags, page checks | §4 |
//! | [`blob`] | blobs of consecutive pages | §4 |
//! | [`bundle`] | the compressed metadata bundle of a small state | §6.7 |
//! | [`tree`] | B+-tree pages | §4 |
//! | [`dataset`] | the dataset header | §5 |
//! | [`records`] | node, block, index, adjacency and free-list records | §6 |
//! | [`directory`] | the cluster directory | §6.5 |
//! | [`tables`] | the list of a state's tables | §6 |
//! | [`payload`] | physical blocks and coarse grids | §7 |
//! | [`Invariant`] (in `crate::error`) | the numbered invariants | §9 |
//! | [`manifest`] | a dataset's manifest | `dataset.md` |
//!
//! Adding a section means one file here, one entry in [`tables`] (for a table) or a root in
//! [`commit::StateRoots`] (for a blob), and its section in the spec.
//!
//! ## The shape of a file, in one paragraph
//!
//! A file is a sequence of pages of one fixed size `P` (a power of two, 4096 by default).
//! Pages 0 and 1 are the two *commit slots*. A reader takes the valid commit record with the
//! higher transaction id, so a writer can publish a new state by writing the other slot (copy on
//! write). The record holds the roots of every section: the *dataset header* and the *cluster
//! directory* (small blobs), the *node table*, the *block table* and the *free list* (static
//! B+-trees of fixed-size records). The directory holds, per cluster, the roots of its *index*
//! (the cut sorted by Hilbert key) and of its four *adjacency lists*. Node grids and physical
//! blocks are *payloads*: byte runs anywhere in the file, found through their records and
//! checked by the CRC stored beside the offset. Since 3.0 a small state keeps its structured
//! pages (all but the free list's) in a *metadata bundle*: one zstd frame, named and checked
//! by the record like a payload, that decompresses to pages numbered from 2^40 ([`bundle`]).
//!
//! ## Versioning policy
//!
//! [`FORMAT_MAJOR`] changes when an older reader would misread a file. Readers refuse a newer
//! major version; this one reads 1.x as well (read-only). [`FORMAT_MINOR`] changes when fields or structures are *added* in space
//! that older versions require to be zero, or under new page tags. A reader opens any minor
//! version of its major. It ignores what it does not know, and it checks reserved bytes for
//! zero only in files whose minor version is not newer than its own. The commit record's
//! *envelope* (magic, versions, page size, txn id, CRC) keeps its place in every major, so an
//! old reader knows when a newer writer has superseded the state it could read
//! ([`commit::choose`]).

// Values read from a file are converted with checks, never truncated by `as`.
#![warn(clippy::cast_possible_truncation)]

/// Declares an on-disk structure of `format-spec/container.md` §3–§6 (and `dataset.md`):
/// `#[repr(C)]` with fixed-width little-endian fields and no padding (`Unaligned`), read and
/// written in place by zerocopy. Every such structure is declared through this one macro, so
/// all have the same derives; a structure that needs more (`Default`, `Eq`) says so above its
/// name.
macro_rules! on_disk {
    ($(#[$attr:meta])* $vis:vis struct $name:ident $body:tt) => {
        $(#[$attr])*
        #[derive(
            Clone,
            Copy,
            Debug,
            PartialEq,
            zerocopy::FromBytes,
            zerocopy::IntoBytes,
            zerocopy::KnownLayout,
            zerocopy::Immutable,
            zerocopy::Unaligned,
        )]
        #[repr(C)]
        $vis struct $name $body
    };
}

pub mod blob;
pub mod bundle;
pub mod commit;
pub mod dataset;
pub mod directory;
pub mod manifest;
pub mod page;
pub mod payload;
pub mod records;
pub mod tables;
pub mod top;
pub mod tree;

pub use crate::error::{Invariant, Violation};
pub use blob::BlobRef;
pub use commit::{
    CommitRecord, StateRoots, COMMIT_PAYLOAD_SLACK, COMMIT_RECORD_LEN, COMMIT_RECOVERY_NEEDED,
    MAX_TXN_ID,
};
#[cfg(any(test, feature = "testing"))]
pub use commit::COMMIT_FLAGS_KNOWN;
pub use dataset::DatasetHeader;
pub use directory::ClusterInfo;
#[cfg(any(test, feature = "testing"))]
pub use directory::{ClusterRecord, EdgeRange};
pub use page::tag;
#[cfg(any(test, feature = "testing"))]
pub use page::{PageHeader, PAGE_HEADER_LEN};
pub use payload::PayloadRef;
pub use records::{AdjacencyEntry, BlockRecord, FreeEntry, FreePage, IndexEntry, NodeRecord, ScanEntry, StoredBlock, StoredNode, NODE_GRID_AGAINST_PARENT, NODE_GRID_BITMAP_FLAGGED, NODE_GRID_HAS_VOIDS, NODE_GRID_THIN_MASK, NODE_GRID_THIN_SHIFT};
#[cfg(any(test, feature = "testing"))]
pub use records::ROOT_PARENT;
pub use tree::{TreeRef, TreeSpec, MAX_TREE_DEPTH};

/// The first eight bytes of a commit record. The `\r\n\x1a\n` tail catches text-mode
/// transfers, as PNG's signature does.
pub const MAGIC: [u8; 8] = *b"FMRH\r\n\x1a\n";

/// Incompatible revisions of the format. Writers write 7; readers read 1 to 7.
///
/// 7.0 may code a payload's residuals with fmrh's own tANS stream rather than pco (payload
/// encodings 9 to 14, the tANS twins of 2 and 4 to 8) and may predict a lattice payload
/// against its parent from the parent's lattice codes in integers (encoding 15): a 6.x
/// reader would take such a payload for a corrupt one. Everything else is as in 6.2, so a
/// 6.x file is read as it is (and a reader refuses encodings 9 and up in it, as corrupt) and a
/// transaction on it writes a 7.0 state whose old payloads keep their pco codes.
///
/// 6.0 may store a node's coarse grid *thinned by area* (the node record's flag bits 3 to 6,
/// `NODE_GRID_THIN_MASK`): only every `k`-th column and the last, which a reader
/// expands back (§7). A 5.x reader would take such a grid for a corrupt one. Everything else
/// is as in 5.0, so a 5.x file is read as it is and a transaction on it writes a 6.0 state.
///
/// 5.0 may code a node's coarse grid *against its parent's grid* as 4.0 codes physical
/// blocks (the node record's flag `NODE_GRID_AGAINST_PARENT`): decoding a grid may
/// then need its ancestors' grids, up to one coded alone. A 4.x reader would take such a grid
/// for a corrupt one. Everything else is as in 4.0, so a 4.x file is read as it is and a
/// transaction on it writes a 5.0 state.
///
/// 4.0 may code a physical block *against its parent's grid* (payload encodings 5 and 6,
/// the block record's `against` field, formerly reserved): a 3.x reader would take such a
/// block for a corrupt one. Everything else is as in 3.0, so a 3.x file is read as it is
/// and a transaction on it writes a 4.0 state.
///
/// 3.0 may keep a small state's structured pages in a compressed *metadata bundle*
/// (§6.7) that the commit record names: a 2.x reader would find the tables missing.
/// Everything else is as in 2.1, so a 2.x file is read as it is and a transaction on it
/// writes a 3.0 state. 2.0 stored payloads coded (§7) where 1.x stored raw `f32`: a 1.x file is read as it is, and refused
/// for writing (it would mix raw and coded payloads): rebuild it with `fmrh build`.
pub const FORMAT_MAJOR: u16 = 7;

/// Compatible additions within [`FORMAT_MAJOR`]: none yet (7.0 is the first release of
/// major 7).
pub const FORMAT_MINOR: u16 = 0;

/// The last minor version of major 6. 6.1 records the heights' vertical datum in the
/// dataset header (byte 156, formerly reserved); 6.2 adds the top of the tree (commit record
/// bytes 200..216, formerly reserved: `format::top`), a copy of the coarsest levels' node
/// records that lets a remote reader start a scene without reading the node table. Both
/// stay in major 7.
pub const LAST_MINOR_OF_6: u16 = 2;

/// The last minor version of major 5.
pub const LAST_MINOR_OF_5: u16 = 0;

/// The last minor version of major 4.
pub const LAST_MINOR_OF_4: u16 = 0;

/// The last minor version of major 3.
pub const LAST_MINOR_OF_3: u16 = 0;

/// The last minor version of major 2. 2.1 added the dataset header's storage `precision`
/// (formerly reserved, zero in 2.0 files: lossless).
pub const LAST_MINOR_OF_2: u16 = 1;

/// The last minor version of major 1. 1.1 added the commit record's flags
/// ([`COMMIT_RECOVERY_NEEDED`]) and files changed by transactions. 1.2 binds every structured
/// page to the transaction that wrote it (the page header's txn tag, the record's
/// `pages_txn`), so a reader of an old state never takes a reused page for its own.
pub const LAST_MINOR_OF_1: u16 = 2;

/// The page size a writer uses unless told otherwise.
pub const DEFAULT_PAGE_SIZE: u32 = 4096;

/// The page size `fmrh build` picks when not told: [`MIN_PAGE_SIZE`] for data of at most
/// [`SMALL_DATA_SAMPLES`] samples, else [`DEFAULT_PAGE_SIZE`]. A file's fixed cost is its two
/// commit slots (two pages) and the tail of its last page: 10 KiB on average at 4 KiB
/// pages, a tenth of a 100 KB file, and a COG of the same small DEM has no such cost.
/// Larger files keep 4 KiB pages, the operating system's, for their tables and commits.
pub fn page_size_for(samples: u64) -> u32 {
    if samples <= SMALL_DATA_SAMPLES {
        MIN_PAGE_SIZE
    } else {
        DEFAULT_PAGE_SIZE
    }
}

/// Data of at most this many samples (1024², 4 MiB of raw `f32`) gets 1 KiB pages from
/// [`page_size_for`].
pub const SMALL_DATA_SAMPLES: u64 = 1 << 20;
/// The smallest page size: a node record and a branch of two entries must fit in one page.
pub const MIN_PAGE_SIZE: u32 = 1024;
/// The largest page size.
pub const MAX_PAGE_SIZE: u32 = 65536;

/// Payloads of a 1.x file start on multiples of this many bytes (they were viewed in place as
/// `f32`). A 2.x file's payloads are decoded, not viewed, and start on any byte.
pub const PAYLOAD_ALIGN: u64 = 8;

/// The alignment of payload offsets in a file whose payloads are `coded` (2.x) or not (1.x).
pub fn payload_align(coded: bool) -> u64 {
    if coded {
        1
    } else {
        PAYLOAD_ALIGN
    }
}
/// Longest string in the dataset header (CRS, units, source format), in bytes.
pub const MAX_STRING_LEN: u32 = 4096;
/// The bits of the `f32` a physical block stores for a void sample (the canonical quiet NaN).
/// A source sample that is any NaN (any sign, any payload) is a void and is stored as these
/// bits; no other NaN appears in a block.
pub const VOID_BITS: u32 = 0x7fc0_0000;

/// Whether `page_size` is one a file may use.
pub fn page_size_is_valid(page_size: u32) -> bool {
    page_size.is_power_of_two() && (MIN_PAGE_SIZE..=MAX_PAGE_SIZE).contains(&page_size)
}

/// CRC-32 (ISO-HDLC, the zlib/PNG polynomial) of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// Whether every byte of `bytes` is zero.
pub fn is_zero(bytes: &[u8]) -> bool {
    bytes.iter().all(|&b| b == 0)
}
