//! Loading a scene's blocks: their payloads read in a few coalesced reads, each checked
//! against its CRC, and decoded to the heights the block draws.
//!
//! A scene's blocks come from range scans in Hilbert order, and the writer lays payloads
//! out in that order, so the payloads of neighbouring blocks are often neighbours in the
//! file: [`crate::Store::payloads`] reads every run of them whose gaps are at most a given
//! number of bytes ([`PAYLOAD_GAP`] by default: none) in one call. Decoding (format 2 payloads are coded) is the other
//! cost of a load; [`super::Scheduler`] keeps what it decoded across frames.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

use rayon::prelude::*;

use crate::error::Result;
use crate::format::{StoredBlock, StoredNode};
use crate::store::{Ahead, ParentGrid, Source, Store};

use super::SceneBlock;

/// Payloads at most this many bytes apart are read together: 0, only payloads that touch.
/// Measured (`cargo bench --bench scene_reads`, Puget Sound 4k, tau 0.5 to 4): gaps of
/// 1 KiB save 5-20 % of the calls for 2-10 % more bytes, gaps of 4 KiB save up to 70 % of
/// the calls for up to twice the bytes. Bytes are the cost this default minimises; a
/// source where a call costs a round trip may pass a larger gap.
pub const PAYLOAD_GAP: u64 = 0;

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

/// Reads and decodes `blocks` (in the order given), coalescing reads of payloads at most
/// `gap` bytes apart. A payload coded against its parent's grid (a physical block since
/// format 4, a node's grid since 5) needs that grid, and that grid may need its own parent's,
/// up to one coded alone: those ancestors are read in the same batch (a parent lies just
/// before its children in the file) and their bytes count among the load's, but they are
/// not among the blocks returned.
pub fn load_blocks<S: Source>(
    store: &Store<S>,
    blocks: &[SceneBlock],
    gap: u64,
) -> Result<Vec<LoadedBlock>> {
    load_blocks_reusing(store, blocks, gap, &|_, _| None)
}

/// The decoded `b × b` heights of a node's grid that a caller already holds (for example a
/// block it keeps resident), by node index and record; `None` when it holds none.
pub type HeldGrid<'a> = dyn Fn(u32, &StoredNode) -> Option<Arc<[f32]>> + Sync + 'a;

/// [`load_blocks`], taking the grids a payload is coded against from `held` when it has
/// them, instead of reading and decoding them (and their own ancestors) again: a renderer
/// that drew a parent in an earlier frame still holds its grid when the parent's children
/// come into view. Ancestors it decodes go into the store's small cache
/// ([`Store::parent_grid`]), and the next load takes them from there (its bytes count only
/// what it reads).
pub fn load_blocks_reusing<S: Source>(
    store: &Store<S>,
    blocks: &[SceneBlock],
    gap: u64,
    held: &HeldGrid<'_>,
) -> Result<Vec<LoadedBlock>> {
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
        for block in blocks {
            if block.level == finest {
                a.block(block.x, block.y);
            }
            if let Some(i) = block.node {
                let node = store.node(i)?;
                if block.level == finest || node.grid_against_parent {
                    a.ancestors(&node, finest);
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
                crate::error::Error::Internal(
                    "a block above the finest level without a node".into(),
                )
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
                .and_then(|h| ParentGrid::from_expanded(store, index, &node, &h))
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
            Ok((index, Arc::new(ParentGrid::of(store, index, &node, &grid))))
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
            let decoded = store.block_with(block.x, block.y, info, bytes, parent.map(|p| &**p))?;
            let view = decoded.view();
            Ok(LoadedBlock {
                stored,
                width: view.width,
                height: view.height,
                heights: Arc::from(view.mended()),
                parent_bytes,
            })
        } else {
            let node = node.as_ref().ok_or_else(|| {
                crate::error::Error::Internal(
                    "a block above the finest level without a node".into(),
                )
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

/// One block to decode: the block, its record (physical blocks) or node (grids), its stored
/// bytes, and the bytes of the ancestors it accounts for.
type Job<'a, 'b> = (
    (
        (
            (&'a SceneBlock, &'a Option<StoredBlock>),
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
