//! Static B+-trees of fixed-size records: bulk-built by the writer, searched and scanned by
//! the reader, walked page by page by the validator.
//!
//! Every table of a container (nodes, blocks, each cluster's index and adjacency lists, the
//! free list) is one of these. Leaves hold records in order. A branch holds one
//! [`BranchEntry`] per child: the child's first key, the ordinal of its first record, and its
//! page. Keyed tables (cluster indexes) are searched by key. The others use the ordinal as the
//! key, so one descent serves "the node with index i" and "the cluster's codes a to b" alike.
//! There are no sibling pointers: a copy-on-write update rewrites a leaf and its path to the
//! root, and with sibling links it would have to rewrite every leaf before it as well. A scan
//! keeps its path on a small stack instead.

use std::borrow::Cow;

use zerocopy::byteorder::little_endian::{U16, U32, U64};
use zerocopy::{FromBytes, FromZeros, IntoBytes};

use super::source::Source;
use crate::error::{Error, Result};
use crate::format::{
    check_page, invariant, is_zero, seal_page, BranchEntry, PageHeader, TreeRef, MAX_TREE_DEPTH,
    PAGE_HEADER_LEN,
};

const BRANCH_ENTRY_LEN: usize = size_of::<BranchEntry>();

/// How many `record_size` records fit in a leaf of a `page_size` page.
pub fn leaf_capacity(page_size: u32, record_size: usize) -> usize {
    (page_size as usize - PAGE_HEADER_LEN) / record_size
}

/// How many children fit in a branch page.
pub fn branch_capacity(page_size: u32) -> usize {
    (page_size as usize - PAGE_HEADER_LEN) / BRANCH_ENTRY_LEN
}

/// A set of page numbers, one bit each, sized by the real file (never by a stored count).
#[derive(Clone, Debug)]
pub struct PageSet {
    bits: Vec<u64>,
    pages: u64,
}

impl PageSet {
    /// An empty set over pages `0..pages`.
    pub fn new(pages: u64) -> PageSet {
        PageSet {
            bits: vec![0; pages.div_ceil(64) as usize],
            pages,
        }
    }

    /// Adds `page`; false if it was already in (or lies outside the file).
    pub fn insert(&mut self, page: u64) -> bool {
        if page >= self.pages {
            return false;
        }
        let (w, b) = ((page / 64) as usize, page % 64);
        let had = self.bits[w] >> b & 1 == 1;
        self.bits[w] |= 1 << b;
        !had
    }

    /// Whether `page` is in.
    pub fn contains(&self, page: u64) -> bool {
        page < self.pages && self.bits[(page / 64) as usize] >> (page % 64) & 1 == 1
    }

    /// Pages in the set.
    pub fn len(&self) -> u64 {
        self.bits.iter().map(|w| u64::from(w.count_ones())).sum()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Page access for tree code: bounds-checked, and checked again on every read when the
/// source is not stable.
pub(crate) struct Pages<'a, S: Source + ?Sized> {
    pub src: &'a S,
    pub page_size: u32,
    pub page_count: u64,
    /// Check tag, number and CRC on every read.
    pub check: bool,
}

impl<'a, S: Source + ?Sized> Pages<'a, S> {
    /// Page `page`, which must be a `tag` page past the commit slots.
    pub fn get(&self, page: u64, tag: [u8; 4]) -> Result<Cow<'a, [u8]>> {
        if page < 2 || page >= self.page_count {
            return Err(Error::corrupt(
                invariant::TREE_SHAPE,
                format!("page {page}"),
                format!("a reference to page {page}, outside 2..{}", self.page_count),
            ));
        }
        let bytes = self
            .src
            .read_at(page * u64::from(self.page_size), self.page_size as usize)
            .map_err(|e| {
                Error::corrupt(
                    invariant::FILE_LENGTH,
                    format!("page {page}"),
                    e.to_string(),
                )
            })?;
        if self.check {
            check_page(&bytes, page, tag)?;
        }
        Ok(bytes)
    }
}

