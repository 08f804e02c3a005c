//! The page cache of an open store: each metadata page is read and checked once, then served
//! from memory, and the store counts what it reads.
//!
//! **Why.** Opening checks only the commit slots, the dataset header and the cluster
//! directory (a few pages); index, node and block pages are checked when a lookup first
//! reaches them (format §4: tag, number, CRC, txn tag). A scene reaches the same index and
//! node pages again and again, and a page read over a network costs a round trip: the cache
//! keeps each checked page so that it is read once.
//!
//! **Two kinds of source.** A *stable* source (a mapping, memory) lends its bytes; the cache
//! keeps one bit per page saying "checked", and a checked page is lent again without a
//! second check, zero-copy. An *unstable* source (`pread`, a remote object) hands out copies;
//! the cache keeps the checked copies, up to a bound, in two generations: lookups hit the
//! young one or promote from the old one, and when the young one is full it becomes the old
//! one (the old one is dropped). That is an LRU approximation with O(1) work and no list.
//! A page a writer reuses later cannot change a cached copy: the copy is this state's page.
//!
//! **Counting.** Every read that reaches the source is counted as metadata (pages) or
//! payload (blocks and grids): calls and bytes ([`ReadStats`]).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use serde::Serialize;

/// The default bound of an unstable source's cache: 2,048 pages (8 MiB of 4 KiB pages).
pub const DEFAULT_CACHED_PAGES: usize = 2048;

/// What a store has read from its source since it was opened (or since a snapshot).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ReadStats {
    /// Reads of metadata pages (commit slots, header, directory, table pages) that reached
    /// the source: cache hits do not count.
    pub metadata_reads: u64,
    /// Bytes of those reads.
    pub metadata_bytes: u64,
    /// Payload reads (blocks and grids) that reached the source.
    pub payload_reads: u64,
    /// Bytes of those reads.
    pub payload_bytes: u64,
}

impl ReadStats {
    /// Reads of both kinds.
    pub fn reads(&self) -> u64 {
        self.metadata_reads + self.payload_reads
    }

    /// Bytes of both kinds.
    pub fn bytes(&self) -> u64 {
        self.metadata_bytes + self.payload_bytes
    }

    /// Both together.
    pub fn plus(&self, other: &ReadStats) -> ReadStats {
        ReadStats {
            metadata_reads: self.metadata_reads + other.metadata_reads,
            metadata_bytes: self.metadata_bytes + other.metadata_bytes,
            payload_reads: self.payload_reads + other.payload_reads,
            payload_bytes: self.payload_bytes + other.payload_bytes,
        }
    }

    /// What was read between `earlier` and `self`.
    pub fn since(&self, earlier: &ReadStats) -> ReadStats {
        ReadStats {
            metadata_reads: self.metadata_reads.saturating_sub(earlier.metadata_reads),
            metadata_bytes: self.metadata_bytes.saturating_sub(earlier.metadata_bytes),
            payload_reads: self.payload_reads.saturating_sub(earlier.payload_reads),
            payload_bytes: self.payload_bytes.saturating_sub(earlier.payload_bytes),
        }
    }
}

/// Counters behind [`ReadStats`].
#[derive(Debug, Default)]
pub(crate) struct Counters {
    metadata_reads: AtomicU64,
    metadata_bytes: AtomicU64,
    payload_reads: AtomicU64,
    payload_bytes: AtomicU64,
}

impl Counters {
    pub fn metadata(&self, bytes: usize) {
        self.metadata_reads.fetch_add(1, Ordering::Relaxed);
        self.metadata_bytes
            .fetch_add(bytes as u64, Ordering::Relaxed);
    }

    pub fn payload(&self, bytes: usize) {
        self.payload_reads.fetch_add(1, Ordering::Relaxed);
        self.payload_bytes
            .fetch_add(bytes as u64, Ordering::Relaxed);
    }

    pub fn snapshot(&self) -> ReadStats {
        ReadStats {
            metadata_reads: self.metadata_reads.load(Ordering::Relaxed),
            metadata_bytes: self.metadata_bytes.load(Ordering::Relaxed),
            payload_reads: self.payload_reads.load(Ordering::Relaxed),
            payload_bytes: self.payload_bytes.load(Ordering::Relaxed),
        }
    }
}

#[derive(Debug, Default)]
struct Generations {
    young: HashMap<u64, Arc<[u8]>>,
    old: HashMap<u64, Arc<[u8]>>,
}

