//! Loading a scene's blocks: their payloads read in a few coalesced reads, each checked
//! against its CRC, and decoded to the heights the block draws.
//!
//! A scene's blocks come from range scans in Hilbert order, and the writer lays payloads
//! out in that order, so the payloads of neighbouring blocks are often neighbours in the
//! file: [`crate::Store::payloads`] reads every run of them whose gaps are at most a given
//! number of bytes ([`PAYLOAD_GAP`] by default: none) in one call. Decoding (format 2 payloads are coded) is the other
//! cost of a load; [`super::Scheduler`] keeps what it decoded across frames.

use std::sync::Arc;

use rayon::prelude::*;

use crate::error::Result;
use crate::store::{Source, Store};

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
}

impl LoadedBlock {
    /// Bytes of memory it holds.
    pub fn memory(&self) -> u64 {
        self.stored.len() as u64 + 4 * self.heights.len() as u64
    }
}

/// Reads and decodes `blocks` (in the order given), coalescing reads of payloads at most
/// `gap` bytes apart.
pub fn load_blocks<S: Source>(
    store: &Store<S>,
    blocks: &[SceneBlock],
    gap: u64,
) -> Result<Vec<LoadedBlock>> {
    let refs: Vec<_> = blocks.iter().map(|b| b.payload).collect();
    let payloads = store.payloads(&refs, gap)?;
    let finest = store.domain().finest_level();
    let b = store.domain().block_size();
    let decode = |(block, bytes): (&SceneBlock, std::borrow::Cow<'_, [u8]>)| {
        let stored: Arc<[u8]> = Arc::from(&*bytes);
        if block.level == finest {
            let info = store.stored_block(block.x, block.y)?;
            let decoded = store.block_from(block.x, block.y, info, bytes)?;
            let view = decoded.view();
            Ok(LoadedBlock {
                stored,
                width: view.width,
                height: view.height,
                heights: Arc::from(view.mended()),
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
            })
        }
    };
    // Decoding is most of a warm load (pco): a scene's blocks decode on every core, in
    // order. A few blocks decode on the calling thread, cheaper than handing them out.
    if blocks.len() >= PARALLEL_FROM {
        blocks.par_iter().zip(payloads).map(decode).collect()
    } else {
        blocks.iter().zip(payloads).map(decode).collect()
    }
}

/// Loads of at least this many blocks decode in parallel.
const PARALLEL_FROM: usize = 8;
