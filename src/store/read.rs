//! Reading an open store: table records, payloads checked against their CRC, and range scans
//! over the cluster indexes.
//!
//! Everything here reads pages through [`Pages`] and decodes them with [`crate::format`];
//! what it hands out are plain values ([`StoredNode`], [`StoredBlock`], [`ScanEntry`]) and
//! stored payload bytes that borrow from the source when it can lend. Decoding them is
//! `decode`'s job.

use std::borrow::Cow;
use std::ops::{Range, RangeInclusive};

use serde::Serialize;
use zerocopy::FromBytes;

use super::btree::{self, Seek};
use super::pages::{PageSet, Pages};
use super::source::{self, Source};
use super::Store;
use crate::curve::HilbertKey;
use crate::error::{Error, Result};

use crate::format::tables::{self, state_trees};
use crate::format::{
    blob, AdjacencyEntry, BlockRecord, ClusterInfo, FreeEntry, FreePage, IndexEntry, Invariant,
    NodeRecord, PayloadRef, ScanEntry, StoredBlock, StoredNode, TreeRef, TreeSpec, Violation,
};

/// Where a file's bytes go, section by section.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Layout {
    /// Bytes per page.
    pub page_size: u32,
    /// Bytes in the committed file.
    pub file_length: u64,
    /// The two commit slots.
    pub commit_pages: u64,
    /// Dataset header pages.
    pub dataset_header_pages: u64,
    /// Cluster directory pages.
    pub cluster_directory_pages: u64,
    /// Pages of the top of the tree (format 6.2), 0 when the state has none.
    pub top_pages: u64,
    /// Node table pages.
    pub node_table_pages: u64,
    /// Block table pages.
    pub block_table_pages: u64,
    /// Free list pages.
    pub free_list_pages: u64,
    /// Free pages (the free list's entries): space transactions left for reuse.
    pub free_pages: u64,
    /// Adjacency table pages.
    pub adjacency_pages: u64,
    /// Index pages of each cluster.
    pub cluster_index_pages: Vec<u64>,
    /// Payload bytes of the physical blocks.
    pub block_bytes: u64,
    /// Payload bytes of the coarse grids.
    pub grid_bytes: u64,
    /// Stored bytes of the metadata bundle (format §6.7), 0 when the state has none. The
    /// page counts above are of file pages: tables in the bundle count here.
    pub bundle_bytes: u64,
    /// Pages the bundle decompresses to.
    pub bundle_pages: u64,
}

impl<S: Source> Store<S> {
    /// The corruption error of this store's file.
    pub(crate) fn corrupt(&self, v: Violation) -> Error {
        v.in_file(self.src.name())
    }

    /// The id a commit on this state takes (`txn_id + 1`); an error when this state has the
    /// last id a file can hold (`MAX_TXN_ID`, format §2).
    pub(crate) fn next_txn_id(&self) -> Result<u64> {
        crate::format::commit::next_txn_id(self.txn_id()).ok_or_else(|| {
            Error::unsupported(
                self.src.name(),
                format!(
                    "transaction {} is the last a file can hold (2^62 - 1): rebuild the file \
                     to commit again",
                    self.txn_id()
                ),
            )
        })
    }

