//! One commit's pages (format §11.2, steps 1–3): every changed payload, the tables and blobs
//! of the new state, and the free list, each in pages the allocator hands out; then the new
//! length and a sync. The caller publishes the record this returns.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

use rayon::prelude::*;
use serde::Serialize;
use zerocopy::IntoBytes;

use super::alloc::Alloc;
use super::clean;
use super::SnapshotStore;
use crate::error::{Error, Result};
use crate::format::blob::encode_blob;
use crate::format::bundle::BundleRef;
use crate::format::payload::PayloadRef;
use crate::format::tables::FREE;
use crate::format::tree::{self, TreeSpec};
use crate::format::{
    tag, BlobRef, CommitRecord, DatasetHeader, FreeEntry, FreePage, Invariant, StateRoots, TreeRef,
    Violation, COMMIT_PAYLOAD_SLACK, COMMIT_RECOVERY_NEEDED,
};
use crate::model::{ModelEditor, SampleRect};
use crate::store::io::Io;
use crate::store::write::tables::{self, PageSink, PayloadRefs};

/// What a commit changed.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct CommitSummary {
    /// The new state's txn id.
    pub txn_id: u64,
    /// Replacements in the transaction.
    pub replacements: u64,
    /// Physical blocks rewritten.
    pub blocks: u64,
    /// Coarse grids rewritten.
    pub grids: u64,
    /// Nodes before.
    pub nodes_before: u64,
    /// Nodes after.
    pub nodes_after: u64,
    /// Nodes new to the tree (split).
    pub nodes_added: u64,
    /// Nodes no longer in the tree (merged).
    pub nodes_removed: u64,
    /// Nodes kept whose error, `e*`, heights or valid count changed.
    pub nodes_changed: u64,
    /// Clusters whose cut changed, by index.
    pub clusters_changed: Vec<usize>,
    /// Pages written (payloads, tables, blobs), commit slot excluded.
    pub pages_written: u64,
    /// Of those, pages reused from the free list.
    pub pages_reused: u64,
    /// Pages this commit freed.
    pub pages_freed: u64,
    /// Kept payloads moved off sparse pages so that those could be freed (`clean`).
    pub payloads_moved: u64,
    /// Their bytes.
    pub bytes_moved: u64,
    /// File length after the commit.
    pub file_length: u64,
    /// `L` of format §11.3: pages freed by states up to this txn id could be reused. Below
    /// the base when a snapshot or a registered reader in another process held an older
    /// state.
    pub reuse_limit: u64,
}

/// A [`PageSink`] that writes each tree or blob into an extent from the allocator, and
/// payloads back to back through runs of pages ([`PayloadRun`]).
struct CommitSink<'a, I: Io> {
    io: &'a I,
    alloc: &'a mut Alloc,
    page_size: u32,
    /// The transaction writing: every structured page carries its tag.
    txn: u64,
    written: u64,
    /// The run payloads are going into now.
    run: Option<PayloadRun>,
    /// Earlier runs of this commit whose last page has room left: a payload that fits a
    /// tail goes there (the smallest tail it fits), so that a run ending in a one-page hole
    /// does not leave most of that page empty (Puget Sound 1k's blocks are 1 to 4 KiB).
    parked: Vec<PayloadRun>,
    /// Bytes of payloads still to come in this batch (a hint: a new run is sized for them).
    pending: u64,
}

/// The most runs a commit keeps open for their tails.
const MAX_PARKED: usize = 8;

/// Consecutive pages a commit packs payloads into end to end, as a build does: a payload
/// straddles pages, and only the run's last page has a tail. Held in memory until the run
/// ends, then written whole (the tail zeroed).
struct PayloadRun {
    first: u64,
    /// The pages reserved: `first .. first + pages`.
    pages: u64,
    /// For each reserved page, the txn that freed it (`None`: appended past the end).
    freed: Vec<Option<u64>>,
    /// The bytes so far, from the run's first byte.
    bytes: Vec<u8>,
}

