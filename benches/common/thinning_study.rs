//! The study that measured thinning by area before format 6 stored it (`cargo bench --bench
//! thinning`, `docs/globe-design.md` §4): a node's grid thinned `k` times east-west and drawn
//! as rectangular cells `k · s` samples wide and `s` tall, each split along its north-west to
//! south-east diagonal (with `k = 1`, the node's own grid and error, bit for bit); its exact
//! static error; every node's thinning and thinned monotone error; and the cut those give.
//! Research code, not the engine: the engine's rule is `fmrh::model::thinning`. Shared by
//! the benchmark and `tests/thinning.rs`, which checks it.

#![allow(dead_code)]

use fmrh::model::surface::surface;
use fmrh::model::thinning::LatLonSpacing;
use fmrh::model::{Domain, Fmrh, MendedRaster};

/// The surface of a rectangular cell `sx` samples wide and `sy` tall at offset `(u, v)` from
/// its north-west corner, split along its NW–SE diagonal. With `sx == sy` it is
/// [`surface`] exactly.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn rect_surface(nw: f32, ne: f32, sw: f32, se: f32, sx: u64, sy: u64, u: u64, v: u64) -> f64 {
    if sx == sy {
        return surface(nw, ne, sw, se, sx, u, v);
    }
    // Compare u/sx with v/sy without rounding: u·sy against v·sx.
    let (a, c) = (u as f64 / sx as f64, v as f64 / sy as f64);
    if u * sy >= v * sx {
        ((1.0 - a) * f64::from(nw) + (a - c) * f64::from(ne)) + c * f64::from(se)
    } else {
        ((1.0 - c) * f64::from(nw) + (c - a) * f64::from(sw)) + a * f64::from(se)
    }
}

/// Node `(level, x, y)`'s grid thinned `k` times east-west: its width (columns) and its
/// heights, row-major from the north-west (mended, padding clamped, as `Model::node_grid`).
pub fn thinned_grid(
    raster: &MendedRaster,
    domain: &Domain,
    level: u8,
    x: u32,
    y: u32,
    k: u32,
) -> (u32, Vec<f32>) {
    let fp = domain.footprint(level, x, y);
    let (b, s) = (u64::from(domain.block_size()), domain.stride(level));
    let cols = (b - 1) / u64::from(k) + 1;
    let mut out = Vec::with_capacity((cols * b) as usize);
    for j in 0..b {
        for i in 0..cols {
            out.push(raster.value(fp.col0 + i * u64::from(k) * s, fp.row0 + j * s));
        }
    }
    (cols as u32, out)
}

/// The static error of node `(level, x, y)`'s grid thinned `k` times east-west: the largest
/// `|h − s|` over the valid samples of its footprint, plus the storage bound as
/// `fmrh::model::measure` adds it. `k` must be a power of two dividing `b − 1`.
pub fn thinned_error(
    raster: &MendedRaster,
    domain: &Domain,
    level: u8,
    x: u32,
    y: u32,
    k: u32,
) -> f64 {
    let s = domain.stride(level);
    let fp = domain.footprint(level, x, y);
    let (w, h) = (u64::from(raster.width()), u64::from(raster.height()));
    let (sx, sy) = (s * u64::from(k), s);
    let mut error = 0.0f64;
    let mut any = false;
    for row in fp.row0..=fp.row1.min(h - 1) {
        let band = (row - fp.row0) / sy;
        // The last row of the footprint is the south edge of the last band.
        let band = band.min((fp.row1 - fp.row0) / sy - 1);
        let (gy0, v) = (fp.row0 + band * sy, (row - fp.row0) - band * sy);
        raster.for_each_valid_run(row, fp.col0, fp.col1.min(w - 1), |first, last| {
            any = true;
            for col in first..=last {
                let cell = ((col - fp.col0) / sx).min((fp.col1 - fp.col0) / sx - 1);
                let gx0 = fp.col0 + cell * sx;
                let u = col - gx0;
                let z = rect_surface(
                    raster.value(gx0, gy0),
                    raster.value(gx0 + sx, gy0),
                    raster.value(gx0, gy0 + sy),
                    raster.value(gx0 + sx, gy0 + sy),
                    sx,
                    sy,
                    u,
                    v,
                );
                let e = (f64::from(raster.value(col, row)) - z).abs();
                error = error.max(e);
            }
        });
    }
    // The storage bound, as `measure` adds it (rounded up by one ulp).
    let storage = raster.storage_error();
    if any && storage > 0.0 {
        (error + storage).next_up()
    } else {
        error
    }
}