    /// Page access for lookups: each page checked on its first read, then cached.
    pub(crate) fn pages(&self) -> Pages<'_, S> {
        Pages {
            src: &self.src,
            page_size: self.page_size,
            page_count: self.page_count,
            check: false,
            state: self.binding(),
            cache: Some(&self.cache),
            wrap_guard: self.wrap_guard,
            bundle: self.bundle.as_deref(),
        }
    }

    /// Pages and bytes of each section (walks every table once).
    pub fn layout(&self) -> Result<Layout> {
        let pages = self.pages();
        let mut table_pages = Vec::new();
        for (spec, tree) in state_trees(&self.commit.roots, &self.clusters) {
            let mut seen = PageSet::with_bundle(self.page_count, self.bundle_pages());
            btree::walk(&pages, &tree, spec, &mut seen, &mut |_, _| Ok(()))?;
            // File pages only: a bundle's pages are counted by its stored bytes.
            table_pages.push((spec, seen.file_pages()));
        }
        let sum = |want: TreeSpec| -> u64 {
            table_pages
                .iter()
                .filter(|(s, _)| *s == want)
                .map(|(_, n)| n)
                .sum()
        };
        let cluster_index_pages = table_pages
            .iter()
            .filter(|(s, _)| *s == tables::INDEX)
            .map(|(_, n)| *n)
            .collect();
        let finest = self.domain().finest_level();
        let grid_bytes = self
            .node_records()?
            .iter()
            .filter(|n| n.level < finest)
            .map(|n| u64::from(n.payload_len.get()))
            .sum();
        let block_bytes = self
            .block_records()?
            .iter()
            .map(|b| u64::from(b.payload_len.get()))
            .sum();
        let blob = |b: &blob::BlobRef| {
            if crate::format::bundle::is_bundle_page(b.first_page.get()) {
                0
            } else {
                blob::blob_pages(b.length.get(), self.page_size)
            }
        };
        Ok(Layout {
            page_size: self.page_size,
            file_length: self.commit.file_length.get(),
            commit_pages: 2,
            dataset_header_pages: blob(&self.commit.roots.dataset_header),
            cluster_directory_pages: blob(&self.commit.roots.cluster_directory),
            top_pages: self.commit.top().map_or(0, |t| blob(&t)),
            node_table_pages: sum(tables::NODES),
            block_table_pages: sum(tables::BLOCKS),
            free_list_pages: sum(tables::FREE),
            free_pages: self.commit.roots.free_list.records.get(),
            adjacency_pages: sum(tables::ADJACENCY),
            cluster_index_pages,
            block_bytes,
            grid_bytes,
            bundle_bytes: u64::from(self.commit.bundle.stored_len.get()),
            bundle_pages: self.bundle_pages(),
        })
    }

    fn cluster(&self, cluster: usize) -> Result<&ClusterInfo> {
        self.clusters.get(cluster).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "cluster {cluster}: the store has {} (0..{})",
                self.clusters.len(),
                self.clusters.len()
            ))
        })
    }

    #[inline]
    fn record<R: FromBytes>(&self, tree: &TreeRef, spec: TreeSpec, ordinal: u64) -> Result<R> {
        btree::get_ordinal(&self.pages(), tree, spec, ordinal)?.ok_or_else(|| {
            Error::InvalidArgument(format!(
                "{} has {} records; no record {ordinal}",
                spec.name,
                tree.records.get()
            ))
        })
    }

    /// Every record of `tree`, in order.
    pub(crate) fn all_records<R: FromBytes>(
        &self,
        tree: &TreeRef,
        spec: TreeSpec,
    ) -> Result<Vec<R>> {
        let pages = self.pages();
        let mut c = btree::seek(&pages, tree, spec, Seek::Ordinal(0))?;
        // Opening walked the tree: it holds exactly this many records, all inside the file.
        let mut out = Vec::with_capacity(usize::try_from(tree.records.get()).unwrap_or(0));
        while let Some(r) = c.next_record(&pages)? {
            out.push(r);
        }
        Ok(out)
    }

    /// The record of node `index`.
    #[inline]
    pub(crate) fn node_record(&self, index: u32) -> Result<NodeRecord> {
        self.record(
            &self.commit.roots.node_table,
            tables::NODES,
            u64::from(index),
        )
    }

    /// Node `index` of the node table (Hilbert pre-order; 0 is the root), checked to be a
    /// node of the domain (I-10's level and position), so that no caller computes with a
    /// level or a position the geometry does not have. A node read before is answered from
    /// the store's memo of decoded nodes (`nodememo`) without reading the table again.
    #[inline]
    pub fn node(&self, index: u32) -> Result<StoredNode> {
        if let Some(n) = self.top.as_deref().and_then(|t| t.get(index)) {
            return self.checked_node(index, *n);
        }
        if let Some(n) = self.nodes.get(index) {
            return Ok(n);
        }
        let n = self.checked_node(index, self.node_record(index)?.decode())?;
        self.nodes.put(index, n);
        Ok(n)
    }

    #[inline]
    fn checked_node(&self, index: u32, n: StoredNode) -> Result<StoredNode> {
        let d = self.domain();
        if n.level > d.finest_level() || !d.exists(n.level, n.x, n.y) {
            return Err(self.corrupt(Violation::new(
                Invariant::NodeTable,
                format!("node {index}"),
                format!(
                    "level {} ({}, {}) is not a node of the domain ({} levels)",
                    n.level,
                    n.x,
                    n.y,
                    d.levels()
                ),
            )));
        }
        Ok(n)
    }

    /// Every node record, in Hilbert pre-order.
    pub(crate) fn node_records(&self) -> Result<Vec<NodeRecord>> {
        self.all_records(&self.commit.roots.node_table, tables::NODES)
    }

    /// Every node, in Hilbert pre-order, each checked as [`Store::node`] checks it.
    pub fn nodes(&self) -> Result<Vec<StoredNode>> {
        self.node_records()?
            .iter()
            .enumerate()
            .map(|(i, r)| self.checked_node(u32::try_from(i).unwrap_or(u32::MAX), r.decode()))
            .collect()
    }

    /// The node a scan entry names, checked to be that node (I-13).
    pub fn node_of(&self, cluster: usize, entry: &ScanEntry) -> Result<StoredNode> {
        let n = self.node(entry.node)?;
        if n.key != entry.key || n.level != entry.level {
            return Err(self.corrupt(Violation::new(
                Invariant::ClusterIndex,
                format!("cluster {cluster} index, key {}", entry.key.0),
                format!("names node {}, which is not that node", entry.node),
            )));
        }
        Ok(n)
    }

    /// The children of node `index` (`node`), in curve order with their indexes, each
    /// checked to be its child in the table's pre-order (I-10).
    pub fn children(&self, index: u32, node: &StoredNode) -> Children<'_, S> {
        Children {
            store: self,
            parent: index,
            level: node.level,
            next: index.saturating_add(1),
            end: index.saturating_add(node.subtree_len),
        }
    }

    pub(crate) fn block_ordinal(&self, x: u32, y: u32) -> Result<u64> {
        let d = self.domain();
        let (cols, rows) = d.nodes_across(d.finest_level());
        if x >= cols || y >= rows {
            return Err(Error::InvalidArgument(format!(
                "block ({x}, {y}) is outside the {cols} x {rows} blocks"
            )));
        }
        Ok(u64::from(y) * u64::from(cols) + u64::from(x))
    }

    /// The block table's description of physical block `(x, y)` (finest-level column and
    /// row).
    pub fn stored_block(&self, x: u32, y: u32) -> Result<StoredBlock> {
        let ordinal = self.block_ordinal(x, y)?;
        let r: BlockRecord =
            self.record(&self.commit.roots.block_table, tables::BLOCKS, ordinal)?;
        Ok(r.decode())
    }

    /// Every block record, row-major.
    pub(crate) fn block_records(&self) -> Result<Vec<BlockRecord>> {
        self.all_records(&self.commit.roots.block_table, tables::BLOCKS)
    }

    /// The free pages (none in a freshly built file).
    pub fn free_pages(&self) -> Result<Vec<FreePage>> {
        let records: Vec<FreeEntry> =
            self.all_records(&self.commit.roots.free_list, tables::FREE)?;
        Ok(records.iter().map(FreeEntry::decode).collect())
    }

    /// The length of a payload reference that lies within the file's pages, or the
    /// corruption error of one that does not.
    fn payload_len(&self, at: &PayloadRef) -> Result<usize> {
        let start = 2 * u64::from(self.page_size);
        let end = at.offset.checked_add(u64::from(at.len));
        let where_ = || format!("payload at byte {}", at.offset);
        if at.offset < start || end.is_none_or(|e| e > self.commit.file_length.get()) {
            return Err(self.corrupt(Violation::new(
                Invariant::Payload,
                where_(),
                format!("{} bytes do not lie within the file's pages", at.len),
            )));
        }
        usize::try_from(at.len).map_err(|_| Error::TooLarge {
            what: where_(),
            detail: format!("{} bytes do not fit in memory", at.len),
        })
    }

    /// Checks payload bytes against the CRC their reference records (I-9).
    fn check_payload(&self, at: &PayloadRef, bytes: &[u8]) -> Result<()> {
        let actual = crate::format::crc32(bytes);
        if actual != at.crc {
            // The CRC in the record binds the payload to the state (a Merkle reference): a
            // later state that reused the pages is told apart from damage by the slots.
            let v = Violation::new(
                Invariant::Payload,
                format!("payload at byte {}", at.offset),
                format!("CRC {:#010x} recorded, {actual:#010x} computed", at.crc),
            );
            return Err(super::slots::superseded_or_corrupt(
                &self.src,
                self.binding().id(),
                v,
            ));
        }
        Ok(())
    }

    /// Reads a payload and checks its CRC (I-9).
    pub fn payload(&self, at: PayloadRef) -> Result<Cow<'_, [u8]>> {
        let len = self.payload_len(&at)?;
        let bytes = source::read(&self.src, at.offset, len)?;
        self.cache.counters.payload(len);
        self.check_payload(&at, &bytes)?;
        Ok(bytes)
    }

    /// Reads many payloads, each checked against its CRC, returned in the order asked. They
    /// are read in file order, and payloads at most `gap` bytes apart share one read: a
    /// scene's payloads lie in Hilbert order, so its neighbours are often neighbours in the
    /// file, and one read instead of dozens matters for `pread` and most for a network.
    /// The bytes of a gap are read and dropped.
    pub fn payloads(&self, refs: &[PayloadRef], gap: u64) -> Result<Vec<Cow<'_, [u8]>>> {
        for r in refs {
            self.payload_len(r)?;
        }
        let mut order: Vec<usize> = (0..refs.len()).collect();
        order.sort_by_key(|&i| (refs[i].offset, refs[i].len));
        // The runs: payloads whose starts lie within `gap` of the run's end so far, as
        // (first index into `order`, end index, start byte, bytes).
        let mut runs: Vec<(usize, usize, u64, usize)> = Vec::new();
        let mut k = 0;
        while k < order.len() {
            let first = &refs[order[k]];
            let (start, mut end) = (first.offset, first.end());
            let mut last = k + 1;
            while last < order.len() {
                let r = &refs[order[last]];
                if r.offset > end.saturating_add(gap) {
                    break;
                }
                end = end.max(r.end());
                last += 1;
            }
            let span = usize::try_from(end - start).map_err(|_| Error::TooLarge {
                what: format!("payloads at byte {start}"),
                detail: format!("{} bytes do not fit in memory", end - start),
            })?;
            runs.push((k, last, start, span));
            k = last;
        }
        // One batch: a remote source fetches the runs together (one round).
        let ranges: Vec<(u64, usize)> = runs.iter().map(|r| (r.2, r.3)).collect();
        let bytes = source::read_many(&self.src, &ranges)?;
        if bytes.len() != runs.len() {
            return Err(Error::Internal("a batch read gave the wrong count".into()));
        }
        let mut out: Vec<Option<Cow<'_, [u8]>>> = vec![None; refs.len()];
        for (&(k, last, start, span), run) in runs.iter().zip(bytes) {
            self.cache.counters.payload(span);
            if run.len() != span {
                return Err(Error::Internal("a batch read gave a short run".into()));
            }
            for &i in &order[k..last] {
                let r = &refs[i];
                let from = usize::try_from(r.offset - start).unwrap_or(usize::MAX);
                let piece = run
                    .get(from..from.saturating_add(r.len as usize))
                    .ok_or_else(|| Error::Internal("a payload outside its run".into()))?;
                self.check_payload(r, piece)?;
                out[i] = Some(match &run {
                    Cow::Borrowed(all) => Cow::Borrowed(&all[from..from + r.len as usize]),
                    Cow::Owned(_) => Cow::Owned(piece.to_vec()),
                });
            }
        }
        out.into_iter()
            .map(|p| p.ok_or_else(|| Error::Internal("a payload was not read".into())))
            .collect()
    }

    /// The nodes of `cluster` whose footprint meets the Hilbert range `range` (keys of
    /// finest-level cells), in Hilbert order: one seek, then a contiguous scan.
    pub fn scan_hilbert(
        &self,
        cluster: usize,
        range: RangeInclusive<u64>,
    ) -> Result<HilbertScan<'_, S>> {
        let c = *self.cluster(cluster)?;
        let pages = self.pages();
        let mut cursor = btree::seek(&pages, c.index(), tables::INDEX, Seek::Key(*range.start()))?;
        cursor.stop_above(*range.end());
        Ok(HilbertScan {
            pages,
            cursor,
            lo: *range.start(),
            hi: *range.end(),
            finest: self.domain().finest_level(),
            done: range.is_empty(),
        })
    }

    /// The nodes of `cluster` at ordinal positions `range` (the paper's "codes a to b").
    pub fn scan_codes(&self, cluster: usize, range: Range<u64>) -> Result<CodeScan<'_, S>> {
        let c = *self.cluster(cluster)?;
        let pages = self.pages();
        let cursor = btree::seek(&pages, c.index(), tables::INDEX, Seek::Ordinal(range.start))?;
        Ok(CodeScan {
            pages,
            cursor,
            left: range.end.saturating_sub(range.start),
        })
    }

    /// The adjacency list of `cluster` along `edge` (0 north, 1 east, 2 south, 3 west): the
    /// cut's nodes touching that edge of the data, in order along it.
    pub fn adjacency(&self, cluster: usize, edge: usize) -> Result<Vec<u32>> {
        let c = *self.cluster(cluster)?;
        let range = c.adjacency.get(edge).ok_or_else(|| {
            Error::InvalidArgument(format!("edge {edge}: edges are 0..4 (N, E, S, W)"))
        })?;
        let pages = self.pages();
        let tree = &self.commit.roots.adjacency;
        let mut cursor = btree::seek(
            &pages,
            tree,
            tables::ADJACENCY,
            Seek::Ordinal(range.first.get()),
        )?;
        let mut out = Vec::new();
        for _ in 0..range.count.get() {
            match cursor.next_record::<S, AdjacencyEntry>(&pages)? {
                Some(e) => out.push(e.node.get()),
                None => break,
            }
        }
        Ok(out)
    }
}