impl<I: Io> CommitSink<'_, I> {
    fn new<'a>(io: &'a I, alloc: &'a mut Alloc, page_size: u32, txn: u64) -> CommitSink<'a, I> {
        CommitSink {
            io,
            alloc,
            page_size,
            txn,
            written: 0,
            run: None,
            parked: Vec::new(),
            pending: 0,
        }
    }

    fn write_pages(&mut self, first: u64, pages: &[Vec<u8>]) -> Result<()> {
        for (page, bytes) in (first..).zip(pages) {
            self.io
                .write_at(page * u64::from(self.page_size), bytes)
                .map_err(|e| Error::io(self.io.name(), e))?;
            self.written += 1;
        }
        Ok(())
    }

    /// Builds a tree of `records` into the pages from `first` on (enough of them are
    /// reserved) and writes them.
    fn tree_at(&mut self, first: u64, records: &[u8], spec: TreeSpec) -> Result<TreeRef> {
        let mut pages = Vec::new();
        let root =
            tree::build::<Error>(records, spec, self.page_size, first, self.txn, &mut |p| {
                pages.push(p);
                Ok(())
            })?;
        self.write_pages(first, &pages)?;
        Ok(root)
    }

    /// Writes `bytes` as a payload, next in the current run: the run grows into the pages
    /// after it when they are free (or past the end), else a new run begins, sized for the
    /// payloads still to come where the free list has room for them.
    fn payload(&mut self, bytes: Vec<u8>) -> Result<PayloadRef> {
        let p = u64::from(self.page_size);
        let len = bytes.len() as u64;
        self.pending = self.pending.saturating_sub(len);
        let room = |run: &PayloadRun| (run.pages * p).saturating_sub(run.bytes.len() as u64);
        let tail = self
            .parked
            .iter()
            .enumerate()
            .filter(|(_, r)| room(r) >= len)
            .min_by_key(|(_, r)| room(r))
            .map(|(i, _)| i);
        let run = match tail {
            Some(i) => &mut self.parked[i],
            None => {
                if self.run.as_ref().is_none_or(|r| room(r) < len) && !self.grow(len) {
                    self.park()?;
                    self.begin_run(len);
                }
                self.run
                    .as_mut()
                    .ok_or_else(|| Error::Internal("a payload without a run".into()))?
            }
        };
        let at = run.first * p + run.bytes.len() as u64;
        let r = PayloadRef::of(at, &bytes)
            .ok_or_else(|| Error::Internal(format!("a payload of {len} bytes")))?;
        run.bytes.extend_from_slice(&bytes);
        Ok(r)
    }

    /// Grows the current run to hold `len` more bytes, when the pages after it are reusable
    /// free pages, or are past the end of the file.
    fn grow(&mut self, len: u64) -> bool {
        let p = u64::from(self.page_size);
        let Some(run) = self.run.as_mut() else {
            return false;
        };
        let need = (run.bytes.len() as u64 + len).div_ceil(p) - run.pages;
        let next = run.first + run.pages;
        // Past the end only while no free run could take the payload: appending whenever
        // a run ended the file grew it at every commit, free runs or not.
        if next == self.alloc.end && self.alloc.best_run(len.div_ceil(p).max(1)).is_none() {
            self.alloc.append(need);
            run.freed.extend((0..need).map(|_| None));
        } else if (next..next + need).all(|page| self.alloc.reusable(page)) {
            run.freed.extend(self.alloc.take_freed(next, need));
        } else {
            return false;
        }
        run.pages += need;
        true
    }

    /// Begins a run for a payload of `len` bytes and the `pending` after it: in the first
    /// run of free pages that holds this payload (`Alloc::best_run`), reserving as much of
    /// it as the payloads to come could fill; else past the end.
    fn begin_run(&mut self, len: u64) {
        let p = u64::from(self.page_size);
        let least = len.div_ceil(p).max(1);
        let want = (len + self.pending).div_ceil(p).max(least);
        let (first, pages, freed) = match self.alloc.best_run(least) {
            Some((first, run)) => {
                let n = run.min(want);
                (first, n, self.alloc.take_freed(first, n))
            }
            None => (
                self.alloc.append(least),
                least,
                (0..least).map(|_| None).collect(),
            ),
        };
        self.run = Some(PayloadRun {
            first,
            pages,
            freed,
            bytes: Vec::new(),
        });
    }

    /// Parks the current run (its tail may take a later payload); beyond [`MAX_PARKED`]
    /// runs, the one with the least room left is written out.
    fn park(&mut self) -> Result<()> {
        let Some(run) = self.run.take() else {
            return Ok(());
        };
        self.parked.push(run);
        if self.parked.len() > MAX_PARKED {
            let p = u64::from(self.page_size);
            let fullest = (0..self.parked.len())
                .min_by_key(|&i| {
                    (self.parked[i].pages * p).saturating_sub(self.parked[i].bytes.len() as u64)
                })
                .unwrap_or(0);
            let run = self.parked.swap_remove(fullest);
            self.end_run(run)?;
        }
        Ok(())
    }

    /// Writes every run out: the last step before the tables.
    fn finish(&mut self) -> Result<()> {
        self.park()?;
        for run in std::mem::take(&mut self.parked) {
            self.end_run(run)?;
        }
        Ok(())
    }

    /// Writes a run's pages (its last zero-padded) and gives back the pages it reserved
    /// and did not use.
    fn end_run(&mut self, mut run: PayloadRun) -> Result<()> {
        let p = u64::from(self.page_size);
        let used = (run.bytes.len() as u64).div_ceil(p);
        run.bytes.resize(usize::try_from(used * p).unwrap_or(0), 0);
        self.io
            .write_at(run.first * p, &run.bytes)
            .map_err(|e| Error::io(self.io.name(), e))?;
        self.written += used;
        // From the last page back, so that appended pages move the end back.
        let unused: Vec<(u64, Option<u64>)> = (run.first..run.first + run.pages)
            .zip(run.freed)
            .skip(usize::try_from(used).unwrap_or(usize::MAX))
            .collect();
        for (page, freed) in unused.into_iter().rev() {
            match freed {
                Some(txn) => self.alloc.give_back(page, txn),
                // Appended: still past the base's end, no state reaches it.
                None => self.alloc.give_back_appended(page),
            }
        }
        Ok(())
    }
}

