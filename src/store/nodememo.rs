//! The store's memo of decoded nodes: the last node read at each of a fixed number of slots,
//! so that a scene, and the next frame's scene, find the nodes they read again without a
//! walk down the node table.
//!
//! **Why.** A scene reads each node it refines, and the next frame of a moving camera reads
//! nearly the same ones. Through the table each read is a descent of the node B-tree: a page
//! lookup per level (a lock, a hash, a shared copy), the page's checks, then the record
//! decoded and checked. Scheduling a frame over a dataset spent a third of its time there
//! (`benches/dataset_scale.rs`, issue 44). The memo answers a repeat read with one lock and
//! a compare.
//!
//! **Shape.** Two generations of a hash map by node index, as the page cache keeps pages
//! (`pagecache`): a read looks in the young one, then in the old one (and moves the node to
//! the young one); when the young one is full it becomes the old one, and the old one is
//! dropped. An LRU approximation with O(1) work, bounded, and empty until nodes are read, so
//! opening a store (a dataset opens tiles by the dozen) costs nothing. The memo holds only
//! nodes [`super::Store::node`] read and checked, and a store is one committed state, so a
//! memoized node is the node the table holds; nothing invalidates it.

use std::sync::Mutex;

use rustc_hash::FxHashMap;

use crate::format::StoredNode;

/// Nodes a generation holds: the memo keeps at most twice as many (about 700 KiB). Over
/// the 1.07 G-sample mosaic's fly-through (tiles of 5,461 nodes), a direct-mapped memo of
/// 4,096 slots answered 90 % of reads and one of 1,024 slots 67 %.
pub const NODE_MEMO_GENERATION: usize = 4096;

#[derive(Debug, Default)]
struct Generations {
    young: FxHashMap<u32, StoredNode>,
    old: FxHashMap<u32, StoredNode>,
}

/// See the module docs.
#[derive(Debug)]
pub(crate) struct NodeMemo {
    generations: Mutex<Generations>,
    /// Nodes a generation holds.
    generation: usize,
}

impl Default for NodeMemo {
    fn default() -> NodeMemo {
        NodeMemo::with_generation(NODE_MEMO_GENERATION)
    }
}

impl NodeMemo {
    /// A memo whose generations hold `generation` nodes (at least 1).
    pub fn with_generation(generation: usize) -> NodeMemo {
        NodeMemo {
            generations: Mutex::default(),
            generation: generation.max(1),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Generations> {
        // A poisoned lock leaves whole entries (each is inserted in one call).
        self.generations.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Node `index`, if the memo holds it.
    #[inline]
    pub fn get(&self, index: u32) -> Option<StoredNode> {
        let mut g = self.lock();
        if let Some(n) = g.young.get(&index) {
            return Some(*n);
        }
        let n = g.old.remove(&index)?;
        self.insert(&mut g, index, n);
        Some(n)
    }

    /// Keeps node `index`, read and checked.
    #[inline]
    pub fn put(&self, index: u32, node: StoredNode) {
        let mut g = self.lock();
        self.insert(&mut g, index, node);
    }

    fn insert(&self, g: &mut Generations, index: u32, node: StoredNode) {
        if g.young.len() >= self.generation {
            g.old = std::mem::take(&mut g.young);
        }
        g.young.insert(index, node);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curve::HilbertKey;
    use crate::format::PayloadRef;

    fn node(x: u32) -> StoredNode {
        StoredNode {
            key: HilbertKey(u64::from(x)),
            level: 3,
            x,
            y: 1,
            child_mask: 0,
            parent: Some(0),
            subtree_len: 1,
            static_error: 0.5,
            monotone_error: 0.5,
            min_height: 0.0,
            max_height: 1.0,
            valid_samples: 9,
            payload: PayloadRef::default(),
            grid_has_voids: false,
            grid_against_parent: false,
            grid_bitmap_flagged: false,
            grid_thin: 0,
        }
    }

    #[test]
    fn the_memo_answers_what_it_keeps_within_two_generations() {
        let memo = NodeMemo::with_generation(2);
        assert_eq!(memo.get(5), None);
        memo.put(5, node(5));
        memo.put(6, node(6));
        assert_eq!(memo.get(5), Some(node(5)));
        // The young generation is full: 7 starts a new one, 5 and 6 are the old one.
        memo.put(7, node(7));
        assert_eq!(memo.get(6), Some(node(6)), "read from the old generation");
        // 6 moved to the young one beside 7; the next insert retires both, drops 5.
        memo.put(8, node(8));
        assert_eq!(memo.get(5), None);
        assert_eq!(memo.get(7), Some(node(7)));
        assert_eq!(memo.get(u32::MAX), None);
        // What it answers is what was put, never another node.
        for i in 0..100 {
            memo.put(i, node(i));
            assert_eq!(memo.get(i), Some(node(i)));
        }
    }
}
