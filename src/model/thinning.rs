//! Thinning by area (issue 19): a geographic grid's nodes coarsened east-west by their true
//! area, stored (format 6): the rule, the kept columns, and their expansion.
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
//! **The study** that measured what thinning would save before the format paid for it is
//! research code beside its benchmark (`benches/common/thinning_study.rs`, `cargo bench
//! --bench thinning`); the finding and the decision are in `docs/globe-design.md` §4.

use crate::heightfield::Georeference;

use super::domain::{Domain, SampleRect};

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
    /// (model §4a); elsewhere never.
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
