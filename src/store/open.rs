//! Opening a container: read the two commit slots, choose the state (format §3), register it
//! against page reuse by writers in other processes (§11.6), read and check its metadata
//! bundle if it has one (§6.7: one read, every page checked once, then kept in memory), then
//! read and check the dataset header and the cluster directory. Readers stop there
//! ([`Walk::Lean`]: table pages are checked as lookups reach them, `btree` and `pagecache`);
//! writers and the validator also walk every table page ([`Walk::Full`]).
//!
//! **Registering.** A reader registers the txn id it chose, then reads the slots again. If the
//! state is still the latest, no commit that could reuse its pages had started before the
//! registration took effect (a commit reuses pages of state `t` only from base `t + 1` on,
//! and a writer computes what it may reuse after its base is published), so from then on
//! every page it reaches stays as it is. Otherwise it tries again with the newer state.
//!
//! **Without registering** (memory, or a system without OFD locks), every structured page is
//! bound to the state by its txn tag (§4), payloads by their CRCs, and a page found unbound
//! while a later state exists makes the open start again with the latest state. Tags have 16
//! bits, so after opening (and, for a source whose bytes can change, after the first read of
//! each page) the reader reads the slots once more: if fewer than 2^16 - 1 commits have
//! passed since its pages were written, no page it read can carry a reused tag.
//!
//! The bytes are decoded by [`crate::format`]; this file only decides what to read. The
//! dataset header and the cluster directory are decoded here, before a [`Store`] exists, so
//! a store always holds a checked header.

use std::sync::Arc;

use super::btree;
use super::pagecache::{PageCache, ReadStats, DEFAULT_CACHED_PAGES};
use super::pages::{Binding, PageSet, Pages};
use super::slots::{latest_txn, no_state, pinned_missing, read_slots};
use super::source::{Counted, Source};
use super::Store;
use crate::error::{Error, Result};
use crate::format::blob::{self, blob_page_content, check_blob_ref};
use crate::format::commit::{self, Slot};
use crate::format::dataset::MAX_DATASET_HEADER_LEN;
use crate::format::directory::{self, MAX_DIRECTORY_LEN};
use crate::format::manifest::StatePin;
use crate::format::tables::state_trees;
use crate::format::top::{Top, MAX_TOP_LEN};
use crate::format::{tag, BlobRef, DatasetHeader, Invariant, TreeRef, Violation};

/// Reads and checks a blob of at most `max_len` bytes, adding its pages to `seen`.
fn read_blob<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    blob: &BlobRef,
    tag: [u8; 4],
    max_len: u64,
    name: &str,
    seen: &mut PageSet,
) -> Result<Vec<u8>> {
    let bundle_pages = pages.bundle.map_or(0, |b| b.page_count(pages.page_size));
    let count = check_blob_ref(
        blob,
        max_len,
        pages.page_size,
        pages.page_count,
        bundle_pages,
        name,
    )
    .map_err(|v| pages.corrupt(v))?;
    // `max_len` bounds the allocation, whatever the record says.
    let mut out = Vec::with_capacity(usize::try_from(blob.length.get()).unwrap_or(0));
    for i in 0..count {
        let page_no = blob.first_page.get() + i;
        if !seen.insert(page_no) {
            return Err(pages.corrupt(Violation::new(
                Invariant::PageOwnership,
                format!("{name} page {page_no}"),
                "page reached twice",
            )));
        }
        let page = pages.get(page_no, tag)?;
        let content = blob_page_content(&page, blob, i, tag, pages.page_size, name)
            .map_err(|v| pages.corrupt(v))?;
        out.extend_from_slice(content);
    }
    Ok(out)
}

/// How many times opening starts again because a writer published a newer state (or, for an
/// unregistered reader, reused a page) while it chose. Each round takes microseconds and a
/// commit at least one `fsync`, so this is never reached unless commits never stop.
const OPEN_ATTEMPTS: u32 = 100;

/// Pages of the dataset header and of the cluster directory fetched ahead at open from a
/// remote source, each (their references are not checked yet: this bounds a damaged one).
const MAX_AHEAD_PAGES: u64 = 16;

