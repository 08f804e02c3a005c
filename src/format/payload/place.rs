//! Where a payload's samples lie: a physical block's footprint, a grid's stored columns and
//! rows (clamped at the data's edge, and only the kept columns of a grid thinned by area,
//! format 6), and [`ParentGrid`], the decoded grid a payload may be coded against. This is
//! all the prediction against a parent needs besides the bytes (`container.md` §7).

use super::PayloadRef;
use crate::codec::parent::{Axes, Parent};
use crate::format::StoredNode;
use crate::model::{Domain, SampleRect};

/// What a payload is and where it lies: all a coder needs to know besides its bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Placement {
    /// A physical block: its footprint clipped to the data, and its voids (whose stand-ins
    /// follow its samples).
    Block {
        /// The footprint within the data: the block is its `width × height` samples.
        rect: SampleRect,
        /// Voids among its samples.
        void_count: u32,
    },
    /// The coarse grid of node `(x, y)` at `level`.
    Grid {
        /// The block geometry.
        domain: Domain,
        /// The node's level (above the finest).
        level: u8,
        /// Its column among the level's nodes.
        x: u32,
        /// Its row.
        y: u32,
        /// Some stored sample stands for a void or padding: a bitmap follows the heights.
        has_voids: bool,
        /// The bitmap follows a void flag (format 5, node flag bit 2), else it is raw.
        flagged_bitmap: bool,
        /// Thinned by `2^thin` east-west (format 6): only the kept columns are coded.
        thin: u8,
    },
}

impl Placement {
    /// A physical block of footprint `rect` (clipped to the data) with `void_count` voids.
    pub fn block(rect: SampleRect, void_count: u32) -> Placement {
        Placement::Block { rect, void_count }
    }

    /// The coarse grid of the stored node `node`.
    pub fn grid(domain: &Domain, node: &StoredNode) -> Placement {
        Placement::Grid {
            domain: *domain,
            level: node.level,
            x: node.x,
            y: node.y,
            has_voids: node.grid_has_voids,
            flagged_bitmap: node.grid_bitmap_flagged,
            thin: node.grid_thin,
        }
    }

    /// The coarse grid of node `(x, y)` at `level` as a writer stores it now: its bitmap,
    /// when `has_voids`, behind a void flag (format 5), thinned by `2^thin` (format 6).
    pub fn node_grid(
        domain: &Domain,
        (level, x, y): (u8, u32, u32),
        has_voids: bool,
        thin: u8,
    ) -> Placement {
        Placement::Grid {
            domain: *domain,
            level,
            x,
            y,
            has_voids,
            flagged_bitmap: true,
            thin,
        }
    }

    /// Samples along a row and down a column of its layout: the block's within the data,
    /// or the grid's stored `gw × gh`.
    pub fn dims(&self) -> (u32, u32) {
        match *self {
            Placement::Block { rect, .. } => (
                u32::try_from(rect.col1 - rect.col0 + 1).unwrap_or(u32::MAX),
                u32::try_from(rect.row1 - rect.row0 + 1).unwrap_or(u32::MAX),
            ),
            Placement::Grid {
                domain,
                level,
                x,
                y,
                ..
            } => domain.grid_dims(level, x, y),
        }
    }

    /// Where its coded values lie, as sample columns and rows: a block's every sample, a
    /// grid's stored ones (only the kept columns of a grid thinned by area).
    pub fn axes(&self) -> (Vec<u64>, Vec<u64>) {
        match *self {
            Placement::Block { rect, .. } => block_axes(&rect),
            Placement::Grid {
                domain,
                level,
                x,
                y,
                thin,
                ..
            } => stored_grid_axes(&domain, level, x, y, thin),
        }
    }
}

/// The decoded grid a payload is coded against (format 4: a block against its parent node's
/// grid; format 5: a grid against its parent's): the node's stored heights and where they
/// lie. A grid stored thinned (format 6) is its kept columns: the heights it stores.
#[derive(Clone, Debug)]
pub struct ParentGrid {
    /// The node's index in the node table.
    pub node: u32,
    /// The node's payload (what the grid was decoded from; a cache's check).
    pub payload: PayloadRef,
    cols: Vec<u64>,
    rows: Vec<u64>,
    heights: Vec<f32>,
}

impl ParentGrid {
    /// The grid of node `node` (payload `payload`) placed by `placement` (a grid), from its
    /// layout's stored heights `layout` (`gw × gh`, row-major), kept as they are when the
    /// grid is not thinned.
    pub fn new(node: u32, payload: PayloadRef, placement: &Placement, layout: Vec<f32>) -> Self {
        let (gw, _) = placement.dims();
        let thin = match *placement {
            Placement::Grid { thin, .. } => thin,
            Placement::Block { .. } => 0,
        };
        let (cols, rows) = placement.axes();
        ParentGrid {
            node,
            payload,
            cols,
            rows,
            heights: if thin == 0 {
                layout
            } else {
                kept_heights(&layout, gw, thin)
            },
        }
    }

