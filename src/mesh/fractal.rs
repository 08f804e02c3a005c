//! Detail past the data (seed 004, fractal nodes): below a physical block, synthetic nodes
//! made on the fly, for a camera so close that one sample spans many pixels.
//!
//! **Amplitude.** A physical block's *roughness* `A` is the mean, over its inner samples, of
//! how far a sample lies from the mean of its four neighbours: flat ground has none, rough
//! ground much. `A` is the block's declared *fractal error* at depth 0.
//!
//! **Children.** A node at depth `k` (0: the physical block) splits into four whose grids
//! have half its spacing. A child's grid point that is a grid point of its parent keeps the
//! parent's height (so the physical samples stay exactly as stored, at every depth); a new
//! point takes the parent's surface there (`model.md` §4) plus a displacement of at most
//! `A · 2^-(k+1)`, deterministic noise seeded by the physical block's key, the depth and the
//! point. Points on the physical block's edges are not displaced: its neighbours, real or
//! refined, see the same straight edges. A point's height so depends on the point alone,
//! whichever node computes it: nodes of one depth agree along shared edges, and stitching
//! joins nodes of different depths.
//!
//! **Errors.** Depth `k + 1` moves the surface by at most `A · 2^-(k+1)`, and so every depth
//! past `k` by less than `A · 2^-k` in all: a depth-`k` node's declared error `e_k = A · 2^-k`
//! (plus the f32 rounding of each depth's heights) bounds how far it lies from any finer
//! refinement, and a child's is half its parent's. A node is refined while its declared
//! error seen from the eye exceeds the tolerance, to at most [`MAX_DEPTH`] depths (blocks a
//! sixteenth of a sample apart at the end). A physical block cut by the data's edge, or
//! holding a void, is not refined.
//!
//! **Coordinates.** Synthetic grids fall between samples: a refined mesh is built in units
//! of `2^-MAX_DEPTH` samples ([`SCALE`]), every block's rectangle and stride multiplied by
//! it, and drawn in a frame whose spacing is divided by it.

use crate::model::surface::surface;
use crate::model::SampleRect;

/// The most depths generated below a physical block.
pub const MAX_DEPTH: u8 = 4;
/// Units of a refined mesh a sample: `2^MAX_DEPTH`.
pub const SCALE: u64 = 1 << MAX_DEPTH;

/// A synthetic node: generated, never stored.
#[derive(Clone, Debug, PartialEq)]
pub struct Synthetic {
    /// Depth below its physical block (`1..=MAX_DEPTH`).
    pub depth: u8,
    /// Column among the `2^depth` nodes across the physical block.
    pub x: u32,
    /// Row among them.
    pub y: u32,
    /// Footprint in units of `1 / SCALE` samples.
    pub rect: SampleRect,
    /// Grid spacing in those units.
    pub stride: u64,
    /// Its `b × b` grid, row-major from the north-west.
    pub heights: Vec<f32>,
    /// Declared error `e_k`, in metres.
    pub error: f64,
}

/// The roughness of a `w × h` block of samples: the mean distance of an inner sample from
/// the mean of its four neighbours (0 without inner samples).
pub fn roughness(heights: &[f32], w: usize, h: usize) -> f64 {
    if w < 3 || h < 3 || heights.len() != w * h {
        return 0.0;
    }
    let at = |x: usize, y: usize| f64::from(heights[y * w + x]);
    let mut sum = 0.0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mean = (at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1)) / 4.0;
            sum += (at(x, y) - mean).abs();
        }
    }
    sum / ((w - 2) * (h - 2)) as f64
}

/// The lowest and highest of `heights`.
fn height_range(heights: &[f32]) -> (f32, f32) {
    heights
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        })
}