fn header(page: &[u8]) -> PageHeader {
    PageHeader::read(page).unwrap_or_else(PageHeader::new_zeroed)
}

fn branch_entry(page: &[u8], i: usize) -> BranchEntry {
    let at = PAGE_HEADER_LEN + i * BRANCH_ENTRY_LEN;
    page.get(at..at + BRANCH_ENTRY_LEN)
        .and_then(|b| BranchEntry::read_from_bytes(b).ok())
        .unwrap_or_else(BranchEntry::new_zeroed)
}

fn record_key(record: &[u8], ordinal: u64, keyed: bool) -> u64 {
    if keyed {
        record
            .get(..8)
            .and_then(|b| U64::read_from_bytes(b).ok())
            .map_or(0, |k| k.get())
    } else {
        ordinal
    }
}

/// Bulk-builds a tree of `records` (`record_size` bytes each) into pages numbered from
/// `*next_page` on, calling `emit` with each finished page in page order; returns its root.
/// Keys: the first 8 bytes of each record when `keyed`, else the ordinal.
pub fn build(
    records: &[u8],
    record_size: usize,
    keyed: bool,
    tag: [u8; 4],
    page_size: u32,
    next_page: &mut u64,
    emit: &mut dyn FnMut(Vec<u8>) -> Result<()>,
) -> Result<TreeRef> {
    let count = (records.len() / record_size) as u64;
    if count == 0 {
        return Ok(empty(record_size));
    }
    let page_bytes = page_size as usize;
    let mut page = |level: u16, count: usize, body: &[u8], next: &mut u64| -> Result<u64> {
        let no = *next;
        *next += 1;
        let mut bytes = vec![0u8; page_bytes];
        let h = PageHeader {
            tag,
            crc: U32::new(0),
            page_no: U64::new(no),
            level: U16::new(level),
            reserved: U16::new(0),
            count: U32::new(count as u32),
        };
        bytes[..PAGE_HEADER_LEN].copy_from_slice(h.as_bytes());
        bytes[PAGE_HEADER_LEN..PAGE_HEADER_LEN + body.len()].copy_from_slice(body);
        seal_page(&mut bytes);
        emit(bytes)?;
        Ok(no)
    };
    // Level 0: the leaves, each described by a branch entry for the level above.
    let per_leaf = leaf_capacity(page_size, record_size);
    let mut level: Vec<BranchEntry> = Vec::new();
    for (i, chunk) in records.chunks(per_leaf * record_size).enumerate() {
        let first_ordinal = (i * per_leaf) as u64;
        let no = page(0, chunk.len() / record_size, chunk, next_page)?;
        level.push(BranchEntry {
            first_key: U64::new(record_key(chunk, first_ordinal, keyed)),
            first_ordinal: U64::new(first_ordinal),
            child: U64::new(no),
        });
    }
    let mut depth = 1u16;
    let fan_out = branch_capacity(page_size);
    while level.len() > 1 {
        let mut up = Vec::with_capacity(level.len().div_ceil(fan_out));
        for chunk in level.chunks(fan_out) {
            let no = page(depth, chunk.len(), chunk.as_bytes(), next_page)?;
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
        record_size: U16::new(record_size as u16),
        reserved: U32::new(0),
    })
}

