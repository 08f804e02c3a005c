//! The surface a set of blocks draws, as a function of position: the height at any point of
//! the sample plane, integer or not, from the block that owns it.
//!
//! [`GridBlock`] is a block as it draws: its footprint, stride and grid, in samples. A mesh
//! (`src/mesh/`) puts vertices at the blocks' own grid points. A resampler
//! that puts vertices elsewhere (a tile of another pyramid, whose grid follows longitude and
//! latitude rather than samples) needs the surface between them: inside a grid cell, the
//! triangulation of `format-spec/model.md` §4, split along the north-west to south-east
//! diagonal, evaluated at fractional offsets. At a sample it is exactly the value the
//! mesher and `scene::reconstruct` give there.
//!
//! **Ownership.** Blocks are given in priority order, and a point belongs to the first
//! block whose closed footprint holds it. Scene blocks meet only along edges, so the order
//! only decides points on a shared edge, and it decides them the same way every time: two
//! tiles that evaluate the same point get the same height. A caller may append coarser
//! blocks after a scene's (a cover of the whole data) to answer where the scene is silent.
//!
//! Lookup is through a grid of buckets as small as the smallest block (capped in number),
//! each listing the blocks that meet it, in priority order.

use crate::error::{Error, Result};
use crate::model::surface::surface;
use crate::model::SampleRect;
use crate::scene::{LoadedBlock, SceneBlock};

/// A block to mesh: its footprint and the grid its surface is drawn over.
#[derive(Clone, Copy, Debug)]
pub struct GridBlock<'a> {
    /// The footprint, inclusive samples, clipped to the data (`col0 < col1`, `row0 < row1`
    /// for a block with area; a block without one is given no triangles).
    pub rect: SampleRect,
    /// Samples between grid points.
    pub stride: u64,
    /// Grid points along a row of `heights`; the grid starts at the footprint's north-west
    /// corner and may reach past the data (padding, mended).
    pub grid_width: u32,
    /// Rows of `heights`.
    pub grid_height: u32,
    /// The grid's heights, row-major from the north-west.
    pub heights: &'a [f32],
    /// The block's `e*`, in metres.
    pub error: f64,
}

impl<'a> GridBlock<'a> {
    /// Scene block `b` as the mesh takes it: its footprint and `e*`, and the grid `loaded`
    /// holds for it, `stride` samples apart (its level's).
    pub fn of(b: &SceneBlock, loaded: &'a LoadedBlock, stride: u64) -> GridBlock<'a> {
        GridBlock {
            rect: b.rect(),
            stride,
            grid_width: loaded.width,
            grid_height: loaded.height,
            heights: &loaded.heights,
            error: b.error,
        }
    }

    /// The height the block's surface draws at sample `(col, row)` of its footprint.
    pub(crate) fn height_at(&self, col: u64, row: u64) -> f64 {
        let (u, v, s) = (col - self.rect.col0, row - self.rect.row0, self.stride);
        let w = u64::from(self.grid_width);
        let at = |i: u64, j: u64| self.heights[(j * w + i) as usize];
        // Strides are powers of two in a quadtree: shifts, where a division costs tens of
        // cycles (a globe tile's error is measured at a million samples).
        let (ui, vi, on_grid) = if s.is_power_of_two() {
            let k = s.trailing_zeros();
            (u >> k, v >> k, (u | v) & (s - 1) == 0)
        } else {
            (u / s, v / s, u % s == 0 && v % s == 0)
        };
        if on_grid {
            return f64::from(at(ui, vi));
        }
        let i = ui.min(w - 2);
        let j = vi.min(u64::from(self.grid_height) - 2);
        surface(
            at(i, j),
            at(i + 1, j),
            at(i, j + 1),
            at(i + 1, j + 1),
            s,
            u - i * s,
            v - j * s,
        )
    }

    /// Whether the block has area.
    pub(crate) fn has_area(&self) -> bool {
        self.rect.col0 < self.rect.col1 && self.rect.row0 < self.rect.row1
    }

    pub(crate) fn check(&self, index: usize) -> Result<()> {
        let r = &self.rect;
        let (w, h) = (u64::from(self.grid_width), u64::from(self.grid_height));
        let ok = self.stride >= 1
            && r.col0 <= r.col1
            && r.row0 <= r.row1
            && w >= 1
            && h >= 1
            && self.heights.len() as u64 == w * h
            && (w - 1) * self.stride >= r.col1 - r.col0
            && (h - 1) * self.stride >= r.row1 - r.row0
            && (self.stride == 1 || (w >= 2 && h >= 2))
            && self.heights.iter().all(|v| v.is_finite());
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "block {index}: a {w}x{h} grid at stride {} does not cover samples \
                 {},{}..{},{} with finite heights",
                self.stride, r.col0, r.row0, r.col1, r.row1
            )))
        }
    }
}

