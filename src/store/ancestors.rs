//! The store's cache of decoded ancestors: the grids that payloads are coded against (format
//! 4: a block against its parent node's grid; format 5: a grid against its parent's).
//!
//! A scene of Puget Sound 4k at τ = 0.5 px needs 155 to 334 such grids that it does not
//! draw, and the next frame of a camera path needs almost the same ones. Decoding them is
//! as dear as decoding the blocks drawn, so a store keeps the ones it decoded, up to a
//! budget in bytes ([`ANCESTOR_CACHE_BYTES`], about 1,900 grids of 65² heights), and drops
//! the least recently used beyond it. A path that stays within the budget decodes no
//! ancestor twice. An entry is keyed by its node and checked against the node's payload, so
//! a grid replaced by a commit is never served for its successor (a store reads one state;
//! the check is for the caller that hands a node from another).

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use super::ParentGrid;
use crate::format::PayloadRef;

/// The bytes of decoded ancestors a store keeps by default: 32 MiB.
pub const ANCESTOR_CACHE_BYTES: u64 = 32 << 20;

/// Decoded grids by node, least recently used first out.
#[derive(Debug)]
pub(crate) struct AncestorCache {
    /// Node → (grid, the tick it was last used at).
    grids: HashMap<u32, (Arc<ParentGrid>, u64)>,
    /// Tick → node: the order of use.
    order: BTreeMap<u64, u32>,
    tick: u64,
    bytes: u64,
    budget: u64,
    /// Grids put in since the store opened: each one a grid decoded.
    decoded: u64,
    /// Of those, grids of a node whose grid had been put in before (dropped since): each
    /// one a decoding the cache did not save.
    #[cfg(any(test, feature = "testing"))]
    again: u64,
    #[cfg(any(test, feature = "testing"))]
    ever: std::collections::HashSet<(u32, PayloadRef)>,
}

impl Default for AncestorCache {
    fn default() -> Self {
        AncestorCache::new(ANCESTOR_CACHE_BYTES)
    }
}

impl AncestorCache {
    /// An empty cache of at most `budget` bytes.
    pub(crate) fn new(budget: u64) -> Self {
        AncestorCache {
            grids: HashMap::new(),
            order: BTreeMap::new(),
            tick: 0,
            bytes: 0,
            budget,
            decoded: 0,
            #[cfg(any(test, feature = "testing"))]
            again: 0,
            #[cfg(any(test, feature = "testing"))]
            ever: std::collections::HashSet::new(),
        }
    }

    fn touch(&mut self, node: u32, old: u64) -> u64 {
        self.order.remove(&old);
        self.tick += 1;
        self.order.insert(self.tick, node);
        self.tick
    }

    /// The grid of node `node` decoded from `payload`, if the cache holds it.
    pub(crate) fn get(&mut self, node: u32, payload: PayloadRef) -> Option<Arc<ParentGrid>> {
        let (grid, used) = self.grids.get(&node)?;
        if grid.payload != payload {
            return None;
        }
        let (grid, used) = (Arc::clone(grid), *used);
        let now = self.touch(node, used);
        if let Some(entry) = self.grids.get_mut(&node) {
            entry.1 = now;
        }
        Some(grid)
    }

    /// Keeps `grid` (just decoded), dropping the least recently used beyond the budget. A
    /// grid larger than the whole budget is not kept.
    pub(crate) fn put(&mut self, grid: &Arc<ParentGrid>) {
        self.decoded += 1;
        #[cfg(any(test, feature = "testing"))]
        if !self.ever.insert((grid.node, grid.payload)) {
            self.again += 1;
        }
        if let Some((old, used)) = self.grids.remove(&grid.node) {
            self.order.remove(&used);
            self.bytes -= old.memory();
        }
        let size = grid.memory();
        if size > self.budget {
            return;
        }
        self.shrink_to(self.budget - size);
        self.tick += 1;
        self.order.insert(self.tick, grid.node);
        self.grids.insert(grid.node, (Arc::clone(grid), self.tick));
        self.bytes += size;
    }

