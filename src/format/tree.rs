//! Static B+-trees of fixed-size records: the page layout of every table, built whole by
//! writers and read page by page.
//!
//! A leaf (level 0) holds `count` records from byte 24. A branch holds `count`
//! [`BranchEntry`]s: the first key and first ordinal under a child, and the child's page.
//! Keyed tables (cluster indexes, the free list) take the key from the first 8 bytes of each
//! record; the others use the ordinal as the key, so one descent serves "record i" and "keys
//! a to b" alike. There are no sibling pointers: a copy-on-write update would have to rewrite
//! every leaf before a changed one to keep them right. Readers keep their path on a stack.
//!
//! This file knows pages as bytes. Following child pages through a file is the store's job
//! (`store/btree.rs`).

use zerocopy::byteorder::little_endian::{U16, U32, U64};
use zerocopy::{FromBytes, FromZeros, IntoBytes};

use super::page::{check_page, check_tail, encode_page, PageHeader, PageStamp, PAGE_HEADER_LEN};
use super::{Invariant, Violation};

/// The deepest B+-tree a reader follows: with 1024-byte pages, a fan-out of 41 reaches
/// 41^7 ≈ 2·10^11 leaves, more than any dataset within the size limits needs.
pub const MAX_TREE_DEPTH: u16 = 8;

on_disk! {
    /// Where a B+-tree lives. An empty tree has root, records and depth zero, and still names its
    /// table's record size.
    #[derive(Default, Eq)]
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
}

on_disk! {
    /// One child of a B+-tree branch page.
    pub struct BranchEntry {
        /// The key of the first record under the child (the ordinal, for unkeyed tables).
        pub first_key: U64,
        /// The ordinal of the first record under the child.
        pub first_ordinal: U64,
        /// The child page.
        pub child: U64,
    }
}

/// Bytes of a branch entry.
pub const BRANCH_ENTRY_LEN: usize = size_of::<BranchEntry>();

const _: () = {
    assert!(size_of::<TreeRef>() == 24);
    assert!(BRANCH_ENTRY_LEN == 24);
};

/// What a table's tree holds: its page tag, record size and whether records carry their key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeSpec {
    /// Page tag.
    pub tag: [u8; 4],
    /// Record size.
    pub record_size: usize,
    /// Whether records carry their key in their first 8 bytes (else the ordinal is the key).
    pub keyed: bool,
    /// A name for messages (`node table`, `cluster index`).
    pub name: &'static str,
}

/// How many `record_size` records fit in a leaf of a `page_size` page.
pub fn leaf_capacity(page_size: u32, record_size: usize) -> usize {
    (page_size as usize - PAGE_HEADER_LEN) / record_size.max(1)
}

/// How many children fit in a branch page.
pub fn branch_capacity(page_size: u32) -> usize {
    (page_size as usize - PAGE_HEADER_LEN) / BRANCH_ENTRY_LEN
}

/// The reference of an empty tree of `record_size`-byte records.
pub fn empty(record_size: usize) -> TreeRef {
    TreeRef {
        record_size: U16::new(u16::try_from(record_size).unwrap_or(u16::MAX)),
        ..TreeRef::default()
    }
}

/// Pages a tree of `count` records of `record_size` bytes needs.
pub fn pages_needed(count: u64, record_size: usize, page_size: u32) -> u64 {
    if count == 0 {
        return 0;
    }
    let mut n = count.div_ceil(leaf_capacity(page_size, record_size) as u64);
    let mut total = n;
    let fan_out = branch_capacity(page_size) as u64;
    while n > 1 {
        n = n.div_ceil(fan_out);
        total += n;
    }
    total
}

/// The key of `record` at `ordinal`: its first 8 bytes when `keyed`, else the ordinal.
#[inline]
pub fn record_key(record: &[u8], ordinal: u64, keyed: bool) -> u64 {
    if keyed {
        record
            .get(..8)
            .and_then(|b| U64::read_from_bytes(b).ok())
            .map_or(0, |k| k.get())
    } else {
        ordinal
    }
}

/// Bulk-builds a tree of `records` (`spec.record_size` bytes each) into pages numbered from
/// `first_page` on, written by transaction `txn`, calling `emit` with each sealed page in page
/// order; returns its root.
/// Leaves are filled left to right, then each level of branches: the pages are consecutive
/// and the root is the last.
pub fn build<E>(
    records: &[u8],
    spec: TreeSpec,
    page_size: u32,
    first_page: u64,
    txn: u64,
    emit: &mut dyn FnMut(Vec<u8>) -> Result<(), E>,
) -> Result<TreeRef, E> {
    build_split(records, spec, page_size, [first_page, 0], txn, emit)
}

/// Leaf pages a tree of `records` records of `record_size` bytes takes.
pub fn leaf_pages(records: u64, page_size: u32, record_size: usize) -> u64 {
    records.div_ceil(leaf_capacity(page_size, record_size) as u64)
}

