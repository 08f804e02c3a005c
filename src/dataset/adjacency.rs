//! Adjacent-cluster tables (seed 000 §4.3, `format-spec/dataset.md` §3.5): for each border
//! between a tile and a neighbour east or south of it, and each pair of their clusters whose
//! thresholds lie within one step of each other, which edge nodes of the one meet which edge
//! nodes of the other along the border, with a positive length in common.
//!
//! Each tile stores its east and south borders (so a border is stored once, by a rule that
//! does not change when the grid's origin moves), and names each neighbour by its offset
//! from the tile, not by index. The tables are the merges of the two tiles' own edge lists
//! (container §6.4) in dataset coordinates: this module reads those lists from the two
//! tiles' stores ([`TileEdges`]), merges them, and encodes and decodes the bytes.

use std::collections::BTreeSet;

use crate::error::Result;
use crate::format::manifest::TileRecord;
use crate::model::SampleRect;
use crate::scene::ranges::Quadrant;
use crate::store::{Source, Store};

/// Side of a tile: east.
pub const EAST: u8 = 1;
/// Side of a tile: south.
pub const SOUTH: u8 = 2;

/// The neighbour shares the border line with the tile (an edge row or column of both).
pub const SHARED: u8 = 0;
/// The neighbour's first column (row) is one past the tile's last.
pub const ABUTTING: u8 = 1;

/// A tile's edge lists, in dataset coordinates: per cluster, per edge (N, E, S, W), the
/// nodes `(ordinal, first, last)` with the span of their footprints along the edge (columns
/// for N and S, rows for E and W), in order along it.
#[derive(Clone, Debug, PartialEq)]
pub struct TileEdges {
    /// The tile's cluster thresholds, ascending.
    pub thresholds: Vec<f64>,
    /// `lists[cluster][edge]`.
    pub lists: Vec<[Vec<(u32, u64, u64)>; 4]>,
}

impl TileEdges {
    /// Reads the edge lists of `store`, the tile `record` places.
    pub fn read<S: Source>(store: &Store<S>, record: &TileRecord) -> Result<TileEdges> {
        let d = *store.domain();
        let r = record.rect();
        let mut lists = Vec::with_capacity(store.clusters().len());
        for c in 0..store.clusters().len() {
            let mut per_edge: [Vec<(u32, u64, u64)>; 4] = Default::default();
            for (e, list) in per_edge.iter_mut().enumerate() {
                for ord in store.adjacency(c, e)? {
                    let n = store.node(ord)?;
                    let f = Quadrant {
                        level: n.level,
                        x: n.x,
                        y: n.y,
                    }
                    .samples(&d);
                    list.push(match e {
                        0 | 2 => (ord, r.col0 + f.col0, r.col0 + f.col1),
                        _ => (ord, r.row0 + f.row0, r.row0 + f.row1),
                    });
                }
            }
            lists.push(per_edge);
        }
        Ok(TileEdges {
            thresholds: store.clusters().iter().map(|c| c.threshold).collect(),
            lists,
        })
    }
}

/// The cluster pairs a border stores: for each cluster of either tile, the other tile's
/// cluster with the largest threshold not above it (the first when none is) and the next
/// finer-to-coarser one, i.e. the clusters whose thresholds lie within one step of it.
pub fn cluster_pairs(a: &[f64], b: &[f64]) -> Vec<(u16, u16)> {
    let mut out = BTreeSet::new();
    let near = |t: f64, other: &[f64]| -> [Option<usize>; 2] {
        let j = other.partition_point(|&x| x <= t).saturating_sub(1);
        [Some(j), (j + 1 < other.len()).then_some(j + 1)]
    };
    for (i, &t) in a.iter().enumerate() {
        for j in near(t, b).into_iter().flatten() {
            out.insert((i as u16, j as u16));
        }
    }
    for (j, &t) in b.iter().enumerate() {
        for i in near(t, a).into_iter().flatten() {
            out.insert((i as u16, j as u16));
        }
    }
    out.into_iter()
        .filter(|&(i, j)| usize::from(i) < a.len() && usize::from(j) < b.len())
        .collect()
}

