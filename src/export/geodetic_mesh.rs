//! A georeferenced surface cut into the tiles of the geographic pyramid ([`super::geodetic`])
//! as Cesium reads them: which tiles a scene needs, and each tile's mesh, a regular grid in
//! longitude and latitude over the tile, with heights from the surface, normals, and its
//! measured error.
//!
//! **Which tiles.** A scene block whose grid points are `g` degrees apart (the finer of its
//! two directions) maps to the shallowest pyramid level whose tile grid is at least as fine,
//! `tile_degrees(z) / 64 <= g` ([`level_for_step`]): the tiles never draw the scene coarser
//! than it chose. Each block brings the tiles of its level that meet its longitude and
//! latitude box, and a tileset holds every ancestor of a tile it holds (Cesium reaches a
//! tile only through its parent) and both root tiles ([`tiles_for`]).
//!
//! **A tile's mesh.** `GRID x GRID` vertices, at the quantized positions
//! `round(32767 i / 64)` across the tile, so the longitude and latitude a decoder reads back
//! are exactly where the heights were taken; two tiles of one level that share an edge put
//! the same vertices on it at the same heights (the same longitude and latitude give the
//! same sample position, and the surface gives the same height there). Each cell is two
//! triangles split along its south-east to north-west diagonal. A vertex is:
//!
//! * *inside* when its sample position is owned by a block: the surface there;
//! * *near* when it is outside but a cell around it meets the data's longitude and latitude
//!   box: the surface at the nearest point of the data, so that a cell holding data samples
//!   is drawn from data on all its corners;
//! * otherwise the ellipsoid, height 0.
//!
//! Heights go through the quantization a decoder undoes, and everything below is measured
//! on the heights a decoder gets.
//!
//! **Error.** A tile's surface is linear in `(u, v)` over each triangle (how Cesium
//! interpolates heights in a tile). At every data sample inside the tile it is compared
//! with the surface there: `resampling` is the largest difference, and `error` the largest
//! difference plus the owning block's `e*`, so that `|tile - source| <= error` at every
//! valid sample (the block is within its `e*` of the source there).
//!
//! Nothing here reads a file or knows what a level, a key or a scene is: the caller gives
//! the surface ([`Surface`]), how samples sit on the globe ([`Placement`]), and the tiles.

use std::collections::BTreeSet;

use super::geodetic::{self, GeodeticTile};
use super::quantized_mesh::{self, Header, TileData, QUANTIZED_MAX};
use crate::crs::{Crs, CrsKind};
use crate::error::{Error, Result};
use crate::heightfield::Georeference;
use crate::model::SampleRect;
use crate::scene::surface::Surface;

/// Vertices along a side of a tile's grid (Cesium's heightmap size).
pub const GRID: usize = 65;

/// Cells along a side of a tile's grid.
const CELLS: usize = GRID - 1;

/// How samples sit on the globe: a georeference whose CRS fmrh can turn into longitude and
/// latitude (a geographic CRS, or a projected one the EPSG registry knows).
#[derive(Clone, Debug)]
pub struct Placement {
    crs: Crs,
    origin: [f64; 2],
    step: [f64; 2],
    /// Multiply sample coordinates by this to get the surface's units (a refined scene's
    /// blocks are in finer units than samples).
    units: f64,
    /// Whether heights are above the EGM96 geoid and go onto the globe above the ellipsoid
    /// (`h = H + N`, [`Placement::lift`]).
    geoid: bool,
}