/// The iterator of [`Store::children`]: hops from one child to the next over its subtree.
pub struct Children<'s, S: Source> {
    store: &'s Store<S>,
    parent: u32,
    level: u8,
    next: u32,
    end: u32,
}

impl<S: Source> Iterator for Children<'_, S> {
    type Item = Result<(u32, StoredNode)>;

    // Inline: a scene's descent calls this once per child; left to the partitioner, it
    // landed in another codegen unit and selection ran ~10% slower (issue 38's bench).
    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.next >= self.end {
            return None;
        }
        let c = self.next;
        let child = match self.store.node(c) {
            Ok(n) => n,
            Err(e) => {
                self.next = self.end;
                return Some(Err(e));
            }
        };
        if child.parent != Some(self.parent)
            || child.level != self.level.saturating_add(1)
            || child.subtree_len == 0
        {
            self.next = self.end;
            return Some(Err(self.store.corrupt(Violation::new(
                Invariant::NodeTable,
                format!("node {c}"),
                format!("not a child of node {} in pre-order", self.parent),
            ))));
        }
        self.next = c.saturating_add(child.subtree_len);
        Some(Ok((c, child)))
    }
}

/// The iterator of [`Store::scan_hilbert`].
pub struct HilbertScan<'a, S: Source> {
    pages: Pages<'a, S>,
    cursor: btree::Cursor<'a>,
    lo: u64,
    hi: u64,
    finest: u8,
    done: bool,
}