/// The pairs of nodes of two edge lists (each in order along the border) whose spans share a
/// positive length inside `first ..= last`.
pub fn merge(
    a: &[(u32, u64, u64)],
    b: &[(u32, u64, u64)],
    first: u64,
    last: u64,
) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        let (na, a0, a1) = a[i];
        let (nb, b0, b1) = b[j];
        let lo = a0.max(b0).max(first);
        let hi = a1.min(b1).min(last);
        if lo < hi {
            out.push((na, nb));
        }
        match a1.cmp(&b1) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                i += 1;
                j += 1;
            }
        }
    }
    out
}

/// One table of a border: the tile's cluster, the neighbour's, and the pairs of their edge
/// nodes that meet (node ordinals: the tile's, the neighbour's), in order along the border.
pub type Table = (u16, u16, Vec<(u32, u32)>);

/// One border as stored.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Border {
    /// The neighbour's first column minus the tile's.
    pub dcol: i64,
    /// The neighbour's first row minus the tile's.
    pub drow: i64,
    /// [`EAST`] or [`SOUTH`].
    pub side: u8,
    /// [`SHARED`] or [`ABUTTING`].
    pub kind: u8,
    /// The span both tiles have along the border, from the tile's first row (east) or
    /// column (south): `first < last`.
    pub first: u64,
    /// Its last row or column, likewise.
    pub last: u64,
    /// `(cluster of the tile, cluster of the neighbour, node pairs (tile's, neighbour's))`.
    pub tables: Vec<Table>,
}

/// The borders tile `a` stores with the tiles of `others` (any tiles of the dataset): those
/// east and south of it that share (or abut along) a positive length of its east or south
/// edge. Returns `(index in others, side, kind, first, last)` in absolute dataset
/// coordinates, sorted by side then neighbour position.
pub fn borders_of(a: &SampleRect, others: &[SampleRect]) -> Vec<(usize, u8, u8, u64, u64)> {
    // Abutting tiles meet across a strip of cells (between the one's last line and the
    // other's first) that no tile covers: a tile spanning part of the strip stands between
    // them, and they have no border.
    let mut out = Vec::new();
    for (k, b) in others.iter().enumerate() {
        if b == a {
            continue;
        }
        if b.col0 == a.col1 || b.col0 == a.col1 + 1 {
            let (lo, hi) = (a.row0.max(b.row0), a.row1.min(b.row1));
            let kind = if b.col0 == a.col1 { SHARED } else { ABUTTING };
            let blocked = kind == ABUTTING
                && others.iter().any(|t| {
                    t.col0 <= a.col1 && t.col1 >= b.col0 && t.row0.max(lo) < t.row1.min(hi)
                });
            if lo < hi && !blocked {
                out.push((k, EAST, kind, lo, hi));
            }
        }
        if b.row0 == a.row1 || b.row0 == a.row1 + 1 {
            let (lo, hi) = (a.col0.max(b.col0), a.col1.min(b.col1));
            let kind = if b.row0 == a.row1 { SHARED } else { ABUTTING };
            let blocked = kind == ABUTTING
                && others.iter().any(|t| {
                    t.row0 <= a.row1 && t.row1 >= b.row0 && t.col0.max(lo) < t.col1.min(hi)
                });
            if lo < hi && !blocked {
                out.push((k, SOUTH, kind, lo, hi));
            }
        }
    }
    out.sort_by_key(|&(k, side, _, _, _)| (side, others[k].col0, others[k].row0));
    out
}