impl Placement {
    /// The placement of `g`'s samples, in a surface whose coordinates are `units` times
    /// the samples'; an error when the georeference cannot be placed on the globe.
    pub fn new(g: &Georeference, units: f64) -> Result<Placement> {
        let name = g.crs.as_deref().ok_or_else(|| {
            Error::InvalidArgument(
                "the georeference names no CRS: it cannot be placed on the globe".into(),
            )
        })?;
        let crs = Crs::parse(name).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "CRS `{name}` is not one fmrh can place on the globe"
            ))
        })?;
        let placeable = match crs.kind {
            CrsKind::Geographic => true,
            CrsKind::Projected { .. } => crs.to_lon_lat(g.origin[0], g.origin[1]).is_some(),
            CrsKind::Other => false,
        };
        let finite = g.origin.iter().chain(&g.step).all(|v| v.is_finite())
            && g.step[0] != 0.0
            && g.step[1] != 0.0;
        if !placeable || !finite || units.is_nan() || units < 1.0 {
            return Err(Error::InvalidArgument(format!(
                "CRS `{name}` with origin {:?} and step {:?} cannot be placed on the globe",
                g.origin, g.step
            )));
        }
        Ok(Placement {
            crs,
            origin: g.origin,
            step: g.step,
            units,
            geoid: false,
        })
    }

    /// This placement with heights above the EGM96 geoid lifted onto the ellipsoid (`on`),
    /// or kept as they are.
    pub fn with_geoid(mut self, on: bool) -> Placement {
        self.geoid = on;
        self
    }

    /// What goes onto a height at `(lon, lat)` to place it above the WGS 84 ellipsoid: the
    /// EGM96 undulation `N` when heights are above that geoid, else 0.
    pub fn lift(&self, lon: f64, lat: f64) -> f64 {
        if self.geoid {
            crate::geoid::egm96_undulation(lat, lon)
        } else {
            0.0
        }
    }

    /// [`Placement::lift`] along the parallel at `lat`, for many longitudes: the geoid's
    /// grid rows found once (the same values, bit for bit).
    pub fn lift_along(&self, lat: f64) -> ParallelLift {
        ParallelLift(self.geoid.then(|| crate::geoid::Egm96Row::new(lat)))
    }

    /// Whether the CRS is geographic (samples are affine in longitude and latitude).
    pub fn is_geographic(&self) -> bool {
        self.crs.kind == CrsKind::Geographic
    }

    /// Longitude and latitude (degrees) of surface positions `(col, row)` (in the
    /// surface's units); `None` where the projection has no answer.
    pub fn lon_lat(&self, points: &[[f64; 2]]) -> Vec<Option<[f64; 2]>> {
        let crs_points: Vec<[f64; 2]> = points
            .iter()
            .map(|&[c, r]| {
                [
                    self.origin[0] + c / self.units * self.step[0],
                    self.origin[1] + r / self.units * self.step[1],
                ]
            })
            .collect();
        match self.crs.to_lon_lat_all(&crs_points) {
            Some(v) => v.into_iter().map(Some).collect(),
            None => crs_points
                .iter()
                .map(|&[x, y]| self.crs.to_lon_lat(x, y))
                .collect(),
        }
    }

    /// Surface positions `(col, row)` of longitudes and latitudes (degrees); `None` where
    /// the projection has no answer.
    pub fn positions(&self, lon_lat: &[[f64; 2]]) -> Vec<Option<[f64; 2]>> {
        let to_position = |[x, y]: [f64; 2]| {
            let p = [
                (x - self.origin[0]) / self.step[0] * self.units,
                (y - self.origin[1]) / self.step[1] * self.units,
            ];
            (p[0].is_finite() && p[1].is_finite()).then_some(p)
        };
        match self.crs.lon_lat_to_crs_all(lon_lat) {
            Some(v) => v.into_iter().map(to_position).collect(),
            None => lon_lat
                .iter()
                .map(|&p| {
                    self.crs
                        .lon_lat_to_crs_all(&[p])
                        .and_then(|v| v.first().copied())
                        .and_then(to_position)
                })
                .collect(),
        }
    }

    /// The surface positions `[col0, row0, col1, row1]` spanned by the longitude and
    /// latitude box `[west, south, east, north]`: its boundary placed at 16 points a side
    /// (a projected box's edges bow between them: callers leave a margin). `None` when no
    /// boundary point can be placed.
    pub fn span_of(&self, lon_lat_box: [f64; 4]) -> Option<[f64; 4]> {
        let [w, s, e, n] = lon_lat_box;
        let mut edge = Vec::with_capacity(68);
        for k in 0..=16 {
            let t = f64::from(k) / 16.0;
            let (lon, lat) = (w + (e - w) * t, s + (n - s) * t);
            edge.extend([[lon, s], [lon, n], [w, lat], [e, lat]]);
        }
        self.positions(&edge).into_iter().flatten().fold(None, |b, [c, r]| {
            let [c0, r0, c1, r1] = b.unwrap_or([c, r, c, r]);
            Some([c0.min(c), r0.min(r), c1.max(c), r1.max(r)])
        })
    }

    /// The longitude and latitude box `[west, south, east, north]` of the closed rectangle
    /// `rect` (surface units): its boundary taken at 16 points a side (a projected
    /// rectangle's image is curved). `None` when no boundary point can be placed.
    pub fn box_of(&self, rect: &SampleRect) -> Option<[f64; 4]> {
        let (c0, r0, c1, r1) = (
            rect.col0 as f64,
            rect.row0 as f64,
            rect.col1 as f64,
            rect.row1 as f64,
        );
        let n = if self.is_geographic() { 1 } else { 16 };
        let mut points = Vec::with_capacity(4 * n + 4);
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (c, r) = (c0 + (c1 - c0) * t, r0 + (r1 - r0) * t);
            points.extend([[c, r0], [c, r1], [c0, r], [c1, r]]);
        }
        let placed: Vec<[f64; 2]> = self.lon_lat(&points).into_iter().flatten().collect();
        if placed.is_empty() {
            return None;
        }
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for [lon, lat] in placed {
            b = [b[0].min(lon), b[1].min(lat), b[2].max(lon), b[3].max(lat)];
        }
        Some(b)
    }
}