/// Chooses the state and registers it (see the module docs). Returns the slot, the record,
/// and whether it is registered. With a `pin`, the state is the one the pin names (a
/// dataset's tile, `format-spec/dataset.md` §4), whichever slot holds it, and not
/// necessarily the latest.
fn choose_state<S: Source + ?Sized>(
    src: &S,
    pin: Option<StatePin>,
) -> Result<(u8, crate::format::CommitRecord, bool)> {
    let mut attempts = 0;
    loop {
        let slots = read_slots(src)?;
        let (slot, commit) = match pin {
            None => commit::choose(&slots).map_err(|why| no_state(src, why))?,
            Some(pin) => pinned(src, &slots, pin)?,
        };
        let txn = commit.txn_id.get();
        if !src
            .register_reader(txn)
            .map_err(|e| Error::io(src.name(), e))?
        {
            return Ok((slot, commit, false));
        }
        match pin {
            None => {
                let latest = latest_txn(src)?;
                if latest == Some(txn) {
                    return Ok((slot, commit, true));
                }
                attempts += 1;
                if attempts >= OPEN_ATTEMPTS {
                    return Err(Error::Superseded {
                        path: src.name().to_path_buf(),
                        txn,
                        latest: latest.unwrap_or(txn),
                        detail: format!(
                            "a writer published {attempts} states while this reader chose one"
                        ),
                    });
                }
            }
            // Registered while the pinned state was still published: writers keep its pages.
            Some(pin) => {
                let again = read_slots(src)?;
                pinned(src, &again, pin)?;
                return Ok((slot, commit, true));
            }
        }
    }
}

/// The valid slot whose record publishes the state `pin` names (the newer, when a mark
/// copied it into both).
fn pinned<S: Source + ?Sized>(
    src: &S,
    slots: &[Slot; 2],
    pin: StatePin,
) -> Result<(u8, crate::format::CommitRecord)> {
    let mut found: Option<(u8, crate::format::CommitRecord)> = None;
    for (i, s) in (0u8..).zip(slots) {
        if let Slot::Valid(r) = s {
            if pin.matches(r) && found.is_none_or(|(_, f)| r.txn_id.get() > f.txn_id.get()) {
                found = Some((i, **r));
            }
        }
    }
    found.ok_or_else(|| pinned_missing(src, pin))
}

/// How much opening checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Walk {
    /// The commit slots, the dataset header and the cluster directory; every other page is
    /// checked when a lookup first reaches it (readers).
    Lean,
    /// Also every page of every table, with the shape of each tree and no page reached
    /// twice (writers and the validator, before they trust the page ownership).
    Full,
}

/// Opens the state `src` holds, checking what `walk` says (see the docs of [`crate::store`]
/// for what that costs).
pub(crate) fn open<S: Source>(src: S, walk: Walk) -> Result<Store<S>> {
    open_at(src, walk, None)
}

/// As [`open`], at the state `pin` names when there is one.
pub(crate) fn open_at<S: Source>(src: S, walk: Walk, pin: Option<StatePin>) -> Result<Store<S>> {
    let mut attempts = 0;
    loop {
        match open_once(&src, walk, pin) {
            Ok(opened) => {
                if let Some(area) = opened.metadata_area.clone() {
                    src.advise_metadata(area);
                }
                return Ok(opened.into_store(src));
            }
            Err(Error::Superseded { .. }) if attempts + 1 < OPEN_ATTEMPTS => attempts += 1,
            Err(e) => return Err(e),
        }
    }
}

/// What opening found, before the store owns its source.
struct Opened {
    bundle: Option<Arc<super::bundled::Bundle>>,
    page_size: u32,
    page_count: u64,
    slot: u8,
    commit: crate::format::CommitRecord,
    header: DatasetHeader,
    clusters: Vec<crate::format::ClusterInfo>,
    metadata_pages: Option<PageSet>,
    registered: bool,
    open_reads: ReadStats,
    top: Option<Top>,
    /// Where the state's table pages lie, as the fresh layout puts them (format §2): from
    /// the dataset header's first page to the end of the file, or the bundle's stored run
    /// when the header is in the metadata bundle (the tables are too).
    metadata_area: Option<std::ops::Range<u64>>,
}

