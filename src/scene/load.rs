//! Loading a scene's blocks: their payloads read in a few coalesced reads, each checked
//! against its CRC, and decoded to the heights the block draws.
//!
//! A scene's blocks come from range scans in Hilbert order, and the writer lays payloads
//! out in that order, so the payloads of neighbouring blocks are often neighbours in the
//! file: [`crate::Store::payloads`] reads every run of them whose gaps are at most a given
//! number of bytes ([`PAYLOAD_GAP`] by default: none) in one call. Decoding (format 2 payloads are coded) is the other
//! cost of a load; [`super::Scheduler`] keeps what it decoded across frames.

use crate::error::Result;
use crate::store::{Source, Store, Wanted};

pub use crate::store::{HeldGrid, LoadedBlock};

use super::SceneBlock;

/// Payloads at most this many bytes apart are read together: 0, only payloads that touch.
/// Measured (`cargo bench --bench scene_reads`, Puget Sound 4k, tau 0.5 to 4): gaps of
/// 1 KiB save 5-20 % of the calls for 2-10 % more bytes, gaps of 4 KiB save up to 70 % of
/// the calls for up to twice the bytes. Bytes are the cost this default minimises; a
/// source where a call costs a round trip may pass a larger gap.
pub const PAYLOAD_GAP: u64 = 0;

/// Reads and decodes `blocks` (in the order given), coalescing reads of payloads at most
/// `gap` bytes apart, each with the ancestors its payload is coded against
/// ([`Store::decode_payloads`]).
pub fn load_blocks<S: Source>(
    store: &Store<S>,
    blocks: &[SceneBlock],
    gap: u64,
) -> Result<Vec<LoadedBlock>> {
    load_blocks_reusing(store, blocks, gap, &|_, _| None)
}

/// [`load_blocks`], taking the grids a payload is coded against from `held` when it has
/// them, instead of reading and decoding them again ([`Store::decode_payloads`]).
pub fn load_blocks_reusing<S: Source>(
    store: &Store<S>,
    blocks: &[SceneBlock],
    gap: u64,
    held: &HeldGrid<'_>,
) -> Result<Vec<LoadedBlock>> {
    let wanted: Vec<Wanted> = blocks
        .iter()
        .map(|b| Wanted {
            node: b.node,
            level: b.level,
            x: b.x,
            y: b.y,
            payload: b.payload,
        })
        .collect();
    store.decode_payloads(&wanted, gap, held)
}
