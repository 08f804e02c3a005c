//! What a scene is: the options a caller gives, the blocks it gets back, and what they cost.

use serde::Serialize;

use super::ranges::KeyRange;
use crate::curve::HilbertKey;
use crate::format::PayloadRef;
use crate::model::{Domain, SampleRect};

/// Gap merge used when none is given: runs separated by at most this many keys are scanned
/// as one (see [`super::ranges`]).
pub const DEFAULT_GAP: u64 = 4;

/// How the tolerance in pixels turns into blocks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// One static bound for the whole region: one cluster.
    Uniform,
    /// Each node meets the tolerance where it is seen.
    #[default]
    View,
}

/// What a scene asks for besides the camera.
///
/// ```
/// use fmrh::types::{Mode, SampleRect};
/// use fmrh::SceneOptions;
///
/// // One static bound over a given window, at 2 pixels.
/// let options = SceneOptions {
///     mode: Mode::Uniform,
///     window: Some(SampleRect { col0: 0, row0: 0, col1: 511, row1: 255 }),
///     ..SceneOptions::new(2.0)
/// };
/// assert_eq!(options.tau, 2.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneOptions {
    /// Tolerance in pixels (finite, `>= 0`).
    pub tau: f64,
    /// Uniform or view-dependent.
    pub mode: Mode,
    /// An explicit window (inclusive samples, inside the data); the frustum's footprint when
    /// `None`.
    pub window: Option<SampleRect>,
    /// Gap merge, in keys.
    pub gap: u64,
}

impl SceneOptions {
    /// View-dependent, no window, runs of keys at most 4 apart scanned as one.
    pub fn new(tau: f64) -> SceneOptions {
        SceneOptions {
            tau,
            mode: Mode::View,
            window: None,
            gap: DEFAULT_GAP,
        }
    }
}

/// The levels of the scene blocks across one edge of a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct NeighbourLevels {
    /// The coarsest (smallest level number): the one to stitch to.
    pub coarsest: u8,
    /// The finest.
    pub finest: u8,
}

/// One block of a scene: a node of the FMRH, or a physical block below a tree leaf.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SceneBlock {
    /// Index in the node table; `None` for a physical block below a pruned leaf.
    pub node: Option<u32>,
    /// Level (0 root, `L` physical blocks).
    pub level: u8,
    /// Column among the level's nodes.
    pub x: u32,
    /// Row among the level's nodes.
    pub y: u32,
    /// Hilbert key.
    pub key: u64,
    /// Footprint clipped to the data, inclusive samples.
    pub col0: u64,
    /// North row.
    pub row0: u64,
    /// East column (inclusive).
    pub col1: u64,
    /// South row (inclusive).
    pub row1: u64,
    /// `e*`: the static error this block guarantees, in metres.
    pub error: f64,
    /// `e*` seen from the eye, in pixels.
    pub screen_error: f64,
    /// Distance from the eye to the block's box.
    pub distance: f64,
    /// Least height the block can draw.
    pub min_height: f32,
    /// Greatest height the block can draw.
    pub max_height: f32,
    /// Its payload: the coarse grid, or at level `L` the physical block.
    pub payload: PayloadRef,
    /// Scene blocks across the north, east, south and west edges (`None`: the data's edge,
    /// or outside the scene).
    pub neighbours: [Option<NeighbourLevels>; 4],
}

impl SceneBlock {
    /// Footprint clipped to the data.
    pub fn rect(&self) -> SampleRect {
        SampleRect {
            col0: self.col0,
            row0: self.row0,
            col1: self.col1,
            row1: self.row1,
        }
    }

    /// Its finest-level Hilbert keys.
    pub fn keys(&self, domain: &Domain) -> KeyRange {
        KeyRange::of_node(HilbertKey(self.key), self.level, domain.finest_level())
    }
}

/// What a scene cost and what it guarantees.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SceneStats {
    /// Blocks.
    pub blocks: u64,
    /// Grid samples of the blocks, `b²` each.
    pub samples: u64,
    /// Triangles to draw them, `2 (b-1)²` each.
    pub triangles: u64,
    /// Payload bytes.
    pub bytes: u64,
    /// Aligned quadrants of the region.
    pub quadrants: u64,
    /// Range scans run.
    pub ranges: u64,
    /// Index pages read by the scans.
    pub index_pages: u64,
    /// Node records read.
    pub node_reads: u64,
    /// Of `node_reads`, the records the top of the tree (format 6.2) answered from memory,
    /// which cost no page; the rest came from the node table's pages (or, for physical
    /// blocks, the block table's).
    pub top_reads: u64,
    /// Wall time of the selection, in nanoseconds.
    pub schedule_ns: u64,
    /// Uniform mode: the chosen cluster's threshold in metres (0 for physical blocks).
    pub threshold: Option<f64>,
    /// Uniform mode: the chosen cluster (`None` for physical blocks).
    pub cluster: Option<usize>,
    /// Uniform mode: `ε = τ / λ · P_min`, the largest static error the view allows.
    pub allowed_error: Option<f64>,
    /// Uniform mode: `P_min`.
    pub p_min: Option<f64>,
    /// The largest `e*` among the blocks, in metres.
    pub max_error: f64,
    /// The largest screen-space error among the blocks, in pixels.
    pub max_screen_error: f64,
}

impl SceneStats {
    /// Counts `block`, drawn with `side`-sample grids, among the answer: its grid's samples
    /// and triangles, its payload bytes, and its errors if they are the largest so far.
    pub fn add_block(&mut self, block: &SceneBlock, side: u64) {
        self.blocks += 1;
        self.samples += side * side;
        self.triangles += 2 * (side - 1) * (side - 1);
        self.bytes += u64::from(block.payload.len);
        self.max_error = self.max_error.max(block.error);
        self.max_screen_error = self.max_screen_error.max(block.screen_error);
    }

    /// Adds what searching cost another selection (a layer's): its quadrants, range scans,
    /// index pages and node reads.
    pub fn add_search(&mut self, other: &SceneStats) {
        self.quadrants += other.quadrants;
        self.ranges += other.ranges;
        self.index_pages += other.index_pages;
        self.node_reads += other.node_reads;
        self.top_reads += other.top_reads;
    }

    /// Adds another selection (a tile's) whole: every count summed, the largest errors and
    /// uniform threshold kept, the first nearest distance and allowed error taken. The time
    /// is not added: selections may run side by side, so the caller times the whole.
    pub fn merge(&mut self, other: &SceneStats) {
        self.blocks += other.blocks;
        self.samples += other.samples;
        self.triangles += other.triangles;
        self.bytes += other.bytes;
        self.add_search(other);
        self.max_error = self.max_error.max(other.max_error);
        self.max_screen_error = self.max_screen_error.max(other.max_screen_error);
        if let Some(t) = other.threshold {
            self.threshold = Some(self.threshold.map_or(t, |m: f64| m.max(t)));
        }
        self.p_min = other.p_min.or(self.p_min);
        self.allowed_error = other.allowed_error.or(self.allowed_error);
    }
}

/// The answer to one view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scene {
    /// The mode used.
    pub mode: Mode,
    /// The tolerance in pixels.
    pub tau: f64,
    /// The explicit window, or the samples the frustum's footprint spans; `None` when the
    /// frustum sees no terrain.
    pub window: Option<SampleRect>,
    /// The blocks, sorted by Hilbert key.
    pub blocks: Vec<SceneBlock>,
    /// Counts and guarantees.
    pub stats: SceneStats,
}
