//! **Uniform mode** (seed 000 §5.1). The tolerance `τ` becomes one static bound,
//! `ε = τ / λ · P_min`, with `P_min` the distance from the eye to the nearest point the region
//! can hold (its box, from the data's lowest to highest height). The answer is the cluster
//! with the largest threshold `δᵢ <= ε`, never a coarser one, scanned over the region's key
//! ranges. When even the finest cluster is above `ε` (thresholds given without 0), the
//! physical blocks of the region are returned: they are exact, or within the storage error
//! (`9Q/16`) of a file with a precision. When that finest cluster's threshold is already it,
//! it is returned instead: nothing is more exact, and its blocks are fewer.

use super::ranges::{self, KeyRun};
use super::terrain::Region;
use super::search::Search;
use crate::error::Result;
use crate::format::StoredNode;
use crate::store::Source;

impl<S: Source> Search<'_, '_, S> {
    /// Fills the scene of `region` in uniform mode; `p_min` is the nearest distance.
    pub fn uniform(&mut self, region: &Region, p_min: f64, gap: u64) -> Result<()> {
        let allowed = self.view.allowed_error(self.tau, p_min);
        self.stats.p_min = Some(p_min);
        self.uniform_within(region, allowed, gap)
    }

    /// The uniform cut within the static bound `allowed` (metres) over `region`: the
    /// cluster with the largest threshold at most `allowed`, or physical blocks below the
    /// finest threshold.
    pub fn uniform_within(&mut self, region: &Region, allowed: f64, gap: u64) -> Result<()> {
        self.stats.allowed_error = Some(allowed);
        // The largest threshold within the bound: the thresholds ascend.
        let thresholds = self.terrain.thresholds();
        let storage = self.terrain.storage_error();
        let cluster = thresholds
            .partition_point(|&t| t <= allowed)
            .checked_sub(1)
            // Below the finest threshold: physical blocks, unless that cluster is already as
            // exact as storage allows (a precision's bound).
            .or_else(|| (storage > 0.0 && thresholds.first() <= Some(&storage)).then_some(0));
        self.stats.cluster = cluster;
        self.stats.threshold = Some(cluster.map_or(storage, |c| thresholds[c]));
        let (zmin, zmax) = self.terrain.height_range();
        let runs = ranges::merge(&region.keys, gap);
        let store = self.terrain.store();
        match cluster {
            // A remote reader holding the top of the tree (format 6.2) descends from the root
            // in memory instead of scanning the index (a round for its pages, one for its
            // nodes): the cluster is the cut C(δ) (container I-13).
            Some(c) if store.top().is_some() && store.prefetches() => {
                self.cut_from_root(thresholds[c], &runs)?;
            }
            Some(c) => {
                for (i, n, _) in self.scan(c, &runs)? {
                    self.emit(i, &n);
                }
            }
            None => {
                for run in &runs {
                    for (q, _) in region
                        .quadrants
                        .iter()
                        .zip(&region.keys)
                        .filter(|(_, k)| run.meets(k))
                    {
                        self.emit_physical(q, run, zmin, zmax)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Emits the cut `C(δ)` that meet each of `runs`: the nodes with `e* <= δ` whose parent
    /// has `e* > δ`, found from the root level by level (the children of a level's nodes
    /// fetched together, on a source that reads ahead).
    fn cut_from_root(&mut self, delta: f64, runs: &[KeyRun]) -> Result<()> {
        let root = self.terrain.root();
        let mut wave: Vec<(u32, StoredNode, usize)> = (0..runs.len()).map(|r| (0, root, r)).collect();
        while !wave.is_empty() {
            let mut split = Vec::new();
            for (i, n, r) in wave {
                // A leaf has `e* <= delta_min <= δ` in a valid file (I-10); kept either way.
                if n.monotone_error <= delta || n.subtree_len <= 1 {
                    self.emit(i, &n);
                } else {
                    split.push((i, n, r));
                }
            }
            wave = self.children_of(split, runs)?;
        }
        Ok(())
    }
}
