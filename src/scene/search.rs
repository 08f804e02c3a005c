//! The working state of one selection, shared by the scene modes: counted node reads, range
//! scans of a cluster over a run of keys, and the blocks emitted so far. A mode is an `impl`
//! block on [`Search`] in a file of its own.

use super::camera::View;
use super::ranges::{self, KeyRange, KeyRun, Quadrant};
use super::result::{SceneBlock, SceneStats};
use super::terrain::Terrain;
use crate::error::Result;
use crate::format::StoredNode;
use crate::store::Source;

/// The working state of one selection.
pub(super) struct Search<'t, 's, S: Source> {
    pub terrain: &'t Terrain<'s, S>,
    pub view: &'t View,
    pub tau: f64,
    pub out: Vec<SceneBlock>,
    pub stats: SceneStats,
}

impl<S: Source> Search<'_, '_, S> {
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

    /// Runs the range scan of `run` in `cluster`, calling `visit` with every node whose keys
    /// meet the region (not merely the run's gaps), each once.
    pub fn scan(
        &mut self,
        cluster: usize,
        run: &KeyRun,
        mut visit: impl FnMut(&mut Self, u32, StoredNode) -> Result<()>,
    ) -> Result<()> {
        let finest = self.terrain.domain().finest_level();
        let mut scan = self
            .terrain
            .store
            .scan_hilbert(cluster, run.scan.lo..=run.scan.hi)?;
        self.stats.ranges += 1;
        let mut entries = Vec::new();
        for e in scan.by_ref() {
            let e = e?;
            if run.meets(&KeyRange::of_node(e.key, e.level, finest)) {
                entries.push(e);
            }
        }
        self.stats.index_pages += u64::from(scan.pages_read());
        for e in entries {
            self.stats.node_reads += 1;
            let n = self.terrain.store.node_of(cluster, &e)?;
            visit(self, e.node, n)?;
        }
        Ok(())
    }
}