impl<I: Io> PageSink for CommitSink<'_, I> {
    fn tree(&mut self, records: &[u8], spec: TreeSpec) -> Result<TreeRef> {
        let count = (records.len() / spec.record_size) as u64;
        let n = tree::pages_needed(count, spec.record_size, self.page_size);
        let first = self.alloc.extent(n);
        self.tree_at(first, records, spec)
    }

    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef> {
        let n = crate::format::blob::blob_pages(content.len() as u64, self.page_size);
        let first = self.alloc.extent(n);
        let (blob, pages) = encode_blob(content, tag, first, self.txn, self.page_size);
        self.write_pages(first, &pages)?;
        Ok(blob)
    }
}

/// Small payloads a commit stores once (as a build does, `tables::MAX_SHARED_PAYLOAD`): the
/// ones it writes, and the base state's, found by length and CRC and compared byte for byte
/// before one is shared. Sea, void and flat blocks code to the same few bytes by the
/// thousand; without this, each edit of sea wrote its own copies.
struct Sharer {
    /// This commit's small payloads.
    written: HashMap<Vec<u8>, PayloadRef>,
    /// The base state's small payloads, by length and CRC.
    base: HashMap<(u32, u32), PayloadRef>,
}

impl Sharer {
    fn new(base_refs: impl Iterator<Item = PayloadRef>) -> Sharer {
        Sharer {
            written: HashMap::new(),
            base: base_refs
                .filter(|r| r.len > 0 && r.len as usize <= tables::MAX_SHARED_PAYLOAD)
                .map(|r| ((r.len, r.crc), r))
                .collect(),
        }
    }

    /// Where `bytes` go: an identical small payload already stored (a base state's one is
    /// pushed on `kept`, so that its pages stay), else written by `sink`.
    fn place<I: Io>(
        &mut self,
        bytes: Vec<u8>,
        base: &SnapshotStore<I>,
        sink: &mut CommitSink<'_, I>,
        kept: &mut Vec<PayloadRef>,
    ) -> Result<PayloadRef> {
        if bytes.is_empty() || bytes.len() > tables::MAX_SHARED_PAYLOAD {
            return sink.payload(bytes);
        }
        if let Some(&r) = self.written.get(&bytes) {
            return Ok(r);
        }
        // At most MAX_SHARED_PAYLOAD bytes here: the length fits.
        let key = (
            u32::try_from(bytes.len()).unwrap_or(u32::MAX),
            crate::format::crc32(&bytes),
        );
        if let Some(&r) = self.base.get(&key) {
            if base.payload(r)?.as_ref() == bytes.as_slice() {
                kept.push(r);
                return Ok(r);
            }
        }
        let r = sink.payload(bytes.clone())?;
        self.written.insert(bytes, r);
        Ok(r)
    }
}

