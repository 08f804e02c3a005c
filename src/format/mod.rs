//! The `.fmrh` container format: byte layouts, constants and the numbered invariants, with
//! no I/O.
//!
//! This module is the code side of `format-spec/container.md`. It says what the bytes mean
//! and nothing about where they come from: every parser here takes a `&[u8]` and returns either
//! a typed value or [`Error::Corrupt`] naming the invariant it broke. The store
//! ([`crate::store`]) decides which bytes to read. The writer ([`crate::store::write`]) decides
//! which bytes to write.
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
//! checked by the CRC stored beside the offset.
//!
//! ## Versioning policy
//!
//! [`FORMAT_MAJOR`] changes when an older reader would misread a file. Readers refuse any
//! other major version. [`FORMAT_MINOR`] changes when fields or structures are *added* in space
//! that older versions require to be zero, or under new page tags. A reader opens any minor
//! version of its major. It ignores what it does not know, and it checks reserved bytes for
//! zero only in files whose minor version is not newer than its own.

pub mod dataset;
pub mod payload;
pub mod records;

pub use dataset::DatasetHeader;
pub use records::*;

use crate::error::{Error, Result};

/// The first eight bytes of a commit record. The `\r\n\x1a\n` tail catches text-mode
/// transfers, as PNG's signature does.
pub const MAGIC: [u8; 8] = *b"FMRH\r\n\x1a\n";

/// Incompatible revisions of the format. This reader reads major version 1 only.
pub const FORMAT_MAJOR: u16 = 1;

/// Compatible additions within [`FORMAT_MAJOR`]. 1.1 added the commit record's flags
/// ([`COMMIT_RECOVERY_NEEDED`]) and files changed by transactions.
pub const FORMAT_MINOR: u16 = 1;

/// Commit record flag: a transactional writer had the file open when this state was
/// committed, and may have written past `file_length` since. The next writer to open the file
/// cuts it back to `file_length` (recovery) before anything else; readers ignore the excess.
/// A writer that closes cleanly commits a record without the flag.
pub const COMMIT_RECOVERY_NEEDED: u32 = 1;

/// Commit record flag: a transaction has replaced payloads, so bytes of dead payloads may
/// remain in payload pages that live payloads still use (a commit never writes a page the
/// previous state reaches, so it cannot zero them). Without it, those bytes are zero (I-9).
/// Once set, later commits keep it.
pub const COMMIT_PAYLOAD_SLACK: u32 = 2;

/// Every commit record flag this reader knows.
pub const COMMIT_FLAGS_KNOWN: u32 = COMMIT_RECOVERY_NEEDED | COMMIT_PAYLOAD_SLACK;

/// The page size a writer uses unless told otherwise.
pub const DEFAULT_PAGE_SIZE: u32 = 4096;
/// The smallest page size: a node record and a branch of two entries must fit in one page.
pub const MIN_PAGE_SIZE: u32 = 1024;
/// The largest page size.
pub const MAX_PAGE_SIZE: u32 = 65536;

/// Bytes of a commit record at the start of its slot page; the rest of the page is zero.
pub const COMMIT_RECORD_LEN: usize = 256;
/// Bytes of the header that opens every structured (non-payload) page.
pub const PAGE_HEADER_LEN: usize = 24;
/// Payloads start on multiples of this many bytes.
pub const PAYLOAD_ALIGN: u64 = 8;
/// The deepest B+-tree a reader follows: with 1024-byte pages, a fan-out of 41 reaches
/// 41^7 ≈ 2·10^11 leaves, more than any dataset within the size limits needs.
pub const MAX_TREE_DEPTH: u16 = 8;
/// Longest string in the dataset header (CRS, units, source format), in bytes.
pub const MAX_STRING_LEN: u32 = 4096;
/// The bits of the `f32` a physical block stores for a void sample (the canonical quiet NaN).
pub const VOID_BITS: u32 = 0x7fc0_0000;

/// Whether `page_size` is one a file may use.
pub fn page_size_is_valid(page_size: u32) -> bool {
    page_size.is_power_of_two() && (MIN_PAGE_SIZE..=MAX_PAGE_SIZE).contains(&page_size)
}