/// Checked pages of one store (see the module docs).
#[derive(Debug)]
pub(crate) struct PageCache {
    /// Stable sources: a bit per page, set once the page passed its checks.
    checked: Vec<AtomicU64>,
    /// Unstable sources: checked copies.
    copies: Option<Mutex<Generations>>,
    /// Pages a generation holds.
    generation: usize,
    pub counters: Counters,
}

impl PageCache {
    /// A cache over `pages` pages of a source that is `stable` or not, keeping at most about
    /// `capacity` copies (unstable sources only).
    pub fn new(pages: u64, stable: bool, capacity: usize) -> PageCache {
        let words = if stable {
            usize::try_from(pages.div_ceil(64)).unwrap_or(0)
        } else {
            0
        };
        PageCache {
            checked: (0..words).map(|_| AtomicU64::new(0)).collect(),
            copies: (!stable).then(|| Mutex::new(Generations::default())),
            generation: (capacity / 2).max(1),
            counters: Counters::default(),
        }
    }

    fn word(&self, page: u64) -> Option<(&AtomicU64, u64)> {
        let w = usize::try_from(page / 64).ok()?;
        Some((self.checked.get(w)?, 1 << (page % 64)))
    }

    /// Stable sources: whether `page` was checked.
    #[inline]
    pub fn is_checked(&self, page: u64) -> bool {
        self.word(page)
            .is_some_and(|(w, bit)| w.load(Ordering::Acquire) & bit != 0)
    }

    /// Stable sources: notes that `page` passed its checks.
    #[inline]
    pub fn mark_checked(&self, page: u64) {
        if let Some((w, bit)) = self.word(page) {
            w.fetch_or(bit, Ordering::AcqRel);
        }
    }

    /// Unstable sources: the checked copy of `page`, if kept.
    pub fn get(&self, page: u64) -> Option<Arc<[u8]>> {
        let mut g = self.copies.as_ref()?.lock().ok()?;
        if let Some(p) = g.young.get(&page) {
            return Some(Arc::clone(p));
        }
        let p = g.old.remove(&page)?;
        self.insert_locked(&mut g, page, Arc::clone(&p));
        Some(p)
    }

    /// Unstable sources: keeps the checked copy of `page`.
    pub fn insert(&self, page: u64, bytes: Arc<[u8]>) {
        if let Some(mut g) = self.copies.as_ref().and_then(|m| m.lock().ok()) {
            self.insert_locked(&mut g, page, bytes);
        }
    }

    fn insert_locked(&self, g: &mut Generations, page: u64, bytes: Arc<[u8]>) {
        if g.young.len() >= self.generation {
            g.old = std::mem::take(&mut g.young);
        }
        g.young.insert(page, bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stable_bits_and_bounded_copies() {
        let c = PageCache::new(200, true, 4);
        assert!(!c.is_checked(130));
        c.mark_checked(130);
        assert!(c.is_checked(130) && !c.is_checked(131) && !c.is_checked(10_000));

        let c = PageCache::new(200, false, 4);
        for p in 0..10u64 {
            c.insert(p, Arc::from(vec![u8::try_from(p).unwrap(); 8]));
        }
        // Two generations of two pages: the last four inserted are kept at most.
        let kept: Vec<u64> = (0..10).filter(|&p| c.get(p).is_some()).collect();
        assert!(kept.len() <= 4 && kept.contains(&9), "{kept:?}");
        assert_eq!(c.get(9).unwrap()[0], 9);
    }

    proptest::proptest! {
        /// Under any sequence of inserts and lookups, a lookup returns nothing or exactly the
        /// bytes last inserted for that page (never another page's), the most recent insert
        /// is always kept, and no more than two generations of copies are held.
        #[test]
        fn copies_are_never_mixed_up(
            ops in proptest::collection::vec((0u64..40, proptest::bool::ANY), 1..400),
            capacity in 1usize..16,
        ) {
            let c = PageCache::new(40, false, capacity);
            let mut model = std::collections::HashMap::new();
            let mut version = 0u8;
            for (page, insert) in ops {
                let p8 = u8::try_from(page).unwrap();
                if insert {
                    version = version.wrapping_add(1);
                    c.insert(page, Arc::from(vec![p8, version]));
                    model.insert(page, version);
                    proptest::prop_assert_eq!(&*c.get(page).unwrap(), &[p8, version][..]);
                } else if let Some(bytes) = c.get(page) {
                    proptest::prop_assert_eq!(&*bytes, &[p8, model[&page]][..]);
                }
                let held = {
                    let g = c.copies.as_ref().unwrap().lock().unwrap();
                    g.young.len() + g.old.len()
                };
                proptest::prop_assert!(held <= 2 * (capacity / 2).max(1) + 1);
            }
        }
    }
}
