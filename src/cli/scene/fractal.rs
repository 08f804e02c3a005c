//! `--refine fractal`: the report of the synthetic nodes past the data.

use serde::Serialize;

use crate::mesh::fractal;
use crate::scene::surface::GridBlock;
use crate::scene::{Camera, LoadedBlock, SceneBlock, WorldFrame};
use crate::Error;

/// `--refine fractal`: the synthetic nodes that replace the physical blocks the camera sees
/// closer than their data's detail (`crate::mesh::fractal`). Generated, never stored.
#[derive(Serialize)]
pub(super) struct FractalReport {
    /// A synthetic grid's units a sample (`fractal::SCALE`).
    scale: u64,
    /// The most depths below a physical block.
    max_depth: u8,
    /// Physical blocks replaced by synthetic nodes.
    refined_blocks: usize,
    /// The largest declared error of a synthetic node, in pixels (0 without nodes).
    max_screen_error: f64,
    nodes: Vec<FractalNode>,
}

/// One synthetic node.
#[derive(Serialize)]
struct FractalNode {
    /// Always true: the node is generated, never stored.
    synthetic: bool,
    /// The physical block it replaces part of.
    physical: PhysicalRef,
    /// Depth below it.
    depth: u8,
    /// Level, column and row in the quadtree, past the stored levels.
    level: u8,
    x: u32,
    y: u32,
    /// Footprint in samples (fractions of a sample), c0, r0, c1, r1.
    footprint: [f64; 4],
    /// Grid spacing in samples.
    stride: f64,
    /// Declared error `e_k`, metres.
    error: f64,
    /// It in pixels.
    screen_error: f64,
}

/// A physical block, by tile (datasets), level, position and key.
#[derive(Serialize)]
struct PhysicalRef {
    #[serde(skip_serializing_if = "Option::is_none")]
    tile: Option<u64>,
    level: u8,
    x: u32,
    y: u32,
    key: u64,
}

/// Refines each loaded block (`(block, tile, loaded, stride)`) for `camera` at `tau`.
pub(super) fn report(
    blocks: &[(SceneBlock, Option<u64>, LoadedBlock, u64)],
    camera: &Camera,
    frame: &WorldFrame,
    tau: f64,
) -> Result<FractalReport, Error> {
    let view = camera.view()?;
    let k = fractal::SCALE as f64;
    let mut report = FractalReport {
        scale: fractal::SCALE,
        max_depth: fractal::MAX_DEPTH,
        refined_blocks: 0,
        max_screen_error: 0.0,
        nodes: Vec::new(),
    };
    for (b, tile, loaded, stride) in blocks {
        let grid = GridBlock::of(b, loaded, *stride);
        let nodes = fractal::refine_block(b.key, &grid, &view, frame, tau);
        if !nodes.is_empty() {
            report.refined_blocks += 1;
        }
        for n in nodes {
            let screen_error = n.screen_error(&view, frame);
            report.max_screen_error = report.max_screen_error.max(screen_error);
            let r = &n.rect;
            report.nodes.push(FractalNode {
                synthetic: true,
                physical: PhysicalRef {
                    tile: *tile,
                    level: b.level,
                    x: b.x,
                    y: b.y,
                    key: b.key,
                },
                depth: n.depth,
                level: b.level + n.depth,
                x: (b.x << n.depth) + n.x,
                y: (b.y << n.depth) + n.y,
                footprint: [
                    r.col0 as f64 / k,
                    r.row0 as f64 / k,
                    r.col1 as f64 / k,
                    r.row1 as f64 / k,
                ],
                stride: n.stride as f64 / k,
                error: n.error,
                screen_error,
            });
        }
    }
    Ok(report)
}

pub(super) fn print(f: &FractalReport) {
    println!(
        "  fractal: {} blocks refined into {} synthetic nodes, max screen-space error {:.4} px",
        f.refined_blocks,
        f.nodes.len(),
        f.max_screen_error
    );
    if f.nodes.is_empty() {
        return;
    }
    println!(
        "  {:>5} {:>6} {:>6} {:>5}  {:>31}  {:>12} {:>9}  below",
        "level", "x", "y", "depth", "col0,row0..col1,row1", "error m", "px"
    );
    for n in &f.nodes {
        let [c0, r0, c1, r1] = n.footprint;
        let p = &n.physical;
        println!(
            "  {:>5} {:>6} {:>6} {:>5}  {:>31}  {:>12.4} {:>9.4}  {}level {} ({},{}) key {}",
            n.level,
            n.x,
            n.y,
            n.depth,
            format!("{c0},{r0}..{c1},{r1}"),
            n.error,
            n.screen_error,
            p.tile.map_or(String::new(), |t| format!("tile {t} ")),
            p.level,
            p.x,
            p.y,
            p.key
        );
    }
}
