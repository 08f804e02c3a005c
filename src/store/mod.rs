//! The store: a container opened for reading, with range scans over its clusters, and the
//! writers that make and change containers.
//!
//! # Opening, and what it costs
//!
//! Opening reads the commit slots and takes the state of the newer valid record. If the state
//! keeps its metadata in a bundle (format 3.0, [`crate::format::bundle`]), opening reads it
//! in one read (12 KiB on Puget Sound 1k), checks every page of it once, and every later
//! lookup is served from memory. Otherwise it reads the dataset header and the cluster
//! directory: a few pages (9 KiB on a real DEM with 4 KiB pages, [`Store::open_reads`]). It
//! does not walk the tables. Each index, node, block or
//! adjacency page is read and checked (tag, page number, CRC, txn tag; the level a descent
//! expects) the first time a lookup reaches it, and then kept by the store's page cache
//! ([`pagecache`]): a mapping or memory is lent again unchecked, a file read with `pread`
//! keeps the checked copy (up to 2,048 pages). So a scene reads each of its pages once, and
//! a second scene over the same region reads none. Payloads (blocks and grids) are checked
//! against their CRC on every read, whatever the source; [`Store::payloads`] reads many at
//! once, coalescing neighbours. [`Store::read_stats`] counts what lookups and payload reads
//! took from the source.
//!
//! A damaged table page is reported by the first lookup that reaches it. The validator
//! ([`verify()`]) and writers ([`Container`]) walk every table page when they open, since they
//! must know every page the state owns.
//!
//! # The API contract, LMDB style
//!
//! * [`Store::open`] reads with positioned reads and *registers* the state it reads (format
//!   §11.6: a shared lock the kernel keeps, on Linux), so that no [`Container`] in any process
//!   reuses a page of it while the store lives: it reads exactly its state while writers
//!   commit. Where it cannot register ([`Store::is_registered`] is false), it is still safe:
//!   a page a later state reused fails its binding (format §4) and the read returns
//!   [`crate::error::Error::Superseded`] (open again), never another state's bytes.
//! * [`Store::open_mapped`] maps the file and registers like [`Store::open`]. It is `unsafe`
//!   because a mapping turns someone else's writes into undefined behaviour: fmrh's writers
//!   leave a registered state's pages alone, but a tool that ignores the registration, or a
//!   writer on a system without it, may change or cut them (a cut raises `SIGBUS`).
//! * [`Store::from_bytes`] reads a container in memory (tests, fuzzing, network buffers).
//! * [`Container::read`] hands out snapshots of a file a writer has open: the safe way to read
//!   while transactions commit.
//!
//! All of them give the same API, because everything above the [`Source`] works on `&[u8]`.
//! Errors name the file: [`crate::error::Error::Corrupt`] for a broken invariant, `Io` when the
//! operating system fails a read, [`crate::error::Error::Superseded`] when an unregistered reader's
//! state was reused by a later commit.
//!
//! # Rooms
//!
//! `open` (slot choice, and the walk for writers), `slots` (the commit slots as the source
//! holds them now, and the superseded-or-corrupt triage), `pagecache` (checked pages kept,
//! reads counted), `pages` (a checked page, from the file, the bundle or the cache), `btree`
//! (following tree pages), `read` (records, payload reads, scans),
//! `decode` (payloads decoded with the ancestors they are coded against), `window`
//! (assembling samples from blocks), `verify` (the validator), `write` (fresh files), `txn`
//! (transactions), and where bytes come from: `io`, `source`, `any` (a file or a URL),
//! `remote` (HTTP and S3).

// Values read from a file are converted with checks, never truncated by `as`.
#![warn(clippy::cast_possible_truncation)]

mod ahead;
mod any;
pub(crate) mod btree;
mod bundled;
mod decode;
mod ancestors;
mod nodememo;
pub mod io;
pub mod lock;
pub(crate) mod open;
pub mod pagecache;
pub(crate) mod pages;
mod read;
#[cfg(feature = "remote")]
pub mod remote;
pub(crate) mod slots;
pub mod source;
pub mod txn;
pub mod verify;
mod window;
pub(crate) mod workers;
pub mod write;

use std::fs::File;
use std::path::Path;

use serde::Serialize;