/// The reference of an empty tree of `record_size`-byte records.
pub fn empty(record_size: usize) -> TreeRef {
    TreeRef {
        record_size: U16::new(record_size as u16),
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

/// What a caller expects of a tree before walking it.
#[derive(Clone, Copy, Debug)]
pub struct TreeSpec {
    /// Page tag.
    pub tag: [u8; 4],
    /// Record size.
    pub record_size: usize,
    /// Whether records carry their key in their first 8 bytes (else the ordinal is the key).
    pub keyed: bool,
    /// A name for messages (`node table`, `cluster 3 index`).
    pub name: &'static str,
}

/// Walks every page of `tree`, checking each page (tag, number, CRC, level, counts, zero
/// tail) and the shape (I-7): branch entries agree with their children, keys strictly
/// increase, the record count matches. Each page is added to `seen` (a page seen twice
/// violates I-8, which also stops cycles). `on_leaf(first_ordinal, records)` sees the leaves
/// in order.
pub(crate) fn walk<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    tree: &TreeRef,
    spec: TreeSpec,
    seen: &mut PageSet,
    on_leaf: &mut dyn FnMut(u64, &[u8]) -> Result<()>,
) -> Result<()> {
    let bad = |detail: String| Error::corrupt(invariant::TREE_SHAPE, spec.name, detail);
    let (depth, records) = (tree.depth.get(), tree.records.get());
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
    if records == 0 || depth == 0 || tree.root_page.get() == 0 {
        return if records == 0 && depth == 0 && tree.root_page.get() == 0 {
            Ok(())
        } else {
            Err(bad(format!(
                "root {}, depth {depth}, {records} records: an empty tree has all three zero",
                tree.root_page.get()
            )))
        };
    }
    if depth > MAX_TREE_DEPTH {
        return Err(bad(format!("depth {depth} exceeds {MAX_TREE_DEPTH}")));
    }
    let mut state = WalkState {
        next_ordinal: 0,
        last_key: None,
    };
    walk_page(
        pages,
        spec,
        tree.root_page.get(),
        depth - 1,
        None,
        seen,
        &mut state,
        on_leaf,
    )?;
    if state.next_ordinal != records {
        return Err(bad(format!(
            "{} records in the leaves, the root says {records}",
            state.next_ordinal
        )));
    }
    Ok(())
}

struct WalkState {
    next_ordinal: u64,
    last_key: Option<u64>,
}

#[allow(clippy::too_many_arguments)]
fn walk_page<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    spec: TreeSpec,
    page_no: u64,
    level: u16,
    expected_first: Option<(u64, u64)>,
    seen: &mut PageSet,
    state: &mut WalkState,
    on_leaf: &mut dyn FnMut(u64, &[u8]) -> Result<()>,
) -> Result<()> {
    let at = format!("{} page {page_no}", spec.name);
    let bad = |detail: String| Error::corrupt(invariant::TREE_SHAPE, at.clone(), detail);
    if !seen.insert(page_no) {
        return Err(Error::corrupt(
            invariant::PAGE_OWNERSHIP,
            at.clone(),
            "page reached twice",
        ));
    }
    let page = pages.get(page_no, spec.tag)?;
    check_page(&page, page_no, spec.tag)?;
    let h = header(&page);
    if h.level.get() != level {
        return Err(bad(format!("level {}, expected {level}", h.level.get())));
    }
    if h.reserved.get() != 0 {
        return Err(bad("reserved field is not zero".into()));
    }
    let count = h.count.get() as usize;
    let (item, capacity) = if level == 0 {
        (
            spec.record_size,
            leaf_capacity(pages.page_size, spec.record_size),
        )
    } else {
        (BRANCH_ENTRY_LEN, branch_capacity(pages.page_size))
    };
    if count == 0 || count > capacity {
        return Err(bad(format!("{count} entries; 1..={capacity} fit")));
    }
    let end = PAGE_HEADER_LEN + count * item;
    if !is_zero(&page[end..]) {
        return Err(Error::corrupt(
            invariant::PAGE,
            at.clone(),
            "bytes after the last entry are not zero",
        ));
    }
    let first_ordinal = state.next_ordinal;
    if level == 0 {
        let body = &page[PAGE_HEADER_LEN..end];
        for (i, rec) in body.chunks_exact(spec.record_size).enumerate() {
            let key = record_key(rec, first_ordinal + i as u64, spec.keyed);
            if state.last_key.is_some_and(|last| key <= last) {
                return Err(bad(format!("key {key} at entry {i} does not increase")));
            }
            if i == 0 {
                if let Some((k, o)) = expected_first {
                    if (k, o) != (key, first_ordinal) {
                        return Err(bad(format!(
                            "first key/ordinal {key}/{first_ordinal}, the branch says {k}/{o}"
                        )));
                    }
                }
            }
            state.last_key = Some(key);
        }
        on_leaf(first_ordinal, body)?;
        state.next_ordinal += count as u64;
        return Ok(());
    }
    let entries: Vec<BranchEntry> = (0..count).map(|i| branch_entry(&page, i)).collect();
    if let Some((k, o)) = expected_first {
        let e = &entries[0];
        if (e.first_key.get(), e.first_ordinal.get()) != (k, o) {
            return Err(bad(format!(
                "first key/ordinal {}/{}, the parent says {k}/{o}",
                e.first_key.get(),
                e.first_ordinal.get()
            )));
        }
    }
    for e in &entries {
        let expected = (e.first_key.get(), e.first_ordinal.get());
        if expected.1 != state.next_ordinal {
            return Err(bad(format!(
                "child page {} starts at ordinal {}, but {} records precede it",
                e.child.get(),
                expected.1,
                state.next_ordinal
            )));
        }
        walk_page(
            pages,
            spec,
            e.child.get(),
            level - 1,
            Some(expected),
            seen,
            state,
            on_leaf,
        )?;
    }
    Ok(())
}

