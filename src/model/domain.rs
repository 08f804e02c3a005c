//! The geometry of the quadtree: block size, levels, padding and node footprints.
//!
//! The grid is cut into square blocks of `b = 2^k + 1` samples a side that share their edge
//! rows and columns. The quadtree's domain is the smallest square of `2^L · (b - 1) + 1` samples
//! that holds the data. Level `L` is the finest: its nodes are the physical blocks, at stride 1.
//! Each level up doubles the stride, and the root (level 0) covers the whole domain at stride
//! `2^L`. Node `(x, y)` at level `l` covers the samples
//! `[x·(b-1)·2^(L-l), (x+1)·(b-1)·2^(L-l)]` along a row, and the same along a column. That
//! closed range is its *footprint*.
//!
//! **Padding** ("mending boundaries", seed 000 §4.3). The domain usually extends east and south
//! of the data. The padding holds no terrain: its samples are void and are never stored. A node
//! *exists* only if its footprint holds at least one cell of data: its west edge lies west of
//! the data's last column and its north edge north of the data's last row. A node outside the
//! data is never created, so it is never reported as terrain. A data grid one sample wide has no
//! cells, and the first node column holds it.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::heightfield::check_dimensions;

/// The block size used when none is given: 65 samples a side (64 cells).
pub const DEFAULT_BLOCK_SIZE: u32 = 65;
/// The smallest block size accepted.
pub const MIN_BLOCK_SIZE: u32 = 9;
/// The largest block size accepted.
pub const MAX_BLOCK_SIZE: u32 = 1025;

/// An inclusive rectangle of sample coordinates: columns `col0..=col1`, rows `row0..=row1`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize)]
pub struct SampleRect {
    /// West column.
    pub col0: u64,
    /// North row.
    pub row0: u64,
    /// East column (inclusive).
    pub col1: u64,
    /// South row (inclusive).
    pub row1: u64,
}

impl SampleRect {
    /// The overlap of two rectangles, if any.
    pub fn intersect(&self, other: &SampleRect) -> Option<SampleRect> {
        let r = SampleRect {
            col0: self.col0.max(other.col0),
            row0: self.row0.max(other.row0),
            col1: self.col1.min(other.col1),
            row1: self.row1.min(other.row1),
        };
        (r.col0 <= r.col1 && r.row0 <= r.row1).then_some(r)
    }

    /// Whether sample `(col, row)` lies inside.
    pub fn contains(&self, col: u64, row: u64) -> bool {
        (self.col0..=self.col1).contains(&col) && (self.row0..=self.row1).contains(&row)
    }

    /// Number of samples inside.
    pub fn samples(&self) -> u64 {
        (self.col1 - self.col0 + 1) * (self.row1 - self.row0 + 1)
    }

    /// `Ok` when this window lies wholly inside `outer` (the data, a dataset's grid), else
    /// the invalid-argument error every reader of a window gives, naming `outer` as `what`.
    pub fn check_inside(&self, outer: &SampleRect, what: &str) -> Result<()> {
        if self.col0 <= self.col1 && self.row0 <= self.row1 && self.intersect(outer) == Some(*self)
        {
            return Ok(());
        }
        Err(Error::InvalidArgument(format!(
            "window {},{},{},{} is not inside the {what} {},{},{},{}",
            self.col0,
            self.row0,
            self.col1,
            self.row1,
            outer.col0,
            outer.row0,
            outer.col1,
            outer.row1
        )))
    }
}

/// The quadtree's geometry for one data grid and block size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Domain {
    width: u32,
    height: u32,
    block_size: u32,
    finest_level: u8,
}

impl Domain {
    /// The domain of a `width × height` data grid cut into blocks of `block_size` samples.
    /// `block_size` must be `2^k + 1` within 9 ..= 1025.
    pub fn new(width: u32, height: u32, block_size: u32) -> Result<Domain> {
        check_dimensions(u64::from(width), u64::from(height))?;
        if !(MIN_BLOCK_SIZE..=MAX_BLOCK_SIZE).contains(&block_size)
            || !(block_size - 1).is_power_of_two()
        {
            return Err(Error::InvalidArgument(format!(
                "block size {block_size}: must be 2^k + 1 between {MIN_BLOCK_SIZE} and {MAX_BLOCK_SIZE} (9, 17, 33, 65, ...)"
            )));
        }
        let cells = u64::from(block_size - 1);
        let need = u64::from(width.max(height));
        let mut finest_level = 0u8;
        while (cells << finest_level) + 1 < need {
            finest_level += 1;
        }
        Ok(Domain {
            width,
            height,
            block_size,
            finest_level,
        })
    }

    /// Data samples along a row.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Data samples down a column.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Samples along a block side, `b`.
    pub fn block_size(&self) -> u32 {
        self.block_size
    }

    /// The finest level, `L` (the root is level 0).
    pub fn finest_level(&self) -> u8 {
        self.finest_level
    }

