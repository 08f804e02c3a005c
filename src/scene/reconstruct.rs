//! The surface a scene draws, sampled at full resolution: what a renderer would show, as
//! numbers anyone can diff against the source.
//!
//! Each sample of the window is taken from the scene block that *owns* it: the block whose
//! half-open footprint holds it (the data's last row and column go to the last block). A
//! coarse block is evaluated with the triangulation of `format-spec/model.md` §4 over its
//! grid; a physical block gives its samples, voids replaced by their stand-ins (§3). Samples
//! no scene block owns (outside the frustum's footprint) are NaN. Every node's error is
//! measured over its closed footprint, so which of two blocks sharing an edge owns a sample
//! does not change the bound: every valid sample is within the owning block's `e*`.

use crate::error::Result;
use crate::heightfield::{Heightfield, Metadata};
use crate::model::surface::surface;
use crate::model::SampleRect;
use crate::store::{Source, Store};

use super::load::{load_blocks, PAYLOAD_GAP};
use super::{Scene, SceneBlock};

/// A window sampled from a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Reconstruction {
    /// The window, inclusive samples.
    pub window: SampleRect,
    /// Row-major heights in binary64, exactly as the surface evaluates; NaN where no block
    /// of the scene owns the sample.
    pub values: Vec<f64>,
    /// For each sample, the `e*` of the block it came from (NaN where none did).
    pub bound: Vec<f64>,
    /// Samples no block owns.
    pub uncovered: u64,
    /// The finest stride (samples between grid points) of the blocks that own samples:
    /// the resolution at which the window holds all the detail the scene has; 0 when no
    /// block owns any.
    pub stride: u64,
}

impl Reconstruction {
    /// The window as a heightfield (binary32, uncovered samples as voids), with `metadata`
    /// shifted to the window's origin.
    pub fn to_heightfield(&self, metadata: &Metadata) -> Result<Heightfield> {
        let w = self.window.col1 - self.window.col0 + 1;
        let h = self.window.row1 - self.window.row0 + 1;
        let samples = self.values.iter().map(|&v| v as f32).collect();
        let mut metadata = metadata.clone();
        if let Some(g) = metadata.georeference.as_mut() {
            g.origin = [
                g.origin[0] + self.window.col0 as f64 * g.step[0],
                g.origin[1] + self.window.row0 as f64 * g.step[1],
            ];
        }
        metadata.source_format = "fmrh-scene".into();
        Ok(Heightfield::new(w as u32, h as u32, samples)?.with_metadata(metadata))
    }
}

/// Samples `window` (inside the data) from `scene`'s blocks, reading their payloads from
/// `store` (each checked against its CRC).
pub fn reconstruct<S: Source>(
    store: &Store<S>,
    scene: &Scene,
    window: SampleRect,
) -> Result<Reconstruction> {
    let d = *store.domain();
    let data = d.data_rect();
    window.check_inside(&data, "data")?;
    let w = (window.col1 - window.col0 + 1) as usize;
    let h = (window.row1 - window.row0 + 1) as usize;
    let mut values = vec![f64::NAN; w * h];
    let mut bound = vec![f64::NAN; w * h];
    let b = u64::from(d.block_size());
    let finest = d.finest_level();
    // The blocks that own part of the window, with that part; their payloads are read
    // together (coalesced) and decoded once.
    let mut parts = Vec::new();
    let mut stride = 0;
    for block in &scene.blocks {
        let rect = block.rect();
        // Owned: the half-open footprint, plus the data's last column and row.
        let owned = SampleRect {
            col0: rect.col0,
            row0: rect.row0,
            col1: if rect.col1 == data.col1 {
                rect.col1
            } else {
                rect.col1 - 1
            },
            row1: if rect.row1 == data.row1 {
                rect.row1
            } else {
                rect.row1 - 1
            },
        };
        if let Some(part) = owned.intersect(&window) {
            let s = d.stride(block.level);
            stride = if stride == 0 { s } else { stride.min(s) };
            parts.push((*block, part));
        }
    }
    let blocks: Vec<SceneBlock> = parts.iter().map(|(b, _)| *b).collect();
    let loaded = load_blocks(store, &blocks, PAYLOAD_GAP)?;
    for ((block, part), l) in parts.iter().zip(&loaded) {
        let rect = block.rect();
        let mut put = |col: u64, row: u64, v: f64| {
            let at = (row - window.row0) as usize * w + (col - window.col0) as usize;
            values[at] = v;
            bound[at] = block.error;
        };
        let g = &l.heights;
        if block.level == finest {
            // The block's samples within the data start at its footprint's corner.
            let bw = u64::from(l.width);
            for row in part.row0..=part.row1 {
                for col in part.col0..=part.col1 {
                    let at = (row - rect.row0) * bw + (col - rect.col0);
                    put(col, row, f64::from(g[at as usize]));
                }
            }
        } else {
            let s = d.stride(block.level);
            for row in part.row0..=part.row1 {
                let v = row - rect.row0;
                let j = (v / s).min(b - 2);
                let vv = v - j * s;
                for col in part.col0..=part.col1 {
                    let u = col - rect.col0;
                    let i = (u / s).min(b - 2);
                    let uu = u - i * s;
                    let at = |ii: u64, jj: u64| g[(jj * b + ii) as usize];
                    let z = surface(
                        at(i, j),
                        at(i + 1, j),
                        at(i, j + 1),
                        at(i + 1, j + 1),
                        s,
                        uu,
                        vv,
                    );
                    put(col, row, z);
                }
            }
        }
    }
    let uncovered = values.iter().filter(|v| v.is_nan()).count() as u64;
    Ok(Reconstruction {
        window,
        values,
        bound,
        uncovered,
        stride,
    })
}
