//! Decoding payloads, and the ancestors they are coded against: one home for what a reader
//! does between a CRC-checked stored payload and the heights it draws.
//!
//! A physical block may be coded against its parent node's grid (format 4), and a grid
//! against its parent's (format 5), so decoding one may need a chain of ancestors, up to a
//! grid coded alone (at most the root). This room finds which node a payload is coded against
//! (checked to be its parent: I-10, I-11), decodes each ancestor once and keeps what it
//! decoded up to [`super::ANCESTOR_CACHE_BYTES`] (`ancestors`), and decodes a scene's worth of payloads at once
//! ([`Store::decode_payloads`]: every payload and the ancestors it needs in one coalesced
//! batch read, a round per tree level on a remote source, then decoded from the root down on
//! every core). The bytes themselves are decoded by [`crate::format::payload`]; the pages and
//! records come from `read`.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

use rayon::prelude::*;

use super::source::Source;
use super::{Ahead, Store};
use crate::error::{Error, Result};
use crate::format::payload::{self, BlockView, GridView, ParentGrid, Placement};
use crate::format::{Invariant, PayloadRef, StoredBlock, StoredNode, Violation};
use crate::model::SampleRect;

/// A payload to read and decode: a node's coarse grid (`level` above the finest), or physical
/// block `(x, y)` at the finest level (`node`: its node, when the tree reaches it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Wanted {
    /// The node, when it is one (always, above the finest level).
    pub node: Option<u32>,
    /// Its level.
    pub level: u8,
    /// Its column among the level's nodes.
    pub x: u32,
    /// Its row.
    pub y: u32,
    /// Its payload.
    pub payload: PayloadRef,
}

/// A scene block, read and decoded.
#[derive(Clone, Debug)]
pub struct LoadedBlock {
    /// Its stored (coded) payload, as the file holds it.
    pub stored: Arc<[u8]>,
    /// Samples along a row of `heights`: the grid side `b` for a node, the block's width
    /// within the data for a physical block.
    pub width: u32,
    /// Rows of `heights`.
    pub height: u32,
    /// The heights it draws, row-major from the north-west corner, voids mended (the
    /// node's grid, or the block's full-resolution samples).
    pub heights: Arc<[f32]>,
    /// Payload bytes read for it besides its own: the stored grids of the ancestors its
    /// payload is coded against (format 4, 5), each counted with the first block of a load
    /// whose chain reaches it, else 0.
    pub parent_bytes: u64,
}

impl LoadedBlock {
    /// Bytes of memory it holds.
    pub fn memory(&self) -> u64 {
        self.stored.len() as u64 + 4 * self.heights.len() as u64
    }
}

/// The decoded `b × b` heights of a node's grid that a caller already holds (for example a
/// block it keeps resident), by node index and record; `None` when it holds none.
pub type HeldGrid<'a> = dyn Fn(u32, &StoredNode) -> Option<Arc<[f32]>> + Sync + 'a;

