//! Thinning by area (issue 19): a geographic grid's nodes coarsened east-west by their true
//! area, stored (format 6), and the study that measured it first.
//!
//! A longitude-latitude grid's samples are `dlon · N(φ) cos φ` metres apart east-west and
//! `dlat · M(φ)` north-south (`N`, `M` the ellipsoid's radii of curvature). Towards the poles
//! the first shrinks, so a node's `b × b` grid samples the ground far more densely east-west
//! than north-south: at 60° twice as densely, at 80° almost six times. Thinning by area
//! keeps every `k`-th grid column of such a node, `k` the largest power of two for which the
//! east-west spacing, times `k`, is still at most the north-south spacing where the node is
//! widest (its latitude nearest the equator). Powers of two keep the thinned columns on the
//! columns of every coarser level, so the quadtree's nesting holds; `k` is at most `b - 1`
//! (two columns). DTED's longitude zones (1, 2, 3, 4, 6 from 50° on) use 3 and 6 too; those
//! do not nest.
//!
//! **As stored (format 6).** A thinned node stores only its *kept columns*
//! ([`kept_columns`]): of its `gw` stored grid columns (format §7, clipped to the data), every
//! `k`-th and the last. A reader expands them back to `gw` columns ([`expand_row`]): a dropped
//! column is the linear interpolation, in `f64` and rounded once to `f32`, of the kept columns
//! either side, so every reader gets the same `b × b` grid bit for bit and nothing downstream
//! (meshes, skirts, scenes, parent-coded payloads) knows a grid was thinned. The node's static
//! error is measured on that expanded grid, exactly as any grid's
//! ([`super::measure::measure_node`]). A build ([`ThinByArea`]) thins a node above the finest
//! level by its factor `k` when the expanded grid's error is no larger than the square
//! grid's ([`THIN_ERROR_RATIO`]), and keeps it square otherwise; the model editor applies the
//! same rule, so an edited container equals a fresh build.
//!
//! **The study** (the rest of this module, `cargo bench --bench thinning`) measured what
//! thinning would save before the format paid for it: a thinned grid of `(b - 1) / k + 1`
//! columns drawn as rectangular cells `k · s` samples wide and `s` tall, each split along its
//! north-west to south-east diagonal; with `k = 1` it is the node's own grid and error, bit
//! for bit. The finding and the decision are in `docs/globe-design.md` §4.

use crate::heightfield::Georeference;

use super::domain::{Domain, SampleRect};
use super::raster::MendedRaster;
use super::tree::Fmrh;

/// Where a geographic grid's rows lie: row `r` at latitude `lat0 + r · dlat` degrees, columns
/// `dlon` degrees apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatLonSpacing {
    /// Latitude of row 0, degrees.
    pub lat0: f64,
    /// Degrees from one row to the next (negative for a north-up grid).
    pub dlat: f64,
    /// Degrees from one column to the next.
    pub dlon: f64,
}

impl LatLonSpacing {
    /// North-south over east-west ground spacing at latitude `lat` (degrees).
    pub fn aspect(&self, lat: f64) -> f64 {
        let phi = lat.to_radians();
        let e2 = crate::globe::WGS84_E2;
        let w2 = 1.0 - e2 * phi.sin().powi(2);
        // M / N = (1 - e²) / (1 - e² sin² φ).
        let m_over_n = (1.0 - e2) / w2;
        (m_over_n * self.dlat.abs()) / (phi.cos().max(0.0) * self.dlon.abs())
    }

    /// The column thinning factor of samples `rect` (see the module doc): the largest power
    /// of two `k <= max_k` with `k` east-west spacings at most one north-south spacing at the
    /// rectangle's latitude nearest the equator.
    pub fn factor(&self, rect: &SampleRect, max_k: u32) -> u32 {
        let a = self.lat0 + rect.row0 as f64 * self.dlat;
        let b = self.lat0 + rect.row1 as f64 * self.dlat;
        let widest = if a.signum() != b.signum() {
            0.0
        } else {
            a.abs().min(b.abs()).min(90.0)
        };
        let aspect = self.aspect(widest);
        let mut k = 1u32;
        while k * 2 <= max_k && f64::from(k * 2) <= aspect {
            k *= 2;
        }
        k
    }
}

impl LatLonSpacing {
    /// The spacing of a georeference whose CRS is geographic (longitude, latitude in
    /// degrees); `None` for any other, or for steps that are zero or not finite.
    pub fn of_georeference(g: &Georeference) -> Option<LatLonSpacing> {
        let crs = crate::crs::Crs::parse(g.crs.as_deref()?)?;
        let finite = g.origin.iter().chain(&g.step).all(|v| v.is_finite());
        (crs.kind == crate::crs::CrsKind::Geographic
            && finite
            && g.step[0] != 0.0
            && g.step[1] != 0.0)
            .then_some(LatLonSpacing {
                lat0: g.origin[1],
                dlat: g.step[1],
                dlon: g.step[0],
            })
    }
}

/// Whether a build thins nodes by area.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ThinByArea {
    /// Never: every grid is square.
    Off,
    /// Where the heightfield's georeference is geographic, by its spacing
    /// ([`LatLonSpacing::of_georeference`]); elsewhere never.
    #[default]
    Auto,
    /// By this spacing, whatever the heightfield says.
    Spacing(LatLonSpacing),
}