/// The zstd level of a commit's metadata bundle: a commit pays for its compression in
/// latency, so it takes a fast level where a build takes 19. On Puget Sound 1k (28 pages of
/// metadata) level 9 added about 1 ms to a 3 ms commit; level 3 keeps the bundle within
/// about 10 % of level 19's size.
const COMMIT_ZSTD_LEVEL: i32 = 3;

/// Writes every page of the state `editor` holds, on top of `base`, with its metadata in a
/// bundle of at most `bundle_limit` stored bytes when it fits; returns its commit
/// record (txn id + 1, sealed, flags `RECOVERY_NEEDED | PAYLOAD_SLACK`) and what changed.
/// Nothing it writes is reachable from `base` or from a snapshot older than `reuse_limit`.
pub(crate) fn write_state<I: Io>(
    io: &Arc<I>,
    base: &SnapshotStore<I>,
    editor: &ModelEditor,
    dirty: &[SampleRect],
    reuse_limit: u64,
    bundle_limit: u64,
    min_pages: u64,
) -> Result<(CommitRecord, CommitSummary)> {
    let p = base.page_size();
    let txn = base.next_txn_id()?;
    let model = editor.model();
    let d = *model.domain();
    let finest = d.finest_level();
    let tree = model.tree();

    let old_nodes = base.node_records()?;
    let old_blocks = base.block_records()?;
    let pool = base
        .free_pages()?
        .iter()
        .map(|f| (f.page, f.freed_txn))
        .collect();
    let mut alloc = Alloc::new(pool, reuse_limit, base.page_count());
    let mut sink = CommitSink::new(io.as_ref(), &mut alloc, p, txn);
    let mut sharer = Sharer::new(
        old_nodes
            .iter()
            .map(|n| n.payload())
            .chain(old_blocks.iter().map(|b| b.payload())),
    );
    let meets = |r: &SampleRect| dirty.iter().any(|x| x.intersect(r).is_some());
    let mut summary = CommitSummary {
        txn_id: txn,
        nodes_before: old_nodes.len() as u64,
        nodes_after: tree.nodes().len() as u64,
        ..CommitSummary::default()
    };

    // Payloads: changed ones are written, the others kept where they are. A payload coded
    // against its parent's grid (blocks since format 4, grids since 5) decodes with whatever
    // that grid's payload holds, so a kept one stays only while the parent's *heights* are
    // as they were: while no changed sample lies in the parent's footprint (a grid is a
    // decimation of the samples in its footprint, mended within it). The parent's payload
    // may still be written again (coded anew against a changed grandparent): its heights,
    // and so its children's payloads, stay good. A child is coded anew at most one level
    // below a changed node, never down the whole tree, and not at all when its own samples
    // are unchanged and its coding is planar (7, 8), which reads only the parent's heights
    // at the child's own samples (the interpolation, 5 and 6, reaches past them).
    let shapes = tables::block_shapes(model);
    let grid_voids = tables::grid_void_flags(model);
    let mut kept: Vec<PayloadRef> = Vec::new();
    let old_at: HashMap<(u8, u32, u32), _> = old_nodes
        .iter()
        .map(|n| ((n.level, n.x.get(), n.y.get()), n))
        .collect();
    let mut new_at: HashMap<(u8, u32, u32), u32> = HashMap::new();
    let mut grid_ref = vec![PayloadRef::default(); tree.nodes().len()];
    let mut grid_against = vec![false; tree.nodes().len()];
    let mut grid_raw_bitmap = vec![false; tree.nodes().len()];
    let mut rewrite_grids: Vec<usize> = Vec::new();
    let mut seen = HashSet::with_capacity(tree.nodes().len());
    // Whether the heights of node `i`'s grid changed: a changed sample in its footprint.
    let heights_changed = |i: u32| meets(&tree.footprint(i));
    // Whether a payload coded against its parent's grid uses only the heights the parent
    // holds at the payload's own samples (the planar encodings 7 and 8): then its own
    // samples being unchanged is enough, whatever else changed in the parent.
    let planar_only = |r: PayloadRef| -> Result<bool> {
        let bytes = base.payload(r)?;
        Ok(matches!(
            bytes
                .get(4)
                .copied()
                .and_then(crate::codec::Encoding::from_id),
            Some(
                crate::codec::Encoding::LatticePlanarFromParent
                    | crate::codec::Encoding::FloatPlanarFromParent
            )
        ))
    };
    // Whether node `i`'s grid is stored thinned as it was (format 6). A planar payload reads
    // its parent's *stored* heights at its own samples: if the parent's thinning changed,
    // so did which of them the parent stores, even where no height did.
    let thin_same = |i: u32| {
        let n = tree.node(i);
        old_at
            .get(&(n.level, n.x, n.y))
            .is_some_and(|o| o.decode().grid_thin == n.thin)
    };
    for (i, n) in tree.nodes().iter().enumerate() {
        let at = (n.level, n.x, n.y);
        seen.insert(at);
        let id = tables::node_id(i);
        if n.level + 1 >= finest {
            new_at.insert(at, id);
        }
        let old = old_at.get(&at);
        match old {
            None => summary.nodes_added += 1,
            Some(o) => {
                if o.static_error.get().to_bits() != n.static_error.to_bits()
                    || o.monotone_error.get().to_bits() != n.monotone_error.to_bits()
                    || o.min_height.get().to_bits() != n.min_height.to_bits()
                    || o.max_height.get().to_bits() != n.max_height.to_bits()
                    || o.valid_samples.get() != n.valid_samples
                {
                    summary.nodes_changed += 1;
                }
            }
        }
        if n.level == finest {
            continue;
        }
        let keep = match old {
            // The thinning decision reads the whole footprint, not only the grid's samples:
            // a grid is kept only as it is stored now.
            Some(o)
                if o.level < finest && !heights_changed(id) && o.decode().grid_thin == n.thin =>
            {
                let against = o.decode().grid_against_parent;
                let parent_same = n.parent != crate::model::NO_PARENT
                    && (!heights_changed(n.parent)
                        || (thin_same(n.parent) && planar_only(o.payload())?));
                (!against || parent_same).then_some(o)
            }
            _ => None,
        };
        match keep {
            Some(o) => {
                kept.push(o.payload());
                grid_ref[i] = o.payload();
                let old = o.decode();
                grid_against[i] = old.grid_against_parent;
                // A grid kept from a state older than 5.0 keeps its raw bitmap.
                grid_raw_bitmap[i] = old.grid_has_voids && !old.grid_bitmap_flagged;
            }
            None => rewrite_grids.push(i),
        }
    }
    // The grids to write are coded on every core, then written in order.
    let coded: Vec<(Vec<u8>, bool)> = rewrite_grids
        .par_iter()
        .map(|&i| tables::encode_grid(model, tables::node_id(i), grid_voids[i], false, true, true))
        .collect();
    sink.pending = coded.iter().map(|(b, _)| b.len() as u64).sum();
    for (&i, (bytes, against)) in rewrite_grids.iter().zip(coded) {
        grid_ref[i] = sharer.place(bytes, base, &mut sink, &mut kept)?;
        grid_against[i] = against;
        summary.grids += 1;
    }
    let (cols, _) = d.nodes_across(finest);
    let mut block_ref = Vec::with_capacity(shapes.len());
    let mut against = Vec::with_capacity(shapes.len());
    let mut rewrite_blocks: Vec<(usize, Option<u32>)> = Vec::new();
    for (i, shape) in shapes.iter().enumerate() {
        let old = old_blocks.get(i).ok_or_else(|| {
            base.corrupt(Violation::new(
                Invariant::BlockTable,
                "block table",
                "fewer records than blocks",
            ))
        })?;
        let (x, y) = (
            tables::node_id(i % cols as usize),
            tables::node_id(i / cols as usize),
        );
        let parent_now = (finest > 0)
            .then(|| new_at.get(&(finest - 1, x / 2, y / 2)).copied())
            .flatten();
        // A kept block coded against a grid still decodes while that grid's heights are
        // as they were.
        let keep = match old.decode().against {
            _ if meets(&shape.rect) => None,
            None => Some(None),
            Some(_) => match parent_now {
                Some(p) if !heights_changed(p) || (thin_same(p) && planar_only(old.payload())?) => {
                    Some(Some(p))
                }
                _ => None,
            },
        };
        match keep {
            Some(a) => {
                kept.push(old.payload());
                block_ref.push(old.payload());
                against.push(a);
            }
            None => {
                block_ref.push(PayloadRef::default());
                against.push(None);
                let node = new_at.get(&(finest, x, y)).copied();
                rewrite_blocks.push((i, tables::block_parent(model, node)));
            }
        }
    }
    // The blocks to write are coded on every core (each tries alone and against its
    // parent), then written in order.
    let coded: Vec<(Vec<u8>, Option<u32>)> = rewrite_blocks
        .par_iter()
        .map(|&(i, parent)| tables::encode_block(model, &shapes[i], parent, false, true))
        .collect();
    sink.pending = coded.iter().map(|(b, _)| b.len() as u64).sum();
    for (&(i, _), (bytes, a)) in rewrite_blocks.iter().zip(coded) {
        block_ref[i] = sharer.place(bytes, base, &mut sink, &mut kept)?;
        against[i] = a;
        summary.blocks += 1;
    }
    // The cleaner: payloads kept on sparse pages move into this commit's pages, so that
    // theirs can be freed (`clean`).
    let mut move_payloads = |moved: Vec<PayloadRef>,
                             sink: &mut CommitSink<'_, I>,
                             kept: &mut Vec<PayloadRef>,
                             summary: &mut CommitSummary|
     -> Result<()> {
        if moved.is_empty() {
            return Ok(());
        }
        let mut to: HashMap<PayloadRef, PayloadRef> = HashMap::with_capacity(moved.len());
        sink.pending = moved.iter().map(|r| u64::from(r.len)).sum();
        for &r in &moved {
            let bytes = base.payload(r)?.into_owned();
            summary.bytes_moved += u64::from(r.len);
            to.insert(r, sink.payload(bytes)?);
        }
        for r in grid_ref.iter_mut().chain(block_ref.iter_mut()) {
            if let Some(&new) = to.get(r) {
                *r = new;
            }
        }
        kept.retain(|r| !to.contains_key(r));
        summary.payloads_moved += moved.len() as u64;
        Ok(())
    };
    // What the moves may take: the holes (less what the tables will), so that they fill
    // holes rather than grow the file; at least two segments, so that cleaning goes on.
    let metadata = base.metadata_pages()?;
    // What the tables (or the bundle) will take of the holes: about what the base's took.
    let reserve = (2..base.page_count())
        .filter(|&pg| metadata.contains(pg))
        .count() as u64;
    let holes = sink.alloc.holes().0.saturating_sub(reserve);
    let budget = (holes * u64::from(p) / 2).max(2 * clean::SEGMENT_PAGES * u64::from(p));
    move_payloads(
        clean::payloads_to_move(&kept, p, budget),
        &mut sink,
        &mut kept,
        &mut summary,
    )?;
    // The tail: when the holes inside the file pass their allowance, the kept payloads at
    // its end move into them, so that a later commit cuts the end off (`clean`).
    let old_bundle = base.commit_record().bundle;
    let old_payload_pages: HashSet<u64> = old_nodes
        .iter()
        .map(|n| n.payload())
        .chain(old_blocks.iter().map(|b| b.payload()))
        .chain(old_bundle.is_present().then(|| old_bundle.payload()))
        .flat_map(|r| r.pages(p))
        .collect();
    let tail = {
        let kept_pages: HashSet<u64> = kept.iter().flat_map(|r| r.pages(p)).collect();
        let pool = &sink.alloc.pool;
        let base_pages = base.page_count();
        let (holes, largest) = sink.alloc.holes();
        let holes = holes.saturating_sub(reserve);
        clean::tail_to_move(&kept, p, sink.alloc.end, holes, largest, |page| {
            if kept_pages.contains(&page) {
                clean::TailPage::Kept
            } else if pool.contains_key(&page)
                || (page < base_pages
                    && (metadata.contains(page) || old_payload_pages.contains(&page)))
            {
                clean::TailPage::Leaves
            } else {
                clean::TailPage::Stays
            }
        })
    };
    move_payloads(tail, &mut sink, &mut kept, &mut summary)?;
    summary.nodes_removed = old_nodes
        .iter()
        .filter(|n| !seen.contains(&(n.level, n.x.get(), n.y.get())))
        .count() as u64;
    summary.clusters_changed = changed_clusters(base, editor)?;

    // The header and tables: one compressed bundle when small (format §6.7), in pages of
    // their own otherwise.
    let header = DatasetHeader::of_model(model, &base.header().metadata).encode();
    let refs = PayloadRefs {
        grid: grid_ref,
        block: block_ref,
        against,
        grid_against,
        grid_raw_bitmap,
        grid_voids,
        shapes,
    };
    let bundled = tables::bundle_metadata(
        model,
        &refs,
        &header,
        p,
        txn,
        bundle_limit,
        COMMIT_ZSTD_LEVEL,
    )?;
    let (dataset_header, roots, bundle) = match bundled {
        Some(b) => {
            let at = sink.payload(b.stored)?;
            (
                b.dataset_header,
                b.roots,
                tables::bundle_at(b.reference, at.offset),
            )
        }
        None => {
            let dataset_header = sink.blob(&header, tag::DATASET_HEADER)?;
            let roots = tables::write_tables(model, &refs, &mut sink)?;
            (dataset_header, roots, BundleRef::default())
        }
    };
    sink.finish()?;
    let written = sink.written;

    // What this commit frees: the old state's metadata pages, and payload pages no kept
    // payload touches.
    let kept_pages: HashSet<u64> = kept.iter().flat_map(|r| r.pages(p)).collect();
    let mut freed: Vec<u64> = (2..base.page_count())
        .filter(|&page| metadata.contains(page))
        .collect();
    // The old bundle (if any) is a payload no new record keeps (in `old_payload_pages`).
    freed.extend(
        old_payload_pages
            .into_iter()
            .filter(|pg| !kept_pages.contains(pg)),
    );
    summary.pages_freed = freed.len() as u64;
    for page in freed {
        alloc.free(page, txn);
    }
    alloc.trim(min_pages);

    let (free_list, free_pages) = write_free_list(io.as_ref(), &mut alloc, p, txn)?;
    summary.pages_written = written + free_pages;
    summary.pages_reused = alloc.reused;

    let length = alloc.end * u64::from(p);
    summary.file_length = length;
    let state = StateRoots {
        dataset_header,
        cluster_directory: roots.cluster_directory,
        node_table: roots.node_table,
        block_table: roots.block_table,
        free_list,
        adjacency: roots.adjacency,
    };
    let flags = COMMIT_RECOVERY_NEEDED | COMMIT_PAYLOAD_SLACK;
    let record = CommitRecord::new(p, txn, length, flags, state).with_bundle(bundle);
    // Step 3: a grown file gets its length before anything refers to it; then sync.
    let e = |err| Error::io(io.name(), err);
    if length > io.len().map_err(e)? {
        io.set_len(length).map_err(e)?;
    }
    io.sync().map_err(e)?;
    Ok((record, summary))
}

