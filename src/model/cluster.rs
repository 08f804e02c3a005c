//! Error clusters: for each threshold δ, the cut of the tree that is exact to within δ.
//!
//! Cluster *i* is the cut
//!
//! ```text
//!   C(δᵢ) = { n : e*(n) <= δᵢ  and  (n is the root  or  e*(parent(n)) > δᵢ) }
//! ```
//!
//! Since `e*` never grows from parent to child and every leaf of the pruned tree has
//! `e* <= δ_min <= δᵢ`, every root-to-leaf path crosses δᵢ exactly once. So `C(δᵢ)` covers the
//! terrain once, with no hole and no overlap, which is seed 000's Theorem 2 on sound footing.
//! Equivalently, a node belongs to the clusters whose thresholds lie in
//! `[e*(n), e*(parent))` (the root's upper end is +∞). [`build_clusters`] walks the tree once in
//! Hilbert pre-order and appends each node to those clusters, so every cluster comes out sorted
//! by [`HilbertKey`](crate::curve::HilbertKey): the multiresolution Hilbert order.
//!
//! **Why not seed 000's Algorithm 1.** The paper puts a node in cluster *i* when its error
//! lies in the interval `[δᵢ, δᵢ₊₁]`, unless an ancestor is already there. When errors jump
//! across an interval, no node on some path lands in it. Take a parent above `δᵢ₊₁` and a child
//! below `δᵢ`: that child's whole area is missing from cluster *i*. The cut has no such hole
//! (see `tests/algorithm1_hole.rs`).
//!
//! **Default thresholds.** A geometric ladder from the root's `e*` down by a factor of √2,
//! stopping below the smallest positive `e*` or after [`LADDER_MAX_RUNGS`] rungs (a range of
//! 2^32), and then the lossless threshold 0. Rungs whose cut is the same node set as the
//! rung below are merged into that lower rung. A viewer picks the largest threshold within its
//! budget, and the lower rung is always the right pick there too, so nothing is lost. Thresholds
//! given by the user are kept exactly as given.

use super::domain::{Domain, SampleRect};
use super::tree::{Fmrh, NO_PARENT};
use crate::error::{Error, Result};

/// The most clusters a model may have.
pub const MAX_CLUSTERS: usize = 256;
/// The longest default ladder, in rungs above 0.
pub const LADDER_MAX_RUNGS: u32 = 64;

/// One error cluster: a cut of the tree, sorted by Hilbert key.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    /// δ: every node of the cut has `e* <= δ`, and its parent has `e* > δ`.
    pub threshold: f64,
    /// Indexes into [`Fmrh::nodes`], in Hilbert order.
    pub nodes: Vec<u32>,
    /// The largest `e*` in the cut: the error this cluster actually guarantees (`<= δ`).
    pub max_error: f64,
}

/// Checks user thresholds: finite, non-negative, at most [`MAX_CLUSTERS`]. Returns them sorted
/// ascending without duplicates.
pub fn validate_thresholds(thresholds: &[f64]) -> Result<Vec<f64>> {
    if thresholds.is_empty() {
        return Err(Error::InvalidArgument(
            "at least one threshold is needed".into(),
        ));
    }
    if let Some(bad) = thresholds.iter().find(|t| !t.is_finite() || **t < 0.0) {
        return Err(Error::InvalidArgument(format!(
            "threshold {bad}: thresholds must be finite and >= 0"
        )));
    }
    let mut sorted = thresholds.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.dedup();
    if sorted.len() > MAX_CLUSTERS {
        return Err(Error::TooLarge {
            what: "threshold list".into(),
            detail: format!("{} thresholds; at most {MAX_CLUSTERS}", sorted.len()),
        });
    }
    Ok(sorted)
}

/// The factor between a ladder rung and the next odd one: `1/√2` as the binary64
/// `0x3FE6A09E667F3BCD`, which is `sqrt(0.5)` correctly rounded (and `FRAC_1_SQRT_2`). The
/// spec gives the bits because `1.0 / 2f64.sqrt()` rounds one ulp lower (model §6).
pub const LADDER_HALF_STEP: f64 = f64::from_bits(0x3FE6_A09E_667F_3BCD);

const _: () = assert!(LADDER_HALF_STEP.to_bits() == std::f64::consts::FRAC_1_SQRT_2.to_bits());

/// The default ladder (see the module docs), ascending, starting with 0.
pub fn default_ladder(root_error: f64, min_positive_error: Option<f64>) -> Vec<f64> {
    let mut rungs = vec![0.0];
    let Some(floor) = min_positive_error else {
        return rungs;
    };
    if root_error.is_nan() || root_error <= 0.0 {
        return rungs;
    }
    let mut k = 0;
    while k <= LADDER_MAX_RUNGS {
        // root · 2^(-k/2); even rungs are exact powers of two apart.
        let mut delta = root_error * 0.5f64.powi((k / 2) as i32);
        if k % 2 == 1 {
            delta *= LADDER_HALF_STEP;
        }
        if delta < floor {
            break;
        }
        rungs.push(delta);
        k += 1;
    }
    rungs.sort_by(f64::total_cmp);
    rungs.dedup();
    rungs
}

