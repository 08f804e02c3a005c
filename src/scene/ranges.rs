//! From a region of the terrain to Hilbert key ranges: maximal aligned quadrants, then runs.
//!
//! A region (a window, or the frustum's footprint) is split into the largest *aligned
//! quadrants* it holds: squares of the finest-block grid that are footprints of quadtree
//! nodes. A quadrant at level `l` is one contiguous run of `4^(L-l)` Hilbert keys (the curve
//! is prefix-consistent), so a region becomes a few key ranges. Runs that touch are joined.
//! A *gap merge* of `g` also joins runs separated by at most `g` keys: one range scan then
//! reads the few index entries in the gap instead of seeking again. The entries in a gap are
//! dropped by the caller ([`KeyRun::meets`]), so merging changes cost, never the answer.
//!
//! This module knows the domain and the curve, nothing of files or cameras: a region is given
//! as a classifier of quadrants.

use crate::curve::{hilbert_encode, HilbertKey};
use crate::model::{Domain, SampleRect};

use super::camera::Coverage;

/// An aligned quadrant: the footprint of quadtree node `(x, y)` at `level`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Quadrant {
    /// Level, 0 (the whole domain) to `L` (one physical block).
    pub level: u8,
    /// Column among the level's nodes.
    pub x: u32,
    /// Row among the level's nodes.
    pub y: u32,
}

impl Quadrant {
    /// The finest-block columns and rows it spans (half-open), clipped to existing blocks.
    pub fn blocks(&self, domain: &Domain) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
        let shift = domain.finest_level() - self.level;
        let (cols, rows) = domain.nodes_across(domain.finest_level());
        let x0 = self.x << shift;
        let y0 = self.y << shift;
        let x1 = ((u64::from(self.x) + 1) << shift).min(u64::from(cols)) as u32;
        let y1 = ((u64::from(self.y) + 1) << shift).min(u64::from(rows)) as u32;
        (x0..x1.max(x0), y0..y1.max(y0))
    }

    /// Its Hilbert keys.
    pub fn keys(&self, domain: &Domain) -> KeyRange {
        let finest = domain.finest_level();
        KeyRange::of_node(
            HilbertKey::of_node(finest, self.level, self.x, self.y),
            self.level,
            finest,
        )
    }

    /// Its footprint in samples, clipped to the data.
    pub fn samples(&self, domain: &Domain) -> SampleRect {
        let fp = domain.footprint(self.level, self.x, self.y);
        let data = domain.data_rect();
        SampleRect {
            col0: fp.col0,
            row0: fp.row0,
            col1: fp.col1.min(data.col1),
            row1: fp.row1.min(data.row1),
        }
    }

    /// Its four children that exist, in no particular order.
    pub fn children<'d>(&self, domain: &'d Domain) -> impl Iterator<Item = Quadrant> + 'd {
        let (level, x, y) = (self.level + 1, self.x, self.y);
        (0..4u32)
            .map(move |q| Quadrant {
                level,
                x: 2 * x + (q & 1),
                y: 2 * y + (q >> 1),
            })
            .filter(move |q| level <= domain.finest_level() && domain.exists(q.level, q.x, q.y))
    }
}

/// An inclusive range of finest-level Hilbert keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct KeyRange {
    /// First key.
    pub lo: u64,
    /// Last key (inclusive).
    pub hi: u64,
}

impl KeyRange {
    /// The finest-level keys of the node at `level` whose key is `key` (its first cell),
    /// with `finest` the finest level.
    #[inline]
    pub fn of_node(key: HilbertKey, level: u8, finest: u8) -> KeyRange {
        KeyRange {
            lo: key.0,
            hi: key.last(finest, level.min(finest)),
        }
    }

    /// The key of one finest-level block.
    #[inline]
    pub fn single(key: u64) -> KeyRange {
        KeyRange { lo: key, hi: key }
    }

    /// Whether the two ranges share a key.
    #[inline]
    pub fn overlaps(&self, other: &KeyRange) -> bool {
        self.lo <= other.hi && other.lo <= self.hi
    }
}

/// One range scan: the keys `scan` covers, and the quadrants' true ranges inside it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KeyRun {
    /// What to scan.
    pub scan: KeyRange,
    /// The ranges of the region inside `scan`, sorted and disjoint.
    pub parts: Vec<KeyRange>,
}

impl KeyRun {
    /// Whether `r` meets the region (not merely a gap of the run).
    pub fn meets(&self, r: &KeyRange) -> bool {
        let i = self.parts.partition_point(|p| p.hi < r.lo);
        self.parts.get(i).is_some_and(|p| p.lo <= r.hi)
    }
}

/// The finest blocks `[x0, x1] × [y0, y1]` (inclusive) that own the samples of `window`: a
/// sample belongs to the block whose half-open cell range holds it, the data's last row and
/// column to the last block. `window` must lie inside the data.
pub fn window_blocks(domain: &Domain, window: &SampleRect) -> [u32; 4] {
    let cells = u64::from(domain.block_size() - 1);
    let (cols, rows) = domain.nodes_across(domain.finest_level());
    let bx = |c: u64| ((c / cells).min(u64::from(cols) - 1)) as u32;
    let by = |r: u64| ((r / cells).min(u64::from(rows) - 1)) as u32;
    [
        bx(window.col0),
        by(window.row0),
        bx(window.col1),
        by(window.row1),
    ]
}

/// The finest block that owns sample `(col, row)` (see [`window_blocks`]).
#[cfg(any(test, feature = "testing"))]
pub fn owner_block(domain: &Domain, col: u64, row: u64) -> (u32, u32) {
    let [x, y, _, _] = window_blocks(
        domain,
        &SampleRect {
            col0: col,
            row0: row,
            col1: col,
            row1: row,
        },
    );
    (x, y)
}

