//! Following the B+-trees of a container through its pages: seeks and scans for the reader,
//! the full walk for opening and the validator.
//!
//! The page layout (headers, branch entries, records, how a tree is built) is
//! [`crate::format::tree`]'s, and reading a checked page is `pages`'s. This file only decides
//! which page to read next, and keeps a scan's path on a small stack, since the trees have no
//! sibling pointers.

use zerocopy::FromBytes;

use super::pages::{PageBytes, PageSet, Pages};
use super::source::Source;
use crate::error::Result;
use crate::format::tree::{read_record, record_key, TreePage};
use crate::format::{Invariant, TreeRef, TreeSpec, Violation, MAX_TREE_DEPTH};

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
    if !crate::format::tree::check_tree_ref(tree, spec).map_err(|v| pages.corrupt(v))? {
        return Ok(());
    }
    let mut state = WalkState {
        next_ordinal: 0,
        last_key: None,
    };
    walk_page(
        pages,
        spec,
        tree.root_page.get(),
        tree.depth.get() - 1,
        None,
        seen,
        &mut state,
        on_leaf,
    )?;
    let records = tree.records.get();
    if state.next_ordinal != records {
        return Err(pages.corrupt(Violation::new(
            Invariant::TreeShape,
            spec.name,
            format!(
                "{} records in the leaves, the root says {records}",
                state.next_ordinal
            ),
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
    let bad =
        |detail: String| pages.corrupt(Violation::new(Invariant::TreeShape, at.clone(), detail));
    if !seen.insert(page_no) {
        return Err(pages.corrupt(Violation::new(
            Invariant::PageOwnership,
            at.clone(),
            "page reached twice",
        )));
    }
    let bytes = pages.get(page_no, spec.tag)?;
    let page = TreePage::checked(&bytes, page_no, spec, level).map_err(|v| pages.corrupt(v))?;
    let first_ordinal = state.next_ordinal;
    if level == 0 {
        let body = page.body(spec.record_size);
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
        state.next_ordinal += page.count() as u64;
        return Ok(());
    }
    let entries: Vec<_> = (0..page.count()).map(|i| page.branch(i)).collect();
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

/// Checks that a page a descent reached is at the level the descent expects and holds at
/// least one entry. Pages are checked one by one as lookups reach them (not walked when the
/// store opens), so this is what keeps a damaged but checksummed branch from sending a
/// lookup sideways; the validator checks the whole shape (I-7).
#[inline]
fn check_level<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    spec: TreeSpec,
    page_no: u64,
    page: &TreePage<'_>,
    level: u16,
) -> Result<()> {
    if page.level() != level || page.count() == 0 {
        return Err(pages.corrupt(Violation::new(
            Invariant::TreeShape,
            format!("{} page {page_no}", spec.name),
            format!(
                "level {} with {} entries where a level-{level} page belongs",
                page.level(),
                page.count()
            ),
        )));
    }
    Ok(())
}

/// A position in a tree: the path from the root, each level's page and entry.
pub(crate) struct Cursor<'a> {
    path: Vec<(PageBytes<'a>, usize)>,
    spec: TreeSpec,
    remaining: u64,
    /// Pages read so far, the descent included.
    pub pages_read: u32,
    /// In a keyed tree, the cursor ends rather than go down to a child whose records all
    /// have keys above this ([`Cursor::stop_above`]).
    stop_above: Option<u64>,
}

/// How a descent picks a child: by key or by ordinal.
#[derive(Clone, Copy)]
pub(crate) enum Seek {
    /// The last record whose key is `<=` this (the first record if none is).
    Key(u64),
    /// The record with this ordinal.
    Ordinal(u64),
}

/// The number of leading `i in 0..n` for which `pred` holds (`pred` must be monotone).
#[inline]
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

/// The child a descent by `seek` takes from a branch page: `(entry index, child page, first
/// ordinal under it)`.
#[inline]
fn descend(page: &TreePage<'_>, seek: Seek) -> (usize, u64, u64) {
    let n = page.branches().max(1);
    let above = partition(n, |i| {
        let e = page.branch(i);
        match seek {
            Seek::Key(k) => e.first_key.get() <= k,
            Seek::Ordinal(o) => e.first_ordinal.get() <= o,
        }
    });
    let idx = above.saturating_sub(1);
    let e = page.branch(idx);
    (idx, e.child.get(), e.first_ordinal.get())
}

/// Records of a tree wanted by a [`prefetch`]: an inclusive span of keys or of ordinals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Span {
    /// The records a scan from key `.0` up to key `.1` reads ([`Seek::Key`] semantics: from
    /// the last record at or below `.0`).
    Keys(u64, u64),
    /// Records with ordinals `.0 ..= .1`.
    Ordinals(u64, u64),
}

impl Span {
    fn bounds(self) -> (u64, u64) {
        match self {
            Span::Keys(a, b) | Span::Ordinals(a, b) => (a, b),
        }
    }

    fn with_bounds(self, a: u64, b: u64) -> Span {
        match self {
            Span::Keys(..) => Span::Keys(a, b),
            Span::Ordinals(..) => Span::Ordinals(a, b),
        }
    }

    fn seek(self, at: u64) -> Seek {
        match self {
            Span::Keys(..) => Seek::Key(at),
            Span::Ordinals(..) => Seek::Ordinal(at),
        }
    }
}

/// Fetches ahead, level by level, the pages that lookups of `wants` (each a tree and the
/// spans of it wanted) will read: every tree's root in one [`Pages::prefetch`], then the
/// children of those pages that the spans reach, down to the leaves (which are fetched,
/// not read). So `k` trees of depth `d` cost `d` rounds on a remote source, not one per
/// page. The branch pages are read (and checked) on the way; nothing is returned, since
/// the lookups that follow read the pages as always, and a page this skipped is simply
/// read then. Spans over keys assume a keyed tree.
pub(crate) fn prefetch<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    wants: &[(TreeRef, TreeSpec, Vec<Span>)],
) -> Result<()> {
    // Pages at the current level: (page, its tree, the spans clipped to what it covers,
    // levels left below it).
    struct At {
        page: u64,
        spec: TreeSpec,
        spans: Vec<Span>,
        below: u16,
    }
    let mut level: Vec<At> = wants
        .iter()
        .filter(|(tree, _, spans)| tree.records.get() > 0 && !spans.is_empty())
        .map(|(tree, spec, spans)| At {
            page: tree.root_page.get(),
            spec: *spec,
            spans: spans.clone(),
            below: tree.depth.get().min(MAX_TREE_DEPTH).saturating_sub(1),
        })
        .collect();
    while !level.is_empty() {
        let mut numbers: Vec<u64> = level.iter().map(|a| a.page).collect();
        numbers.sort_unstable();
        numbers.dedup();
        pages.prefetch(&numbers)?;
        let mut next = Vec::new();
        for at in level.into_iter().filter(|a| a.below > 0) {
            let bytes = pages.get(at.page, at.spec.tag)?;
            let page = TreePage::new(&bytes);
            check_level(pages, at.spec, at.page, &page, at.below)?;
            let n = page.branches().max(1);
            // Each child with the spans that reach it, clipped to its own first entry and
            // the next child's.
            let mut children: Vec<(usize, Vec<Span>)> = Vec::new();
            for span in &at.spans {
                let (a, b) = span.bounds();
                let (first, _, _) = descend(&page, span.seek(a));
                let (last, _, _) = descend(&page, span.seek(b));
                for i in first..=last.min(n - 1) {
                    let e = page.branch(i);
                    let lo = match span {
                        Span::Keys(..) => e.first_key.get(),
                        Span::Ordinals(..) => e.first_ordinal.get(),
                    };
                    let clipped = span.with_bounds(a.max(lo).min(b), b);
                    match children.iter_mut().find(|(c, _)| *c == i) {
                        Some((_, spans)) => spans.push(clipped),
                        None => children.push((i, vec![clipped])),
                    }
                }
            }
            next.extend(children.into_iter().map(|(i, spans)| At {
                page: page.branch(i).child.get(),
                spec: at.spec,
                spans,
                below: at.below - 1,
            }));
        }
        level = next;
    }
    Ok(())
}

/// A cursor on the record `seek` picks in `tree`. For [`Seek::Ordinal`] beyond the end, the
/// cursor yields nothing.
pub(crate) fn seek<'a, S: Source + ?Sized>(
    pages: &Pages<'a, S>,
    tree: &TreeRef,
    spec: TreeSpec,
    seek: Seek,
) -> Result<Cursor<'a>> {
    let records = tree.records.get();
    let mut cursor = Cursor {
        path: Vec::with_capacity(usize::from(tree.depth.get())),
        spec,
        remaining: records,
        pages_read: 0,
        stop_above: None,
    };
    if records == 0 {
        return Ok(cursor);
    }
    if let Seek::Ordinal(o) = seek {
        if o >= records {
            cursor.remaining = 0;
            return Ok(cursor);
        }
    }
    let mut page_no = tree.root_page.get();
    let mut base_ordinal = 0u64;
    let depth = tree.depth.get().min(MAX_TREE_DEPTH);
    for step in 0..depth {
        let bytes = pages.get(page_no, spec.tag)?;
        cursor.pages_read += 1;
        let page = TreePage::new(&bytes);
        check_level(pages, spec, page_no, &page, depth - 1 - step)?;
        if page.level() == 0 {
            let idx = match seek {
                Seek::Ordinal(o) => o - base_ordinal.min(o),
                Seek::Key(k) => {
                    let count = page.records(spec.record_size);
                    let above = partition(count, |i| {
                        page.record(i, spec.record_size).is_some_and(|r| {
                            record_key(r, base_ordinal + i as u64, spec.keyed) <= k
                        })
                    });
                    above.saturating_sub(1) as u64
                }
            };
            cursor.remaining = records.saturating_sub(base_ordinal.saturating_add(idx));
            let idx = usize::try_from(idx).unwrap_or(usize::MAX);
            cursor.path.push((bytes, idx));
            return Ok(cursor);
        }
        let (idx, child, first) = descend(&page, seek);
        page_no = child;
        base_ordinal = first;
        cursor.path.push((bytes, idx));
    }
    Err(pages.corrupt(Violation::new(
        Invariant::TreeShape,
        spec.name,
        "no leaf within the tree's depth",
    )))
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
    let depth = tree.depth.get().min(MAX_TREE_DEPTH);
    for step in 0..depth {
        let bytes = pages.get(page_no, spec.tag)?;
        let page = TreePage::new(&bytes);
        check_level(pages, spec, page_no, &page, depth - 1 - step)?;
        if page.level() == 0 {
            let idx = usize::try_from(ordinal - base_ordinal.min(ordinal)).unwrap_or(usize::MAX);
            if idx >= page.records(spec.record_size) {
                break;
            }
            return page
                .record(idx, spec.record_size)
                .and_then(read_record)
                .map(Some)
                .ok_or_else(|| {
                    pages.corrupt(Violation::new(
                        Invariant::TreeShape,
                        spec.name,
                        "record past the page",
                    ))
                });
        }
        let (_, child, first) = descend(&page, Seek::Ordinal(ordinal));
        page_no = child;
        base_ordinal = first;
    }
    Err(pages.corrupt(Violation::new(
        Invariant::TreeShape,
        spec.name,
        format!("record {ordinal} is not where the branch pages lead"),
    )))
}

