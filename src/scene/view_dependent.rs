//! **View-dependent mode** (seed 004 eq. 2). Node `n` seen from the eye covers
//! `ρ(n) = e*(n) · λ / d(n)` pixels, `d(n)` the distance to its box (footprint by
//! `[min_height, max_height]`). A child's box lies inside its parent's and `e*` never grows
//! downwards, so `ρ` never grows from parent to child: the predicate `ρ <= τ` is monotone and
//! its cut `V = { n : ρ(n) <= τ, ρ(parent) > τ }` covers the region once. fmrh finds `V`
//! through the clusters instead of from the root. With `D` the distance from the eye to the
//! farthest point of the region, any `V` node meeting the region is at most `D` away, so its
//! `e*` is at most `τ · D / λ`. Take the cluster with the smallest `δ >= τ · D / λ`: at each
//! place its node is at or above the `V` node. Scan it over the region's keys; a scanned node
//! that meets `τ` is in `V` (its parent has `e* > δ`, and is at most `D` away, so it fails);
//! one that does not is refined through its children, only where they meet the region.
//! Nodes above that cluster are never read. (Seeding each quadrant of the region from its
//! own farthest point, and splitting quadrants until their nearest and farthest points pick
//! the same cluster, were both measured on Puget Sound 1k and 4k: the extra range scans cost
//! more than the refinement they save, 10-30 % slower.)
//! A tree leaf above the finest level that still misses `τ` (possible only when the finest
//! threshold is above 0) is replaced by its physical blocks, unless its `e*` is already the
//! file's storage error (a precision `Q` gives every block at least `9Q/16`): then it is kept,
//! since no block is more exact, and its screen error is reported as it is, above `τ`.
//!

use super::camera::Coverage;
use super::ranges::{self, KeyRun, Quadrant};
use super::search::Search;
use super::terrain::Region;
use crate::error::Result;
use crate::format::StoredNode;
use crate::store::Source;

impl<S: Source> Search<'_, '_, S> {
    /// Fills the scene of `region` in view-dependent mode.
    pub fn view_dependent(&mut self, region: &Region, gap: u64) -> Result<()> {
        let terrain = self.terrain;
        let thresholds = terrain.thresholds();
        let (tau, view) = (self.tau, self.view);
        // One seed for the whole region, from its farthest point: the finest cluster at or
        // above every V node of the region; None: the root.
        let need = view.allowed_error(tau, region.far);
        let first = thresholds.partition_point(|&t| t < need);
        // A remote reader holding the top of the tree (format 6.2) starts from the root: the
        // coarse levels are in memory, where the seed's range scan would cost a round for
        // the index and one for its nodes. The cut is the same (the argument above holds
        // for any start at or above it).
        let store = terrain.store();
        let from_top = store.top().is_some() && store.prefetches();
        let seed = (first < thresholds.len() && !from_top).then_some(first);
        let runs = ranges::merge(&region.keys, gap);
        let start = match seed {
            Some(c) => self.scan(c, &runs)?,
            None => {
                let root = self.terrain.root();
                (0..runs.len()).map(|r| (0, root, r)).collect()
            }
        };
        self.refine(start, &runs)
    }

    /// Emits the V nodes at or below each of `start` (node index, node, and the run of
    /// `runs` it meets) that meet its run. Level by level: on a source that reads ahead,
    /// the children of every node refined at one level are fetched together.
    fn refine(&mut self, start: Vec<(u32, StoredNode, usize)>, runs: &[KeyRun]) -> Result<()> {
        let finest = self.terrain.domain().finest_level();
        let mut wave = start;
        while !wave.is_empty() {
            let mut split = Vec::new();
            for (i, n, r) in wave {
                let node_box = self.terrain.node_box(&n);
                if self.cull && self.view.classify(&node_box) == Coverage::Outside {
                    continue;
                }
                let distance = node_box.distance(self.view.eye);
                // A node as exact as storage allows is kept even when it misses `tau`:
                // nothing below it is better (a file with a precision, model §4).
                if self.view.screen_error(n.monotone_error, distance) <= self.tau
                    || n.level >= finest
                    || (n.monotone_error <= self.terrain.storage_error() && n.monotone_error > 0.0)
                {
                    let block = self.terrain.node_block_at(self.view, i, &n, distance);
                    self.out.push(block);
                    continue;
                }
                if n.subtree_len <= 1 {
                    // A pruned leaf that misses the tolerance: its physical blocks are exact.
                    let q = Quadrant {
                        level: n.level,
                        x: n.x,
                        y: n.y,
                    };
                    self.emit_physical(&q, &runs[r], n.min_height, n.max_height)?;
                    continue;
                }
                split.push((i, n, r));
            }
            wave = self.children_of(split, runs)?;
        }
        Ok(())
    }
}
