//! Following the B+-trees of a container through its pages: seeks and scans for the reader,
//! the full walk for opening and the validator.
//!
//! The page layout (headers, branch entries, records, how a tree is built) is
//! [`crate::format::tree`]'s. This file only decides which page to read next, and keeps a
//! scan's path on a small stack, since the trees have no sibling pointers.

use std::borrow::Cow;
use std::sync::Arc;

use zerocopy::FromBytes;

use super::bundled::{PageError, PageRef};
use super::pagecache::PageCache;
use super::source::{self, Source};
use crate::error::{Error, Result};
use crate::format::bundle::{self, BUNDLE_FIRST_PAGE};
use crate::format::tree::{read_record, record_key, TreePage};
use crate::format::{page::check_page, Invariant, TreeRef, TreeSpec, Violation, MAX_TREE_DEPTH};

/// A set of page numbers, one bit each, sized by the real file (never by a stored count)
/// and, past it, by the state's metadata bundle (format §6.7): file pages `0..pages` and
/// bundle pages `BUNDLE_FIRST_PAGE..BUNDLE_FIRST_PAGE + bundle_pages`.
#[derive(Clone, Debug)]
pub struct PageSet {
    bits: Vec<u64>,
    pages: u64,
    bundle_pages: u64,
}

impl PageSet {
    /// An empty set over file pages `0..pages` (no bundle pages).
    pub fn new(pages: u64) -> PageSet {
        PageSet::with_bundle(pages, 0)
    }

    /// An empty set over file pages `0..pages` and `bundle_pages` bundle pages.
    pub fn with_bundle(pages: u64, bundle_pages: u64) -> PageSet {
        let total = pages.saturating_add(bundle_pages);
        PageSet {
            bits: vec![0; usize::try_from(total.div_ceil(64)).unwrap_or(0)],
            pages,
            bundle_pages,
        }
    }

    /// The bit of `page`, if the set covers it.
    fn bit(&self, page: u64) -> Option<(usize, u64)> {
        let i = if page < self.pages {
            page
        } else {
            let b = page.checked_sub(BUNDLE_FIRST_PAGE)?;
            if b >= self.bundle_pages {
                return None;
            }
            self.pages + b
        };
        // `i` is below the bit count, whose word count fit a usize when the set was made.
        Some((usize::try_from(i / 64).ok()?, i % 64))
    }

    /// Adds `page`; false if it was already in (or lies outside the file and the bundle).
    pub fn insert(&mut self, page: u64) -> bool {
        let Some((w, b)) = self.bit(page) else {
            return false;
        };
        let had = self.bits[w] >> b & 1 == 1;
        self.bits[w] |= 1 << b;
        !had
    }

    /// Whether `page` is in.
    pub fn contains(&self, page: u64) -> bool {
        self.bit(page)
            .is_some_and(|(w, b)| self.bits[w] >> b & 1 == 1)
    }

    /// File pages in the set (bundle pages left out).
    pub fn file_pages(&self) -> u64 {
        (0..self.pages).filter(|&p| self.contains(p)).count() as u64
    }
}

/// Page access for tree code: bounds-checked, and checked (tag, number, CRC, txn tag) on the
/// first read through a cache, or on every read when `check`.
pub(crate) struct Pages<'a, S: Source + ?Sized> {
    pub src: &'a S,
    pub page_size: u32,
    pub page_count: u64,
    /// Check every read, whatever the cache says (the walk of a validator or a writer).
    pub check: bool,
    /// The state read: its txn id, and the txn tag each of its pages carries (format §4).
    pub state: Binding,
    /// The store's cache: pages checked once are served from it (see [`PageCache`]).
    pub cache: Option<&'a PageCache>,
    /// For a reader that did not register, on a source whose pages a writer may reuse: the
    /// state's `pages_txn`. Each page read first is then checked to be within 2^16
    /// transactions of it, so its 16-bit txn tag cannot have been reused (format §4).
    pub wrap_guard: Option<u64>,
    /// The state's metadata bundle (format §6.7): pages from `BUNDLE_FIRST_PAGE` on are
    /// served from it, each checked when it was opened (4.x) or first read (5.0).
    pub bundle: Option<&'a super::bundled::Bundle>,
}

