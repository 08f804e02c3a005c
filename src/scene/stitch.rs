//! Edge stitching: for every block of a scene, the levels of the scene blocks across each of
//! its four edges, so a renderer can stitch to the coarsest neighbour or hang skirts.

use super::ranges::{self, Quadrant};
use super::result::{NeighbourLevels, SceneBlock};
use crate::curve::HilbertKey;
use crate::model::Domain;

/// Which block holds each finest-block cell of the scene's bounding rectangle, when that
/// rectangle is small enough to tabulate cheaply (otherwise lookups fall back to a binary
/// search by key).
struct CellMap {
    x0: u32,
    y0: u32,
    width: u32,
    height: u32,
    /// Row-major block index + 1; 0 for no block.
    cells: Vec<u32>,
}

impl CellMap {
    /// The most cells tabulated per block of the scene (and at most 2^20 in all).
    const CELLS_PER_BLOCK: u64 = 64;

    fn new(d: &Domain, blocks: &[SceneBlock], cells_per_block: u64) -> CellMap {
        let empty = CellMap {
            x0: 0,
            y0: 0,
            width: 0,
            height: 0,
            cells: Vec::new(),
        };
        let spans: Vec<_> = blocks
            .iter()
            .map(|b| {
                Quadrant {
                    level: b.level,
                    x: b.x,
                    y: b.y,
                }
                .blocks(d)
            })
            .collect();
        let (Some(x0), Some(y0), Some(x1), Some(y1)) = (
            spans.iter().map(|s| s.0.start).min(),
            spans.iter().map(|s| s.1.start).min(),
            spans.iter().map(|s| s.0.end).max(),
            spans.iter().map(|s| s.1.end).max(),
        ) else {
            return empty;
        };
        let (width, height) = (x1 - x0, y1 - y0);
        let area = u64::from(width) * u64::from(height);
        if area > (blocks.len() as u64).saturating_mul(cells_per_block).min(1 << 20) {
            return empty;
        }
        let mut cells = vec![0u32; area as usize];
        for (i, (xs, ys)) in spans.iter().enumerate() {
            for y in ys.clone() {
                let row = ((y - y0) * width) as usize;
                cells[row + (xs.start - x0) as usize..row + (xs.end - x0) as usize]
                    .fill(i as u32 + 1);
            }
        }
        CellMap {
            x0,
            y0,
            width,
            height,
            cells,
        }
    }

    /// `Some(answer)` when the cell is tabulated or outside the rectangle (no block);
    /// `None` when the map could not be built.
    fn get(&self, x: u32, y: u32) -> Option<Option<usize>> {
        if self.cells.is_empty() {
            return None;
        }
        if x < self.x0 || y < self.y0 || x - self.x0 >= self.width || y - self.y0 >= self.height {
            return Some(None);
        }
        let v = self.cells[((y - self.y0) * self.width + (x - self.x0)) as usize];
        Some(v.checked_sub(1).map(|i| i as usize))
    }
}

/// Fills every block's neighbour levels. `blocks` must be sorted by key and disjoint.
pub(super) fn set_neighbours(d: &Domain, blocks: &mut [SceneBlock]) {
    set_neighbours_with(d, blocks, CellMap::CELLS_PER_BLOCK);
}