/// The shallowest level whose tile grid steps are at most `step_deg` degrees (capped at
/// [`geodetic::MAX_LEVEL`]).
pub fn level_for_step(step_deg: f64) -> u8 {
    let mut z = 0u8;
    while z < geodetic::MAX_LEVEL && geodetic::tile_degrees(z) / CELLS as f64 > step_deg {
        z += 1;
    }
    z
}

/// The tiles that draw areas `(box, level)` — each the tiles of that level meeting the
/// box — with every ancestor of each, and both root tiles: a set Cesium can walk from its
/// roots.
pub fn tiles_for(areas: &[([f64; 4], u8)]) -> BTreeSet<GeodeticTile> {
    let mut out: BTreeSet<GeodeticTile> = geodetic::tiles_meeting(0, [-180.0, -90.0, 180.0, 90.0])
        .into_iter()
        .collect();
    for &(b, z) in areas {
        for t in geodetic::tiles_meeting(z, b) {
            let mut at = Some(t);
            while let Some(t) = at {
                if !out.insert(t) {
                    break;
                }
                at = t.parent();
            }
        }
    }
    out
}

/// The quantized position of grid line `i` across a tile.
pub(crate) fn grid_code(i: usize) -> u16 {
    ((f64::from(QUANTIZED_MAX) * i as f64 / CELLS as f64).round()) as u16
}

/// A tile sampled from a surface, ready to write, with what it draws from.
pub struct SampledTile {
    /// The tile.
    #[cfg_attr(not(any(test, feature = "testing")), allow(dead_code))] // read by the tests
    pub tile: GeodeticTile,
    /// Its quantized mesh (the metadata left empty for the caller).
    pub data: TileData,
    /// The height of each vertex as a decoder reads it, row-major from the south-west
    /// (`v` then `u`).
    #[cfg_attr(not(any(test, feature = "testing")), allow(dead_code))] // read by the tests
    pub heights: Vec<f64>,
    /// Whether each vertex is inside the data.
    pub inside: Vec<bool>,
    /// The blocks the inside vertices' heights come from, ascending.
    pub blocks: Vec<usize>,
    /// `max |tile - surface|` over the data samples inside the tile (0 with none).
    pub resampling: f64,
    /// `max (|tile - surface| + e*)` over the data samples inside the tile: the tile is
    /// within this of the source at every valid sample (0 with none).
    pub error: f64,
    /// Data samples the error was measured at.
    pub measured: u64,
    /// The largest `e*` of the blocks owning them (0: the error was measured against
    /// physical blocks, the source itself at valid samples).
    pub block_error: f64,
}

