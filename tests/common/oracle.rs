//! Independent, slow re-implementations of what the library computes fast, written from
//! `format-spec/model.md` and the seed papers. Tests compare the library against them.
//!
//! * [`NaiveModel`]: void mending by scanning each direction, and every node's error, height
//!   range and valid count by visiting each sample of its footprint, then `e*` by recursion over
//!   the full quadtree.
//! * [`algorithm1_literal`]: seed 000's Algorithm 1 exactly as printed (interval membership and
//!   "no ancestor already in the cluster"). It can leave holes.
//! * [`algorithm2`]: seed 000's Algorithm 2, the type I–IV production-rule traversal of a
//!   cluster, with the rules copied from the paper.
//! * [`hilbert_by_rotation`]: the textbook rotate-and-flip Hilbert index, unrelated to the
//!   library's table machine.
//! * [`check_model`]: every invariant of a built model, asserted.

#![allow(dead_code)]

use std::collections::{HashMap, HashSet};

use fmrh::model::{cluster, Cluster, Domain, Model, Node, NO_PARENT};
use fmrh::Heightfield;

/// The mended field and per-node measurements, computed naively.
pub struct NaiveModel {
    pub domain: Domain,
    w: u64,
    h: u64,
    mended: Vec<f32>,
    valid: Vec<bool>,
}

impl NaiveModel {
    pub fn new(source: &Heightfield, domain: Domain) -> NaiveModel {
        let (w, h) = (source.width() as usize, source.height() as usize);
        let s = source.samples();
        let valid: Vec<bool> = s.iter().map(|v| !v.is_nan()).collect();
        // Rule 1: nearest valid in row or column, ties W, E, N, S.
        let rule1 = |x: usize, y: usize| -> Option<f32> {
            let mut best: Option<(usize, f32)> = None;
            let mut consider = |d: usize, v: f32| {
                if best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, v));
                }
            };
            if let Some(xx) = (0..x).rev().find(|&xx| valid[y * w + xx]) {
                consider(x - xx, s[y * w + xx]);
            }
            if let Some(xx) = (x + 1..w).find(|&xx| valid[y * w + xx]) {
                consider(xx - x, s[y * w + xx]);
            }
            if let Some(yy) = (0..y).rev().find(|&yy| valid[yy * w + x]) {
                consider(y - yy, s[yy * w + x]);
            }
            if let Some(yy) = (y + 1..h).find(|&yy| valid[yy * w + x]) {
                consider(yy - y, s[yy * w + x]);
            }
            best.map(|(_, v)| v)
        };
        let any_valid = valid.iter().any(|&v| v);
        let column_has_valid: Vec<bool> =
            (0..w).map(|x| (0..h).any(|y| valid[y * w + x])).collect();
        let mut mended = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                mended[i] = if valid[i] {
                    s[i]
                } else if !any_valid {
                    0.0
                } else if let Some(v) = rule1(x, y) {
                    v
                } else {
                    // Rule 2: nearest column with data, ties west; its rule-1 value in this row.
                    let west = (0..=x).rev().find(|&c| column_has_valid[c]);
                    let east = (x..w).find(|&c| column_has_valid[c]);
                    let c = match (west, east) {
                        (Some(a), Some(b)) => {
                            if x - a <= b - x {
                                a
                            } else {
                                b
                            }
                        }
                        (Some(a), None) => a,
                        (None, Some(b)) => b,
                        (None, None) => unreachable!("some column has data"),
                    };
                    rule1(c, y).expect("a column with data gives a rule-1 value")
                };
            }
        }
        NaiveModel {
            domain,
            w: w as u64,
            h: h as u64,
            mended,
            valid,
        }
    }

    /// Mended height of any domain sample (padding clamps).
    pub fn mended(&self, col: u64, row: u64) -> f32 {
        let (c, r) = (col.min(self.w - 1), row.min(self.h - 1));
        self.mended[(r * self.w + c) as usize]
    }

    fn valid(&self, col: u64, row: u64) -> bool {
        col < self.w && row < self.h && self.valid[(row * self.w + col) as usize]
    }

    /// (error, min height, max height, valid samples) of node (level, x, y).
    pub fn stats(&self, level: u8, x: u32, y: u32) -> (f64, f32, f32, u64) {
        let d = &self.domain;
        let fp = d.footprint(level, x, y);
        let s = d.stride(level);
        let b = u64::from(d.block_size());
        let (mut err, mut lo, mut hi, mut count) = (0.0f64, f32::INFINITY, f32::NEG_INFINITY, 0u64);
        for row in fp.row0..=fp.row1 {
            for col in fp.col0..=fp.col1 {
                if col >= self.w || row >= self.h {
                    continue;
                }
                let m = self.mended(col, row);
                lo = lo.min(m);
                hi = hi.max(m);
                if !self.valid(col, row) {
                    continue;
                }
                count += 1;
                let ci = ((col - fp.col0) / s).min(b - 2);
                let cj = ((row - fp.row0) / s).min(b - 2);
                let (x0, y0) = (fp.col0 + ci * s, fp.row0 + cj * s);
                let (u, v) = (col - x0, row - y0);
                let nw = f64::from(self.mended(x0, y0));
                let ne = f64::from(self.mended(x0 + s, y0));
                let sw = f64::from(self.mended(x0, y0 + s));
                let se = f64::from(self.mended(x0 + s, y0 + s));
                let inv = 1.0 / s as f64;
                // format-spec/model.md §4, word for word.
                let surface = if u >= v {
                    ((s - u) as f64 * inv * nw + (u - v) as f64 * inv * ne) + v as f64 * inv * se
                } else {
                    ((s - v) as f64 * inv * nw + (v - u) as f64 * inv * sw) + u as f64 * inv * se
                };
                err = err.max((f64::from(self.mended(col, row)) - surface).abs());
            }
        }
        (err, lo, hi, count)
    }

    /// e* of every existing node of the full quadtree, by recursion.
    pub fn monotone(&self) -> HashMap<(u8, u32, u32), f64> {
        let mut out = HashMap::new();
        self.monotone_rec(0, 0, 0, &mut out);
        out
    }

    fn monotone_rec(
        &self,
        level: u8,
        x: u32,
        y: u32,
        out: &mut HashMap<(u8, u32, u32), f64>,
    ) -> f64 {
        let mut e = self.stats(level, x, y).0;
        if level < self.domain.finest_level() {
            for q in 0..4u32 {
                let (cx, cy) = (2 * x + (q & 1), 2 * y + (q >> 1));
                if self.domain.exists(level + 1, cx, cy) {
                    e = e.max(self.monotone_rec(level + 1, cx, cy, out));
                }
            }
        }
        out.insert((level, x, y), e);
        e
    }
}