    /// Grids decoded since the store opened.
    pub(crate) fn decoded(&self) -> u64 {
        self.decoded
    }

    /// Grids decoded a second time or more (the cache had dropped them).
    #[cfg(any(test, feature = "testing"))]
    pub(crate) fn decoded_again(&self) -> u64 {
        self.again
    }

    /// Changes the budget, dropping the least recently used grids until the rest fit.
    pub(crate) fn set_budget(&mut self, budget: u64) {
        self.budget = budget;
        self.shrink_to(budget);
    }

    /// Drops the least recently used grids until at most `limit` bytes are held.
    fn shrink_to(&mut self, limit: u64) {
        while self.bytes > limit {
            let Some((_, node)) = self.order.pop_first() else {
                break;
            };
            if let Some((old, _)) = self.grids.remove(&node) {
                self.bytes -= old.memory();
            }
        }
    }

    /// Bytes held.
    #[cfg(test)]
    fn bytes(&self) -> u64 {
        self.bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(node: u32, n: usize, offset: u64) -> Arc<ParentGrid> {
        let cols: Vec<u64> = (0..n as u64).collect();
        let mut g = ParentGrid::from_parts(cols.clone(), cols, vec![0.0; n * n]).expect("fits");
        g.node = node;
        g.payload = PayloadRef {
            offset,
            len: 1,
            crc: 0,
        };
        Arc::new(g)
    }

    proptest::proptest! {
        /// Under any sequence of uses, the cache never holds more than its budget, serves
        /// only the grid of the node and payload asked for, and drops the least recently
        /// used first: a grid used within the last few (that fit together) is still held.
        #[test]
        fn the_budget_holds_and_the_least_recent_goes_first(
            uses in proptest::collection::vec((0u32..12, 0u64..2), 1..200),
            fit in 1usize..6,
        ) {
            let one = grid(0, 5, 0).memory();
            let mut cache = AncestorCache::new(fit as u64 * one);
            let mut recent: Vec<(u32, u64)> = Vec::new();
            for (node, payload) in uses {
                let at = PayloadRef { offset: payload, len: 1, crc: 0 };
                match cache.get(node, at) {
                    Some(g) => {
                        proptest::prop_assert_eq!((g.node, g.payload), (node, at));
                    }
                    None => {
                        // Not held: must not be among the last `fit` distinct grids used.
                        let held = recent.iter().rev().take(fit).any(|&u| u == (node, payload));
                        proptest::prop_assert!(!held, "dropped a recent grid");
                        cache.put(&grid(node, 5, payload));
                    }
                }
                recent.retain(|&u| u.0 != node);
                recent.push((node, payload));
                proptest::prop_assert!(cache.bytes() <= fit as u64 * one);
            }
        }
    }

    #[test]
    fn a_grid_decoded_again_is_counted() {
        let one = grid(0, 5, 0).memory();
        let mut cache = AncestorCache::new(one);
        cache.put(&grid(1, 5, 0));
        cache.put(&grid(2, 5, 0)); // drops 1
        assert!(cache.get(1, grid(1, 5, 0).payload).is_none());
        cache.put(&grid(1, 5, 0));
        assert_eq!((cache.decoded(), cache.decoded_again()), (3, 1));
        // Larger than the budget: not kept.
        cache.put(&grid(3, 9, 0));
        assert!(cache.get(3, grid(3, 9, 0).payload).is_none());
        // A smaller budget drops the least recent until the rest fit.
        let mut cache = AncestorCache::new(3 * one);
        for node in 1..=3 {
            cache.put(&grid(node, 5, 0));
        }
        assert!(cache.get(1, grid(1, 5, 0).payload).is_some()); // 1 is now the most recent
        cache.set_budget(one);
        assert_eq!(cache.bytes(), one);
        assert!(cache.get(1, grid(1, 5, 0).payload).is_some());
        cache.set_budget(0);
        assert_eq!(cache.bytes(), 0);
    }
}
