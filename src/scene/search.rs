//! The working state of one selection, shared by the scene modes: counted node reads, range
//! scans of a cluster over a run of keys, and the blocks emitted so far. A mode is an `impl`
//! block on [`Search`] in a file of its own.

use super::camera::View;
use super::ranges::{self, KeyRange, KeyRun, Quadrant};
use super::result::{SceneBlock, SceneStats};
use super::terrain::Terrain;
use crate::error::Result;
use crate::format::StoredNode;
use crate::store::{Ahead, Source};

/// The working state of one selection.
pub(super) struct Search<'t, 's, S: Source> {
    pub terrain: &'t Terrain<'s, S>,
    pub view: &'t View,
    pub tau: f64,
    /// The frustum decides a coarse region: a node whose box lies wholly outside it is dropped
    /// with its subtree (each descendant's box lies inside its own), since `finish` would
    /// cull every block of it.
    pub cull: bool,
    pub out: Vec<SceneBlock>,
    pub stats: SceneStats,
}

impl<S: Source> Search<'_, '_, S> {
    /// Counts a read of the record of a node at `level`, and whether the top of the tree
    /// held it (it holds every node of its levels: a test of the level, not a search).
    fn count_node_read(&mut self, level: u8) {
        self.stats.node_reads += 1;
        if self.terrain.store().top().is_some_and(|t| t.holds_level(level)) {
            self.stats.top_reads += 1;
        }
    }

    /// Emits node `index` as a scene block.
    pub fn emit(&mut self, index: u32, n: &StoredNode) {
        let block = self.terrain.node_block(self.view, index, n);
        self.out.push(block);
    }

    /// Emits the physical blocks of `q` that meet `run`, exact (`e* = 0`), bounded by the
    /// heights `zmin..=zmax` of the node above them.
    pub fn emit_physical(
        &mut self,
        q: &Quadrant,
        run: &KeyRun,
        zmin: f32,
        zmax: f32,
    ) -> Result<()> {
        let d = *self.terrain.domain();
        let (xs, ys) = q.blocks(&d);
        for y in ys {
            for x in xs.clone() {
                let key = ranges::block_key(&d, x, y);
                if run.meets(&KeyRange::single(key)) {
                    self.stats.node_reads += 1;
                    let block = self.terrain.physical_block(self.view, x, y, zmin, zmax)?;
                    self.out.push(block);
                }
            }
        }
        Ok(())
    }

    /// The nodes of `cluster` whose keys meet each of `runs` (not merely a run's gaps), each
    /// with the index of the run it meets, by a range scan per run. On a source that reads
    /// ahead (a remote object) every run's index pages are fetched together, then every
    /// entry's node: a round per tree level, not per page.
    pub fn scan(
        &mut self,
        cluster: usize,
        runs: &[KeyRun],
    ) -> Result<Vec<(u32, StoredNode, usize)>> {
        let store = self.terrain.store;
        let finest = self.terrain.domain().finest_level();
        let ahead = store.prefetches();
        if ahead {
            let mut a = Ahead::new();
            for run in runs {
                a.scan(cluster, run.scan.lo, run.scan.hi);
            }
            store.fetch_ahead(&a)?;
        }
        let mut entries = Vec::new();
        for (r, run) in runs.iter().enumerate() {
            let mut scan = store.scan_hilbert(cluster, run.scan.lo..=run.scan.hi)?;
            self.stats.ranges += 1;
            for e in scan.by_ref() {
                let e = e?;
                if run.meets(&KeyRange::of_node(e.key, e.level, finest)) {
                    entries.push((e, r));
                }
            }
            self.stats.index_pages += u64::from(scan.pages_read());
        }
        if ahead {
            let mut a = Ahead::new();
            for (e, _) in &entries {
                a.nodes(e.node, e.node);
            }
            store.fetch_ahead(&a)?;
        }
        let mut out = Vec::with_capacity(entries.len());
        for (e, r) in entries {
            self.count_node_read(e.level);
            out.push((e.node, store.node_of(cluster, &e)?, r));
        }
        Ok(out)
    }

    /// Fetches ahead the children of each of `parents` (node index and node) on a source
    /// that reads ahead: a parent's whole subtree when it is small, else where its children
    /// lie if its subtree is complete (a node's children follow it in pre-order, each after
    /// the subtrees of those before it). A guess that misses costs a round, never an answer.
    pub fn fetch_children(&self, parents: &[(u32, StoredNode)]) -> Result<()> {
        let store = self.terrain.store;
        if parents.is_empty() || !store.prefetches() {
            return Ok(());
        }
        let top = store.top();
        let mut a = Ahead::new();
        for &(i, ref n) in parents {
            let below = n.subtree_len.saturating_sub(1);
            // Children the top holds (format 6.2) are read from memory.
            if below == 0 || top.is_some_and(|t| t.holds_level(n.level.saturating_add(1))) {
                continue;
            }
            // Saturating: the lengths come from the file, and a lookup checks what they name.
            let first = i.saturating_add(1);
            if below <= SMALL_SUBTREE {
                a.nodes(first, i.saturating_add(below));
                // Below the top (format 6.2), a small subtree is one the view refines
                // into: its blocks' records come in the same round, since a load reads
                // them for the finest nodes the refinement ends at.
                if top.is_some() {
                    self.name_blocks_under(&mut a, n);
                }
            } else {
                let child = below / 4;
                for k in 0..4 {
                    let at = first.saturating_add(k * child);
                    a.nodes(at, at);
                }
            }
        }
        store.fetch_ahead(&a)
    }
}

impl<S: Source> Search<'_, '_, S> {
    /// The next level of a descent: the children of each of `split` (node index, node,
    /// and the run of `runs` it meets) that meet its run, fetched together first on a
    /// source that reads ahead.
    pub fn children_of(
        &mut self,
        split: Vec<(u32, StoredNode, usize)>,
        runs: &[KeyRun],
    ) -> Result<Vec<(u32, StoredNode, usize)>> {
        let finest = self.terrain.domain().finest_level();
        let parents: Vec<(u32, StoredNode)> = split.iter().map(|&(i, n, _)| (i, n)).collect();
        self.fetch_children(&parents)?;
        let mut next = Vec::new();
        for (i, n, r) in split {
            for child in self.terrain.store().children(i, &n) {
                let (c, child) = child?;
                self.count_node_read(child.level);
                if runs[r].meets(&KeyRange::of_node(child.key, child.level, finest)) {
                    next.push((c, child, r));
                }
            }
        }
        Ok(next)
    }

    /// Names the block records of the physical blocks under `n`, when they are few (at most
    /// [`SMALL_SUBTREE`] / 2 blocks).
    fn name_blocks_under(&self, a: &mut Ahead, n: &StoredNode) {
        let d = self.terrain.domain();
        let finest = d.finest_level();
        let Some(depth) = finest.checked_sub(n.level).filter(|&k| k <= 3) else {
            return;
        };
        let (cols, rows) = d.nodes_across(finest);
        let side = 1u32 << depth;
        let (x0, y0) = (n.x.saturating_mul(side), n.y.saturating_mul(side));
        for y in y0..y0.saturating_add(side).min(rows) {
            for x in x0..x0.saturating_add(side).min(cols) {
                a.block(x, y);
            }
        }
    }
}

/// Nodes below a parent fetched ahead whole when refining it (about three pages of node
/// records at 4 KiB).
const SMALL_SUBTREE: u32 = 128;
