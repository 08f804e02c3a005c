//! The page header that opens every structured (non-payload) page, the page tags, and the one
//! place a structured page is built and checked.
//!
//! ```text
//!  0      4      8              16     18     20     24                                P
//!  | tag  | crc  |   page_no    | level| txn  | count|  content ... | zero tail        |
//!         └─ CRC-32 of bytes 8..P (number, level, txn tag, count, content, tail) ────┘
//! ```
//!
//! The CRC covers the page's own number, so a page written to the wrong place fails its check.
//! Since format 1.2 it also covers the *txn tag*: the low 16 bits of the id of the transaction
//! that wrote the page. Every structured page a state reaches was written by one transaction,
//! the one its commit record names (`pages_txn`), so a reader that follows an old state's
//! reference into a page a later state has reused finds the wrong tag, however valid the
//! page's own CRC (`format-spec/container.md` §4, §11.6). Files before 1.2 hold zero there.

use zerocopy::byteorder::little_endian::{U16, U32, U64};
use zerocopy::{FromBytes, IntoBytes};

use super::{crc32, is_zero, Invariant, Violation};

/// Bytes of the header that opens every structured page.
pub const PAGE_HEADER_LEN: usize = 24;

/// Where the CRC of a page starts: the tag and the CRC field itself are not covered.
const PAGE_CRC_FROM: usize = 8;

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
    /// A page of the top of the tree (6.2).
    pub const TOP: [u8; 4] = *b"FMTP";
}

on_disk! {
    /// The header that opens every structured page.
    pub struct PageHeader {
        /// What the page is (see [`tag`]).
        pub tag: [u8; 4],
        /// CRC-32 of bytes `8..P` of the page.
        pub crc: U32,
        /// The page's own number: a page written to the wrong place is caught.
        pub page_no: U64,
        /// Tree pages: 0 for a leaf, else the height above the leaves. Blob pages: 0.
        pub level: U16,
        /// [`txn_tag`] of the transaction that wrote the page (1.2); zero in older files.
        pub txn_tag: U16,
        /// Tree pages: records or branch entries in the page. Blob pages: content bytes.
        pub count: U32,
    }
}

const _: () = assert!(size_of::<PageHeader>() == PAGE_HEADER_LEN);

impl PageHeader {
    /// The header at the start of `bytes`, if there are enough of them.
    #[inline]
    pub fn read(bytes: &[u8]) -> Option<PageHeader> {
        PageHeader::read_from_prefix(bytes).ok().map(|(h, _)| h)
    }
}

/// The tag a page written by transaction `txn` carries: its low 16 bits.
#[inline]
pub fn txn_tag(txn: u64) -> u16 {
    (txn & 0xffff) as u16
}

/// The placement of a structured page: its number, and the transaction writing it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageStamp {
    /// The page's number.
    pub page_no: u64,
    /// The transaction that writes it (its [`txn_tag`] goes into the header).
    pub txn: u64,
}

/// Builds a sealed structured page of `page_size` bytes: the header (`tag`, the stamp,
/// `level`, `count`), then `body`, then zeros, with the CRC filled in. `body` must fit.
pub fn encode_page(
    page_size: u32,
    tag: [u8; 4],
    stamp: PageStamp,
    level: u16,
    count: u32,
    body: &[u8],
) -> Vec<u8> {
    let mut bytes = vec![0u8; page_size as usize];
    let header = PageHeader {
        tag,
        crc: U32::new(0),
        page_no: U64::new(stamp.page_no),
        level: U16::new(level),
        txn_tag: U16::new(txn_tag(stamp.txn)),
        count: U32::new(count),
    };
    bytes[..PAGE_HEADER_LEN].copy_from_slice(header.as_bytes());
    bytes[PAGE_HEADER_LEN..PAGE_HEADER_LEN + body.len()].copy_from_slice(body);
    let crc = crc32(&bytes[PAGE_CRC_FROM..]);
    bytes[4..8].copy_from_slice(&crc.to_le_bytes());
    bytes
}

/// Checks the header of structured page `page_no` (I-5: tag, CRC, own number) and returns it.
/// `bytes` is the whole page. The txn tag is the caller's to check: only the store knows which
/// transaction its state's pages must come from.
pub fn check_page(bytes: &[u8], page_no: u64, expected: [u8; 4]) -> Result<PageHeader, Violation> {
    let at = || format!("page {page_no}");
    let header = PageHeader::read(bytes)
        .ok_or_else(|| Violation::new(Invariant::Page, at(), "short page"))?;
    if header.tag != expected {
        return Err(Violation::new(
            Invariant::Page,
            at(),
            format!(
                "tag {:?}, expected {:?}",
                String::from_utf8_lossy(&header.tag),
                String::from_utf8_lossy(&expected)
            ),
        ));
    }
    let stored = header.crc.get();
    let actual = crc32(&bytes[PAGE_CRC_FROM..]);
    if stored != actual {
        return Err(Violation::new(
            Invariant::Page,
            at(),
            format!("CRC {stored:#010x} stored, {actual:#010x} computed"),
        ));
    }
    if header.page_no.get() != page_no {
        return Err(Violation::new(
            Invariant::Page,
            at(),
            format!("page claims to be page {}", header.page_no.get()),
        ));
    }
    Ok(header)
}

/// Checks that the bytes of `page` after `content_end` (the header plus its entries or
/// content) are zero (I-5).
pub fn check_tail(page: &[u8], content_end: usize, at: &str) -> Result<(), Violation> {
    if page.get(content_end..).is_none_or(|tail| !is_zero(tail)) {
        return Err(Violation::new(
            Invariant::Page,
            at,
            "bytes after the content are not zero",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_encoded_page_checks_and_a_moved_one_does_not() {
        let stamp = PageStamp {
            page_no: 7,
            txn: 0x1_0005,
        };
        let page = encode_page(1024, tag::NODE_TABLE, stamp, 1, 3, &[1, 2, 3]);
        let h = check_page(&page, 7, tag::NODE_TABLE).unwrap();
        assert_eq!((h.level.get(), h.count.get(), h.txn_tag.get()), (1, 3, 5));
        assert!(check_tail(&page, PAGE_HEADER_LEN + 3, "p").is_ok());
        assert!(check_page(&page, 8, tag::NODE_TABLE).is_err());
        assert!(check_page(&page, 7, tag::BLOCK_TABLE).is_err());
        for at in [18, 100] {
            // The txn tag is covered by the CRC like the content.
            let mut flipped = page.clone();
            flipped[at] ^= 1;
            assert!(check_page(&flipped, 7, tag::NODE_TABLE).is_err());
        }
    }
}