/// The textbook Hilbert index (rotate and flip per level), on a `2^order` grid. Its top-level
/// order is (0,0), (0,1), (1,1), (1,0): fmrh's type I.
pub fn hilbert_by_rotation(order: u32, mut x: u64, mut y: u64) -> u64 {
    let mut d = 0u64;
    let mut s = if order == 0 { 0 } else { 1u64 << (order - 1) };
    while s > 0 {
        let rx = u64::from(x & s != 0);
        let ry = u64::from(y & s != 0);
        d += s * s * ((3 * rx) ^ ry);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - (x & (s - 1));
                y = s - 1 - (y & (s - 1));
            }
            std::mem::swap(&mut x, &mut y);
        }
        x &= s - 1;
        y &= s - 1;
        s /= 2;
    }
    d
}

/// The paper's Roman numerals, kept as printed.
#[allow(clippy::upper_case_acronyms)]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum PaperType {
    I,
    II,
    III,
    IV,
}

impl PaperType {
    /// Quadrants (dx, dy) in the order the type visits them (dy = 1 is south).
    fn order(self) -> [(u32, u32); 4] {
        match self {
            PaperType::I => [(0, 0), (0, 1), (1, 1), (1, 0)],
            PaperType::II => [(1, 1), (1, 0), (0, 0), (0, 1)],
            PaperType::III => [(0, 0), (1, 0), (1, 1), (0, 1)],
            PaperType::IV => [(1, 1), (0, 1), (0, 0), (1, 0)],
        }
    }

    /// Seed 000, Algorithm 2 step (3.2.1)–(3.2.4), copied.
    fn rules(self) -> [PaperType; 4] {
        use PaperType::*;
        match self {
            I => [III, I, I, IV],
            II => [IV, II, II, III],
            III => [I, III, III, II],
            IV => [II, IV, IV, I],
        }
    }
}

