//! Where blocks meet: every block edge filed under the line it lies on, so that the blocks
//! across an edge and the blocks holding a point are found by a binary search on one line.
//!
//! Blocks of a cover meet only along edges, so the blocks whose south edges lie on one row
//! are disjoint along it, as are those whose north edges do: each side of a line is a
//! sorted list of disjoint spans. Nothing here assumes a quadtree, so blocks from tiles whose
//! grids are offset from each other are found as well as blocks of one tile.

use std::collections::HashMap;

use crate::model::SampleRect;

/// One block's edge on a line: the closed span `lo..=hi` along it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Span {
    pub lo: u64,
    pub hi: u64,
    pub block: usize,
}

/// The blocks on either side of one line: `[before, after]`, where *before* is north of a
/// row or west of a column.
type Sides = [Vec<Span>; 2];

/// Every block edge, by line.
pub(super) struct Lines {
    /// Rows: blocks north of the row (their south edge on it), then south of it.
    rows: HashMap<u64, Sides>,
    /// Columns: blocks west of the column (their east edge on it), then east of it.
    cols: HashMap<u64, Sides>,
}

/// The spans of `side` that meet the closed span `lo..=hi` (touching at a point counts).
fn meeting(side: &[Span], lo: u64, hi: u64) -> &[Span] {
    let start = side.partition_point(|s| s.hi < lo);
    let end = side.partition_point(|s| s.lo <= hi);
    &side[start..end.max(start)]
}

impl Lines {
    /// Files the edges of `rects` (blocks with area: `col0 < col1`, `row0 < row1`).
    pub fn new(rects: &[SampleRect]) -> Lines {
        let mut rows: HashMap<u64, Sides> = HashMap::new();
        let mut cols: HashMap<u64, Sides> = HashMap::new();
        for (block, r) in rects.iter().enumerate() {
            let across = |lo, hi| Span { lo, hi, block };
            rows.entry(r.row1).or_default()[0].push(across(r.col0, r.col1));
            rows.entry(r.row0).or_default()[1].push(across(r.col0, r.col1));
            cols.entry(r.col1).or_default()[0].push(across(r.row0, r.row1));
            cols.entry(r.col0).or_default()[1].push(across(r.row0, r.row1));
        }
        for sides in rows.values_mut().chain(cols.values_mut()) {
            for side in sides {
                side.sort_unstable_by_key(|s| s.lo);
            }
        }
        Lines { rows, cols }
    }

    /// The blocks across the edge `e` (0 north, 1 east, 2 south, 3 west) of `rect`, with
    /// the part of the edge each shares (positive length only), in increasing order along
    /// the edge.
    pub fn across(&self, rect: &SampleRect, e: usize) -> Vec<Span> {
        let (line, side, lo, hi) = match e {
            0 => (self.rows.get(&rect.row0), 0, rect.col0, rect.col1),
            1 => (self.cols.get(&rect.col1), 1, rect.row0, rect.row1),
            2 => (self.rows.get(&rect.row1), 1, rect.col0, rect.col1),
            _ => (self.cols.get(&rect.col0), 0, rect.row0, rect.row1),
        };
        let Some(sides) = line else {
            return Vec::new();
        };
        meeting(&sides[side], lo, hi)
            .iter()
            .filter_map(|s| {
                let (a, b) = (s.lo.max(lo), s.hi.min(hi));
                (a < b).then_some(Span {
                    lo: a,
                    hi: b,
                    block: s.block,
                })
            })
            .collect()
    }

    /// Every block whose closed rectangle holds the point `(col, row)`, given that the
    /// point lies on some block's edge (a cover's blocks then hold it only on their edges).
    pub fn holding(&self, col: u64, row: u64, out: &mut Vec<usize>) {
        out.clear();
        let lines = [(self.rows.get(&row), col), (self.cols.get(&col), row)];
        for (sides, t) in lines {
            for side in sides.into_iter().flatten() {
                out.extend(meeting(side, t, t).iter().map(|s| s.block));
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}