impl<'a> Cursor<'a> {
    /// Ends the cursor before it goes down to a child whose records all have keys above
    /// `key` (the child's branch entry says so), in a keyed tree: a range scan up to `key`
    /// then never reads the page after its last record only to find it past the range.
    pub fn stop_above(&mut self, key: u64) {
        if self.spec.keyed {
            self.stop_above = Some(key);
        }
    }

    /// The record under the cursor, then advances. `None` at the end.
    pub fn next_record<S: Source + ?Sized, R: FromBytes>(
        &mut self,
        pages: &Pages<'a, S>,
    ) -> Result<Option<R>> {
        let size = self.spec.record_size;
        loop {
            if self.remaining == 0 {
                return Ok(None);
            }
            let Some((bytes, idx)) = self.path.last_mut() else {
                return Ok(None);
            };
            let page = TreePage::new(bytes);
            if *idx < page.count() {
                let rec = page
                    .record(*idx, size)
                    .and_then(read_record)
                    .ok_or_else(|| {
                        pages.corrupt(Violation::new(
                            Invariant::TreeShape,
                            self.spec.name,
                            "record past the page",
                        ))
                    })?;
                *idx += 1;
                self.remaining -= 1;
                return Ok(Some(rec));
            }
            // Leaf exhausted: climb to the first ancestor with a next child, then go down its
            // leftmost path.
            self.path.pop();
            let (child, depth_below) = loop {
                let Some((bytes, idx)) = self.path.last_mut() else {
                    return Ok(None);
                };
                *idx += 1;
                let page = TreePage::new(bytes);
                if *idx < page.count() {
                    let e = page.branch(*idx);
                    if self.stop_above.is_some_and(|k| e.first_key.get() > k) {
                        self.remaining = 0;
                        return Ok(None);
                    }
                    break (e.child.get(), page.level());
                }
                self.path.pop();
            };
            let mut child = child;
            for step in 0..depth_below {
                let bytes = pages.get(child, self.spec.tag)?;
                self.pages_read += 1;
                let page = TreePage::new(&bytes);
                check_level(pages, self.spec, child, &page, depth_below - 1 - step)?;
                let leaf = page.level() == 0;
                if !leaf {
                    child = page.branch(0).child.get();
                }
                self.path.push((bytes, 0));
                if leaf {
                    break;
                }
            }
        }
    }
}