/// Seed 000's Algorithm 2: the cluster's nodes in the order the production rules visit them,
/// starting from the root as type I. `cluster` holds tree indexes.
pub fn algorithm2(model: &Model, cluster: &[u32]) -> Vec<u32> {
    let members: HashSet<u32> = cluster.iter().copied().collect();
    let mut out = Vec::new();
    if members.contains(&0) {
        out.push(0);
        return out;
    }
    fn deep(model: &Model, members: &HashSet<u32>, node: u32, t: PaperType, out: &mut Vec<u32>) {
        let tree = model.tree();
        let n = tree.node(node);
        for (i, (dx, dy)) in t.order().into_iter().enumerate() {
            let Some(child) = tree.find(n.level + 1, 2 * n.x + dx, 2 * n.y + dy) else {
                continue; // the quadrant is padding
            };
            if members.contains(&child) {
                out.push(child);
            } else if tree.node(child).level < model.domain().finest_level() {
                deep(model, members, child, t.rules()[i], out);
            }
        }
    }
    deep(model, &members, 0, PaperType::I, &mut out);
    out
}

/// Seed 000's Algorithm 1 as printed: `m` thresholds make `m - 1` clusters. A node joins
/// cluster `i` when `δ_i <= e* <= δ_{i+1}`, unless an ancestor is already in cluster `i`, and
/// the traversal goes depth-first through the whole tree.
pub fn algorithm1_literal(model: &Model, thresholds: &[f64]) -> Vec<Vec<u32>> {
    let tree = model.tree();
    let mut clusters = vec![Vec::new(); thresholds.len().saturating_sub(1)];
    let mut ancestors_in: Vec<Vec<bool>> = vec![vec![false; clusters.len()]; tree.nodes().len()];
    for (i, n) in tree.nodes().iter().enumerate() {
        let inherited = if n.parent == NO_PARENT {
            vec![false; clusters.len()]
        } else {
            ancestors_in[n.parent as usize].clone()
        };
        let mut mine = inherited.clone();
        for (c, w) in thresholds.windows(2).enumerate() {
            if w[0] <= n.monotone_error && n.monotone_error <= w[1] && !inherited[c] {
                clusters[c].push(i as u32);
                mine[c] = true;
            }
        }
        ancestors_in[i] = mine;
    }
    clusters
}

/// The units a cover must cover along one axis of `n` samples: the cells `[i, i+1]`, or for a
/// grid one sample wide, the single sample. Returns the indexes of the units that the closed
/// sample range `[lo, hi]` holds.
fn units_within(n: u32, lo: u64, hi: u64) -> std::ops::Range<u64> {
    if n >= 2 {
        let last = u64::from(n) - 2; // last cell index
        lo.min(last + 1)..hi.min(last + 1)
    } else if lo == 0 {
        0..1
    } else {
        0..0
    }
}

/// How many nodes of `nodes` cover each unit (row-major over the units). The units are the data
/// cells, or for a grid one sample wide or tall, the segments or the single sample of its line.
pub fn cover_counts(model: &Model, nodes: &[u32]) -> Vec<u32> {
    let d = model.domain();
    let count = |n: u32| if n >= 2 { n as usize - 1 } else { 1 };
    let (ux, uy) = (count(d.width()), count(d.height()));
    let mut counts = vec![0u32; ux * uy];
    for &i in nodes {
        let fp = model.tree().footprint(i);
        for y in units_within(d.height(), fp.row0, fp.row1) {
            for x in units_within(d.width(), fp.col0, fp.col1) {
                counts[y as usize * ux + x as usize] += 1;
            }
        }
    }
    counts
}

/// Asserts that node `n` carries exactly the naive oracle's error, height range and valid
/// count (bit for bit).
pub fn assert_measured_exactly(naive: &NaiveModel, n: &Node) {
    let (err, lo, hi, count) = naive.stats(n.level, n.x, n.y);
    assert_eq!(
        n.static_error.to_bits(),
        err.to_bits(),
        "node level {} ({}, {}): static error {} vs naive {err}",
        n.level,
        n.x,
        n.y,
        n.static_error
    );
    assert_eq!(
        (n.min_height, n.max_height, n.valid_samples),
        (lo, hi, count),
        "node level {} ({}, {}): range and count",
        n.level,
        n.x,
        n.y
    );
}