/// The page tags: the first four bytes of every structured page.
pub mod tag {
    /// A page of the dataset header blob.
    pub const DATASET_HEADER: [u8; 4] = *b"FMHD";
    /// A page of the cluster directory blob.
    pub const CLUSTER_DIRECTORY: [u8; 4] = *b"FMCD";
    /// A page of the node table.
    pub const NODE_TABLE: [u8; 4] = *b"FMNT";
    /// A page of the block table.
    pub const BLOCK_TABLE: [u8; 4] = *b"FMBT";
    /// A page of a cluster index.
    pub const CLUSTER_INDEX: [u8; 4] = *b"FMCI";
    /// A page of an adjacency list.
    pub const ADJACENCY: [u8; 4] = *b"FMAJ";
    /// A page of the free list.
    pub const FREE_LIST: [u8; 4] = *b"FMFL";
}

/// The numbered invariants of a valid file (`format-spec/container.md` §9). The validator and
/// [`Error::Corrupt`] name them by these ids.
pub mod invariant {
    /// A commit record is valid: magic, CRC, fields in range, zero tail.
    pub const COMMIT_RECORD: &str = "I-1";
    /// The major version is one this reader knows.
    pub const VERSION: &str = "I-2";
    /// Page size allowed; file length equals the record's and is whole pages.
    pub const FILE_LENGTH: &str = "I-3";
    /// The inactive commit slot is zero or an older valid record.
    pub const INACTIVE_SLOT: &str = "I-4";
    /// Every structured page: tag, own page number, CRC, zero tail.
    pub const PAGE: &str = "I-5";
    /// The dataset header parses and is self-consistent.
    pub const DATASET_HEADER: &str = "I-6";
    /// Every table is a well-formed B+-tree.
    pub const TREE_SHAPE: &str = "I-7";
    /// Every page belongs to exactly one structure.
    pub const PAGE_OWNERSHIP: &str = "I-8";
    /// Payloads: inside the file, aligned, disjoint, CRC, zero gaps, implied lengths.
    pub const PAYLOAD: &str = "I-9";
    /// The node table is the FMRH in Hilbert pre-order.
    pub const NODE_TABLE: &str = "I-10";
    /// The block table holds every physical block, row-major.
    pub const BLOCK_TABLE: &str = "I-11";
    /// The cluster directory: thresholds and summaries.
    pub const CLUSTER_DIRECTORY: &str = "I-12";
    /// Each cluster index is its cut, sorted by Hilbert key.
    pub const CLUSTER_INDEX: &str = "I-13";
    /// Adjacency lists list each cut's edge nodes in order.
    pub const ADJACENCY: &str = "I-14";
    /// Errors, ranges and node grids equal their recomputation from the blocks.
    pub const MEASURED: &str = "I-15";
    /// The free list names free pages only.
    pub const FREE_LIST: &str = "I-16";
}

/// CRC-32 (ISO-HDLC, the zlib/PNG polynomial) of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// Checks the header of structured page `page_no` and returns its parsed header.
/// `bytes` is the whole page.
pub fn check_page(bytes: &[u8], page_no: u64, expected: [u8; 4]) -> Result<PageHeader> {
    let header = PageHeader::read(bytes)
        .ok_or_else(|| Error::corrupt(invariant::PAGE, format!("page {page_no}"), "short page"))?;
    if header.tag != expected {
        return Err(Error::corrupt(
            invariant::PAGE,
            format!("page {page_no}"),
            format!(
                "tag {:?}, expected {:?}",
                String::from_utf8_lossy(&header.tag),
                String::from_utf8_lossy(&expected)
            ),
        ));
    }
    let stored = header.crc.get();
    let actual = crc32(&bytes[8..]);
    if stored != actual {
        return Err(Error::corrupt(
            invariant::PAGE,
            format!("page {page_no}"),
            format!("CRC {stored:#010x} stored, {actual:#010x} computed"),
        ));
    }
    if header.page_no.get() != page_no {
        return Err(Error::corrupt(
            invariant::PAGE,
            format!("page {page_no}"),
            format!("page claims to be page {}", header.page_no.get()),
        ));
    }
    Ok(header)
}

/// Seals a structured page in place: fills the CRC over bytes `8..`.
pub fn seal_page(bytes: &mut [u8]) {
    let crc = crc32(&bytes[8..]);
    bytes[4..8].copy_from_slice(&crc.to_le_bytes());
}

/// Whether every byte of `bytes` is zero.
pub fn is_zero(bytes: &[u8]) -> bool {
    bytes.iter().all(|&b| b == 0)
}