impl<S: Source> HilbertScan<'_, S> {
    /// Index pages read so far, the seek's descent included.
    pub fn pages_read(&self) -> u32 {
        self.cursor.pages_read
    }
}

impl<S: Source> Iterator for HilbertScan<'_, S> {
    type Item = Result<ScanEntry>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let e: IndexEntry = match self.cursor.next_record(&self.pages) {
                Ok(Some(e)) => e,
                Ok(None) => break,
                Err(err) => {
                    self.done = true;
                    return Some(Err(err));
                }
            };
            let key = e.key.get();
            if key > self.hi {
                break;
            }
            let level = e.level.min(self.finest);
            let span = HilbertKey::span(self.finest, level);
            if key.saturating_add(span - 1) < self.lo {
                continue; // the entry the seek landed on ends before the range
            }
            return Some(Ok(e.decode()));
        }
        self.done = true;
        None
    }
}

/// The iterator of [`Store::scan_codes`].
pub struct CodeScan<'a, S: Source> {
    pages: Pages<'a, S>,
    cursor: btree::Cursor<'a>,
    left: u64,
}

impl<S: Source> Iterator for CodeScan<'_, S> {
    type Item = Result<ScanEntry>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        match self.cursor.next_record::<S, IndexEntry>(&self.pages) {
            Ok(Some(e)) => Some(Ok(e.decode())),
            Ok(None) => {
                self.left = 0;
                None
            }
            Err(err) => {
                self.left = 0;
                Some(Err(err))
            }
        }
    }
}