/// splitmix64: a well-mixed 64-bit hash.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Noise in `[-1, 1]` for point `(x, y)` (scaled units) new at `depth` below block `key`.
fn noise(key: u64, depth: u8, x: u64, y: u64) -> f64 {
    let h = mix(mix(mix(key ^ (u64::from(depth) << 58)) ^ x) ^ y.rotate_left(32));
    (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// A physical block to refine: its `b × b` samples, in scaled units.
pub struct Physical<'a> {
    /// The block's key (the noise's seed).
    pub key: u64,
    /// Its footprint, in scaled units (`SCALE` a sample).
    pub rect: SampleRect,
    /// Samples a side (`b`).
    pub side: u32,
    /// Its samples, row-major.
    pub heights: &'a [f32],
}

/// A node being refined: depth, position, footprint, stride, grid.
struct Node {
    depth: u8,
    x: u32,
    y: u32,
    rect: SampleRect,
    stride: u64,
    heights: Vec<f32>,
}

/// The declared error of a node at `depth` below a block of roughness `a` whose heights
/// reach `peak` in magnitude: `a · 2^-depth`, plus the f32 rounding of the depths between.
pub fn declared_error(a: f64, depth: u8, peak: f64) -> f64 {
    a / f64::from(1u32 << depth) + f64::from(MAX_DEPTH) * f64::from(f32::EPSILON) * (1.0 + peak)
}

/// Refines `block` (roughness `a`) while `wants(depth, rect, lo, hi, error)` says a node
/// should split (rect in scaled units, `lo..hi` its heights): the synthetic nodes that
/// replace it, or none when the block itself is kept.
pub fn refine(
    block: &Physical<'_>,
    a: f64,
    wants: &mut dyn FnMut(u8, &SampleRect, f32, f32, f64) -> bool,
) -> Vec<Synthetic> {
    let b = block.side as usize;
    let peak = block
        .heights
        .iter()
        .fold(0.0f64, |m, &h| m.max(f64::from(h).abs()));
    let root = Node {
        depth: 0,
        x: 0,
        y: 0,
        rect: block.rect,
        stride: SCALE,
        heights: block.heights.to_vec(),
    };
    let mut out = Vec::new();
    let mut stack = vec![root];
    while let Some(node) = stack.pop() {
        let error = declared_error(a, node.depth, peak);
        let (lo, hi) = height_range(&node.heights);
        if a > 0.0 && node.depth < MAX_DEPTH && wants(node.depth, &node.rect, lo, hi, error) {
            for q in 0..4 {
                stack.push(child(block, a, &node, q % 2, q / 2, b));
            }
        } else if node.depth > 0 {
            out.push(Synthetic {
                depth: node.depth,
                x: node.x,
                y: node.y,
                rect: node.rect,
                stride: node.stride,
                heights: node.heights,
                error,
            });
        }
    }
    out.sort_by_key(|s| (s.rect.row0, s.rect.col0));
    out
}

/// Quadrant `(qx, qy)` of `parent`.
fn child(block: &Physical<'_>, a: f64, parent: &Node, qx: u32, qy: u32, b: usize) -> Node {
    let s = parent.stride / 2;
    let half = (b as u64 - 1) * s;
    let (c0, r0) = (
        parent.rect.col0 + u64::from(qx) * half,
        parent.rect.row0 + u64::from(qy) * half,
    );
    let depth = parent.depth + 1;
    let amplitude = a / f64::from(1u32 << depth);
    let edge = &block.rect;
    let g = |i: usize, j: usize| parent.heights[j * b + i];
    let mut heights = Vec::with_capacity(b * b);
    // The child's corner, in child steps from the parent's.
    let off = b - 1;
    for j in 0..b {
        for i in 0..b {
            // Offsets from the parent's corner, in child steps.
            let (pi, pj) = (qx as usize * off + i, qy as usize * off + j);
            if pi % 2 == 0 && pj % 2 == 0 {
                heights.push(g(pi / 2, pj / 2));
                continue;
            }
            let (u, v) = (pi as u64 * s, pj as u64 * s);
            let ps = 2 * s;
            let ci = ((u / ps) as usize).min(b - 2);
            let cj = ((v / ps) as usize).min(b - 2);
            let base = surface(
                g(ci, cj),
                g(ci + 1, cj),
                g(ci, cj + 1),
                g(ci + 1, cj + 1),
                ps,
                u - ci as u64 * ps,
                v - cj as u64 * ps,
            );
            let (x, y) = (c0 + i as u64 * s, r0 + j as u64 * s);
            let on_edge = x == edge.col0 || x == edge.col1 || y == edge.row0 || y == edge.row1;
            let d = if on_edge {
                0.0
            } else {
                amplitude * noise(block.key, depth, x, y)
            };
            heights.push((base + d) as f32);
        }
    }
    Node {
        depth,
        x: parent.x * 2 + qx,
        y: parent.y * 2 + qy,
        rect: SampleRect {
            col0: c0,
            row0: r0,
            col1: c0 + half,
            row1: r0 + half,
        },
        stride: s,
        heights,
    }
}

/// The pixels that `error` metres span seen from the eye at the distance of the box over
/// `r` (scaled units) from `lo - error` to `hi + error`: the scene's own measure
/// (`View::screen_error`) applied to a node's footprint.
fn screen_error(
    r: &SampleRect,
    lo: f32,
    hi: f32,
    error: f64,
    view: &crate::scene::View,
    frame: &crate::scene::WorldFrame,
) -> f64 {
    let k = SCALE as f64;
    let b = crate::scene::Aabb {
        min: frame.point(r.col0 as f64 / k, r.row0 as f64 / k, f64::from(lo) - error),
        max: frame.point(r.col1 as f64 / k, r.row1 as f64 / k, f64::from(hi) + error),
    };
    view.screen_error(error, b.distance(view.eye))
}

impl Synthetic {
    /// Its declared error in pixels, seen by `view` (`frame`: the world frame of samples).
    pub fn screen_error(&self, view: &crate::scene::View, frame: &crate::scene::WorldFrame) -> f64 {
        let (lo, hi) = height_range(&self.heights);
        screen_error(&self.rect, lo, hi, self.error, view, frame)
    }
}

/// [`refine`] for a camera: a node splits while its declared error, seen from the eye at
/// the distance of its box, exceeds `tau` pixels. `frame` is the world frame of samples.
pub fn refine_for_view(
    block: &Physical<'_>,
    a: f64,
    view: &crate::scene::View,
    frame: &crate::scene::WorldFrame,
    tau: f64,
) -> Vec<Synthetic> {
    refine(block, a, &mut |_, r, lo, hi, error| {
        screen_error(r, lo, hi, error, view, frame) > tau
    })
}

/// The synthetic nodes that replace the block keyed `key`, whose grid is `grid` (rectangle
/// and stride in samples), for `view` at `tau` pixels; none when the block is kept. Only a
/// whole physical block is refined: `b × b` samples at stride 1 with `b ≥ 9`, none of them
/// void; a node's decimated grid, a block cut by the data's edge, or one with a void (no
/// surface to displace) is drawn as it is.
pub fn refine_block(
    key: u64,
    grid: &crate::scene::surface::GridBlock<'_>,
    view: &crate::scene::View,
    frame: &crate::scene::WorldFrame,
    tau: f64,
) -> Vec<Synthetic> {
    let r = grid.rect;
    let whole = grid.stride == 1
        && u64::from(grid.grid_width) == r.col1 - r.col0 + 1
        && grid.grid_width == grid.grid_height
        && r.col1 - r.col0 == r.row1 - r.row0
        && grid.grid_width >= 9
        && grid.heights.len() == grid.grid_width as usize * grid.grid_height as usize
        && grid.heights.iter().all(|h| h.is_finite());
    if !whole {
        return Vec::new();
    }
    let side = grid.grid_width as usize;
    let a = roughness(grid.heights, side, side);
    let physical = Physical {
        key,
        rect: SampleRect {
            col0: r.col0 * SCALE,
            row0: r.row0 * SCALE,
            col1: r.col1 * SCALE,
            row1: r.row1 * SCALE,
        },
        side: grid.grid_width,
        heights: grid.heights,
    };
    refine_for_view(&physical, a, view, frame, tau)
}