/// As [`build`], numbering the leaves from `first[0]` on and the branches from `first[1]`
/// on, each consecutively; `first[1] == 0` numbers the branches right after the leaves
/// (what [`build`] does). A writer that wants a tree's branches elsewhere than beside its
/// leaves (the fresh layout puts the node and block tables' branches in the file's last
/// pages, which a remote reader fetches at open) writes the pages `emit` is given at the
/// numbers their headers carry.
pub fn build_split<E>(
    records: &[u8],
    spec: TreeSpec,
    page_size: u32,
    first: [u64; 2],
    txn: u64,
    emit: &mut dyn FnMut(Vec<u8>) -> Result<(), E>,
) -> Result<TreeRef, E> {
    let size = spec.record_size;
    let count = (records.len() / size) as u64;
    if count == 0 {
        return Ok(empty(size));
    }
    let mut next_leaf = first[0];
    let mut next_branch = if first[1] == 0 {
        first[0] + leaf_pages(count, page_size, size)
    } else {
        first[1]
    };
    let mut page = |level: u16, count: usize, body: &[u8]| -> Result<u64, E> {
        let next = if level == 0 {
            &mut next_leaf
        } else {
            &mut next_branch
        };
        let no = *next;
        *next += 1;
        // A page holds fewer than 2^16 entries.
        let count = u32::try_from(count).unwrap_or(u32::MAX);
        let stamp = PageStamp { page_no: no, txn };
        emit(encode_page(page_size, spec.tag, stamp, level, count, body))?;
        Ok(no)
    };
    // Level 0: the leaves, each described by a branch entry for the level above.
    let per_leaf = leaf_capacity(page_size, size);
    let mut level: Vec<BranchEntry> = Vec::new();
    for (i, chunk) in records.chunks(per_leaf * size).enumerate() {
        let first_ordinal = (i * per_leaf) as u64;
        let no = page(0, chunk.len() / size, chunk)?;
        level.push(BranchEntry {
            first_key: U64::new(record_key(chunk, first_ordinal, spec.keyed)),
            first_ordinal: U64::new(first_ordinal),
            child: U64::new(no),
        });
    }
    let mut depth = 1u16;
    let fan_out = branch_capacity(page_size);
    while level.len() > 1 {
        let mut up = Vec::with_capacity(level.len().div_ceil(fan_out));
        for chunk in level.chunks(fan_out) {
            let no = page(depth, chunk.len(), chunk.as_bytes())?;
            up.push(BranchEntry {
                child: U64::new(no),
                ..chunk[0]
            });
        }
        level = up;
        depth += 1;
    }
    Ok(TreeRef {
        root_page: level[0].child,
        records: U64::new(count),
        depth: U16::new(depth),
        ..empty(size)
    })
}

/// Checks a tree reference against its spec before any page is read (I-7): record size,
/// reserved field, an empty tree all zero, depth within [`MAX_TREE_DEPTH`]. `Ok(false)` for
/// an empty tree.
pub fn check_tree_ref(tree: &TreeRef, spec: TreeSpec) -> Result<bool, Violation> {
    let bad = |detail: String| Violation::new(Invariant::TreeShape, spec.name, detail);
    let (depth, records, root) = (tree.depth.get(), tree.records.get(), tree.root_page.get());
    if usize::from(tree.record_size.get()) != spec.record_size {
        return Err(bad(format!(
            "record size {}, expected {}",
            tree.record_size.get(),
            spec.record_size
        )));
    }
    if tree.reserved.get() != 0 {
        return Err(bad("reserved field is not zero".into()));
    }
    if records == 0 || depth == 0 || root == 0 {
        return if records == 0 && depth == 0 && root == 0 {
            Ok(false)
        } else {
            Err(bad(format!(
                "root {root}, depth {depth}, {records} records: an empty tree has all three zero"
            )))
        };
    }
    if depth > MAX_TREE_DEPTH {
        return Err(bad(format!("depth {depth} exceeds {MAX_TREE_DEPTH}")));
    }
    Ok(true)
}

/// A tree page read without checks, for lookups in pages already checked: fields that lie
/// past the page read as zero, counts are clamped to the page's capacity.
#[derive(Clone, Copy, Debug)]
pub struct TreePage<'p> {
    bytes: &'p [u8],
    header: PageHeader,
}