impl Opened {
    fn into_store<S: Source>(self, src: S) -> Store<S> {
        Store {
            bundle: self.bundle,
            page_size: self.page_size,
            page_count: self.page_count,
            slot: self.slot,
            commit: self.commit,
            header: self.header,
            clusters: self.clusters,
            metadata_pages: self
                .metadata_pages
                .map(std::sync::OnceLock::from)
                .unwrap_or_default(),
            wrap_guard: (!self.registered && !src.stable() && self.commit.binds_pages())
                .then(|| self.commit.pages_txn.get()),
            cache: PageCache::new(self.page_count, src.stable(), DEFAULT_CACHED_PAGES),
            registered: self.registered,
            open_reads: self.open_reads,
            ancestors: std::sync::Mutex::default(),
            nodes: super::nodememo::NodeMemo::default(),
            top: self.top.map(Arc::new),
            src,
        }
    }
}

fn open_once<S: Source>(src: &S, walk: Walk, pin: Option<StatePin>) -> Result<Opened> {
    // What opening reads, counted by a wrapper around the source.
    let counted = Counted::new(src);
    let src = &counted;
    let (slot, commit, registered) = choose_state(src, pin)?;
    // The state may be newer than the length the source saw when it was opened: a writer
    // grows the file before it publishes a record.
    let len = if commit.file_length.get() > src.len() {
        src.refresh_len().map_err(|e| Error::io(src.name(), e))?
    } else {
        src.len()
    };
    commit::check_length(&commit, len).map_err(|v| v.in_file(src.name()))?;
    let page_size = commit.page_size.get();
    let page_count = commit.file_length.get() / u64::from(page_size);
    let bundle = super::bundled::read(src, &commit)?;
    let pages = Pages {
        src,
        page_size,
        page_count,
        check: true,
        state: Binding {
            txn: commit.txn_id.get(),
            record_crc: commit.crc.get(),
            txn_tag: commit.page_txn_tag(),
        },
        cache: None,
        wrap_guard: None,
        bundle: bundle.as_ref(),
    };
    let bundle_pages = bundle.as_ref().map_or(0, |b| b.page_count(page_size));
    let mut seen = PageSet::with_bundle(page_count, bundle_pages);
    if src.prefetches() {
        // One round for what opening reads next and scenes and loads read first: the
        // header's, the directory's and the top's pages, and the roots of the node and
        // block tables (a remote source). A fresh paged file holds them all in its last
        // pages, which the source fetched with the commit slots.
        let roots = &commit.roots;
        let top = commit.top().unwrap_or_default();
        let mut ahead = Vec::new();
        for blob in [&roots.dataset_header, &roots.cluster_directory, &top] {
            let count = blob::blob_pages(blob.length.get(), page_size).min(MAX_AHEAD_PAGES);
            ahead.extend((0..count).map(|i| blob.first_page.get().saturating_add(i)));
        }
        ahead.push(roots.node_table.root_page.get());
        ahead.push(roots.block_table.root_page.get());
        pages.prefetch(&ahead)?;
    }
    let header_bytes = read_blob(
        &pages,
        &commit.roots.dataset_header,
        tag::DATASET_HEADER,
        MAX_DATASET_HEADER_LEN,
        "dataset header",
        &mut seen,
    )?;
    let version = (commit.major.get(), commit.minor.get());
    let header = DatasetHeader::decode(&header_bytes, version).map_err(|v| pages.corrupt(v))?;
    let dir = read_blob(
        &pages,
        &commit.roots.cluster_directory,
        tag::CLUSTER_DIRECTORY,
        MAX_DIRECTORY_LEN,
        "cluster directory",
        &mut seen,
    )?;
    let clusters = directory::decode(&dir, &header, commit.roots.adjacency.records.get())
        .map_err(|v| pages.corrupt(v))?;
    // The top of the tree serves a reader that pays a round trip per page (a remote
    // source) and the validator; a local reader finds the same nodes in the table, and
    // opening stays within its few pages (`tests/lean_reads.rs`).
    let top = match commit.top() {
        Some(blob) if src.prefetches() || walk == Walk::Full => {
            Some(read_top(&pages, &blob, &header, &mut seen)?)
        }
        _ => None,
    };
    let expect = |tree: &TreeRef, n: u64, what: &str| -> Result<()> {
        if tree.records.get() != n {
            return Err(pages.corrupt(Violation::new(
                Invariant::TreeShape,
                what,
                format!("{} records, expected {n}", tree.records.get()),
            )));
        }
        Ok(())
    };
    expect(&commit.roots.node_table, header.node_count, "node table")?;
    expect(&commit.roots.block_table, header.block_count, "block table")?;
    for (spec, tree) in state_trees(&commit.roots, &clusters) {
        // Cheap and local: the root reference's own fields (depth, record size).
        crate::format::tree::check_tree_ref(&tree, spec).map_err(|v| pages.corrupt(v))?;
        if walk == Walk::Full {
            btree::walk(&pages, &tree, spec, &mut seen, &mut |_, _| Ok(()))?;
        }
    }
    if !registered && commit.binds_pages() {
        // A tag repeats every 2^16 transactions: if that many could have committed since the
        // state's pages were written, a page read above might carry a reused tag. While the
        // state is still the latest, no commit after it wrote a page it reaches, however many
        // marks republished it (a state never names itself superseded).
        let latest = latest_txn(src)?.unwrap_or(0);
        if latest > commit.txn_id.get()
            && latest.saturating_add(1) >= commit.pages_txn.get().saturating_add(0xffff)
        {
            return Err(Error::Superseded {
                path: src.name().to_path_buf(),
                txn: commit.txn_id.get(),
                latest,
                detail: "2^16 transactions committed since its pages were written".into(),
            });
        }
    }
    Ok(Opened {
        bundle: bundle.map(Arc::new),
        page_size,
        page_count,
        slot,
        commit,
        header,
        clusters,
        metadata_pages: (walk == Walk::Full).then_some(seen),
        registered,
        open_reads: counted.stats(),
        // With a top, a scene reads the node table's subtrees it refines into, a run each:
        // fetching the whole area would cost more bytes than the rounds it saves.
        metadata_area: if commit.top().is_some() {
            None
        } else {
            let first = commit.roots.dataset_header.first_page.get();
            let bundle = &commit.bundle;
            if first >= crate::format::bundle::BUNDLE_FIRST_PAGE {
                // A bundled state: its tables are frames of the bundle's stored run.
                let start = bundle.offset.get();
                Some(start..start.saturating_add(u64::from(bundle.stored_len.get())))
            } else {
                Some(first.saturating_mul(u64::from(page_size))..commit.file_length.get())
            }
            .filter(|area| !area.is_empty())
        },
        top,
    })
}

/// Reads and checks the top of the tree (format 6.2) that `blob` names: in file pages,
/// well formed, and naming nodes the header's table and levels hold (the validator checks
/// each record against the table's, I-10).
fn read_top<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    blob: &BlobRef,
    header: &DatasetHeader,
    seen: &mut PageSet,
) -> Result<Top> {
    let bad = |detail: String| pages.corrupt(Violation::new(Invariant::NodeTable, "top", detail));
    if crate::format::bundle::is_bundle_page(blob.first_page.get()) {
        return Err(bad("in the metadata bundle, where a top never lies".into()));
    }
    let bytes = read_blob(pages, blob, tag::TOP, MAX_TOP_LEN, "top", seen)?;
    let top = crate::format::top::decode(&bytes).map_err(|v| pages.corrupt(v))?;
    let nodes = header.node_count;
    if let Some(&(o, _)) = top.nodes.iter().find(|&&(o, _)| u64::from(o) >= nodes) {
        return Err(bad(format!("node {o} is past the table's {nodes} nodes")));
    }
    Ok(top)
}
