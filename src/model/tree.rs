//! The FMRH: a quadtree of measured nodes, pruned where the terrain is already exact enough.
//!
//! Building it takes three steps:
//!
//! 1. **Measure** every existing node of every level ([`Measurements`]): static error, height
//!    range, valid count (see [`super::measure`]).
//! 2. **Monotone error**, bottom-up: `e*(n) = max(error(n), max over children e*(c))`.
//!    Errors measured on a grid need not shrink from parent to child. `e*` does, and Theorem 2
//!    of seed 000 (every cut covers the terrain) needs exactly that.
//! 3. **Prune**, top-down: a node is subdivided only where `e*(n) > delta_min`, the smallest
//!    cluster threshold. Flat ground stops early, and with `delta_min = 0` only exactly
//!    representable regions stop.
//!
//! The kept nodes are stored in *Hilbert pre-order*: a parent first, then its children's
//! subtrees in curve order. That order sorts the table by `(HilbertKey, level)`, so a node is
//! found by binary search. A node's descendants are the contiguous run `i..i + subtree_len`,
//! and its children are found by hopping over subtrees. Every field of [`Node`] is
//! fixed-width, so the container stores the table as fixed-size records.

use std::ops::Range;

use super::domain::{Domain, SampleRect};
use super::measure::{measure_level, NodeStats};
use super::raster::MendedRaster;
use crate::curve::HilbertKey;

/// `parent` of the root.
pub const NO_PARENT: u32 = u32::MAX;

/// One node of the FMRH. Every field is fixed-width, ready to become an on-disk record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Place on the multiresolution Hilbert curve.
    pub key: HilbertKey,
    /// Level: 0 is the root, `L` the physical blocks.
    pub level: u8,
    /// Which children are kept in the tree: bit `dy * 2 + dx` for the child in quadrant
    /// `(dx, dy)` (bit 0 NW, 1 NE, 2 SW, 3 SE).
    pub child_mask: u8,
    /// Column of the node among those of its level.
    pub x: u32,
    /// Row of the node among those of its level (from the north).
    pub y: u32,
    /// The measured static error of this node's own grid, in height units.
    pub static_error: f64,
    /// The monotone error `e*`: the largest static error in this node's subtree of the full
    /// quadtree. Never grows from parent to child.
    pub monotone_error: f64,
    /// Least mended height over the footprint (a bound for everything the node draws).
    pub min_height: f32,
    /// Greatest mended height over the footprint.
    pub max_height: f32,
    /// Valid samples in the footprint; the rest of the footprint is void or padding.
    pub valid_samples: u64,
    /// Index of the parent, [`NO_PARENT`] for the root.
    pub parent: u32,
    /// `log₂` of the factor its grid is thinned by east-west (format 6, [`super::thinning`]);
    /// 0 for a square grid.
    pub thin: u8,
    /// Nodes in this node's subtree, itself included: its descendants are
    /// `index + 1 .. index + subtree_len`.
    pub subtree_len: u32,
}

/// The measurements of one level, row-major over its existing nodes.
#[derive(Clone, Debug)]
pub struct LevelMeasurements {
    /// Node columns at this level.
    pub cols: u32,
    /// Node rows at this level.
    pub rows: u32,
    /// Per node: error, height range, valid count.
    pub stats: Vec<NodeStats>,
    /// Per node: the monotone error `e*`.
    pub monotone: Vec<f64>,
    /// Per node: `log₂` of its thinning factor ([`super::thinning`]); empty when none is
    /// thinned.
    pub thin: Vec<u8>,
}

impl LevelMeasurements {
    fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.cols as usize + x as usize
    }
}

/// Every existing node of every level, measured, with monotone errors.
#[derive(Clone, Debug)]
pub struct Measurements {
    /// Indexed by level.
    pub levels: Vec<LevelMeasurements>,
}

impl Measurements {
    /// Measures every level of `domain` over `raster` and computes monotone errors.
    pub fn measure(raster: &MendedRaster, domain: &Domain) -> Measurements {
        Measurements::measure_with_progress(raster, domain, &crate::progress::Silent)
    }

