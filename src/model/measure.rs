//! Measuring nodes: the static error, height range and valid-sample count of every node.
//!
//! **The static error** (format-spec §"Static error") of a node is the largest
//! `|h(x, y) - s(x, y)|` over the *valid* full-resolution samples `(x, y)` of its footprint.
//! Here `h` is the sample's height and `s` is the piecewise-linear surface of the node's grid.
//! Each grid cell is split along its NW–SE diagonal, and `s` is evaluated in `f64` by
//! [`surface`]'s exact formula. Grid vertices take the mended raster's values (voids mended,
//! padding clamped), so `s` is defined everywhere and is never infinite.
//!
//! The same scan gathers the node's height range: the least and greatest mended height over its
//! footprint. Everything the node's grid can draw lies in that range, and so does every real
//! height under it. The scan also counts the footprint's valid samples.
//!
//! **With a storage precision `Q`** (see [`super::precision`]) the raster holds the stored
//! heights, and every band with a valid sample adds the storage bound `9Q/16` to its error
//! (rounded up by one ulp), so the error bounds the distance to the source as well: finest
//! nodes get exactly the bound (model §4).
//!
//! One level costs one pass over the data: each node scans its own footprint. The work is
//! spread over cores by node, or for the few big nodes near the root by band of cell rows. At
//! the finest level the grid *is* the data, so the error is 0 by definition and only the range
//! and count are scanned.

use rayon::prelude::*;

use super::domain::Domain;
use super::raster::MendedRaster;
use super::surface::surface;

/// What one scan of a node's footprint finds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeStats {
    /// The static error: max `|h - s|` over valid samples (0 if none).
    pub error: f64,
    /// Least mended height in the footprint.
    pub min_height: f32,
    /// Greatest mended height in the footprint.
    pub max_height: f32,
    /// Valid samples in the footprint (its edges included).
    pub valid_samples: u64,
}

impl NodeStats {
    /// Nothing seen yet.
    pub const EMPTY: NodeStats = NodeStats {
        error: 0.0,
        min_height: f32::INFINITY,
        max_height: f32::NEG_INFINITY,
        valid_samples: 0,
    };

    /// Combines the findings of two disjoint parts of one footprint.
    #[inline]
    pub fn merge(self, other: NodeStats) -> NodeStats {
        NodeStats {
            error: self.error.max(other.error),
            min_height: self.min_height.min(other.min_height),
            max_height: self.max_height.max(other.max_height),
            valid_samples: self.valid_samples + other.valid_samples,
        }
    }
}

/// Measures every existing node of `level`; the result is row-major over
/// [`Domain::nodes_across`].
pub fn measure_level(raster: &MendedRaster, domain: &Domain, level: u8) -> Vec<NodeStats> {
    measure_level_with(raster, domain, level, |_| Some(0))
}

/// Measures the nodes of `level` whose grid is thinned by `2^t` for `thin[i] = t > 0`
/// (row-major, [`super::thinning`]); the others come back [`NodeStats::EMPTY`], unmeasured.
pub fn measure_level_thinned(
    raster: &MendedRaster,
    domain: &Domain,
    level: u8,
    thin: &[u8],
) -> Vec<NodeStats> {
    measure_level_with(raster, domain, level, |i| {
        thin.get(i).copied().filter(|&t| t > 0)
    })
}

/// Measures node `i` of `level` (row-major) thinned by `2^t` where `thin(i)` is `Some(t)`,
/// not at all where it is `None`. The work is spread by node, or for the few big nodes near
/// the root by band.
fn measure_level_with(
    raster: &MendedRaster,
    domain: &Domain,
    level: u8,
    thin: impl Fn(usize) -> Option<u8> + Sync,
) -> Vec<NodeStats> {
    let (cols, rows) = domain.nodes_across(level);
    let nodes = cols as usize * rows as usize;
    let bands = domain.block_size() as usize - 1;
    let node_at = |i: usize| ((i % cols as usize) as u32, (i / cols as usize) as u32);
    if nodes >= 64 {
        (0..nodes)
            .into_par_iter()
            .map(|i| {
                thin(i).map_or(NodeStats::EMPTY, |t| {
                    measure_node(raster, domain, level, node_at(i), t)
                })
            })
            .collect()
    } else {
        let parts: Vec<NodeStats> = (0..nodes * bands)
            .into_par_iter()
            .map(|k| {
                thin(k / bands).map_or(NodeStats::EMPTY, |t| {
                    measure_band(
                        raster,
                        domain,
                        level,
                        node_at(k / bands),
                        (k % bands) as u64,
                        t,
                    )
                })
            })
            .collect();
        parts
            .chunks(bands)
            .map(|c| c.iter().fold(NodeStats::EMPTY, |a, &b| a.merge(b)))
            .collect()
    }
}