impl<'p> TreePage<'p> {
    /// Views `bytes` (a whole page) as a tree page.
    #[inline]
    pub fn new(bytes: &'p [u8]) -> TreePage<'p> {
        TreePage {
            bytes,
            header: PageHeader::read(bytes).unwrap_or_else(PageHeader::new_zeroed),
        }
    }

    /// Checks page `page_no` as a page of `spec`'s tree at `level` (I-5, I-7): header (all but
    /// the txn tag, which the store checks), level, an entry count that fits, zero tail.
    pub fn checked(
        bytes: &'p [u8],
        page_no: u64,
        spec: TreeSpec,
        level: u16,
    ) -> Result<TreePage<'p>, Violation> {
        let at = format!("{} page {page_no}", spec.name);
        let bad = |detail: String| Violation::new(Invariant::TreeShape, at.clone(), detail);
        let header = check_page(bytes, page_no, spec.tag)?;
        if header.level.get() != level {
            return Err(bad(format!(
                "level {}, expected {level}",
                header.level.get()
            )));
        }
        let page_size = u32::try_from(bytes.len()).unwrap_or(u32::MAX);
        let (item, capacity) = if level == 0 {
            (spec.record_size, leaf_capacity(page_size, spec.record_size))
        } else {
            (BRANCH_ENTRY_LEN, branch_capacity(page_size))
        };
        let count = usize::try_from(header.count.get()).unwrap_or(usize::MAX);
        if count == 0 || count > capacity {
            return Err(bad(format!("{count} entries; 1..={capacity} fit")));
        }
        check_tail(bytes, PAGE_HEADER_LEN + count * item, &at)?;
        Ok(TreePage { bytes, header })
    }

    /// 0 for a leaf, else the height above the leaves.
    #[inline]
    pub fn level(&self) -> u16 {
        self.header.level.get()
    }

    /// Entries (records or branch entries) the header claims.
    #[inline]
    pub fn count(&self) -> usize {
        usize::try_from(self.header.count.get()).unwrap_or(usize::MAX)
    }

    /// Leaf records of `record_size` bytes that the header claims and the page holds.
    #[inline]
    pub fn records(&self, record_size: usize) -> usize {
        let capacity = (self.bytes.len().saturating_sub(PAGE_HEADER_LEN)) / record_size.max(1);
        self.count().min(capacity)
    }

    /// Branch entries that the header claims and the page holds.
    #[inline]
    pub fn branches(&self) -> usize {
        let capacity = (self.bytes.len().saturating_sub(PAGE_HEADER_LEN)) / BRANCH_ENTRY_LEN;
        self.count().min(capacity)
    }

    /// Branch entry `i` (zero past the page).
    #[inline]
    pub fn branch(&self, i: usize) -> BranchEntry {
        let at = PAGE_HEADER_LEN + i * BRANCH_ENTRY_LEN;
        self.bytes
            .get(at..at + BRANCH_ENTRY_LEN)
            .and_then(|b| BranchEntry::read_from_bytes(b).ok())
            .unwrap_or_else(BranchEntry::new_zeroed)
    }

    /// The bytes of leaf record `i`, if the page holds them.
    #[inline]
    pub fn record(&self, i: usize, record_size: usize) -> Option<&'p [u8]> {
        let at = PAGE_HEADER_LEN + i * record_size;
        self.bytes.get(at..at + record_size)
    }

    /// The leaf's records, back to back (the first [`TreePage::records`] of them).
    #[inline]
    pub fn body(&self, record_size: usize) -> &'p [u8] {
        let n = self.records(record_size);
        &self.bytes[PAGE_HEADER_LEN..PAGE_HEADER_LEN + n * record_size]
    }
}

/// Reads a record of type `R` from the first bytes of `bytes`.
#[inline]
pub fn read_record<R: FromBytes>(bytes: &[u8]) -> Option<R> {
    R::read_from_prefix(bytes).ok().map(|(r, _)| r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::page::tag;

    const SPEC: TreeSpec = TreeSpec {
        tag: tag::FREE_LIST,
        record_size: 16,
        keyed: true,
        name: "test tree",
    };

    #[test]
    fn built_pages_check_and_count_as_planned() {
        let records: Vec<u8> = (0..500u64)
            .flat_map(|k| [(k * 3).to_le_bytes(), k.to_le_bytes()].concat())
            .collect();
        let mut pages = Vec::new();
        let root = build::<()>(&records, SPEC, 1024, 10, 1, &mut |p| {
            pages.push(p);
            Ok(())
        })
        .unwrap();
        assert_eq!(pages.len() as u64, pages_needed(500, 16, 1024));
        assert_eq!(root.root_page.get(), 10 + pages.len() as u64 - 1);
        assert!(check_tree_ref(&root, SPEC).unwrap());
        let root_page = pages.last().unwrap();
        let page =
            TreePage::checked(root_page, root.root_page.get(), SPEC, root.depth.get() - 1).unwrap();
        assert_eq!(page.branch(0).first_key.get(), 0);
        assert_eq!(page.branch(1).first_ordinal.get(), 62);
        assert_eq!(page.branch(1).first_key.get(), 186);
    }

    #[test]
    fn an_empty_tree_names_its_record_size() {
        let e = empty(16);
        assert_eq!(e.as_bytes()[18..20], 16u16.to_le_bytes());
        assert!(!check_tree_ref(&e, SPEC).unwrap());
        assert!(check_tree_ref(&empty(80), SPEC).is_err());
    }
}