/// A position in a tree: the path from the root, each level's page and entry.
pub(crate) struct Cursor<'a> {
    path: Vec<(Cow<'a, [u8]>, usize)>,
    record_size: usize,
    remaining: u64,
    /// Pages read so far, the descent included.
    pub pages_read: u32,
}

/// How a descent picks a child: by key or by ordinal.
#[derive(Clone, Copy)]
pub(crate) enum Seek {
    /// The last record whose key is `<=` this (the first record if none is).
    Key(u64),
    /// The record with this ordinal.
    Ordinal(u64),
}

/// A cursor on the record `seek` picks in `tree`. For [`Seek::Ordinal`] beyond the end, the
/// cursor yields nothing.
pub(crate) fn seek<'a, S: Source + ?Sized>(
    pages: &Pages<'a, S>,
    tree: &TreeRef,
    spec: TreeSpec,
    seek: Seek,
) -> Result<Cursor<'a>> {
    let mut cursor = Cursor {
        path: Vec::with_capacity(usize::from(tree.depth.get())),
        record_size: spec.record_size,
        remaining: tree.records.get(),
        pages_read: 0,
    };
    if tree.records.get() == 0 {
        return Ok(cursor);
    }
    if let Seek::Ordinal(o) = seek {
        if o >= tree.records.get() {
            cursor.remaining = 0;
            return Ok(cursor);
        }
    }
    let mut page_no = tree.root_page.get();
    let mut base_ordinal = 0u64;
    for _ in 0..tree.depth.get().min(MAX_TREE_DEPTH) {
        let page = pages.get(page_no, spec.tag)?;
        cursor.pages_read += 1;
        let h = header(&page);
        let count = h.count.get() as usize;
        if h.level.get() == 0 {
            let capacity = leaf_capacity(pages.page_size, spec.record_size);
            let count = count.min(capacity);
            let rec = |i: usize| &page[PAGE_HEADER_LEN + i * spec.record_size..];
            let idx = match seek {
                Seek::Ordinal(o) => (o - base_ordinal.min(o)) as usize,
                Seek::Key(k) => {
                    let above = partition(count, |i| {
                        record_key(rec(i), base_ordinal + i as u64, spec.keyed) <= k
                    });
                    above.saturating_sub(1)
                }
            };
            cursor.remaining = tree.records.get().saturating_sub(base_ordinal + idx as u64);
            cursor.path.push((page, idx));
            return Ok(cursor);
        }
        let count = count.min(branch_capacity(pages.page_size)).max(1);
        let above = partition(count, |i| {
            let e = branch_entry(&page, i);
            match seek {
                Seek::Key(k) => e.first_key.get() <= k,
                Seek::Ordinal(o) => e.first_ordinal.get() <= o,
            }
        });
        let idx = above.saturating_sub(1);
        let e = branch_entry(&page, idx);
        page_no = e.child.get();
        base_ordinal = e.first_ordinal.get();
        cursor.path.push((page, idx));
    }
    Err(Error::corrupt(
        invariant::TREE_SHAPE,
        spec.name,
        "no leaf within the tree's depth",
    ))
}

