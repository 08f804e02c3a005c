//! Page access for lookups and walks: each structured page read from the source, the
//! metadata bundle or the page cache, checked once (tag, number, CRC, txn tag: format §4)
//! and bound to the state the store reads; and [`PageSet`], the pages a walk has seen (I-8).
//! Which page to read next is `btree`'s question; this room answers "give me page `n`".

use std::borrow::Cow;
use std::sync::Arc;

use super::bundled::{PageError, PageRef};
use super::pagecache::PageCache;
use super::source::{self, Source};
use crate::error::{Error, Result};
use crate::format::bundle::{self, BUNDLE_FIRST_PAGE};
use crate::format::{page::check_page, Invariant, Violation};

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
    /// The CRC of the state's commit record (with the id, which state this is).
    pub record_crc: u32,
    /// The txn tag its structured pages carry.
    pub txn_tag: u16,
}

impl Binding {
    /// The state's identity, for triage.
    pub fn id(&self) -> super::slots::StateId {
        super::slots::StateId {
            txn: self.txn,
            record_crc: self.record_crc,
        }
    }
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
        // While the state is the latest, no commit after it wrote a page (format §4).
        if latest > self.state.txn && latest.saturating_add(1) >= pages_txn.saturating_add(0xffff)
        {
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
        super::slots::superseded_or_corrupt(self.src, self.state.id(), v)
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
        super::slots::superseded_or_corrupt(self.src, self.state.id(), v)
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