impl<S: Source> Store<S> {
    /// Physical block `(x, y)`: its full-resolution samples, checked against their CRC, then
    /// decoded (format 2; a 1.x file's are read zero-copy from a mapping). A block coded
    /// against its parent's grid (format 4) reads and decodes that grid too.
    pub fn block(&self, x: u32, y: u32) -> Result<Block<'_>> {
        let info = self.stored_block(x, y)?;
        let bytes = self.payload(info.payload)?;
        self.block_from(x, y, info, bytes)
    }

    /// Physical block `(x, y)` of block record `info` from its stored payload `bytes`
    /// (already checked against their CRC, by [`Store::payload`] or [`Store::payloads`]).
    /// A block coded against its parent's grid reads that grid ([`Store::block_with`] takes
    /// one already read).
    pub fn block_from<'a>(
        &self,
        x: u32,
        y: u32,
        info: StoredBlock,
        bytes: Cow<'a, [u8]>,
    ) -> Result<Block<'a>> {
        let parent = match self.against_node(x, y, &info)? {
            Some((index, node)) => Some(self.parent_grid(index, &node)?),
            None => None,
        };
        self.block_with(x, y, info, bytes, parent.as_deref())
    }

    /// [`Store::block`] for callers that read many blocks in turn: the grid a block is coded
    /// against is kept in `parent` and reused by the next block coded against the same one
    /// (siblings), instead of being read again.
    pub fn block_reusing(
        &self,
        x: u32,
        y: u32,
        parent: &mut Option<Arc<ParentGrid>>,
    ) -> Result<Block<'_>> {
        let info = self.stored_block(x, y)?;
        self.keep_parent(x, y, &info, parent)?;
        let bytes = self.payload(info.payload)?;
        self.block_with(x, y, info, bytes, parent.as_deref())
    }

    /// Makes `parent` hold the grid block `(x, y)` of record `info` is coded against, reading
    /// it only when `parent` holds another (or none); leaves it as it is for a block coded
    /// alone. What [`Store::block_reusing`] and the validator share.
    pub(crate) fn keep_parent(
        &self,
        x: u32,
        y: u32,
        info: &StoredBlock,
        parent: &mut Option<Arc<ParentGrid>>,
    ) -> Result<()> {
        if let Some((index, node)) = self.against_node(x, y, info)? {
            if parent.as_ref().is_none_or(|p| p.node != index) {
                *parent = Some(self.parent_grid(index, &node)?);
            }
        }
        Ok(())
    }

    /// The decoded grid of node `index` (`node`, above the finest level), as the payloads
    /// coded against it decode with. Decoding a grid coded against its parent's (format 5)
    /// needs that grid first, and so on up to one coded alone; readers that walk the tree
    /// (windows, `extract`, the validator) ask for the same ancestors again and again, so
    /// those decoded are kept, up to a budget (`ancestors`).
    pub fn parent_grid(&self, index: u32, node: &StoredNode) -> Result<Arc<ParentGrid>> {
        if let Some(g) = self.cached_parent_grid(index, node) {
            return Ok(g);
        }
        let grid = Arc::new(self.parent_of(index, node, &self.grid(node)?));
        self.keep_parent_grid(&grid);
        Ok(grid)
    }

    /// The decoded grid of node `index` (`node`) if the store's cache of ancestors holds it.
    pub(crate) fn cached_parent_grid(
        &self,
        index: u32,
        node: &StoredNode,
    ) -> Option<Arc<ParentGrid>> {
        self.lock_ancestors().get(index, node.payload)
    }

    /// Puts `grid`, just decoded, in the store's cache of ancestors (which drops the least
    /// recently used beyond its budget).
    pub(crate) fn keep_parent_grid(&self, grid: &Arc<ParentGrid>) {
        self.lock_ancestors().put(grid);
    }

    fn lock_ancestors(&self) -> std::sync::MutexGuard<'_, super::ancestors::AncestorCache> {
        // A panic elsewhere cannot leave the cache half changed: take it as it is.
        self.ancestors
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// How many grids that payloads are coded against this store has decoded since it
    /// opened (each ancestor a scene or read needed and the cache did not hold).
    pub fn ancestors_decoded(&self) -> u64 {
        self.lock_ancestors().decoded()
    }

    /// How many of [`Store::ancestors_decoded`] were decoded a second time or more (the
    /// cache had dropped them): what a camera path within the budget keeps at zero.
    #[cfg(any(test, feature = "testing"))]
    pub fn ancestors_decoded_again(&self) -> u64 {
        self.lock_ancestors().decoded_again()
    }

    /// Sets the budget of the cache of decoded ancestors, in bytes (default
    /// [`super::ANCESTOR_CACHE_BYTES`]): a reader that keeps many stores open (a dataset's
    /// tiles) gives each a share; 0 keeps none. What no longer fits is dropped.
    pub fn set_ancestor_budget(&self, bytes: u64) {
        self.lock_ancestors().set_budget(bytes);
    }

    /// The node whose grid `node`'s grid is coded against, if it is (format 5): checked to be
    /// its parent, the node at the level above covering it (I-10).
    pub fn grid_against_node(&self, node: &StoredNode) -> Result<Option<(u32, StoredNode)>> {
        if !node.grid_against_parent {
            return Ok(None);
        }
        let at = || format!("node at level {} ({}, {})", node.level, node.x, node.y);
        let Some(index) = node.parent.filter(|_| self.commit.grids_against_parents()) else {
            return Err(self.corrupt(Violation::new(
                Invariant::NodeTable,
                at(),
                format!(
                    "a grid coded against its parent, which {} in format {}.{}",
                    if node.parent.is_none() {
                        "the root has not"
                    } else {
                        "no grid may be"
                    },
                    self.commit.major.get(),
                    self.commit.minor.get()
                ),
            )));
        };
        let parent = self.node(index)?;
        if node.level == 0
            || (parent.level, parent.x, parent.y) != (node.level - 1, node.x / 2, node.y / 2)
        {
            return Err(self.corrupt(Violation::new(
                Invariant::NodeTable,
                at(),
                format!(
                    "its grid is coded against node {index} at level {} ({}, {}), not its parent",
                    parent.level, parent.x, parent.y
                ),
            )));
        }
        Ok(Some((index, parent)))
    }

    /// The node whose grid block `(x, y)` of record `info` is coded against, if any: checked
    /// to be the block's parent, the node at the level above covering it (format 4, I-11).
    pub fn against_node(
        &self,
        x: u32,
        y: u32,
        info: &StoredBlock,
    ) -> Result<Option<(u32, StoredNode)>> {
        let Some(index) = info.against else {
            return Ok(None);
        };
        let at = || format!("block ({x}, {y})");
        let finest = self.domain().finest_level();
        if !self.commit.blocks_against_parents() || finest == 0 {
            return Err(self.corrupt(Violation::new(
                Invariant::BlockTable,
                at(),
                format!(
                    "coded against node {index}, which format {}.{} has no field for",
                    self.commit.major.get(),
                    self.commit.minor.get()
                ),
            )));
        }
        let node = self.node(index)?;
        if (node.level, node.x, node.y) != (finest - 1, x / 2, y / 2) {
            return Err(self.corrupt(Violation::new(
                Invariant::BlockTable,
                at(),
                format!(
                    "coded against node {index} at level {} ({}, {}), not its parent",
                    node.level, node.x, node.y
                ),
            )));
        }
        Ok(Some((index, node)))
    }

    /// [`Store::block_from`] with the grid the block is coded against, if it is, already
    /// read (`parent`, made by [`Store::parent_grid`] for the node [`Store::against_node`] names).
    pub fn block_with<'a>(
        &self,
        x: u32,
        y: u32,
        info: StoredBlock,
        bytes: Cow<'a, [u8]>,
        parent: Option<&ParentGrid>,
    ) -> Result<Block<'a>> {
        let d = self.domain();
        let at = || format!("block ({x}, {y})");
        let rect = d
            .footprint(d.finest_level(), x, y)
            .intersect(&d.data_rect())
            .ok_or_else(|| {
                self.corrupt(Violation::new(
                    Invariant::BlockTable,
                    at(),
                    "outside the data",
                ))
            })?;
        let (w, h) = (info.width, info.height);
        if u64::from(w) != rect.col1 - rect.col0 + 1 || u64::from(h) != rect.row1 - rect.row0 + 1 {
            return Err(self.corrupt(Violation::new(
                Invariant::BlockTable,
                at(),
                format!("{w} x {h} samples; its footprint within the data is {rect:?}"),
            )));
        }
        let bytes = if self.commit.payloads_coded() {
            let against = match (info.against, parent) {
                (None, _) => None,
                (Some(n), Some(p)) if p.node == n => Some(p),
                (Some(n), _) => {
                    return Err(Error::Internal(format!(
                        "block ({x}, {y}) is coded against node {n}, whose grid was not given"
                    )))
                }
            };
            let decoded =
                payload::decode(
                    &bytes,
                    &Placement::block(rect, info.void_count),
                    against,
                    self.commit.payload_codes(),
                )
                .map_err(|e| self.corrupt(Violation::new(Invariant::Payload, at(), e)))?;
            Cow::Owned(decoded)
        } else {
            bytes
        };
        if BlockView::new(&bytes, w, h, info.void_count).is_none() {
            return Err(self.corrupt(Violation::new(
                Invariant::Payload,
                at(),
                format!("{} payload bytes for {w} x {h} samples", bytes.len()),
            )));
        }
        Ok(Block { rect, info, bytes })
    }

    /// The coarse grid of `node` (a node above the finest level), checked against its CRC.
    pub fn grid(&self, node: &StoredNode) -> Result<Grid<'_>> {
        self.check_grid_record(node)?;
        let bytes = self.payload(node.payload)?;
        self.grid_with_ancestors(node, bytes)
    }

    /// The coarse grid of `node` from its stored payload `bytes` (already checked against
    /// their CRC, by [`Store::payload`] or [`Store::payloads`]). A grid coded against its
    /// parent's (format 5) decodes with that grid, read (or taken from the store's cache of
    /// ancestors) as [`Store::parent_grid`] does.
    pub fn grid_from<'a>(&self, node: &StoredNode, bytes: Cow<'a, [u8]>) -> Result<Grid<'a>> {
        // The record first: a grid its file's version cannot hold is refused as what it is,
        // before its ancestors are decoded (whose damage would hide it).
        self.check_grid_record(node)?;
        self.grid_with_ancestors(node, bytes)
    }

    /// [`Store::grid_from`] for a record [`Store::check_grid_record`] has passed.
    fn grid_with_ancestors<'a>(
        &self,
        node: &StoredNode,
        bytes: Cow<'a, [u8]>,
    ) -> Result<Grid<'a>> {
        let parent = match self.grid_against_node(node)? {
            Some((index, p)) => Some(self.parent_grid(index, &p)?),
            None => None,
        };
        self.decode_grid(node, bytes, parent.as_deref())
    }

    /// Refuses a node that has no grid (a finest-level one: an invalid argument) and a grid
    /// record that no grid of this file can have: a node outside the domain, or thinned where
    /// the file's version, its header or its grid size does not allow it.
    fn check_grid_record(&self, node: &StoredNode) -> Result<()> {
        let d = self.domain();
        if node.level >= d.finest_level() {
            return Err(Error::InvalidArgument(
                "finest-level nodes have physical blocks, not grids".into(),
            ));
        }
        let size = d.block_size();
        let at = || format!("node at level {} ({}, {})", node.level, node.x, node.y);
        if !d.exists(node.level, node.x, node.y) {
            return Err(self.corrupt(Violation::new(
                Invariant::NodeTable,
                at(),
                "not a node of the domain",
            )));
        }
        let thin = node.grid_thin;
        if thin > 0
            && (!self.commit.grids_thinned()
                || !self.header().thinned_by_area
                || (1u32 << thin) >= size)
        {
            return Err(self.corrupt(Violation::new(
                Invariant::NodeTable,
                at(),
                format!(
                    "a grid thinned by 2^{thin}, which format {}.{} with {size}-sample grids \
                     and a header {} flag 16 cannot hold",
                    self.commit.major.get(),
                    self.commit.minor.get(),
                    if self.header().thinned_by_area {
                        "with"
                    } else {
                        "without"
                    }
                ),
            )));
        }
        Ok(())
    }

    /// [`Store::grid_from`] with the grid `node`'s is coded against, if it is, already
    /// decoded (`parent`, for the node [`Store::grid_against_node`] names).
    pub fn grid_with<'a>(
        &self,
        node: &StoredNode,
        bytes: Cow<'a, [u8]>,
        parent: Option<&ParentGrid>,
    ) -> Result<Grid<'a>> {
        self.check_grid_record(node)?;
        self.decode_grid(node, bytes, parent)
    }

    /// [`Store::grid_with`] for a record [`Store::check_grid_record`] has passed.
    fn decode_grid<'a>(
        &self,
        node: &StoredNode,
        bytes: Cow<'a, [u8]>,
        parent: Option<&ParentGrid>,
    ) -> Result<Grid<'a>> {
        let d = self.domain();
        let size = d.block_size();
        let at = || format!("node at level {} ({}, {})", node.level, node.x, node.y);
        let dims = d.grid_dims(node.level, node.x, node.y);
        let has_voids = node.grid_has_voids;
        let bytes = if self.commit.payloads_coded() {
            let against = if node.grid_against_parent {
                match parent {
                    Some(p) if Some(p.node) == node.parent => Some(p),
                    _ => {
                        return Err(Error::Internal(format!(
                            "the grid of the {} is coded against its parent's, which was not given",
                            at()
                        )))
                    }
                }
            } else {
                None
            };
            let decoded =
                payload::decode(
                    &bytes,
                    &Placement::grid(d, node),
                    against,
                    self.commit.payload_codes(),
                )
                .map_err(|e| {
                    self.corrupt(Violation::new(
                        Invariant::Payload,
                        format!("grid at byte {}", node.payload.offset),
                        e,
                    ))
                })?;
            Cow::Owned(decoded)
        } else {
            bytes
        };
        if GridView::new(&bytes, size, dims, has_voids).is_none() {
            return Err(self.corrupt(Violation::new(
                Invariant::Payload,
                format!("grid at byte {}", node.payload.offset),
                format!("{} bytes for a {size} x {size} grid", bytes.len()),
            )));
        }
        Ok(Grid {
            size,
            dims,
            has_voids,
            bytes,
        })
    }

    /// Reads and decodes `blocks` (in the order given), coalescing reads of payloads at most
    /// `gap` bytes apart, taking the grids a payload is coded against from `held` when it has
    /// them instead of reading and decoding them (and their own ancestors) again: a renderer
    /// that drew a parent in an earlier frame still holds its grid when the parent's children
    /// come into view. A payload coded against its parent's grid needs that grid, and that
    /// grid may need its own parent's, up to one coded alone: those ancestors are read in the
    /// same batch (a parent lies just before its children in the file) and their bytes count
    /// among the load's ([`LoadedBlock::parent_bytes`]), but they are not among the blocks
    /// returned. Ancestors decoded go into the store's small cache ([`Store::parent_grid`]),
    /// and the next load takes them from there (its bytes count only what it reads).
    pub fn decode_payloads(
        &self,
        blocks: &[Wanted],
        gap: u64,
        held: &HeldGrid<'_>,
    ) -> Result<Vec<LoadedBlock>> {
        let store = self;
        let finest = store.domain().finest_level();
        let b = store.domain().block_size();
        // On a source that reads ahead (a remote object), each step below names its lookups
        // first, so that they cost a round together rather than one each.
        let ahead = store.prefetches();
        if ahead {
            // The blocks' nodes (a scene just read them: usually at hand already), then the
            // block records and the ancestors the payloads are coded against, together.
            let mut a = Ahead::new();
            for i in blocks.iter().filter_map(|b| b.node) {
                a.nodes(i, i);
            }
            store.fetch_ahead(&a)?;
            let mut a = Ahead::new();
            let held = store.top().map_or(0, |t| t.levels);
            for block in blocks {
                if block.level == finest {
                    a.block(block.x, block.y);
                }
                if let Some(i) = block.node {
                    let node = store.node(i)?;
                    if block.level == finest || node.grid_against_parent {
                        a.ancestors_below(&node, finest, held);
                    }
                }
            }
            store.fetch_ahead(&a)?;
        }
        // Block records and grid nodes, and the node each block's payload is coded against.
        let mut records = Vec::with_capacity(blocks.len());
        let mut nodes = Vec::with_capacity(blocks.len());
        for block in blocks {
            if block.level == finest {
                records.push(Some(store.stored_block(block.x, block.y)?));
                nodes.push(None);
            } else {
                let index = block.node.ok_or_else(|| {
                    Error::Internal("a block above the finest level without a node".into())
                })?;
                records.push(None);
                nodes.push(Some(store.node(index)?));
            }
        }
        if ahead {
            // The grids coded against that the guesses above missed (a physical block below a
            // pruned leaf names its own).
            let mut a = Ahead::new();
            for i in records.iter().flatten().filter_map(|r| r.against) {
                a.nodes(i, i);
            }
            store.fetch_ahead(&a)?;
        }
        let mut needs: Vec<Option<(u32, StoredNode)>> = Vec::with_capacity(blocks.len());
        for ((block, record), node) in blocks.iter().zip(&records).zip(&nodes) {
            needs.push(match (record, node) {
                (Some(info), _) => store.against_node(block.x, block.y, info)?,
                (None, Some(node)) => store.grid_against_node(node)?,
                (None, None) => None,
            });
        }
        // The ancestors to decode first: the grids the blocks need, then the grids those need,
        // up to grids coded alone or held by the caller (which need nothing more). A level at a
        // time, each level's parents fetched ahead together.
        let mut grids: HashMap<u32, Arc<ParentGrid>> = HashMap::new();
        let mut to_read: BTreeMap<u32, StoredNode> = BTreeMap::new();
        let mut wave: Vec<(u32, StoredNode)> = needs.iter().flatten().copied().collect();
        while !wave.is_empty() {
            let mut up = Vec::new();
            for (index, node) in wave {
                if grids.contains_key(&index) || to_read.contains_key(&index) {
                    continue;
                }
                let have = held(index, &node)
                    .and_then(|h| {
                        ParentGrid::from_expanded(
                            index,
                            node.payload,
                            &Placement::grid(store.domain(), &node),
                            &h,
                        )
                    })
                    .map(Arc::new)
                    .or_else(|| store.cached_parent_grid(index, &node));
                if let Some(grid) = have {
                    grids.insert(index, grid);
                    continue;
                }
                if node.grid_against_parent {
                    up.push(node);
                }
                to_read.insert(index, node);
            }
            if ahead {
                let mut a = Ahead::new();
                for i in up.iter().filter_map(|n| n.parent) {
                    a.nodes(i, i);
                }
                store.fetch_ahead(&a)?;
            }
            wave = Vec::with_capacity(up.len());
            for node in &up {
                wave.extend(store.grid_against_node(node)?);
            }
        }
        let ancestors: Vec<(u32, StoredNode)> = to_read.into_iter().collect();
        let refs: Vec<_> = blocks
            .iter()
            .map(|b| b.payload)
            .chain(ancestors.iter().map(|(_, n)| n.payload))
            .collect();
        let mut payloads = store.payloads(&refs, gap)?;
        let ancestor_payloads = payloads.split_off(blocks.len());
        // Ancestors decode from the root down, a level at a time (each needs the one above).
        let mut by_level: BTreeMap<u8, Vec<Ancestor<'_>>> = BTreeMap::new();
        for ((index, node), bytes) in ancestors.iter().zip(ancestor_payloads) {
            by_level
                .entry(node.level)
                .or_default()
                .push((*index, *node, bytes));
        }
        for (_, level) in by_level {
            let decode = |(index, node, bytes): Ancestor<'_>| {
                let parent = node
                    .grid_against_parent
                    .then(|| node.parent.and_then(|p| grids.get(&p)))
                    .flatten();
                let grid = store.grid_with(&node, bytes, parent.map(|p| &**p))?;
                Ok((index, Arc::new(store.parent_of(index, &node, &grid))))
            };
            let decoded: Vec<(u32, Arc<ParentGrid>)> = if level.len() >= PARALLEL_FROM {
                level.into_par_iter().map(decode).collect::<Result<_>>()?
            } else {
                level.into_iter().map(decode).collect::<Result<_>>()?
            };
            for (index, grid) in decoded {
                store.keep_parent_grid(&grid);
                grids.insert(index, grid);
            }
        }
        // Each ancestor read is counted once, with the first block whose chain reaches it.
        let read_len: HashMap<u32, u64> = ancestors
            .iter()
            .map(|(i, n)| (*i, u64::from(n.payload.len)))
            .collect();
        let mut counted = HashSet::new();
        let parent_bytes: Vec<u64> = needs
            .iter()
            .map(|need| {
                let mut sum = 0;
                let mut at = need.map(|(i, _)| i);
                while let Some(i) = at {
                    let Some(len) = read_len.get(&i) else { break };
                    if counted.insert(i) {
                        sum += len;
                    }
                    at = ancestors
                        .binary_search_by_key(&i, |(k, _)| *k)
                        .ok()
                        .and_then(|k| {
                            let n = &ancestors[k].1;
                            n.grid_against_parent.then_some(n.parent).flatten()
                        });
                }
                sum
            })
            .collect();
        let decode = |((((block, info), node), bytes), &parent_bytes): Job<'_, '_>| {
            let stored: Arc<[u8]> = Arc::from(&*bytes);
            if let Some(info) = *info {
                let parent = info.against.and_then(|n| grids.get(&n));
                let decoded =
                    store.block_with(block.x, block.y, info, bytes, parent.map(|p| &**p))?;
                let view = decoded.view();
                Ok(LoadedBlock {
                    stored,
                    width: view.width,
                    height: view.height,
                    heights: view.mended_shared(),
                    parent_bytes,
                })
            } else {
                let node = node.as_ref().ok_or_else(|| {
                    Error::Internal("a block above the finest level without a node".into())
                })?;
                let parent = node
                    .grid_against_parent
                    .then(|| node.parent.and_then(|p| grids.get(&p)))
                    .flatten();
                let grid = store.grid_with(node, bytes, parent.map(|p| &**p))?;
                Ok(LoadedBlock {
                    stored,
                    width: b,
                    height: b,
                    heights: Arc::from(grid.view().expanded()),
                    parent_bytes,
                })
            }
        };
        // Decoding is most of a warm load (pco): a scene's blocks decode on every core, in
        // order. A few blocks decode on the calling thread, cheaper than handing them out.
        if blocks.len() >= PARALLEL_FROM {
            blocks
                .par_iter()
                .zip(records.par_iter())
                .zip(nodes.par_iter())
                .zip(payloads)
                .zip(parent_bytes.par_iter())
                .map(decode)
                .collect()
        } else {
            blocks
                .iter()
                .zip(records.iter())
                .zip(nodes.iter())
                .zip(payloads)
                .zip(parent_bytes.iter())
                .map(decode)
                .collect()
        }
    }

    /// The grid of node `index` (`node`) as the payloads coded against it see it.
    fn parent_of(&self, index: u32, node: &StoredNode, grid: &Grid<'_>) -> ParentGrid {
        let layout: Vec<f32> = grid.view().stored().iter().map(|h| h.get()).collect();
        ParentGrid::new(
            index,
            node.payload,
            &Placement::grid(self.domain(), node),
            layout,
        )
    }
}