impl ThinByArea {
    /// The spacing to thin by, for a heightfield with georeference `g`.
    pub fn spacing(&self, g: Option<&Georeference>) -> Option<LatLonSpacing> {
        match self {
            ThinByArea::Off => None,
            ThinByArea::Auto => g.and_then(LatLonSpacing::of_georeference),
            ThinByArea::Spacing(s) => Some(*s),
        }
    }
}

/// A node is stored thinned only when its expanded grid's static error is at most this many
/// times its square grid's: 1, so thinning never raises a node's error. Then no node's `e*`
/// grows either, so no cut at any δ goes deeper than the square tree's, and a scene never
/// loads more nodes for thinning. Looser guards (√2, 2^¼) were measured
/// (`cargo bench --bench thinning`, docs/globe-design.md §4): they thin more grids of
/// isotropic polar data, but on relief that really is finer east-west they push cuts down and
/// read up to a fifth more at middle thresholds, and 2 to 3.4 times as much at the top.
pub const THIN_ERROR_RATIO: f64 = 1.0;

/// The largest `log₂ k` a node record holds (4 bits; `k <= b - 1 <= 1024`).
pub const MAX_THIN_LOG2: u8 = 10;

/// The candidate `log₂ k` of node `(level, x, y)`: 0 at the finest level (the data itself),
/// else the log of [`LatLonSpacing::factor`] over the node's footprint within the data.
pub fn candidate_log2(spacing: &LatLonSpacing, domain: &Domain, level: u8, x: u32, y: u32) -> u8 {
    if level >= domain.finest_level() {
        return 0;
    }
    let fp = domain.footprint(level, x, y);
    let within = fp.intersect(&domain.data_rect()).unwrap_or(fp);
    let k = spacing.factor(&within, domain.block_size() - 1);
    // A power of two at most 1024.
    k.trailing_zeros() as u8
}

/// Whether a node whose square grid's error is `square` and whose grid thinned by its
/// candidate factor has error `thinned` is stored thinned ([`THIN_ERROR_RATIO`]).
pub fn keeps_thinned(square: f64, thinned: f64) -> bool {
    thinned <= THIN_ERROR_RATIO * square
}

/// The kept columns of a grid of `gw` stored columns thinned by `k` (a power of two): every
/// `k`-th, and the last.
pub fn kept_columns(gw: u32, k: u32) -> impl Iterator<Item = u32> {
    let k = k.max(1);
    (0..gw).filter(move |&i| i % k == 0 || i + 1 == gw)
}

/// How many columns [`kept_columns`] keeps.
pub fn kept_count(gw: u32, k: u32) -> u32 {
    let k = k.max(1);
    if gw == 0 {
        return 0;
    }
    (gw - 1) / k + 1 + u32::from(!(gw - 1).is_multiple_of(k))
}

/// One row of a thinned grid expanded back to `out.len()` (= `gw`) columns from its `kept`
/// heights ([`kept_columns`]): a kept column is its height, a dropped one the linear
/// interpolation `((n - t) · a + t · b) / n` in `f64`, rounded once to `f32`, of the kept
/// columns `a` before and `b` after it, `t` columns past `a` and `n` apart.
pub fn expand_row(kept: &[f32], k: u32, out: &mut [f32]) {
    let k = k.max(1);
    let gw = out.len() as u32;
    // Kept column `j` is grid column `j·k`, but for the last: grid column `gw - 1`.
    for (i, o) in (0..gw).zip(out.iter_mut()) {
        let j = (i / k) as usize;
        let c0 = i / k * k;
        let (Some(&a), after) = (kept.get(j), kept.get(j + 1)) else {
            continue;
        };
        *o = match after {
            Some(&b) if i != c0 => {
                let c1 = (c0 + k).min(gw - 1);
                let (t, n) = (f64::from(i - c0), f64::from(c1 - c0));
                ((f64::from(a) * (n - t) + f64::from(b) * t) / n) as f32
            }
            _ => a,
        };
    }
}

/// The first `gw` columns of every row of a `b`-wide row-major grid, thinned by `k` and
/// expanded back in place ([`expand_row`]): what a reader of the stored grid draws.
pub fn thin_in_place(heights: &mut [f32], b: usize, gw: u32, k: u32) {
    if k <= 1 || b == 0 {
        return;
    }
    let mut kept = Vec::with_capacity(gw as usize);
    for row in heights.chunks_exact_mut(b) {
        kept.clear();
        kept.extend(kept_columns(gw, k).map(|i| row[i as usize]));
        expand_row(&kept, k, &mut row[..gw as usize]);
    }
}

/// The surface of a rectangular cell `sx` samples wide and `sy` tall at offset `(u, v)` from
/// its north-west corner, split along its NW–SE diagonal. With `sx == sy` it is
/// [`super::measure::surface`] exactly.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn rect_surface(nw: f32, ne: f32, sw: f32, se: f32, sx: u64, sy: u64, u: u64, v: u64) -> f64 {
    if sx == sy {
        return super::measure::surface(nw, ne, sw, se, sx, u, v);
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
/// heights, row-major from the north-west (mended, padding clamped, as [`super::Model::node_grid`]).
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
/// [`super::measure`] adds it. `k` must be a power of two dividing `b − 1`.
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