/// [`set_neighbours`], tabulating cells when that costs at most `cells_per_block` cells a
/// block (0: never; the lookups then search by key).
fn set_neighbours_with(d: &Domain, blocks: &mut [SceneBlock], cells_per_block: u64) {
    let finest = d.finest_level();
    let (cols, rows) = d.nodes_across(finest);
    let cells = CellMap::new(d, blocks, cells_per_block);
    let find = |blocks: &[SceneBlock], x: u32, y: u32| -> Option<usize> {
        if let Some(found) = cells.get(x, y) {
            return found;
        }
        let key = ranges::block_key(d, x, y);
        let i = blocks.partition_point(|b| b.key <= key).checked_sub(1)?;
        (key <= HilbertKey(blocks[i].key).last(finest, blocks[i].level)).then_some(i)
    };
    for i in 0..blocks.len() {
        let b = blocks[i];
        let q = Quadrant {
            level: b.level,
            x: b.x,
            y: b.y,
        };
        let (xs, ys) = q.blocks(d);
        // For each edge: the fixed coordinate just outside it, and whether it runs along x.
        let edges: [Option<(u32, bool)>; 4] = [
            ys.start.checked_sub(1).map(|y| (y, true)),
            (xs.end < cols).then_some((xs.end, false)),
            (ys.end < rows).then_some((ys.end, true)),
            xs.start.checked_sub(1).map(|x| (x, false)),
        ];
        for (e, edge) in edges.into_iter().enumerate() {
            let Some((fixed, along_x)) = edge else {
                continue;
            };
            let span = if along_x { xs.clone() } else { ys.clone() };
            let mut levels: Option<NeighbourLevels> = None;
            let mut t = span.start;
            while t < span.end {
                let (x, y) = if along_x { (t, fixed) } else { (fixed, t) };
                match find(blocks, x, y) {
                    Some(j) => {
                        let nb = &blocks[j];
                        let l = nb.level;
                        levels = Some(match levels {
                            None => NeighbourLevels {
                                coarsest: l,
                                finest: l,
                            },
                            Some(v) => NeighbourLevels {
                                coarsest: v.coarsest.min(l),
                                finest: v.finest.max(l),
                            },
                        });
                        let (nxs, nys) = Quadrant {
                            level: nb.level,
                            x: nb.x,
                            y: nb.y,
                        }
                        .blocks(d);
                        t = if along_x { nxs.end } else { nys.end };
                    }
                    None => t += 1,
                }
            }
            blocks[i].neighbours[e] = levels;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::PayloadRef;
    use crate::heightfield::Heightfield;
    use crate::model::{BuildOptions, Model};

    /// The tabulated and the binary-search neighbour lookups agree on every cluster cut.
    #[test]
    fn neighbour_lookups_agree() {
        let hf = Heightfield::from_fn(300, 200, |x, y| {
            ((x as f32 * 0.07).sin() * 40.0 + (y as f32 * 0.05).cos() * 30.0) * (x as f32 / 100.0)
        })
        .unwrap();
        let model = Model::build(
            hf,
            &BuildOptions {
                block_size: 9,
                ..BuildOptions::default()
            },
        )
        .unwrap();
        let d = *model.domain();
        for c in model.clusters() {
            let mut blocks: Vec<SceneBlock> = c
                .nodes
                .iter()
                .map(|&i| {
                    let n = model.tree().node(i);
                    let rect = Quadrant {
                        level: n.level,
                        x: n.x,
                        y: n.y,
                    }
                    .samples(&d);
                    SceneBlock {
                        node: Some(i),
                        level: n.level,
                        x: n.x,
                        y: n.y,
                        key: n.key.0,
                        col0: rect.col0,
                        row0: rect.row0,
                        col1: rect.col1,
                        row1: rect.row1,
                        error: n.monotone_error,
                        screen_error: 0.0,
                        distance: 0.0,
                        min_height: n.min_height,
                        max_height: n.max_height,
                        payload: PayloadRef::default(),
                        neighbours: [None; 4],
                    }
                })
                .collect();
            // Drop every third block so that some edges face no block.
            let mut i = 0;
            blocks.retain(|_| {
                i += 1;
                i % 3 != 0
            });
            let mut searched = blocks.clone();
            set_neighbours_with(&d, &mut blocks, u64::MAX);
            set_neighbours_with(&d, &mut searched, 0);
            assert_eq!(blocks, searched, "cluster {}", c.threshold);
            if blocks.len() > 2 {
                assert!(blocks
                    .iter()
                    .any(|b| b.neighbours.iter().any(Option::is_some)));
            }
        }
    }
}