/// Measures node `(x, y)` of `level` on its own, its grid thinned by `2^thin` east-west
/// (0: square; see [`super::thinning`]).
pub fn measure_node(
    raster: &MendedRaster,
    domain: &Domain,
    level: u8,
    (x, y): (u32, u32),
    thin: u8,
) -> NodeStats {
    (0..u64::from(domain.block_size() - 1))
        .map(|band| measure_band(raster, domain, level, (x, y), band, thin))
        .fold(NodeStats::EMPTY, NodeStats::merge)
}

/// Measures one band of a node: the sample rows of its cell row `band`. The band takes its
/// north edge row; its south edge row belongs to the next band, except for the last band.
/// The grid is thinned by `2^thin` east-west and expanded back as a reader draws it
/// ([`super::thinning::thin_in_place`]); 0 keeps it square.
pub(crate) fn measure_band(
    raster: &MendedRaster,
    domain: &Domain,
    level: u8,
    (x, y): (u32, u32),
    band: u64,
    thin: u8,
) -> NodeStats {
    let fp = domain.footprint(level, x, y);
    let s = domain.stride(level);
    let last_band = u64::from(domain.block_size() - 2);
    let gy0 = fp.row0 + band * s;
    let (w, h) = (u64::from(raster.width()), u64::from(raster.height()));
    if gy0 >= h {
        return NodeStats::EMPTY;
    }
    let row_end = if band == last_band {
        gy0 + s
    } else {
        gy0 + s - 1
    }
    .min(h - 1);
    let (col0, col1) = (fp.col0, fp.col1.min(w - 1));
    let mut stats = NodeStats::EMPTY;

    // Height range and valid count: plain row scans.
    for row in gy0..=row_end {
        let vals = &raster.row(row)[col0 as usize..=col1 as usize];
        let (lo, hi) = vals
            .iter()
            .fold((stats.min_height, stats.max_height), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        stats.min_height = lo;
        stats.max_height = hi;
        stats.valid_samples += raster.count_valid(row, col0, col1);
    }
    // A stored height may be off its source by the storage error (0 when lossless), so
    // every band with a real height adds it (model §4).
    let storage = if stats.valid_samples > 0 {
        raster.storage_error()
    } else {
        0.0
    };
    if s == 1 {
        // The finest grid is the stored data: no sample is off the surface.
        stats.error = storage;
        return stats;
    }

    // The band's grid rows: north and south edges of its cells, clamped into the data.
    let b = domain.block_size() as usize;
    let mut north: Vec<f32> = (0..b as u64)
        .map(|i| raster.value(fp.col0 + i * s, gy0))
        .collect();
    let mut south: Vec<f32> = (0..b as u64)
        .map(|i| raster.value(fp.col0 + i * s, gy0 + s))
        .collect();
    if thin > 0 {
        let (gw, _) = domain.grid_dims(level, x, y);
        super::thinning::thin_in_place(&mut north, b, gw, 1 << thin);
        super::thinning::thin_in_place(&mut south, b, gw, 1 << thin);
    }
    let shift = s.trailing_zeros();
    let last_cell = b as u64 - 2;
    let mut error = 0.0f64;
    for row in gy0..=row_end {
        let v = row - gy0;
        let vals = raster.row(row);
        raster.for_each_valid_run(row, col0, col1, |first, last| {
            let mut col = first;
            while col <= last {
                let cell = ((col - fp.col0) >> shift).min(last_cell);
                let cx0 = fp.col0 + cell * s;
                let cell_last = if cell == last_cell {
                    cx0 + s
                } else {
                    cx0 + s - 1
                };
                let end = cell_last.min(last);
                let c = cell as usize;
                let (nw, ne, sw, se) = (north[c], north[c + 1], south[c], south[c + 1]);
                for xx in col..=end {
                    let z = surface(nw, ne, sw, se, s, xx - cx0, v);
                    let e = (f64::from(vals[xx as usize]) - z).abs();
                    if e > error {
                        error = e;
                    }
                }
                col = end + 1;
            }
        });
    }
    stats.error = if storage > 0.0 {
        // Rounded up by one ulp, so that the recorded error is at least the exact sum of
        // the measured error and the storage bound, whatever the rounding of each: then
        // any |surface - source| computed in f64 stays within it.
        (error + storage).next_up()
    } else {
        error
    };
    stats
}