/// Longitude and latitude of grid line `i` (any integer, past the tile for the apron) of
/// tile `t`, as `(lon, lat)` for `(i, j)` with `j` from the south.
fn grid_lon_lat(t: &GeodeticTile, i: i64, j: i64) -> [f64; 2] {
    let d = geodetic::tile_degrees(t.z);
    // Past the tile, the next tile's own grid line: every tile of a level then puts a
    // given line at the same longitude or latitude, to the bit.
    let at = |k: i64| -> f64 {
        let (whole, part) = (k.div_euclid(CELLS as i64), k.rem_euclid(CELLS as i64));
        whole as f64 + f64::from(grid_code(part as usize)) / f64::from(QUANTIZED_MAX)
    };
    [
        -180.0 + (f64::from(t.x) + at(i)) * d,
        (-90.0 + (f64::from(t.y) + at(j)) * d).clamp(-90.0, 90.0),
    ]
}

/// A tile's grid sampled from a surface, before quantization: `GRID²` lines and a one-line
/// apron, `APRON²` values row-major from the south-west corner of the apron.
pub struct GridSample {
    /// Longitude and latitude of each point.
    pub lon_lat: Vec<[f64; 2]>,
    /// Its height: the surface inside the data, the nearest data next to it, else 0.
    pub raw: Vec<f64>,
    /// Whether the surface holds it.
    pub inside: Vec<bool>,
    /// The block it was taken from (`usize::MAX` outside).
    pub owner: Vec<usize>,
}

/// Values along a side of a [`GridSample`]: the grid and its apron.
pub const APRON: usize = GRID + 2;

impl GridSample {
    /// Index of grid point `(i, j)` (from the tile's south-west corner) in the arrays.
    pub fn index(i: usize, j: usize) -> usize {
        (j + 1) * APRON + (i + 1)
    }

    /// The `GRID²` heights of the tile's own grid, row-major from the south-west.
    pub fn grid_heights(&self) -> Vec<f64> {
        (0..GRID)
            .flat_map(|j| (0..GRID).map(move |i| (i, j)))
            .map(|(i, j)| self.raw[GridSample::index(i, j)])
            .collect()
    }
}

/// Samples `tile`'s grid and apron from `surface` placed by `placement`; `data_box` is the
/// longitude and latitude box of the data (what decides *near* points). A point's height
/// depends on its longitude and latitude alone, so two tiles sharing a point (an edge, or
/// an apron line on the next tile's grid) give it the same height.
pub fn sample_grid(
    tile: GeodeticTile,
    surface: &Surface<'_>,
    placement: &Placement,
    data_box: [f64; 4],
) -> GridSample {
    // The grid with an apron one line beyond each edge, for normals across tile edges.
    const A: usize = APRON;
    let mut lon_lat = Vec::with_capacity(A * A);
    for j in -1..=GRID as i64 {
        for i in -1..=GRID as i64 {
            lon_lat.push(grid_lon_lat(&tile, i, j));
        }
    }
    // Only points within two cells of the data's box are placed: the rest are far from
    // it (and a projection far from its zone may answer nonsense, even inside the data).
    let [dw, ds, de, dn] = data_box;
    let reach = 2.0 * geodetic::tile_degrees(tile.z) / CELLS as f64;
    let wanted: Vec<usize> = (0..A * A)
        .filter(|&k| {
            let [lon, lat] = lon_lat[k];
            lon >= dw - reach && lon <= de + reach && lat >= ds - reach && lat <= dn + reach
        })
        .collect();
    let placed = placement.positions(&wanted.iter().map(|&k| lon_lat[k]).collect::<Vec<_>>());
    let mut positions = vec![None; A * A];
    for (&k, p) in wanted.iter().zip(placed) {
        positions[k] = p;
    }
    let cell_meets_data = |i: i64, j: i64| {
        if i < -1 || j < -1 || i >= GRID as i64 || j >= GRID as i64 {
            return false;
        }
        let a = lon_lat[((j + 1) as usize) * A + (i + 1) as usize];
        let b = lon_lat[((j + 2) as usize) * A + (i + 2) as usize];
        a[0] <= de && b[0] >= dw && a[1] <= dn && b[1] >= ds
    };
    let mut raw = vec![0.0f64; A * A];
    let mut inside = vec![false; A * A];
    let mut owner = vec![usize::MAX; A * A];
    for j in 0..A {
        for i in 0..A {
            let k = j * A + i;
            let Some([c, r]) = positions[k] else {
                continue;
            };
            if let Some(s) = surface.at(c, r) {
                raw[k] = s.height;
                inside[k] = true;
                owner[k] = s.block;
                continue;
            }
            let (gi, gj) = (i as i64 - 1, j as i64 - 1);
            let near = [(gi - 1, gj - 1), (gi, gj - 1), (gi - 1, gj), (gi, gj)]
                .iter()
                .any(|&(ci, cj)| cell_meets_data(ci, cj));
            if near {
                if let Some(s) = surface.nearest(c, r) {
                    raw[k] = s.height;
                }
            }
        }
    }
    // Every point, on the data or off it (sea level there), onto the ellipsoid.
    if placement.geoid {
        for (h, &[lon, lat]) in raw.iter_mut().zip(&lon_lat) {
            *h += placement.lift(lon, lat);
        }
    }
    GridSample {
        lon_lat,
        raw,
        inside,
        owner,
    }
}