    /// The grid of node `node` from its full `b × b` heights as a renderer holds them (a
    /// grid expanded, clamp columns and rows repeated): the stored heights are their top-left
    /// `gw × gh` (format §7). Lets a cache of decoded grids stand in for reading one again.
    /// `None` when `heights` is not `b × b`, or `placement` is not a grid.
    pub fn from_expanded(
        node: u32,
        payload: PayloadRef,
        placement: &Placement,
        heights: &[f32],
    ) -> Option<Self> {
        let Placement::Grid { domain, level, .. } = placement else {
            return None;
        };
        let b = domain.block_size() as usize;
        let (gw, gh) = placement.dims();
        if heights.len() != b * b || *level >= domain.finest_level() {
            return None;
        }
        let layout: Vec<f32> = heights
            .chunks_exact(b)
            .take(gh as usize)
            .flat_map(|row| row[..gw as usize].iter().copied())
            .collect();
        Some(ParentGrid::new(node, payload, placement, layout))
    }

    /// A grid of `heights` (row-major) at sample columns `cols` and rows `rows` (each
    /// non-decreasing), for the coders' tests and fuzz targets, which place a payload
    /// anywhere; `None` when the heights do not fill the axes.
    #[cfg(any(test, feature = "testing"))]
    pub fn from_parts(cols: Vec<u64>, rows: Vec<u64>, heights: Vec<f32>) -> Option<Self> {
        (heights.len() == cols.len() * rows.len()).then(|| ParentGrid {
            node: 0,
            payload: PayloadRef::default(),
            cols,
            rows,
            heights,
        })
    }

    /// As the codec takes it.
    pub fn parent(&self) -> Parent<'_> {
        Parent {
            at: Axes {
                cols: &self.cols,
                rows: &self.rows,
            },
            heights: &self.heights,
        }
    }

    /// Bytes of memory it holds.
    pub fn memory(&self) -> u64 {
        8 * (self.cols.len() + self.rows.len()) as u64 + 4 * self.heights.len() as u64
    }
}

/// Where the samples of a physical block lie: its columns and rows (its footprint clipped
/// to the data, `rect`).
pub fn block_axes(rect: &SampleRect) -> (Vec<u64>, Vec<u64>) {
    (
        (rect.col0..=rect.col1).collect(),
        (rect.row0..=rect.row1).collect(),
    )
}

/// Where the stored samples of the grid of node `(x, y)` at `level` lie: the sample column
/// of each of its `gw` stored columns and the row of each of its `gh` rows, a sample past the
/// data's edge clamped to it (see [`Domain::grid_dims`]).
pub fn grid_axes(domain: &Domain, level: u8, x: u32, y: u32) -> (Vec<u64>, Vec<u64>) {
    let fp = domain.footprint(level, x, y);
    let s = domain.stride(level);
    let (gw, gh) = domain.grid_dims(level, x, y);
    let data = domain.data_rect();
    (
        (0..u64::from(gw))
            .map(|i| (fp.col0 + i * s).min(data.col1))
            .collect(),
        (0..u64::from(gh))
            .map(|j| (fp.row0 + j * s).min(data.row1))
            .collect(),
    )
}

/// Where the stored heights of a grid thinned by `2^thin` lie ([`grid_axes`], its columns
/// the kept ones, [`kept_axis`]): what a payload coded against it sees, and what its own
/// heights are coded at.
fn stored_grid_axes(domain: &Domain, level: u8, x: u32, y: u32, thin: u8) -> (Vec<u64>, Vec<u64>) {
    let (cols, rows) = grid_axes(domain, level, x, y);
    if thin == 0 {
        return (cols, rows);
    }
    (kept_axis(&cols, thin), rows)
}

/// The kept columns' heights of a row-major grid layout `heights` of `gw` columns thinned by
/// `2^thin` (all of them when `thin` is 0).
pub fn kept_heights(heights: &[f32], gw: u32, thin: u8) -> Vec<f32> {
    if thin == 0 {
        return heights.to_vec();
    }
    let kept: Vec<usize> = crate::model::thinning::kept_columns(gw, 1 << thin)
        .map(|i| i as usize)
        .collect();
    heights
        .chunks_exact(gw.max(1) as usize)
        .flat_map(|row| kept.iter().filter_map(move |&i| row.get(i).copied()))
        .collect()
}

/// How many columns a grid of `gw` stored columns thinned by `2^thin` keeps.
pub fn kept_width(gw: u32, thin: u8) -> u32 {
    crate::model::thinning::kept_count(gw, 1 << thin)
}

/// The sample columns a grid stored thinned by `2^thin` keeps, of its columns `cols`
/// ([`grid_axes`]).
fn kept_axis(cols: &[u64], thin: u8) -> Vec<u64> {
    let gw = u32::try_from(cols.len()).unwrap_or(u32::MAX);
    crate::model::thinning::kept_columns(gw, 1 << thin)
        .filter_map(|i| cols.get(i as usize).copied())
        .collect()
}