    /// As [`Measurements::measure`], telling `progress` of each level measured (each costs
    /// about one pass over the samples).
    pub fn measure_with_progress(
        raster: &MendedRaster,
        domain: &Domain,
        progress: &dyn crate::progress::Progress,
    ) -> Measurements {
        let phase = crate::progress::Phase::start(
            progress,
            "measuring levels",
            u64::from(domain.levels()),
            crate::progress::Unit::Steps,
        );
        let levels = (0..domain.levels())
            .map(|level| {
                let (cols, rows) = domain.nodes_across(level);
                let stats = measure_level(raster, domain, level);
                phase.advance(1);
                (cols, rows, stats)
            })
            .collect();
        drop(phase);
        Measurements::from_stats(levels)
    }

    /// The measurements of per-level node statistics `(cols, rows, stats)` (row-major),
    /// root level first: `e*` is taken bottom-up as the largest error in each subtree.
    pub fn from_stats(levels: Vec<(u32, u32, Vec<NodeStats>)>) -> Measurements {
        let mut m = Measurements {
            levels: levels
                .into_iter()
                .map(|(cols, rows, stats)| LevelMeasurements {
                    cols,
                    rows,
                    monotone: Vec::new(),
                    thin: Vec::new(),
                    stats,
                })
                .collect(),
        };
        m.update_monotone();
        m
    }

    /// Thins every node above the finest level by area ([`super::thinning`]): where its
    /// grid thinned by its candidate factor keeps its error within
    /// [`super::thinning::THIN_ERROR_RATIO`] times the square grid's, the node's error
    /// becomes the thinned grid's and its factor is kept. Then every `e*` again.
    pub fn thin_by_area(
        &mut self,
        raster: &MendedRaster,
        domain: &Domain,
        spacing: &super::thinning::LatLonSpacing,
    ) {
        use super::thinning::{candidate_log2, keeps_thinned};
        for (level, m) in self.levels.iter_mut().enumerate() {
            let level = level as u8;
            let cols = m.cols as usize;
            let candidates: Vec<u8> = (0..m.stats.len())
                .map(|i| {
                    candidate_log2(spacing, domain, level, (i % cols) as u32, (i / cols) as u32)
                })
                .collect();
            m.thin.clear();
            if candidates.iter().all(|&t| t == 0) {
                continue;
            }
            let thinned = super::measure::measure_level_thinned(raster, domain, level, &candidates);
            m.thin = candidates;
            for ((s, t), e) in m.stats.iter_mut().zip(m.thin.iter_mut()).zip(&thinned) {
                if *t > 0 && keeps_thinned(s.error, e.error) {
                    s.error = e.error;
                } else {
                    *t = 0;
                }
            }
        }
        self.update_monotone();
    }

    /// Recomputes every `e*` from the node errors.
    pub fn update_monotone(&mut self) {
        let levels = &mut self.levels;
        for l in levels.iter_mut() {
            l.monotone.clear();
            l.monotone.extend(l.stats.iter().map(|s| s.error));
        }
        for level in (0..levels.len().saturating_sub(1)).rev() {
            let (upper, lower) = levels.split_at_mut(level + 1);
            let (parent, child) = (&mut upper[level], &lower[0]);
            for cy in 0..child.rows {
                for cx in 0..child.cols {
                    let e = child.monotone[child.index(cx, cy)];
                    let p = parent.index(cx / 2, cy / 2);
                    if e > parent.monotone[p] {
                        parent.monotone[p] = e;
                    }
                }
            }
        }
    }

    pub fn root_error(&self) -> f64 {
        self.levels[0].monotone[0]
    }

    /// The smallest positive monotone error of any node, if some node has one.
    pub fn min_positive_error(&self) -> Option<f64> {
        self.levels
            .iter()
            .flat_map(|l| l.monotone.iter().copied())
            .filter(|&e| e > 0.0)
            .min_by(f64::total_cmp)
    }
}

/// The pruned quadtree, in Hilbert pre-order.
#[derive(Clone, Debug)]
pub struct Fmrh {
    domain: Domain,
    delta_min: f64,
    nodes: Vec<Node>,
}