    /// Number of levels, `L + 1`.
    pub fn levels(&self) -> u8 {
        self.finest_level + 1
    }

    /// Samples along a side of the padded square domain, `2^L · (b - 1) + 1`.
    pub fn side(&self) -> u64 {
        (u64::from(self.block_size - 1) << self.finest_level) + 1
    }

    /// Sample spacing of a node's grid at `level`: `2^(L - level)`.
    pub fn stride(&self, level: u8) -> u64 {
        1u64 << (self.finest_level - level)
    }

    /// Cells along a side of a node's footprint at `level`: `(b - 1) · stride`.
    pub fn node_cells(&self, level: u8) -> u64 {
        u64::from(self.block_size - 1) << (self.finest_level - level)
    }

    /// How many node columns and rows exist at `level` (see the module docs for existence).
    pub fn nodes_across(&self, level: u8) -> (u32, u32) {
        let span = self.node_cells(level);
        let cols = u64::from((self.width - 1).max(1)).div_ceil(span);
        let rows = u64::from((self.height - 1).max(1)).div_ceil(span);
        (cols as u32, rows as u32)
    }

    /// Whether node `(x, y)` at `level` exists: its footprint holds data.
    pub fn exists(&self, level: u8, x: u32, y: u32) -> bool {
        // The level first: `nodes_across` has no answer past the finest level.
        if level > self.finest_level {
            return false;
        }
        let (cols, rows) = self.nodes_across(level);
        x < cols && y < rows
    }

    /// The footprint of node `(x, y)` at `level`, padding included.
    pub fn footprint(&self, level: u8, x: u32, y: u32) -> SampleRect {
        let span = self.node_cells(level);
        let (col0, row0) = (u64::from(x) * span, u64::from(y) * span);
        SampleRect {
            col0,
            row0,
            col1: col0 + span,
            row1: row0 + span,
        }
    }

    /// The data rectangle: every sample that is terrain or void, never padding.
    pub fn data_rect(&self) -> SampleRect {
        SampleRect {
            col0: 0,
            row0: 0,
            col1: u64::from(self.width - 1),
            row1: u64::from(self.height - 1),
        }
    }

    /// The stored columns and rows `(gw, gh)` of the grid of node `(x, y)` at `level`
    /// (format §7): its grid samples inside the data, plus one clamp sample if any lie past
    /// the data's east (south) edge. Grid column `i >= gw` reads column `gw - 1`.
    pub fn grid_dims(&self, level: u8, x: u32, y: u32) -> (u32, u32) {
        let fp = self.footprint(level, x, y);
        let s = self.stride(level);
        let b = self.block_size;
        let dim = |start: u64, last_data: u64| -> u32 {
            let inside = if start > last_data {
                0
            } else {
                u32::try_from((last_data - start) / s + 1).map_or(b, |n| n.min(b))
            };
            if inside < b {
                inside + 1
            } else {
                b
            }
        };
        (
            dim(fp.col0, u64::from(self.width - 1)),
            dim(fp.row0, u64::from(self.height - 1)),
        )
    }

    /// Padding samples added east and south to square the domain.
    pub fn padding_samples(&self) -> u64 {
        self.side() * self.side() - u64::from(self.width) * u64::from(self.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_fit_the_data() {
        let d = Domain::new(4096, 4096, 65).unwrap();
        assert_eq!((d.finest_level(), d.side()), (6, 4097));
        let d = Domain::new(1025, 1025, 65).unwrap();
        assert_eq!((d.finest_level(), d.side()), (4, 1025));
        let d = Domain::new(1, 1, 9).unwrap();
        assert_eq!((d.finest_level(), d.side()), (0, 9));
        let d = Domain::new(1197, 643, 65).unwrap();
        assert_eq!((d.finest_level(), d.side()), (5, 2049));
        assert_eq!(d.nodes_across(5), (19, 11));
        assert_eq!(d.nodes_across(0), (1, 1));
    }

    #[test]
    fn block_sizes_are_checked() {
        for bad in [0, 1, 2, 3, 5, 8, 10, 64, 66, 2049] {
            assert!(Domain::new(100, 100, bad).is_err(), "{bad}");
        }
        for good in [9, 17, 33, 65, 129, 257, 513, 1025] {
            assert!(Domain::new(100, 100, good).is_ok(), "{good}");
        }
    }

    #[test]
    fn existence_follows_data_cells() {
        // 65 samples = exactly one block: the block whose west edge is the data's east edge
        // holds no cell and does not exist.
        let d = Domain::new(66, 65, 65).unwrap();
        assert_eq!(d.finest_level(), 1);
        assert!(d.exists(1, 0, 0) && d.exists(1, 1, 0));
        assert!(!d.exists(1, 0, 1));
        let line = Domain::new(1, 300, 9).unwrap();
        assert_eq!(line.nodes_across(line.finest_level()).0, 1);
    }
}