/// Every kept node's thinning: its factor, its thinned static error, and the thinned
/// monotone error (the largest thinned static error in its kept subtree; physical blocks are
/// never thinned), in the tree's order.
#[derive(Clone, Debug, PartialEq)]
pub struct AreaThinning {
    /// Column factor per node (1 at the finest level).
    pub factor: Vec<u32>,
    /// Static error of the thinned grid per node.
    pub static_error: Vec<f64>,
    /// Largest thinned static error in each node's kept subtree.
    pub monotone_error: Vec<f64>,
}

impl AreaThinning {
    /// Measures every node of `tree` over `raster` placed by `spacing`, each node thinned
    /// by its area factor.
    pub fn measure(raster: &MendedRaster, tree: &Fmrh, spacing: &LatLonSpacing) -> AreaThinning {
        AreaThinning::measure_within(raster, tree, spacing, f64::INFINITY)
    }

    /// As [`AreaThinning::measure`], but a node's factor is halved (down to 1) while its
    /// thinned error exceeds `ratio` times its square grid's: thinning only where it costs
    /// the error little.
    pub fn measure_within(
        raster: &MendedRaster,
        tree: &Fmrh,
        spacing: &LatLonSpacing,
        ratio: f64,
    ) -> AreaThinning {
        use rayon::prelude::*;
        let domain = tree.domain();
        let max_k = domain.block_size() - 1;
        let finest = domain.finest_level();
        let nodes = tree.nodes();
        let measured: Vec<(u32, f64)> = nodes
            .par_iter()
            .enumerate()
            .map(|(i, n)| {
                if n.level == finest {
                    return (1, n.static_error);
                }
                let within = tree.footprint(i as u32).intersect(&domain.data_rect());
                let mut k = within.map_or(1, |r| spacing.factor(&r, max_k));
                while k > 1 {
                    let e = thinned_error(raster, domain, n.level, n.x, n.y, k);
                    if ratio == f64::INFINITY || e <= ratio * n.static_error {
                        return (k, e);
                    }
                    k /= 2;
                }
                (1, n.static_error)
            })
            .collect();
        let factor: Vec<u32> = measured.iter().map(|m| m.0).collect();
        let static_error: Vec<f64> = measured.iter().map(|m| m.1).collect();
        // Children follow their parents in pre-order: fold from the back.
        let mut monotone = static_error.clone();
        for i in (1..nodes.len()).rev() {
            let p = nodes[i].parent as usize;
            monotone[p] = monotone[p].max(monotone[i]);
        }
        AreaThinning {
            factor,
            static_error,
            monotone_error: monotone,
        }
    }
}

/// The cut of `tree` at `delta` by the monotone errors `monotone` (one per node): the nodes
/// nearest the root whose error is at most `delta`, and where a kept leaf's is more, the
/// physical blocks under it (as `(level, x, y)` with `None` for the node index).
pub fn cut(tree: &Fmrh, monotone: &[f64], delta: f64) -> Vec<(Option<u32>, u8, u32, u32)> {
    let domain = tree.domain();
    let finest = domain.finest_level();
    let mut out = Vec::new();
    let mut todo = vec![0u32];
    while let Some(i) = todo.pop() {
        let n = tree.node(i);
        if monotone[i as usize] <= delta || n.level == finest {
            out.push((Some(i), n.level, n.x, n.y));
            continue;
        }
        let kids: Vec<u32> = tree.children(i).collect();
        if kids.is_empty() {
            // A pruned leaf: the physical blocks of its footprint.
            let span = 1u32 << (finest - n.level);
            for y in n.y * span..(n.y + 1) * span {
                for x in n.x * span..(n.x + 1) * span {
                    if domain.exists(finest, x, y) {
                        out.push((None, finest, x, y));
                    }
                }
            }
        } else {
            todo.extend(kids);
        }
    }
    out
}