/// A physical block read from a store.
#[derive(Clone, Debug)]
pub struct Block<'a> {
    /// The samples it holds: its footprint clipped to the data.
    pub rect: SampleRect,
    /// Its entry in the block table.
    pub info: StoredBlock,
    bytes: Cow<'a, [u8]>,
}

impl Block<'_> {
    /// The samples and stand-ins, in place.
    pub fn view(&self) -> BlockView<'_> {
        let b = &self.info;
        BlockView::new(&self.bytes, b.width, b.height, b.void_count)
            .unwrap_or_else(|| unreachable!("the length was checked when the block was read"))
    }

    /// The block's layout (`format/payload.rs`): the samples then the stand-ins, as
    /// little-endian `f32`, decoded from the stored payload.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// A coarse grid read from a store.
#[derive(Clone, Debug)]
pub struct Grid<'a> {
    size: u32,
    dims: (u32, u32),
    has_voids: bool,
    bytes: Cow<'a, [u8]>,
}

impl Grid<'_> {
    /// The heights and void flags, in place.
    pub fn view(&self) -> GridView<'_> {
        GridView::new(&self.bytes, self.size, self.dims, self.has_voids)
            .unwrap_or_else(|| unreachable!("the length was checked when the grid was read"))
    }

    /// The grid's layout (`format/payload.rs`): heights then the void bitmap, decoded from
    /// the stored payload.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// One block to decode: the block, its record (physical blocks) or node (grids), its stored
/// bytes, and the bytes of the ancestors it accounts for.
type Job<'a, 'b> = (
    (
        (
            (&'a Wanted, &'a Option<StoredBlock>),
            &'a Option<StoredNode>,
        ),
        Cow<'b, [u8]>,
    ),
    &'a u64,
);

/// An ancestor to decode: its index, record and stored bytes.
type Ancestor<'b> = (u32, StoredNode, Cow<'b, [u8]>);

/// Loads of at least this many blocks decode in parallel.
const PARALLEL_FROM: usize = 8;