pub use crate::format::payload::ParentGrid;
pub use crate::format::ClusterInfo;
#[cfg(any(test, feature = "testing"))]
pub use crate::format::{FreePage, PayloadRef, ScanEntry, StoredBlock, StoredNode};
pub use ahead::Ahead;
pub use any::{is_url, AnySource};
pub use decode::{Block, Grid, HeldGrid, LoadedBlock, Wanted};
pub use ancestors::ANCESTOR_CACHE_BYTES;
pub use pagecache::ReadStats;
pub use read::{Children, CodeScan, HilbertScan, Layout};
pub use source::{Bytes, Counted, FileSource, MmapSource, RequestStats, Source};
pub use txn::{
    compact, CommitSummary, CompactOptions, Compacted, Container, Recovery, Snapshot, WriteTxn,
};
pub use verify::{
    verify, verify_pinned, verify_with_progress, CheckReport, CheckStatus, VerifyMode, VerifyReport,
};
pub use write::{write_atomically, write_file, Progress, WriteOptions, WriteSummary};
#[cfg(any(test, feature = "testing"))]
pub use write::{write_to, SectionBytes};

use crate::error::Result;
use crate::format::{CommitRecord, DatasetHeader, COMMIT_PAYLOAD_SLACK, COMMIT_RECOVERY_NEEDED};
use crate::model::Domain;

/// An open container (see the module docs for the contract of each constructor).
#[derive(Debug)]
pub struct Store<S: Source = FileSource> {
    src: S,
    /// The state's metadata bundle (format §6.7).
    bundle: Option<std::sync::Arc<bundled::Bundle>>,
    page_size: u32,
    page_count: u64,
    slot: u8,
    commit: CommitRecord,
    header: DatasetHeader,
    clusters: Vec<ClusterInfo>,
    /// Every metadata page of the state, once walked (at open for writers and the
    /// validator, on demand otherwise).
    metadata_pages: std::sync::OnceLock<pages::PageSet>,
    registered: bool,
    /// Checked pages, and what the store read.
    cache: pagecache::PageCache,
    /// See [`pages::Pages::wrap_guard`].
    wrap_guard: Option<u64>,
    /// What opening read.
    open_reads: ReadStats,
    /// Decoded grids that payloads are coded against (format 4, 5), up to a budget in bytes
    /// ([`Store::parent_grid`], `ancestors`).
    ancestors: std::sync::Mutex<ancestors::AncestorCache>,
    /// Nodes read, by index ([`Store::node`], `nodememo`).
    nodes: nodememo::NodeMemo,
    /// The top of the tree (format 6.2), read at open when the state has one: the
    /// coarsest levels' nodes, which [`Store::node`] then never looks up in the table.
    top: Option<std::sync::Arc<crate::format::top::Top>>,
}

/// The state a store reads, as its commit record describes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct StateInfo {
    /// The format version of its writer: major, minor.
    pub format_version: (u16, u16),
    /// Its transaction id.
    pub txn_id: u64,
    /// Which commit slot (0 or 1) holds its record.
    pub commit_slot: u8,
    /// Bytes per page.
    pub page_size: u32,
    /// Bytes of the file in this state.
    pub file_length: u64,
    /// A writer had the file open when it was committed and has not closed it cleanly since
    /// (format §3, §11.4).
    pub recovery_needed: bool,
    /// Transactions have replaced payloads, so payload pages may hold dead bytes (format §7).
    pub payload_slack: bool,
}

impl Store<FileSource> {
    /// Opens the container at `path` for positioned reads: safe whatever other processes do to
    /// the file (see the module docs).
    ///
    /// ```
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("hill.fmrh");
    /// # let hill = fmrh::Heightfield::from_fn(100, 80, |x, y| (x * y) as f32 * 0.1)?;
    /// # fmrh::create(&path, hill, &fmrh::CreateOptions::default())?;
    /// let store = fmrh::raw::Store::open(&path)?;
    /// assert_eq!(store.domain().width(), 100);
    /// let root = store.node(0)?;
    /// assert_eq!(root.level, 0);
    /// println!("{} clusters, the coarsest within {} m", store.clusters().len(), root.monotone_error);
    /// # Ok(()) }
    /// ```
    pub fn open(path: &Path) -> Result<Self> {
        Store::from_source(FileSource::open(path)?)
    }

    /// Opens the container at `path` at the state `pin` names, which need not be its latest:
    /// a dataset's tile (`format-spec/dataset.md` §4). Fails with a `D-4` corruption error
    /// when neither commit slot publishes that state.
    pub fn open_pinned(path: &Path, pin: crate::format::manifest::StatePin) -> Result<Self> {
        open::open_at(FileSource::open(path)?, open::Walk::Lean, Some(pin))
    }
}