/// Samples `tile` from `surface` placed by `placement`; `data_box` is the longitude and
/// latitude box of the data (what decides *near* vertices).
pub fn sample_tile(
    tile: GeodeticTile,
    surface: &Surface<'_>,
    placement: &Placement,
    data_box: [f64; 4],
) -> Result<SampledTile> {
    const A: usize = APRON;
    let GridSample {
        lon_lat,
        mut raw,
        inside,
        owner,
    } = sample_grid(tile, surface, placement, data_box);
    // The tile's own vertices, quantized as a decoder reads them.
    let index = |i: usize, j: usize| (j + 1) * A + (i + 1);
    let mut heights = Vec::with_capacity(GRID * GRID);
    let mut vertex_inside = Vec::with_capacity(GRID * GRID);
    let mut blocks = BTreeSet::new();
    for j in 0..GRID {
        for i in 0..GRID {
            let k = index(i, j);
            heights.push(raw[k]);
            vertex_inside.push(inside[k]);
            if inside[k] {
                blocks.insert(owner[k]);
            }
        }
    }
    let (lo, hi, h) = quantized_mesh::quantize_heights(&heights);
    let heights: Vec<f64> = h
        .iter()
        .map(|&code| quantized_mesh::dequantize_height(lo, hi, code))
        .collect();
    for j in 0..GRID {
        for i in 0..GRID {
            raw[index(i, j)] = heights[j * GRID + i];
        }
    }
    let mut u = Vec::with_capacity(GRID * GRID);
    let mut v = Vec::with_capacity(GRID * GRID);
    for j in 0..GRID {
        for i in 0..GRID {
            u.push(grid_code(i));
            v.push(grid_code(j));
        }
    }
    let mut triangles = Vec::with_capacity(2 * CELLS * CELLS);
    for j in 0..CELLS {
        for i in 0..CELLS {
            let sw = (j * GRID + i) as u32;
            let (se, nw, ne) = (sw + 1, sw + GRID as u32, sw + GRID as u32 + 1);
            triangles.push([sw, se, nw]);
            triangles.push([se, ne, nw]);
        }
    }
    // ECEF positions: of the vertices for the header, of the apron too for normals.
    let ecef: Vec<[f64; 3]> = (0..A * A)
        .map(|k| geodetic::ecef(lon_lat[k][0], lon_lat[k][1], raw[k]))
        .collect();
    let mut normals = Vec::with_capacity(GRID * GRID);
    for j in 0..GRID {
        for i in 0..GRID {
            normals.push(apron_normal(&ecef, &lon_lat, index(i, j)));
        }
    }
    let points: Vec<[f64; 3]> = (0..GRID)
        .flat_map(|j| (0..GRID).map(move |i| (i, j)))
        .map(|(i, j)| ecef[index(i, j)])
        .collect();
    let header = header_of(
        &tile,
        &points,
        lo,
        hi,
        (f64::from(lo) + f64::from(hi)) / 2.0,
    );
    let (resampling, error, measured, block_error) =
        measure(
            &tile,
            |lon, lat| tile_height(&tile, &heights, lon, lat),
            surface,
            placement,
            data_box,
        );
    Ok(SampledTile {
        tile,
        data: TileData {
            header,
            u,
            v,
            h,
            triangles,
            normals: Some(normals),
            metadata: serde_json::Value::Null,
        },
        heights,
        inside: vertex_inside,
        blocks: blocks.into_iter().collect(),
        resampling,
        error,
        measured,
        block_error,
    })
}