/// The most buckets an index keeps (about 32 MiB of lists at worst).
const MAX_BUCKETS: u64 = 1 << 22;

/// What the surface says at a point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sampled {
    /// The height the owning block draws there.
    pub height: f64,
    /// The owning block's index among those given.
    pub block: usize,
}

/// The surface of blocks, queried by position.
pub struct Surface<'a> {
    blocks: Vec<GridBlock<'a>>,
    /// Bucket side, in samples.
    side: u64,
    /// The buckets' north-west corner, in samples.
    origin: (u64, u64),
    /// Buckets across and down.
    across: u64,
    down: u64,
    /// For each bucket, the blocks meeting it, in priority order.
    buckets: Vec<Vec<u32>>,
    /// The bounding rectangle of all the blocks.
    bounds: Option<SampleRect>,
}

impl<'a> Surface<'a> {
    /// The surface of `blocks` (each with area; those without are never owners), owned in
    /// the order given.
    pub fn new(blocks: Vec<GridBlock<'a>>) -> Surface<'a> {
        let with_area: Vec<&GridBlock<'_>> = blocks.iter().filter(|b| b.has_area()).collect();
        let bounds = with_area.iter().map(|b| b.rect).reduce(|a, b| SampleRect {
            col0: a.col0.min(b.col0),
            row0: a.row0.min(b.row0),
            col1: a.col1.max(b.col1),
            row1: a.row1.max(b.row1),
        });
        let Some(all) = bounds else {
            return Surface {
                blocks,
                side: 1,
                origin: (0, 0),
                across: 0,
                down: 0,
                buckets: Vec::new(),
                bounds: None,
            };
        };
        let smallest = with_area
            .iter()
            .map(|b| (b.rect.col1 - b.rect.col0).min(b.rect.row1 - b.rect.row0))
            .min()
            .unwrap_or(1)
            .max(1);
        let (w, h) = (all.col1 - all.col0 + 1, all.row1 - all.row0 + 1);
        let mut side = smallest;
        while w.div_ceil(side).saturating_mul(h.div_ceil(side)) > MAX_BUCKETS {
            side = side.saturating_mul(2);
        }
        let (across, down) = (w.div_ceil(side), h.div_ceil(side));
        let mut buckets = vec![Vec::new(); (across * down) as usize];
        for (i, b) in blocks.iter().enumerate() {
            if !b.has_area() {
                continue;
            }
            let r = &b.rect;
            for by in (r.row0 - all.row0) / side..=((r.row1 - all.row0) / side).min(down - 1) {
                for bx in (r.col0 - all.col0) / side..=((r.col1 - all.col0) / side).min(across - 1)
                {
                    buckets[(by * across + bx) as usize].push(i as u32);
                }
            }
        }
        Surface {
            blocks,
            side,
            origin: (all.col0, all.row0),
            across,
            down,
            buckets,
            bounds,
        }
    }

    /// The blocks, in the order given.
    pub fn blocks(&self) -> &[GridBlock<'a>] {
        &self.blocks
    }

    /// The rectangle holding every block, if any has area.
    pub fn bounds(&self) -> Option<SampleRect> {
        self.bounds
    }

    /// The candidates for the point `(col, row)`, or none outside the buckets.
    fn candidates(&self, col: f64, row: f64) -> &[u32] {
        let (c0, r0) = (self.origin.0 as f64, self.origin.1 as f64);
        if !(col >= c0 && row >= r0) {
            return &[];
        }
        let side = self.side as f64;
        let (bx, by) = (((col - c0) / side).floor(), ((row - r0) / side).floor());
        if bx >= self.across as f64 || by >= self.down as f64 {
            return &[];
        }
        &self.buckets[(by as u64 * self.across + bx as u64) as usize]
    }

    /// The surface at `(col, row)` (sample coordinates, fractional allowed), from the first
    /// block whose closed footprint holds it; `None` where no block does.
    pub fn at(&self, col: f64, row: f64) -> Option<Sampled> {
        for &i in self.candidates(col, row) {
            let b = &self.blocks[i as usize];
            let r = &b.rect;
            if col >= r.col0 as f64
                && col <= r.col1 as f64
                && row >= r.row0 as f64
                && row <= r.row1 as f64
            {
                return Some(Sampled {
                    height: height_at(b, col, row),
                    block: i as usize,
                });
            }
        }
        None
    }

    /// Whether some block's footprint meets the closed rectangle `[col0, col1] x [row0,
    /// row1]`.
    #[cfg(any(test, feature = "testing"))]
    pub fn meets(&self, col0: f64, row0: f64, col1: f64, row1: f64) -> bool {
        self.blocks.iter().any(|b| {
            let r = &b.rect;
            b.has_area()
                && col0 <= r.col1 as f64
                && col1 >= r.col0 as f64
                && row0 <= r.row1 as f64
                && row1 >= r.row0 as f64
        })
    }

    /// The surface at the point of the blocks nearest `(col, row)` (the point itself when a
    /// block holds it); `None` when there are no blocks. Ties go to the earlier block.
    pub fn nearest(&self, col: f64, row: f64) -> Option<Sampled> {
        if let Some(s) = self.at(col, row) {
            return Some(s);
        }
        let mut best: Option<(f64, f64, f64)> = None;
        for b in self.blocks.iter().filter(|b| b.has_area()) {
            let r = &b.rect;
            let c = col.clamp(r.col0 as f64, r.col1 as f64);
            let w = row.clamp(r.row0 as f64, r.row1 as f64);
            let d = (c - col).powi(2) + (w - row).powi(2);
            if best.is_none_or(|(bd, ..)| d < bd) {
                best = Some((d, c, w));
            }
        }
        best.and_then(|(_, c, w)| self.at(c, w))
    }
}

/// The height block `b` draws at `(col, row)` inside its footprint: at a sample, exactly
/// the block's own evaluation there; between samples, the cell's triangle at fractional
/// offsets.
pub fn height_at(b: &GridBlock<'_>, col: f64, row: f64) -> f64 {
    let r = &b.rect;
    if col.fract() == 0.0 && row.fract() == 0.0 {
        return b.height_at(col as u64, row as u64);
    }
    let (w, h) = (u64::from(b.grid_width), u64::from(b.grid_height));
    let s = b.stride as f64;
    let (u, v) = ((col - r.col0 as f64) / s, (row - r.row0 as f64) / s);
    let at = |i: u64, j: u64| f64::from(b.heights[(j * w + i) as usize]);
    if w < 2 || h < 2 {
        return at(0, 0);
    }
    let i = (u.floor().max(0.0) as u64).min(w - 2);
    let j = (v.floor().max(0.0) as u64).min(h - 2);
    let (fu, fv) = (u - i as f64, v - j as f64);
    let (nw, ne, sw, se) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
    if fu >= fv {
        (1.0 - fu) * nw + (fu - fv) * ne + fv * se
    } else {
        (1.0 - fv) * nw + (fv - fu) * sw + fu * se
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn rect(col0: u64, row0: u64, col1: u64, row1: u64) -> SampleRect {
        SampleRect {
            col0,
            row0,
            col1,
            row1,
        }
    }

    /// A 3x3 grid at stride 4 over 0..=8, and a physical 5x5 block at 8..=12 beside it.
    fn two_blocks<'a>(coarse: &'a [f32], fine: &'a [f32]) -> Vec<GridBlock<'a>> {
        vec![
            GridBlock {
                rect: rect(0, 0, 8, 8),
                stride: 4,
                grid_width: 3,
                grid_height: 3,
                heights: coarse,
                error: 2.0,
            },
            GridBlock {
                rect: rect(8, 0, 12, 4),
                stride: 1,
                grid_width: 5,
                grid_height: 5,
                heights: fine,
                error: 0.0,
            },
        ]
    }

    #[test]
    fn ownership_lookup_and_the_nearest_point() {
        let coarse: Vec<f32> = (0..9).map(|k| k as f32).collect();
        let fine: Vec<f32> = (0..25).map(|k| 100.0 + k as f32).collect();
        let s = Surface::new(two_blocks(&coarse, &fine));
        // A grid point of the coarse block, the shared edge (first block wins), the fine one.
        assert_eq!(s.at(4.0, 4.0).map(|x| (x.height, x.block)), Some((4.0, 0)));
        assert_eq!(s.at(8.0, 0.0).map(|x| x.block), Some(0));
        assert_eq!(
            s.at(9.0, 1.0).map(|x| (x.height, x.block)),
            Some((106.0, 1))
        );
        // Between grid points: the triangle (NW 0, NE 1, SE 4) at (1/2, 1/4) of the cell.
        let h = s.at(2.0, 1.0).unwrap().height;
        assert!(
            (h - (0.5 * 0.0 + 0.25 * 1.0 + 0.25 * 4.0)).abs() < 1e-12,
            "{h}"
        );
        // Outside: nothing at the point, the nearest edge point's height near it.
        assert!(s.at(10.0, 6.0).is_none() && s.at(-1.0, 2.0).is_none());
        assert_eq!(s.nearest(11.0, 6.0).map(|x| x.block), Some(1));
        assert_eq!(
            s.nearest(11.0, 6.0).unwrap().height,
            s.at(11.0, 4.0).unwrap().height
        );
        // Equally near both: the earlier block.
        assert_eq!(s.nearest(10.0, 6.0).map(|x| x.block), Some(0));
        assert!(s.meets(11.0, 3.0, 20.0, 20.0) && !s.meets(13.0, 0.0, 20.0, 20.0));
        assert!(Surface::new(Vec::new()).nearest(0.0, 0.0).is_none());
    }

    proptest! {
        /// At samples the surface is the blocks' own evaluation; between them it is
        /// continuous across cells (two nearby points differ by at most the slope times
        /// their distance) and within the cell's corner heights.
        #[test]
        fn fractional_heights_agree_with_the_grid(
            heights in proptest::collection::vec(-50.0f32..50.0, 25),
            col in 0.0f64..16.0, row in 0.0f64..16.0,
        ) {
            let b = GridBlock {
                rect: rect(0, 0, 16, 16),
                stride: 4,
                grid_width: 5,
                grid_height: 5,
                heights: &heights,
                error: 0.0,
            };
            let (c, r) = (col.round(), row.round());
            prop_assert_eq!(height_at(&b, c, r), b.height_at(c as u64, r as u64));
            let z = height_at(&b, col, row);
            let (i, j) = (((col / 4.0) as usize).min(3), ((row / 4.0) as usize).min(3));
            let corners = [heights[j * 5 + i], heights[j * 5 + i + 1], heights[(j + 1) * 5 + i], heights[(j + 1) * 5 + i + 1]];
            let lo = corners.iter().copied().fold(f32::INFINITY, f32::min) as f64;
            let hi = corners.iter().copied().fold(f32::NEG_INFINITY, f32::max) as f64;
            prop_assert!(z >= lo - 1e-9 && z <= hi + 1e-9);
            // Lipschitz: a cell's triangles have slope at most 2 * 100 / 4 per sample.
            let eps = 1e-3;
            let z2 = height_at(&b, (col + eps).min(16.0), row);
            prop_assert!((z2 - z).abs() <= 50.0 * eps + 1e-9);
        }

        /// `GridBlock::height_at` shifts for a stride that is a power of two and divides
        /// for any other: both give the heights the division gives, bit for bit, on and
        /// off the grid, for blocks anywhere.
        #[test]
        fn integer_heights_are_the_divisions(
            k in 0u32..5, odd in prop::sample::select(vec![3u64, 5, 6, 7]), power in any::<bool>(),
            col0 in 0u64..1_000_000, row0 in 0u64..1_000_000,
            heights in proptest::collection::vec(-50.0f32..50.0, 36),
            u in 0u64..1000, v in 0u64..1000,
        ) {
            let s = if power { 1u64 << k } else { odd };
            let b = GridBlock {
                rect: rect(col0, row0, col0 + 5 * s, row0 + 5 * s),
                stride: s,
                grid_width: 6,
                grid_height: 6,
                heights: &heights,
                error: 0.0,
            };
            let (u, v) = (u % (5 * s + 1), v % (5 * s + 1));
            let at = |i: u64, j: u64| heights[(j * 6 + i) as usize];
            let want = if u % s == 0 && v % s == 0 {
                f64::from(at(u / s, v / s))
            } else {
                let (i, j) = ((u / s).min(4), (v / s).min(4));
                surface(at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1), s, u - i * s, v - j * s)
            };
            prop_assert_eq!(b.height_at(col0 + u, row0 + v).to_bits(), want.to_bits());
        }
    }
}