impl<S: Source> Store<S> {
    /// Opens the container `src` holds at the state `pin` names (see
    /// [`Store::open_pinned`]).
    pub fn open_pinned_source(src: S, pin: crate::format::manifest::StatePin) -> Result<Self> {
        open::open_at(src, open::Walk::Lean, Some(pin))
    }
}

#[cfg(feature = "remote")]
impl Store<remote::HttpSource> {
    /// Opens the container at `url` (`http://` or `https://`) with range requests, pinned to
    /// the object's version (`docs/remote-design.md`): a change on the server is an error,
    /// never a mix of versions.
    pub fn open_url(url: &str) -> Result<Self> {
        Store::from_source(remote::HttpSource::open(url)?)
    }
}

impl Store<MmapSource> {
    /// Opens the container at `path` through a read-only memory map: payloads are read
    /// zero-copy.
    ///
    /// # Safety
    /// While the returned store (or anything borrowed from it) lives, no process may modify
    /// or cut the pages its state reaches. A write would change bytes the store has already
    /// checked (undefined behaviour for the zero-copy views); a cut raises `SIGBUS` on the next
    /// access. fmrh's own writers keep that promise for a *registered* store
    /// ([`Store::is_registered`], format §11.6): a [`Container`] never reuses or cuts a page
    /// of a state a live reader registered, and `fmrh build` never writes a file in place. So
    /// the caller promises that no other tool writes the file, and, if the store is not
    /// registered, that no writer has the file open. Use [`Store::open`] when this cannot be
    /// promised.
    pub unsafe fn open_mapped(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| crate::error::Error::io(path, e))?;
        let mut attempts = 0;
        loop {
            // SAFETY: our caller upholds the no-modification contract stated above.
            let src = unsafe { MmapSource::new(&file, path) }?;
            let mapped = src.len();
            match Store::from_source(src) {
                // A writer grew the file and published a state past the mapping's end after
                // it was made: map again. A file truly shorter than its state keeps its length.
                Err(crate::error::Error::Corrupt {
                    invariant: crate::error::Invariant::FileLength,
                    ..
                }) if attempts < 100
                    && file
                        .metadata()
                        .map_err(|e| crate::error::Error::io(path, e))?
                        .len()
                        > mapped =>
                {
                    attempts += 1;
                }
                other => return other,
            }
        }
    }
}

impl<T: AsRef<[u8]> + Send + Sync> Store<Bytes<T>> {
    /// Opens a container held in memory.
    pub fn from_bytes(bytes: T) -> Result<Self> {
        Store::from_source(Bytes(bytes))
    }
}

impl<S: Source> Store<S> {
    /// Opens a container from any source (see the module docs for what is checked).
    pub fn from_source(src: S) -> Result<Self> {
        open::open(src, open::Walk::Lean)
    }

    /// Opens a container from any source, walking every metadata page first (writers and
    /// the validator).
    pub(crate) fn from_source_walked(src: S) -> Result<Self> {
        open::open(src, open::Walk::Full)
    }

    /// What this store has read from its source since it was opened, opening excluded:
    /// metadata reads (pages the cache did not hold) and payload reads, calls and bytes.
    /// Take one before and one after a piece of work and subtract ([`ReadStats::since`]).
    pub fn read_stats(&self) -> ReadStats {
        self.cache.counters.snapshot()
    }

    /// What opening read: the commit slots, the dataset header and the cluster directory
    /// (and, for a writer or the validator, every table page).
    pub fn open_reads(&self) -> ReadStats {
        self.open_reads
    }

    /// The dataset header.
    pub fn header(&self) -> &DatasetHeader {
        &self.header
    }

    /// The block geometry.
    pub fn domain(&self) -> &Domain {
        &self.header.domain
    }

    /// The state this store reads.
    pub fn state(&self) -> StateInfo {
        let r = &self.commit;
        StateInfo {
            format_version: (r.major.get(), r.minor.get()),
            txn_id: r.txn_id.get(),
            commit_slot: self.slot,
            page_size: self.page_size,
            file_length: r.file_length.get(),
            recovery_needed: r.has_flag(COMMIT_RECOVERY_NEEDED),
            payload_slack: r.has_flag(COMMIT_PAYLOAD_SLACK),
        }
    }