/// The oct-encoded normal at point `k` of a tile's grid and apron (`APRON` a side): across
/// the ECEF positions `ecef` of its east and west, north and south neighbours, or the
/// ellipsoid's up where they give no direction.
pub(crate) fn apron_normal(ecef: &[[f64; 3]], lon_lat: &[[f64; 2]], k: usize) -> [u8; 2] {
    let (e, w, n, s) = (ecef[k + 1], ecef[k - 1], ecef[k + APRON], ecef[k - APRON]);
    let east = [e[0] - w[0], e[1] - w[1], e[2] - w[2]];
    let north = [n[0] - s[0], n[1] - s[1], n[2] - s[2]];
    let c = [
        east[1] * north[2] - east[2] * north[1],
        east[2] * north[0] - east[0] * north[2],
        east[0] * north[1] - east[1] * north[0],
    ];
    let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    let unit = if len > 0.0 && len.is_finite() {
        [c[0] / len, c[1] / len, c[2] / len]
    } else {
        geodetic::up(lon_lat[k][0], lon_lat[k][1])
    };
    quantized_mesh::oct_encode(unit)
}

/// The header of tile `tile` whose vertices are `points` (ECEF), heights quantized over
/// `[lo, hi]`: its centre on the tile's middle at `centre_height`, the bounding sphere of
/// the points' box centre, and the horizon occlusion point.
pub(crate) fn header_of(
    tile: &GeodeticTile,
    points: &[[f64; 3]],
    lo: f32,
    hi: f32,
    centre_height: f64,
) -> Header {
    let mut lo3 = [f64::INFINITY; 3];
    let mut hi3 = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo3[a] = lo3[a].min(p[a]);
            hi3[a] = hi3[a].max(p[a]);
        }
    }
    let sphere_centre = [
        (lo3[0] + hi3[0]) / 2.0,
        (lo3[1] + hi3[1]) / 2.0,
        (lo3[2] + hi3[2]) / 2.0,
    ];
    let radius = points
        .iter()
        .map(|p| {
            ((p[0] - sphere_centre[0]).powi(2)
                + (p[1] - sphere_centre[1]).powi(2)
                + (p[2] - sphere_centre[2]).powi(2))
            .sqrt()
        })
        .fold(0.0f64, f64::max);
    let [w, s, e, n] = tile.bounds();
    Header {
        centre: geodetic::ecef((w + e) / 2.0, (s + n) / 2.0, centre_height),
        min_height: lo,
        max_height: hi,
        sphere_centre,
        // Past the rounding of the distances above.
        sphere_radius: radius * (1.0 + 1e-12) + 1e-6,
        horizon: geodetic::horizon_occlusion_point(sphere_centre, points),
    }
}

/// The height a tile with vertex heights `heights` (row-major from the south-west) draws
/// at `(lon, lat)` inside it: linear in `(u, v)` over the triangle holding the point.
pub fn tile_height(tile: &GeodeticTile, heights: &[f64], lon: f64, lat: f64) -> f64 {
    let [w, s, e, n] = tile.bounds();
    let q = f64::from(QUANTIZED_MAX);
    let fu = ((lon - w) / (e - w) * q).clamp(0.0, q);
    let fv = ((lat - s) / (n - s) * q).clamp(0.0, q);
    let cell = |f: f64| {
        let mut i = ((f / q * CELLS as f64).floor() as usize).min(CELLS - 1);
        while i > 0 && f < f64::from(grid_code(i)) {
            i -= 1;
        }
        while i < CELLS - 1 && f > f64::from(grid_code(i + 1)) {
            i += 1;
        }
        let (a, b) = (f64::from(grid_code(i)), f64::from(grid_code(i + 1)));
        (i, ((f - a) / (b - a)).clamp(0.0, 1.0))
    };
    let (i, a) = cell(fu);
    let (j, b) = cell(fv);
    let at = |i: usize, j: usize| heights[j * GRID + i];
    let (sw, se, nw, ne) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
    if a + b <= 1.0 {
        sw + a * (se - sw) + b * (nw - sw)
    } else {
        ne + (1.0 - a) * (nw - ne) + (1.0 - b) * (se - ne)
    }
}