impl Fmrh {
    /// Prunes the full measured quadtree: a node is kept if it is the root, or its parent is
    /// kept and has `e* > delta_min`.
    pub fn prune(domain: Domain, measured: &Measurements, delta_min: f64) -> Fmrh {
        let mut tree = Fmrh {
            domain,
            delta_min,
            nodes: Vec::new(),
        };
        tree.visit(measured, 0, 0, 0, NO_PARENT);
        tree
    }

    fn visit(&mut self, measured: &Measurements, level: u8, x: u32, y: u32, parent: u32) {
        let m = &measured.levels[usize::from(level)];
        let i = m.index(x, y);
        let (stats, monotone) = (m.stats[i], m.monotone[i]);
        let index = self.nodes.len() as u32;
        self.nodes.push(Node {
            key: HilbertKey::of_node(self.domain.finest_level(), level, x, y),
            level,
            child_mask: 0,
            x,
            y,
            static_error: stats.error,
            monotone_error: monotone,
            min_height: stats.min_height,
            max_height: stats.max_height,
            valid_samples: stats.valid_samples,
            parent,
            subtree_len: 1,
            thin: m.thin.get(i).copied().unwrap_or(0),
        });
        if level < self.domain.finest_level() && monotone > self.delta_min {
            let mut children: Vec<(HilbertKey, u32, u32)> = (0..4u32)
                .map(|q| (2 * x + (q & 1), 2 * y + (q >> 1)))
                .filter(|&(cx, cy)| self.domain.exists(level + 1, cx, cy))
                .map(|(cx, cy)| {
                    let key = HilbertKey::of_node(self.domain.finest_level(), level + 1, cx, cy);
                    (key, cx, cy)
                })
                .collect();
            children.sort_unstable();
            let mut mask = 0u8;
            for (_, cx, cy) in children {
                mask |= 1 << ((cy & 1) * 2 + (cx & 1));
                self.visit(measured, level + 1, cx, cy, index);
            }
            let len = self.nodes.len() as u32 - index;
            let node = &mut self.nodes[index as usize];
            node.child_mask = mask;
            node.subtree_len = len;
        }
    }

    /// The tree's geometry.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// The subdivision threshold the tree was pruned with.
    pub fn delta_min(&self) -> f64 {
        self.delta_min
    }

    /// All nodes, in Hilbert pre-order (sorted by `(key, level)`); the root is first.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// Node `index`.
    pub fn node(&self, index: u32) -> &Node {
        &self.nodes[index as usize]
    }

    /// Indexes of the descendants of `index` (not itself), a contiguous run.
    pub fn descendants(&self, index: u32) -> Range<u32> {
        index + 1..index + self.nodes[index as usize].subtree_len
    }

    /// Indexes of the children of `index`, in Hilbert order.
    pub fn children(&self, index: u32) -> impl Iterator<Item = u32> + '_ {
        let end = index + self.nodes[index as usize].subtree_len;
        let mut next = index + 1;
        std::iter::from_fn(move || {
            (next < end).then(|| {
                let c = next;
                next += self.nodes[c as usize].subtree_len;
                c
            })
        })
    }

    /// The index of node `(x, y)` at `level`, if the tree keeps it.
    pub fn find(&self, level: u8, x: u32, y: u32) -> Option<u32> {
        if !self.domain.exists(level, x, y) {
            return None;
        }
        let key = HilbertKey::of_node(self.domain.finest_level(), level, x, y);
        self.nodes
            .binary_search_by(|n| (n.key, n.level).cmp(&(key, level)))
            .ok()
            .map(|i| i as u32)
    }

    /// The footprint of node `index` (padding included).
    pub fn footprint(&self, index: u32) -> SampleRect {
        let n = &self.nodes[index as usize];
        self.domain.footprint(n.level, n.x, n.y)
    }

    /// Number of kept nodes at each level.
    pub fn nodes_per_level(&self) -> Vec<u64> {
        let mut counts = vec![0u64; usize::from(self.domain.levels())];
        for n in &self.nodes {
            counts[usize::from(n.level)] += 1;
        }
        counts
    }
}