    /// The pin of the state this store reads: what a dataset's manifest records to name it
    /// (`format-spec/dataset.md` §4).
    pub fn pin(&self) -> crate::format::manifest::StatePin {
        crate::format::manifest::StatePin::of(&self.commit)
    }

    /// Page levels of the node table and of the block table (1: a root leaf). A lookup
    /// reads this many pages; on a remote source, reading ahead costs this many rounds.
    pub fn table_depths(&self) -> (u16, u16) {
        let roots = &self.commit.roots;
        (roots.node_table.depth.get(), roots.block_table.depth.get())
    }

    /// The transaction id of the state this store reads.
    pub fn txn_id(&self) -> u64 {
        self.commit.txn_id.get()
    }

    /// Bytes per page.
    pub fn page_size(&self) -> u32 {
        self.page_size
    }

    /// Pages of the committed file.
    pub fn page_count(&self) -> u64 {
        self.page_count
    }

    /// The clusters, ascending by threshold.
    pub fn clusters(&self) -> &[ClusterInfo] {
        &self.clusters
    }

    /// The source.
    pub fn source(&self) -> &S {
        &self.src
    }

    /// The commit record in use.
    pub(crate) fn commit_record(&self) -> &CommitRecord {
        &self.commit
    }

    /// Which slot (0 or 1) holds the commit record in use.
    pub(crate) fn commit_slot(&self) -> u8 {
        self.slot
    }

    /// What binds pages to this store's state.
    pub(crate) fn binding(&self) -> pages::Binding {
        pages::Binding {
            txn: self.txn_id(),
            record_crc: self.commit.crc.get(),
            txn_tag: self.commit.page_txn_tag(),
        }
    }

    /// Pages of the state's metadata bundle (0 when it has none).
    pub(crate) fn bundle_pages(&self) -> u64 {
        self.bundle
            .as_ref()
            .map_or(0, |b| b.page_count(self.page_size))
    }

    /// Reads and checks every page of the state's metadata bundle (5.0 reads each when a
    /// lookup first reaches it): what the validator does to find a damaged frame that no
    /// lookup has reached yet.
    pub(crate) fn check_bundle_pages(&self) -> Result<()> {
        let Some(b) = &self.bundle else {
            return Ok(());
        };
        for i in 0..self.bundle_pages() {
            let page = crate::format::bundle::BUNDLE_FIRST_PAGE + i;
            match b.page(&self.src, page, self.page_size, &|n| {
                self.cache.counters.metadata(n)
            }) {
                Ok(_) | Err(bundled::PageError::Outside) => {}
                Err(bundled::PageError::Read(e)) => return Err(e),
                Err(bundled::PageError::Bad(v)) => {
                    return Err(slots::superseded_or_corrupt(&self.src, self.binding().id(), v))
                }
            }
        }
        Ok(())
    }

    /// Whether this store registered its state against page reuse by writers in other
    /// processes (format §11.6): then no commit reuses a page it reaches while it lives.
    pub fn is_registered(&self) -> bool {
        self.registered
    }

    /// Every metadata page of the state (blobs and every table page), walked and checked
    /// the first time it is asked for: the tree shapes (I-7) and no page reached twice
    /// (I-8). Writers rely on it to know which pages a state owns.
    pub(crate) fn metadata_pages(&self) -> Result<&pages::PageSet> {
        if let Some(set) = self.metadata_pages.get() {
            return Ok(set);
        }
        let pages = pages::Pages {
            check: true,
            cache: None,
            ..self.pages()
        };
        let mut seen = pages::PageSet::with_bundle(self.page_count, self.bundle_pages());
        let roots = &self.commit.roots;
        let top = self.commit.top().unwrap_or_default();
        for blob in [&roots.dataset_header, &roots.cluster_directory, &top] {
            let count = crate::format::blob::blob_pages(blob.length.get(), self.page_size);
            for i in 0..count {
                let page = blob.first_page.get() + i;
                if !seen.insert(page) {
                    return Err(self.corrupt(crate::format::Violation::new(
                        crate::format::Invariant::PageOwnership,
                        format!("blob page {page}"),
                        "page reached twice",
                    )));
                }
            }
        }
        for (spec, tree) in crate::format::tables::state_trees(roots, &self.clusters) {
            btree::walk(&pages, &tree, spec, &mut seen, &mut |_, _| Ok(()))?;
        }
        let _ = self.metadata_pages.set(seen);
        self.metadata_pages.get().ok_or_else(|| {
            crate::error::Error::Internal("the metadata page set was not kept".into())
        })
    }
}