/// What [`Placement::lift`] gives along one parallel: the EGM96 undulation, or 0 where
/// heights are not lifted.
pub struct ParallelLift(Option<crate::geoid::Egm96Row>);

impl ParallelLift {
    /// The lift at longitude `lon` on this parallel.
    pub fn at(&self, lon: f64) -> f64 {
        self.0.as_ref().map_or(0.0, |row| row.at(lon))
    }
}

/// `(resampling, error, samples, block error)` of a tile that draws `height(lon, lat)`:
/// over the data samples inside it, the largest `|tile - surface|`, `|tile - surface| +
/// e*` and `e*`.
pub(crate) fn measure(
    tile: &GeodeticTile,
    height: impl Fn(f64, f64) -> f64,
    surface: &Surface<'_>,
    placement: &Placement,
    data_box: [f64; 4],
) -> (f64, f64, u64, f64) {
    let [w, s, e, n] = tile.bounds();
    let clip = [
        w.max(data_box[0]),
        s.max(data_box[1]),
        e.min(data_box[2]),
        n.min(data_box[3]),
    ];
    let Some(all) = surface.bounds() else {
        return (0.0, 0.0, 0, 0.0);
    };
    if !(clip[0] <= clip[2] && clip[1] <= clip[3]) {
        return (0.0, 0.0, 0, 0.0);
    }
    // The samples that may lie in the clipped box.
    let Some([c0, r0, c1, r1]) = placement.span_of(clip) else {
        return (0.0, 0.0, 0, 0.0);
    };
    let units = placement.units;
    // A projected box's edges bow between the points placed: a sample of margin.
    let margin = if placement.is_geographic() { 0.0 } else { 1.0 };
    let to_sample = |x: f64, lo: u64, hi: u64, up: bool| {
        let s = x / units;
        let s = if up {
            (s + margin).ceil()
        } else {
            (s - margin).floor()
        };
        (s.max(lo as f64 / units).min(hi as f64 / units)) as u64
    };
    let (sc0, sc1) = (
        to_sample(c0, all.col0, all.col1, false),
        to_sample(c1, all.col0, all.col1, true),
    );
    let (sr0, sr1) = (
        to_sample(r0, all.row0, all.row1, false),
        to_sample(r1, all.row0, all.row1, true),
    );
    let (mut resampling, mut error, mut measured, mut block_error) = (0.0f64, 0.0f64, 0u64, 0.0f64);
    let mut row_points = Vec::new();
    // The geoid along the last parallel asked (a geographic row shares one latitude).
    let mut lift = (f64::NAN, placement.lift_along(f64::NAN));
    for row in sr0..=sr1 {
        row_points.clear();
        row_points.extend((sc0..=sc1).map(|col| [(col as f64) * units, (row as f64) * units]));
        let placed = placement.lon_lat(&row_points);
        for (p, ll) in row_points.iter().zip(placed) {
            let Some([lon, lat]) = ll else { continue };
            if !(lon >= w && lon <= e && lat >= s && lat <= n) {
                continue;
            }
            let Some(sampled) = surface.at(p[0], p[1]) else {
                continue;
            };
            if lift.0.to_bits() != lat.to_bits() {
                lift = (lat, placement.lift_along(lat));
            }
            let d = (height(lon, lat) - (sampled.height + lift.1.at(lon))).abs();
            resampling = resampling.max(d);
            let e = surface.blocks()[sampled.block].error;
            error = error.max(d + e);
            block_error = block_error.max(e);
            measured += 1;
        }
    }
    (resampling, error, measured, block_error)
}