/// The record with ordinal `ordinal` of `tree`, by one descent that keeps no path (`None`
/// beyond the end).
pub(crate) fn get_ordinal<S: Source + ?Sized, R: FromBytes>(
    pages: &Pages<'_, S>,
    tree: &TreeRef,
    spec: TreeSpec,
    ordinal: u64,
) -> Result<Option<R>> {
    if ordinal >= tree.records.get() {
        return Ok(None);
    }
    let mut page_no = tree.root_page.get();
    let mut base_ordinal = 0u64;
    for _ in 0..tree.depth.get().min(MAX_TREE_DEPTH) {
        let page = pages.get(page_no, spec.tag)?;
        let h = header(&page);
        let count = h.count.get() as usize;
        if h.level.get() == 0 {
            let idx = (ordinal - base_ordinal.min(ordinal)) as usize;
            if idx >= count.min(leaf_capacity(pages.page_size, spec.record_size)) {
                break;
            }
            let at = PAGE_HEADER_LEN + idx * spec.record_size;
            return page
                .get(at..at + size_of::<R>())
                .and_then(|b| R::read_from_bytes(b).ok())
                .map(Some)
                .ok_or_else(|| {
                    Error::corrupt(invariant::TREE_SHAPE, spec.name, "record past the page")
                });
        }
        let count = count.min(branch_capacity(pages.page_size)).max(1);
        let above = partition(count, |i| {
            branch_entry(&page, i).first_ordinal.get() <= ordinal
        });
        let e = branch_entry(&page, above.saturating_sub(1));
        page_no = e.child.get();
        base_ordinal = e.first_ordinal.get();
    }
    Err(Error::corrupt(
        invariant::TREE_SHAPE,
        spec.name,
        format!("record {ordinal} is not where the branch pages lead"),
    ))
}

/// The number of leading `i in 0..n` for which `pred` holds (`pred` must be monotone).
fn partition(n: usize, pred: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

impl<'a> Cursor<'a> {
    /// The record under the cursor, then advances. `None` at the end.
    pub fn next_record<S: Source + ?Sized, R: FromBytes>(
        &mut self,
        pages: &Pages<'a, S>,
        tag: [u8; 4],
    ) -> Result<Option<R>> {
        loop {
            if self.remaining == 0 {
                return Ok(None);
            }
            let Some((page, idx)) = self.path.last_mut() else {
                return Ok(None);
            };
            let count = header(page).count.get() as usize;
            if *idx < count {
                let at = PAGE_HEADER_LEN + *idx * self.record_size;
                let rec = page
                    .get(at..at + size_of::<R>())
                    .and_then(|b| R::read_from_bytes(b).ok())
                    .ok_or_else(|| {
                        Error::corrupt(invariant::TREE_SHAPE, "leaf", "record past the page")
                    })?;
                *idx += 1;
                self.remaining -= 1;
                return Ok(Some(rec));
            }
            // Leaf exhausted: climb to the first ancestor with a next child, then go down its
            // leftmost path.
            self.path.pop();
            let depth_below;
            loop {
                let Some((page, idx)) = self.path.last_mut() else {
                    return Ok(None);
                };
                *idx += 1;
                if *idx < header(page).count.get() as usize {
                    depth_below = header(page).level.get();
                    break;
                }
                self.path.pop();
            }
            let (page, idx) = self
                .path
                .last()
                .map(|(p, i)| (p.clone(), *i))
                .unwrap_or_default();
            let mut child = branch_entry(&page, idx).child.get();
            for _ in 0..depth_below {
                let p = pages.get(child, tag)?;
                self.pages_read += 1;
                let leaf = header(&p).level.get() == 0;
                if !leaf {
                    child = branch_entry(&p, 0).child.get();
                }
                self.path.push((p, 0));
                if leaf {
                    break;
                }
            }
        }
    }
}