/// The Hilbert key of finest block `(x, y)`.
pub fn block_key(domain: &Domain, x: u32, y: u32) -> u64 {
    hilbert_encode(u32::from(domain.finest_level()), x, y)
}

/// Splits the region `classify` describes into maximal aligned quadrants, sorted by key,
/// each with its key range (computed once, here). `classify` sees each candidate quadrant at
/// most once, coarse to fine; a `Partial` quadrant at level `deepest` (or the finest level)
/// is kept whole.
pub fn decompose(
    domain: &Domain,
    deepest: u8,
    mut classify: impl FnMut(&Quadrant) -> Coverage,
) -> (Vec<Quadrant>, Vec<KeyRange>) {
    let deepest = deepest.min(domain.finest_level());
    let mut out: Vec<(KeyRange, Quadrant)> = Vec::new();
    let mut stack = vec![Quadrant {
        level: 0,
        x: 0,
        y: 0,
    }];
    while let Some(q) = stack.pop() {
        match classify(&q) {
            Coverage::Outside => {}
            c if kept_whole(c, q.level, deepest) => out.push((q.keys(domain), q)),
            _ => stack.extend(q.children(domain)),
        }
    }
    // The quadrants are disjoint, so no two share a first key: the order is total.
    out.sort_unstable_by_key(|(k, _)| k.lo);
    out.into_iter().map(|(k, q)| (q, k)).unzip()
}

/// Whether [`decompose`] keeps a quadrant at `level` that `classify` found `c` whole, rather
/// than splitting it (`Outside` is dropped either way): inside, or partly inside at level
/// `deepest` or below.
pub fn kept_whole(c: Coverage, level: u8, deepest: u8) -> bool {
    c == Coverage::Inside || (c == Coverage::Partial && level >= deepest)
}

/// The classifier of a window given in finest blocks `[x0, y0, x1, y1]` (inclusive).
pub fn window_classifier(domain: &Domain, blocks: [u32; 4]) -> impl Fn(&Quadrant) -> Coverage + '_ {
    move |q| {
        let (xs, ys) = q.blocks(domain);
        let [x0, y0, x1, y1] = blocks;
        if xs.is_empty()
            || ys.is_empty()
            || xs.end <= x0
            || xs.start > x1
            || ys.end <= y0
            || ys.start > y1
        {
            Coverage::Outside
        } else if xs.start >= x0 && xs.end - 1 <= x1 && ys.start >= y0 && ys.end - 1 <= y1 {
            Coverage::Inside
        } else {
            Coverage::Partial
        }
    }
}

/// Joins the sorted, disjoint `ranges` into runs: touching ranges always, ranges separated
/// by at most `gap` keys too.
pub fn merge(ranges: &[KeyRange], gap: u64) -> Vec<KeyRun> {
    let mut runs: Vec<KeyRun> = Vec::new();
    for r in ranges {
        match runs.last_mut() {
            Some(run) if r.lo.saturating_sub(run.scan.hi).saturating_sub(1) <= gap => {
                run.scan.hi = run.scan.hi.max(r.hi);
                match run.parts.last_mut() {
                    Some(p) if p.hi + 1 == r.lo => p.hi = r.hi,
                    _ => run.parts.push(*r),
                }
            }
            _ => runs.push(KeyRun {
                scan: *r,
                parts: vec![*r],
            }),
        }
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_becomes_maximal_quadrants() {
        // 8 x 8 blocks (L = 3); the window of blocks 0..=3 x 0..=3 is one level-1 quadrant.
        let d = Domain::new(8 * 8 + 1, 8 * 8 + 1, 9).unwrap();
        let (qs, keys) = decompose(&d, d.finest_level(), window_classifier(&d, [0, 0, 3, 3]));
        assert_eq!(keys, vec![qs[0].keys(&d)]);
        assert_eq!(
            qs,
            vec![Quadrant {
                level: 1,
                x: 0,
                y: 0
            }]
        );
        // Blocks 1..=4 x 1..=2 need finer pieces; their key ranges cover exactly 8 blocks.
        let (qs, keys) = decompose(&d, d.finest_level(), window_classifier(&d, [1, 1, 4, 2]));
        assert!(qs.iter().zip(&keys).all(|(q, k)| q.keys(&d) == *k));
        assert!(keys.windows(2).all(|w| w[0].hi < w[1].lo), "sorted and disjoint");
        let count: u64 = keys.iter().map(|k| k.hi - k.lo + 1).sum();
        assert_eq!(count, 8);
    }

    #[test]
    fn merge_joins_touching_and_small_gaps() {
        let r = |lo, hi| KeyRange { lo, hi };
        let ranges = [r(0, 3), r(4, 7), r(10, 10), r(20, 23)];
        let runs = merge(&ranges, 0);
        assert_eq!(runs.len(), 3);
        assert_eq!(runs[0].scan, r(0, 7));
        assert_eq!(runs[0].parts, vec![r(0, 7)]);
        let runs = merge(&ranges, 2);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0].scan, r(0, 10));
        assert!(runs[0].meets(&r(10, 10)) && !runs[0].meets(&r(8, 9)));
        assert!(runs[0].meets(&r(5, 12)));
        let runs = merge(&ranges, u64::MAX);
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].parts.len(), 3);
    }

    #[test]
    fn sample_ownership() {
        let d = Domain::new(100, 70, 9).unwrap(); // 8 cells a block
        assert_eq!(owner_block(&d, 0, 0), (0, 0));
        assert_eq!(owner_block(&d, 8, 7), (1, 0));
        assert_eq!(owner_block(&d, 99, 69), (12, 8)); // last sample to the last block
        assert_eq!(d.nodes_across(d.finest_level()), (13, 9));
    }
}