/// The cut `C(delta)` straight from its definition: the nodes with `e* <= delta` whose parent
/// has `e* > delta`, in tree order. For tests and single queries; [`build_clusters`] makes all
/// cuts at once.
#[cfg(any(test, feature = "testing"))]
pub fn cut(tree: &Fmrh, delta: f64) -> Vec<u32> {
    let nodes = tree.nodes();
    (0..nodes.len() as u32)
        .filter(|&i| {
            let n = &nodes[i as usize];
            n.monotone_error <= delta
                && (n.parent == NO_PARENT || nodes[n.parent as usize].monotone_error > delta)
        })
        .collect()
}

/// Every cluster for `thresholds` (ascending, each `>= tree.delta_min()`), built in one pass.
pub fn build_clusters(tree: &Fmrh, thresholds: &[f64]) -> Vec<Cluster> {
    debug_assert!(thresholds.windows(2).all(|w| w[0] < w[1]));
    debug_assert!(thresholds.first().is_none_or(|&t| t >= tree.delta_min()));
    let mut clusters: Vec<Cluster> = thresholds
        .iter()
        .map(|&threshold| Cluster {
            threshold,
            nodes: Vec::new(),
            max_error: 0.0,
        })
        .collect();
    let nodes = tree.nodes();
    for (i, n) in nodes.iter().enumerate() {
        let upper = if n.parent == NO_PARENT {
            f64::INFINITY
        } else {
            nodes[n.parent as usize].monotone_error
        };
        // Thresholds in [e*(n), e*(parent)).
        let lo = thresholds.partition_point(|&t| t < n.monotone_error);
        let hi = thresholds.partition_point(|&t| t < upper);
        for c in &mut clusters[lo..hi.max(lo)] {
            c.nodes.push(i as u32);
            c.max_error = c.max_error.max(n.monotone_error);
        }
    }
    clusters
}

/// Merges clusters whose cut equals the next lower cluster's, keeping the lower threshold
/// (see the module docs). `clusters` ascending by threshold.
pub fn merge_identical_cuts(clusters: Vec<Cluster>) -> Vec<Cluster> {
    let mut out: Vec<Cluster> = Vec::with_capacity(clusters.len());
    for c in clusters {
        match out.last() {
            Some(prev) if prev.nodes == c.nodes => {}
            _ => out.push(c),
        }
    }
    out
}

/// The edges of the data rectangle, in the order adjacency lists are stored.
pub const EDGES: [&str; 4] = ["north", "east", "south", "west"];

/// For each edge of the data rectangle (north, east, south, west), the nodes of `cut` whose
/// footprint touches it, in order along it: west to east for north and south, north to south
/// for east and west. Multi-file stitching walks these lists side by side.
pub fn edge_nodes(tree: &Fmrh, cut: &[u32]) -> [Vec<u32>; 4] {
    edge_nodes_by(tree.domain(), cut, |i| tree.footprint(i))
}

/// [`edge_nodes`] for nodes known only by their footprints.
pub fn edge_nodes_by(
    domain: &Domain,
    cut: &[u32],
    footprint: impl Fn(u32) -> SampleRect,
) -> [Vec<u32>; 4] {
    let data = domain.data_rect();
    let mut edges: [Vec<(u64, u32)>; 4] = Default::default();
    for &i in cut {
        let fp = footprint(i);
        if fp.row0 == data.row0 {
            edges[0].push((fp.col0, i));
        }
        if fp.col0 <= data.col1 && data.col1 <= fp.col1 {
            edges[1].push((fp.row0, i));
        }
        if fp.row0 <= data.row1 && data.row1 <= fp.row1 {
            edges[2].push((fp.col0, i));
        }
        if fp.col0 == data.col0 {
            edges[3].push((fp.row0, i));
        }
    }
    edges.map(|mut e| {
        e.sort_unstable();
        e.into_iter().map(|(_, i)| i).collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ladder_steps_by_root_two() {
        let l = default_ladder(8.0, Some(1.0));
        assert_eq!(l[0], 0.0);
        assert_eq!(*l.last().unwrap(), 8.0);
        assert_eq!(l.len(), 1 + 7); // 8, 5.66, 4, 2.83, 2, 1.41, 1
        for w in l[1..].windows(2) {
            let ratio = w[1] / w[0];
            assert!((ratio - std::f64::consts::SQRT_2).abs() < 1e-12, "{ratio}");
        }
        assert_eq!(default_ladder(0.0, None), vec![0.0]);
        let capped = default_ladder(1e30, Some(1e-30));
        assert_eq!(capped.len(), 1 + LADDER_MAX_RUNGS as usize + 1);
    }

    #[test]
    fn thresholds_are_checked() {
        assert!(validate_thresholds(&[]).is_err());
        assert!(validate_thresholds(&[1.0, f64::NAN]).is_err());
        assert!(validate_thresholds(&[-1.0]).is_err());
        assert!(validate_thresholds(&[1.0, f64::INFINITY]).is_err());
        assert_eq!(
            validate_thresholds(&[3.0, 0.0, 3.0, 1.0]).unwrap(),
            vec![0.0, 1.0, 3.0]
        );
        let many: Vec<f64> = (0..300).map(f64::from).collect();
        assert!(validate_thresholds(&many).is_err());
    }
}