/// The bytes of a page: lent by the source, or a checked copy the cache shares.
#[derive(Clone, Debug)]
pub(crate) enum PageBytes<'a> {
    /// Borrowed from the source (a mapping, memory) or read into a buffer for this call.
    Source(Cow<'a, [u8]>),
    /// A cached copy.
    Shared(Arc<[u8]>),
}

impl std::ops::Deref for PageBytes<'_> {
    type Target = [u8];

    #[inline]
    fn deref(&self) -> &[u8] {
        match self {
            PageBytes::Source(c) => c,
            PageBytes::Shared(a) => a,
        }
    }
}

/// What binds a page to the state a reader holds.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Binding {
    /// The txn id of the state.
    pub txn: u64,
    /// The txn tag its structured pages carry.
    pub txn_tag: u16,
}

impl<'a, S: Source + ?Sized> Pages<'a, S> {
    /// The corruption error of this source.
    pub fn corrupt(&self, v: Violation) -> Error {
        v.in_file(self.src.name())
    }

    /// Page `page`, which must be a `tag` page past the commit slots.
    #[inline]
    pub fn get(&self, page: u64, tag: [u8; 4]) -> Result<PageBytes<'a>> {
        if bundle::is_bundle_page(page) {
            // Checked (number, CRC, txn tag) when the bundle was opened or the page first
            // read; the kind a reference expects is checked on every read.
            let Some(b) = self.bundle else {
                return Err(self.outside(page));
            };
            let counted = |n: usize| {
                if let Some(c) = self.cache {
                    c.counters.metadata(n);
                }
            };
            return match b.page(self.src, page, self.page_size, &counted) {
                Ok(PageRef::Borrowed(bytes)) => {
                    self.tagged(page, tag, PageBytes::Source(Cow::Borrowed(bytes)))
                }
                Ok(PageRef::Shared(bytes)) => self.tagged(page, tag, PageBytes::Shared(bytes)),
                Err(PageError::Outside) => Err(self.outside(page)),
                Err(PageError::Read(e)) => Err(e),
                Err(PageError::Bad(v)) => Err(self.reused_or_corrupt(v)),
            };
        }
        if page < 2 || page >= self.page_count {
            return Err(self.outside(page));
        }
        let offset = page * u64::from(self.page_size);
        let cache = self.cache.filter(|_| !self.check);
        if let Some(c) = cache {
            // A page checked once is not checked again, but the kind a reference expects
            // is: a damaged reference to a page of another table must not read as this one.
            if self.src.stable() {
                if c.is_checked(page) {
                    return match self.src.read_at(offset, self.page_size as usize) {
                        Ok(bytes) => self.tagged(page, tag, PageBytes::Source(bytes)),
                        Err(e) => Err(self.read_failed(offset, e)),
                    };
                }
            } else if let Some(bytes) = c.get(page) {
                return self.tagged(page, tag, PageBytes::Shared(bytes));
            }
        }
        let bytes = match self.src.read_at(offset, self.page_size as usize) {
            Ok(bytes) => bytes,
            Err(e) => return Err(self.read_failed(offset, e)),
        };
        if let Some(c) = self.cache {
            c.counters.metadata(bytes.len());
        }
        // A page that fails its own checks may be one a later state reused for something
        // else (a reader that did not register): the slots tell.
        let h = check_page(&bytes, page, tag).map_err(|v| self.reused_or_corrupt(v))?;
        if h.txn_tag.get() != self.state.txn_tag {
            return Err(self.unbound(page, h.txn_tag.get()));
        }
        if let Some(pages_txn) = self.wrap_guard {
            self.check_wrap(pages_txn)?;
        }
        match cache {
            Some(c) if self.src.stable() => {
                c.mark_checked(page);
                Ok(PageBytes::Source(bytes))
            }
            Some(c) => {
                let shared: Arc<[u8]> = Arc::from(bytes.into_owned());
                c.insert(page, Arc::clone(&shared));
                Ok(PageBytes::Shared(shared))
            }
            None => Ok(PageBytes::Source(bytes)),
        }
    }

    /// Asks the source to fetch `pages` ahead of reading them ([`Source::prefetch`]):
    /// pages of the metadata bundle and pages outside the file are left out (they are
    /// already in memory, or a read reports them).
    pub fn prefetch(&self, pages: &[u64]) -> Result<()> {
        let size = u64::from(self.page_size);
        let ranges: Vec<(u64, usize)> = pages
            .iter()
            .filter(|&&p| p >= 2 && p < self.page_count && !bundle::is_bundle_page(p))
            .map(|&p| (p * size, self.page_size as usize))
            .collect();
        if ranges.is_empty() {
            return Ok(());
        }
        self.src
            .prefetch(&ranges)
            .map_err(|e| source::read_error(self.src.name(), ranges[0].0, ranges[0].1, e))
    }

    /// `bytes` (page `page`, checked when first read) if it is a `tag` page.
    #[inline]
    fn tagged(&self, page: u64, tag: [u8; 4], bytes: PageBytes<'a>) -> Result<PageBytes<'a>> {
        if bytes.get(..4) == Some(&tag[..]) {
            return Ok(bytes);
        }
        Err(self.wrong_kind(page, tag, &bytes))
    }

    #[cold]
    #[inline(never)]
    fn wrong_kind(&self, page: u64, tag: [u8; 4], bytes: &[u8]) -> Error {
        let found = bytes.get(..4).unwrap_or(&[]);
        self.corrupt(Violation::new(
            Invariant::Page,
            format!("page {page}"),
            format!(
                "tag {:?} where a reference expects {:?}",
                String::from_utf8_lossy(found),
                String::from_utf8_lossy(&tag)
            ),
        ))
    }

    /// Fails when 2^16 - 1 or more transactions committed since the state's pages were
    /// written: a page read now could carry a reused tag.
    #[cold]
    fn check_wrap(&self, pages_txn: u64) -> Result<()> {
        let latest = super::slots::latest_txn(self.src)?.unwrap_or(0);
        if latest.saturating_add(1) >= pages_txn.saturating_add(0xffff) {
            return Err(Error::Superseded {
                path: self.src.name().to_path_buf(),
                txn: self.state.txn,
                latest,
                detail: "2^16 transactions committed since its pages were written".into(),
            });
        }
        Ok(())
    }

    #[cold]
    #[inline(never)]
    fn reused_or_corrupt(&self, v: Violation) -> Error {
        super::slots::superseded_or_corrupt(self.src, self.state.txn, v)
    }

    /// A valid page with another transaction's tag: a later state reused it, or (if the state
    /// is still the latest) a stale or misplaced page.
    #[cold]
    #[inline(never)]
    fn unbound(&self, page: u64, found: u16) -> Error {
        let v = Violation::new(
            Invariant::Page,
            format!("page {page}"),
            format!(
                "carries txn tag {found:#06x}; the state's pages carry {:#06x}",
                self.state.txn_tag
            ),
        );
        super::slots::superseded_or_corrupt(self.src, self.state.txn, v)
    }

    // The error paths stay out of line: `get` runs for every page of every lookup.
    #[cold]
    #[inline(never)]
    fn outside(&self, page: u64) -> Error {
        self.corrupt(Violation::new(
            Invariant::TreeShape,
            format!("page {page}"),
            format!(
                "a reference to page {page}, outside 2..{} and the metadata bundle",
                self.page_count
            ),
        ))
    }

    #[cold]
    #[inline(never)]
    fn read_failed(&self, offset: u64, e: std::io::Error) -> Error {
        source::read_error(self.src.name(), offset, self.page_size as usize, e)
    }
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