/// Writes the free list of `alloc`'s pool, last: into a reusable run when taking it leaves
/// the page count the list needs unchanged, else appended. Returns its root and its pages.
fn write_free_list<I: Io>(io: &I, alloc: &mut Alloc, p: u32, txn: u64) -> Result<(TreeRef, u64)> {
    let need = |count: usize| tree::pages_needed(count as u64, FREE.record_size, p);
    let k = need(alloc.pool.len());
    if k == 0 {
        return Ok((tree::empty(FREE.record_size), 0));
    }
    let first = match alloc.reusable_run(k) {
        Some(first) if need(alloc.pool.len() - usize::try_from(k).unwrap_or(0)) == k => {
            alloc.take(first, k)
        }
        _ => alloc.append(k),
    };
    let records: Vec<u8> = free_entries(&alloc.pool);
    let mut sink = CommitSink::new(io, alloc, p, txn);
    Ok((sink.tree_at(first, &records, FREE)?, k))
}

fn free_entries(pool: &BTreeMap<u64, u64>) -> Vec<u8> {
    let mut out = Vec::with_capacity(pool.len() * FREE.record_size);
    for (&page, &freed_txn) in pool {
        out.extend_from_slice(FreeEntry::encode(&FreePage { page, freed_txn }).as_bytes());
    }
    out
}

/// The clusters whose cut differs between `base` and the editor's model.
fn changed_clusters<I: Io>(base: &SnapshotStore<I>, editor: &ModelEditor) -> Result<Vec<usize>> {
    let tree = editor.model().tree();
    let mut changed = Vec::new();
    for (c, cluster) in editor.model().clusters().iter().enumerate() {
        let new: Vec<(u64, u8)> = cluster
            .nodes
            .iter()
            .map(|&i| (tree.node(i).key.0, tree.node(i).level))
            .collect();
        let old: Vec<(u64, u8)> = match base.clusters().get(c) {
            Some(info) => base
                .scan_codes(c, 0..info.nodes())?
                .map(|e| e.map(|e| (e.key.0, e.level)))
                .collect::<Result<_>>()?,
            None => Vec::new(),
        };
        if new != old {
            changed.push(c);
        }
    }
    Ok(changed)
}