/// The tables of one border: tile `a` (edges `ea`) and its neighbour `b` (edges `eb`),
/// found by [`borders_of`] as `(side, kind, first, last)` (absolute).
pub fn border(
    (a, ea): (&SampleRect, &TileEdges),
    (b, eb): (&SampleRect, &TileEdges),
    (side, kind, first, last): (u8, u8, u64, u64),
) -> Border {
    // East: the tile's east list (1) meets the neighbour's west list (3); south: 2 and 0.
    let (mine, theirs) = if side == EAST { (1, 3) } else { (2, 0) };
    let tables = cluster_pairs(&ea.thresholds, &eb.thresholds)
        .into_iter()
        .map(|(i, j)| {
            let pairs = merge(
                &ea.lists[usize::from(i)][mine],
                &eb.lists[usize::from(j)][theirs],
                first,
                last,
            );
            (i, j, pairs)
        })
        .collect();
    let origin = if side == EAST { a.row0 } else { a.col0 };
    Border {
        dcol: b.col0 as i64 - a.col0 as i64,
        drow: b.row0 as i64 - a.row0 as i64,
        side,
        kind,
        first: first - origin,
        last: last - origin,
        tables,
    }
}

/// Encodes a tile's borders (empty: no bytes).
pub fn encode(borders: &[Border]) -> Vec<u8> {
    if borders.is_empty() {
        return Vec::new();
    }
    let mut out = Vec::new();
    out.extend_from_slice(&(borders.len() as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    for b in borders {
        out.extend_from_slice(&b.dcol.to_le_bytes());
        out.extend_from_slice(&b.drow.to_le_bytes());
        out.push(b.side);
        out.push(b.kind);
        out.extend_from_slice(&(b.tables.len() as u16).to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&b.first.to_le_bytes());
        out.extend_from_slice(&b.last.to_le_bytes());
        for (i, j, pairs) in &b.tables {
            out.extend_from_slice(&i.to_le_bytes());
            out.extend_from_slice(&j.to_le_bytes());
            out.extend_from_slice(&(pairs.len() as u32).to_le_bytes());
            for (x, y) in pairs {
                out.extend_from_slice(&x.to_le_bytes());
                out.extend_from_slice(&y.to_le_bytes());
            }
        }
    }
    out
}

/// Decodes a tile's borders; `Err` names what is malformed.
pub fn decode(bytes: &[u8]) -> std::result::Result<Vec<Border>, String> {
    if bytes.is_empty() {
        return Ok(Vec::new());
    }
    let mut at = 0usize;
    let mut take = |n: usize| -> std::result::Result<&[u8], String> {
        let s = bytes
            .get(at..at + n)
            .ok_or_else(|| format!("ends at byte {} inside a field of {n} bytes", bytes.len()))?;
        at += n;
        Ok(s)
    };
    let u32_of = |s: &[u8]| u32::from_le_bytes([s[0], s[1], s[2], s[3]]);
    let u64_of = |s: &[u8]| u64::from_le_bytes([s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]]);
    let count = u32_of(take(4)?);
    if u32_of(take(4)?) != 0 {
        return Err("reserved bytes not zero".into());
    }
    let mut out = Vec::new();
    for _ in 0..count {
        let dcol = u64_of(take(8)?) as i64;
        let drow = u64_of(take(8)?) as i64;
        let head = take(8)?;
        let (side, kind) = (head[0], head[1]);
        let tables = u16::from_le_bytes([head[2], head[3]]);
        if u32_of(&head[4..8]) != 0 || !(side == EAST || side == SOUTH) || kind > ABUTTING {
            return Err(format!(
                "border side {side}, kind {kind}, or reserved bytes"
            ));
        }
        let first = u64_of(take(8)?);
        let last = u64_of(take(8)?);
        if first >= last {
            return Err(format!("border span {first} ..= {last}"));
        }
        let mut ts = Vec::with_capacity(usize::from(tables));
        for _ in 0..tables {
            let h = take(8)?;
            let (i, j) = (
                u16::from_le_bytes([h[0], h[1]]),
                u16::from_le_bytes([h[2], h[3]]),
            );
            let n = u32_of(&h[4..8]) as usize;
            let raw = take(n.checked_mul(8).ok_or("pair count overflows")?)?;
            let pairs = raw
                .chunks_exact(8)
                .map(|c| (u32_of(&c[..4]), u32_of(&c[4..])))
                .collect();
            ts.push((i, j, pairs));
        }
        out.push(Border {
            dcol,
            drow,
            side,
            kind,
            first,
            last,
            tables: ts,
        });
    }
    if at != bytes.len() {
        return Err(format!("{} bytes after the last border", bytes.len() - at));
    }
    Ok(out)
}

/// The encoded tables of tile `a`, from its edges and its neighbours'. `edges(k)` gives the
/// edges of tile `k` of `rects`.
pub fn tables_of(
    a: usize,
    rects: &[SampleRect],
    edges: &mut dyn FnMut(usize) -> Result<std::sync::Arc<TileEdges>>,
) -> Result<Vec<u8>> {
    let mut borders = Vec::new();
    for (k, side, kind, first, last) in borders_of(&rects[a], rects) {
        let ea = edges(a)?;
        let eb = edges(k)?;
        borders.push(border(
            (&rects[a], &ea),
            (&rects[k], &eb),
            (side, kind, first, last),
        ));
    }
    Ok(encode(&borders))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn clusters_pair_within_one_step() {
        let same = [0.0, 1.0, 2.0, 4.0];
        assert_eq!(
            cluster_pairs(&same, &same),
            vec![
                (0, 0),
                (0, 1),
                (1, 0),
                (1, 1),
                (1, 2),
                (2, 1),
                (2, 2),
                (2, 3),
                (3, 2),
                (3, 3)
            ]
        );
        // A coarser neighbour: each of mine meets the nearest of its at or below, and the next.
        let pairs = cluster_pairs(&[0.0, 0.5, 1.0], &[0.0, 3.0]);
        assert!(pairs.contains(&(1, 0)) && pairs.contains(&(1, 1)) && pairs.contains(&(2, 1)));
        assert!(pairs.iter().all(|&(i, j)| i < 3 && j < 2));
    }

    #[test]
    fn a_merge_pairs_spans_that_share_a_length() {
        // Mine: 0..=4, 4..=8; theirs: 0..=2, 2..=6, 6..=8. Touching at a point is no pair.
        let a = [(10, 0, 4), (11, 4, 8)];
        let b = [(20, 0, 2), (21, 2, 6), (22, 6, 8)];
        assert_eq!(
            merge(&a, &b, 0, 8),
            vec![(10, 20), (10, 21), (11, 21), (11, 22)]
        );
        // Inside a shorter common span, only what meets it.
        assert_eq!(merge(&a, &b, 5, 8), vec![(11, 21), (11, 22)]);
    }

    #[test]
    fn borders_are_east_and_south_shared_or_abutting() {
        let a = SampleRect {
            col0: 0,
            row0: 0,
            col1: 10,
            row1: 10,
        };
        let east = SampleRect {
            col0: 10,
            row0: 5,
            col1: 20,
            row1: 30,
        };
        let south = SampleRect {
            col0: 3,
            row0: 11,
            col1: 9,
            row1: 20,
        };
        let corner = SampleRect {
            col0: 10,
            row0: 10,
            col1: 20,
            row1: 20,
        };
        let far = SampleRect {
            col0: 0,
            row0: 20,
            col1: 5,
            row1: 25,
        };
        let found = borders_of(&a, &[a, east, south, corner, far]);
        assert_eq!(
            found,
            vec![(1, EAST, SHARED, 5, 10), (2, SOUTH, ABUTTING, 3, 9)]
        );
    }

    proptest! {
        #[test]
        fn tables_round_trip(
            borders in proptest::collection::vec(
                (any::<i32>(), any::<i32>(), prop_oneof![Just(EAST), Just(SOUTH)], 0u8..2, 0u64..1000, 1u64..1000,
                 proptest::collection::vec((any::<u16>(), any::<u16>(), proptest::collection::vec(any::<(u32, u32)>(), 0..6)), 0..4)),
                0..4,
            ),
        ) {
            let borders: Vec<Border> = borders
                .into_iter()
                .map(|(dc, dr, side, kind, first, len, tables)| Border {
                    dcol: i64::from(dc), drow: i64::from(dr), side, kind, first, last: first + len, tables,
                })
                .collect();
            prop_assert_eq!(decode(&encode(&borders)).unwrap(), borders);
        }

        #[test]
        fn any_bytes_decode_or_fail(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = decode(&bytes);
        }
    }
}