/// Asserts bound (`e* <= δ`), minimality (the parent's `e* > δ`) and cover (every unit in
/// exactly one node) for cluster `c`.
pub fn assert_cut_covers(model: &Model, c: &Cluster) {
    let nodes = model.tree().nodes();
    for &i in &c.nodes {
        let n = &nodes[i as usize];
        assert!(n.monotone_error <= c.threshold, "bound at {}", c.threshold);
        assert!(
            n.parent == NO_PARENT || nodes[n.parent as usize].monotone_error > c.threshold,
            "minimality at {}",
            c.threshold
        );
    }
    let counts = cover_counts(model, &c.nodes);
    if let Some(bad) = counts.iter().position(|&k| k != 1) {
        panic!(
            "cluster {}: unit {bad} covered {} times",
            c.threshold, counts[bad]
        );
    }
}

/// Asserts every invariant of `model`, built from `source`.
pub fn check_model(model: &Model, source: &Heightfield) {
    let tree = model.tree();
    let domain = *model.domain();
    let nodes = tree.nodes();
    let naive = NaiveModel::new(source, domain);
    let monotone = naive.monotone();
    let finest = domain.finest_level();

    assert!(!nodes.is_empty());
    assert_eq!(
        (nodes[0].level, nodes[0].parent),
        (0, NO_PARENT),
        "root first"
    );
    for (i, n) in nodes.iter().enumerate() {
        let i = i as u32;
        // Order, keys, structure.
        if i > 0 {
            let p = &nodes[i as usize - 1];
            assert!(
                (p.key, p.level) < (n.key, n.level),
                "pre-order sorts by (key, level)"
            );
        }
        assert!(
            domain.exists(n.level, n.x, n.y),
            "node {i} outside the data"
        );
        let key = hilbert_by_rotation(u32::from(n.level), u64::from(n.x), u64::from(n.y))
            << (2 * u32::from(finest - n.level));
        assert_eq!(n.key.0, key, "node {i}: key");
        assert_eq!(tree.find(n.level, n.x, n.y), Some(i));
        if n.parent != NO_PARENT {
            let p = &nodes[n.parent as usize];
            assert_eq!(
                (p.level + 1, p.x, p.y),
                (n.level, n.x / 2, n.y / 2),
                "node {i}: parent"
            );
            // Monotonicity.
            assert!(
                n.monotone_error <= p.monotone_error,
                "node {i}: e* grows from parent to child"
            );
        }
        assert!(n.monotone_error >= n.static_error);
        assert_measured_exactly(&naive, n);
        assert_eq!(
            n.monotone_error.to_bits(),
            monotone[&(n.level, n.x, n.y)].to_bits(),
            "node {i}: e*"
        );
        if n.level == finest {
            assert_eq!(n.static_error, 0.0, "finest nodes are the data");
        }
        // Pruning: subdivided exactly where e* > delta_min, with every existing child.
        let children: Vec<u32> = tree.children(i).collect();
        let existing = (0..4u32)
            .filter(|q| {
                n.level < finest
                    && domain.exists(n.level + 1, 2 * n.x + (q & 1), 2 * n.y + (q >> 1))
            })
            .count();
        if n.level < finest && n.monotone_error > tree.delta_min() {
            assert_eq!(
                children.len(),
                existing,
                "node {i}: subdivided with every existing child"
            );
        } else {
            assert!(
                children.is_empty(),
                "node {i}: e* <= delta_min or finest, so a leaf"
            );
        }
        for &c in &children {
            assert_eq!(nodes[c as usize].parent, i);
        }
    }

    // Clusters.
    let clusters = model.clusters();
    assert!(!clusters.is_empty());
    assert!(clusters.windows(2).all(|w| w[0].threshold < w[1].threshold));
    for c in clusters {
        let members: HashSet<u32> = c.nodes.iter().copied().collect();
        assert_eq!(members.len(), c.nodes.len(), "no node twice");
        assert_cut_covers(model, c);
        assert!(
            c.nodes
                .windows(2)
                .all(|w| nodes[w[0] as usize].key < nodes[w[1] as usize].key),
            "Hilbert order"
        );
        assert_eq!(
            c.nodes,
            cluster::cut(tree, c.threshold),
            "the cut's definition"
        );
        assert_eq!(
            algorithm2(model, &c.nodes),
            c.nodes,
            "Algorithm 2 order = key order"
        );
        let max = c
            .nodes
            .iter()
            .map(|&i| nodes[i as usize].monotone_error)
            .fold(0.0, f64::max);
        assert_eq!(c.max_error, max);
    }
}
