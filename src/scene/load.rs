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
use crate::store::{ParentGrid, Source, Store};

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
    /// Payload bytes read for it besides its own: the stored grid it is coded against
    /// (format 4), counted with the first block of a load that needs that grid, else 0.
    pub parent_bytes: u64,
}

impl LoadedBlock {
    /// Bytes of memory it holds.
    pub fn memory(&self) -> u64 {
        self.stored.len() as u64 + 4 * self.heights.len() as u64
    }
}

/// Reads and decodes `blocks` (in the order given), coalescing reads of payloads at most
/// `gap` bytes apart. A physical block coded against its parent's grid (format 4) needs that
/// grid: it is read in the same batch (it lies just before its children in the file) and
/// its bytes count among the load's, but it is not one of the blocks returned.
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

/// [`load_blocks`], taking the grids a block is coded against from `held` when it has them,
/// instead of reading and decoding them again: a renderer that drew a parent in an earlier
/// frame still holds its grid when the parent's children come into view.
pub fn load_blocks_reusing<S: Source>(
    store: &Store<S>,
    blocks: &[SceneBlock],
    gap: u64,
    held: &HeldGrid<'_>,
) -> Result<Vec<LoadedBlock>> {
    let finest = store.domain().finest_level();
    let b = store.domain().block_size();
    // Block records, and the grids the blocks are coded against.
    let mut records = Vec::with_capacity(blocks.len());
    let mut parents: BTreeMap<u32, StoredNode> = BTreeMap::new();
    for block in blocks {
        if block.level == finest {
            let info = store.stored_block(block.x, block.y)?;
            if let Some((index, node)) = store.against_node(block.x, block.y, &info)? {
                parents.insert(index, node);
            }
            records.push(Some(info));
        } else {
            records.push(None);
        }
    }
    // Grids the caller holds need no read.
    let mut grids: HashMap<u32, ParentGrid> = HashMap::new();
    parents.retain(|&index, node| {
        match held(index, node).and_then(|h| ParentGrid::from_expanded(store, index, node, &h)) {
            Some(grid) => {
                grids.insert(index, grid);
                false
            }
            None => true,
        }
    });
    let parents: Vec<(u32, StoredNode)> = parents.into_iter().collect();
    let refs: Vec<_> = blocks
        .iter()
        .map(|b| b.payload)
        .chain(parents.iter().map(|(_, n)| n.payload))
        .collect();
    let mut payloads = store.payloads(&refs, gap)?;
    let grid_payloads = payloads.split_off(blocks.len());
    let grid_of = |((index, node), bytes): (&(u32, StoredNode), Cow<'_, [u8]>)| {
        let grid = store.grid_from(node, bytes)?;
        Ok((*index, ParentGrid::of(store, *index, node, &grid)))
    };
    let read: Vec<(u32, ParentGrid)> = if parents.len() >= PARALLEL_FROM {
        parents
            .par_iter()
            .zip(grid_payloads)
            .map(grid_of)
            .collect::<Result<_>>()?
    } else {
        parents
            .iter()
            .zip(grid_payloads)
            .map(grid_of)
            .collect::<Result<_>>()?
    };
    grids.extend(read);
    let grid_len: HashMap<u32, u64> = parents
        .iter()
        .map(|(i, n)| (*i, u64::from(n.payload.len)))
        .collect();
    let mut counted = HashSet::new();
    let parent_bytes: Vec<u64> = records
        .iter()
        .map(|r| {
            r.and_then(|info| info.against)
                .filter(|&n| counted.insert(n))
                .map_or(0, |n| grid_len.get(&n).copied().unwrap_or(0))
        })
        .collect();
    let decode = |(((block, info), bytes), &parent_bytes): Job<'_, '_>| {
        let stored: Arc<[u8]> = Arc::from(&*bytes);
        if let Some(info) = *info {
            let parent = info.against.and_then(|n| grids.get(&n));
            let decoded = store.block_with(block.x, block.y, info, bytes, parent)?;
            let view = decoded.view();
            Ok(LoadedBlock {
                stored,
                width: view.width,
                height: view.height,
                heights: Arc::from(view.mended()),
                parent_bytes,
            })
        } else {
            let index = block.node.ok_or_else(|| {
                crate::Error::Internal("a block above the finest level without a node".into())
            })?;
            let node = store.node(index)?;
            let grid = store.grid_from(&node, bytes)?;
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
            .zip(payloads)
            .zip(parent_bytes.par_iter())
            .map(decode)
            .collect()
    } else {
        blocks
            .iter()
            .zip(records.iter())
            .zip(payloads)
            .zip(parent_bytes.iter())
            .map(decode)
            .collect()
    }
}

/// One block to decode: the block, its record (physical blocks), its stored bytes, and the
/// bytes of the grid it is coded against that it accounts for.
type Job<'a, 'b> = (
    ((&'a SceneBlock, &'a Option<StoredBlock>), Cow<'b, [u8]>),
    &'a u64,
);

/// Loads of at least this many blocks decode in parallel.
const PARALLEL_FROM: usize = 8;
