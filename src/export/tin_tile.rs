//! A tile of the geographic pyramid as an error-bounded TIN: the tile's 65² grid
//! (`super::geodetic_mesh::sample_grid`) meshed by `crate::mesh::rtin` within a budget, its
//! edges shared with its four neighbours, its heights quantized so that shared vertices
//! decode to the same heights, and its error measured.
//!
//! **Edges.** Each neighbour's grid is sampled and meshed too (the same budget), and every
//! edge gets the vertices both sides put on it ([`RtinMesh::add_edge_vertices`]). A point's
//! height depends on its longitude and latitude alone, so a tile and its neighbour compute
//! the same meshes for each other, and agree on their common edge: the same vertices, at
//! the same heights. (Across levels, Cesium hangs skirts from the edge lists.)
//!
//! **Heights.** A tile quantizes heights in steps of a power of two `s` metres over
//! `[lo, lo + 32767 s]`, `lo` a multiple of `s`. Interior vertices are rounded to `s`; a
//! vertex on an edge to the coarser step of the two tiles, and a corner to the pyramid's
//! corner step `Q` ([`Quanta`]), which no tile's step exceeds: a multiple of a coarser power
//! of two is one of every finer one, so both tiles store exactly the same height there (up
//! to the rounding of a decoder's `lo + code / 32767 · (hi - lo)`, about 1e-12 m).
//!
//! **Error.** The mesh is within the budget of the grid at every grid point (and between
//! them, where the grid is linear), but for the fans an edge's added vertices make
//! (`mesh::rtin`), and the grid resamples the surface. So the error a tile reports is
//! measured: the tile as a decoder draws it (quantized heights, linear in `(u, v)` over each
//! triangle) against the surface at every data sample inside the tile, plus the `e*` of
//! the block owning the sample (`geodetic_mesh::measure`).

use super::geodetic::{self, GeodeticTile};
use super::geodetic_mesh::{self, sample_grid, GridSample, Placement, APRON, GRID};
use super::quantized_mesh::{self, TileData, QUANTIZED_MAX};
use crate::error::Result;
use crate::mesh::rtin::{Grid, Rtin, RtinMesh};
use crate::scene::surface::Surface;

/// Cells along a side of a tile's grid.
const CELLS: usize = GRID - 1;

/// The smallest step worth quantizing to, metres (a micrometre, about 2^-20).
const MIN_STEP: f64 = 1.0 / (1u64 << 20) as f64;

/// The steps a pyramid's tiles quantize heights in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quanta {
    /// The corner step `Q`: a power of two no tile's own step exceeds.
    pub corner: f64,
}

impl Quanta {
    /// The steps for a pyramid whose every height (the data's, and 0 off the data) lies in
    /// `[min, max]`.
    pub fn for_range(min: f64, max: f64) -> Quanta {
        // A tile's step covers its range plus `Q` each way in 32766 steps; with `Q` at
        // least the whole range over 32764, that step is never past `Q`. And the header
        // stores the range as binary32: a step fine enough for a flat tile would put `lo`
        // between two f32 values, so a step is never below 2^-23 of the heights' size
        // ([`f32_exact`]), nor `Q` below 2^-22 of it, which no tile's step then passes.
        let span = (max - min).abs();
        let size = min.abs().max(max.abs()) + 1.0;
        Quanta {
            corner: power_of_two_at_least(span / 32764.0)
                .max(power_of_two_at_least(size / f64::from(1u32 << 22))),
        }
    }

    /// A tile's own step and base `(s, lo)` for grid heights in `[min, max]`: `lo` and
    /// `lo + 32767 s` are exact in binary32, as the header stores them.
    fn of_tile(&self, min: f64, max: f64) -> (f64, f64) {
        let (lo_raw, hi_raw) = (min - self.corner, max + self.corner);
        let s = power_of_two_at_least((hi_raw - lo_raw) / 32766.0)
            .max(f32_exact(lo_raw.abs().max(hi_raw.abs())));
        (s, (lo_raw / s).floor() * s)
    }
}

/// The finest power-of-two step whose multiples up to `size` are all exact in binary32
/// (24 significant bits, one to spare).
fn f32_exact(size: f64) -> f64 {
    power_of_two_at_least(size / f64::from(1u32 << 23))
}

fn power_of_two_at_least(x: f64) -> f64 {
    let x = if x.is_finite() { x.max(MIN_STEP) } else { 1.0 };
    2f64.powi(x.log2().ceil() as i32)
}

/// A tile cut as a TIN, ready to write, with what it measured.
pub struct TinTile {
    /// The tile.
    #[cfg_attr(not(any(test, feature = "testing")), allow(dead_code))] // read by the tests
    pub tile: GeodeticTile,
    /// Its quantized mesh (the metadata left empty for the caller).
    pub data: TileData,
    /// `max |tile - surface|` over the data samples inside the tile (0 with none).
    pub resampling: f64,
    /// `max (|tile - surface| + e*)` over them: the tile's measured error.
    pub error: f64,
    /// Data samples measured.
    pub measured: u64,
    /// The largest `e*` of the blocks owning them.
    pub block_error: f64,
}

/// What a tile's neighbours need of it: the vertices its own mesh (before any neighbour's
/// were added) puts on each side ([`RtinMesh::edge`]), and its height step. A function of
/// the tile's grid and budget alone, so it may be kept and given back to [`tin_tile`] for
/// as long as the data and budget are the same.
#[derive(Clone, Debug, PartialEq)]
pub struct Edges {
    /// Positions along each side (`mesh::rtin`'s sides: south, east, north, west).
    pub sides: [Vec<u32>; 4],
    /// Its height step, metres.
    pub step: f64,
}

/// The tile across side `side` (0 south, 1 east, 2 north, 3 west: `mesh::rtin`'s sides
/// with `i` east and `j` north), wrapping around the antimeridian; `None` past a pole.
pub fn neighbour(t: GeodeticTile, side: usize) -> Option<GeodeticTile> {
    let columns = 2u32 << t.z;
    let rows = 1u32 << t.z;
    match side {
        0 => (t.y > 0).then(|| GeodeticTile { y: t.y - 1, ..t }),
        1 => Some(GeodeticTile {
            x: (t.x + 1) % columns,
            ..t
        }),
        2 => (t.y + 1 < rows).then(|| GeodeticTile { y: t.y + 1, ..t }),
        _ => Some(GeodeticTile {
            x: (t.x + columns - 1) % columns,
            ..t
        }),
    }
}

/// The grid of `tile` meshed within `budget`, and its heights' range.
fn meshed(
    tile: GeodeticTile,
    surface: &Surface<'_>,
    placement: &Placement,
    data_box: [f64; 4],
    budget: f64,
) -> (GridSample, Vec<f64>, RtinMesh) {
    let sample = sample_grid(tile, surface, placement, data_box);
    let heights = sample.grid_heights();
    let mesh = match Grid::new(CELLS, &heights) {
        Some(grid) => Rtin::new(&grid).mesh(budget),
        None => RtinMesh::default(), // unreachable: GRID is 2^6 + 1
    };
    (sample, heights, mesh)
}

fn range(heights: &[f64]) -> (f64, f64) {
    heights
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        })
}

/// Cuts `tile` from `surface` as a TIN within `budget` metres of its grid, its edges
/// shared with its neighbours, heights quantized by `quanta`.
pub fn tin_tile(
    tile: GeodeticTile,
    surface: &Surface<'_>,
    placement: &Placement,
    data_box: [f64; 4],
    budget: f64,
    quanta: Quanta,
    known: &dyn Fn(GeodeticTile) -> Option<Edges>,
) -> Result<(TinTile, Vec<(GeodeticTile, Edges)>)> {
    let (sample, grid, mut mesh) = meshed(tile, surface, placement, data_box, budget);
    let (min, max) = range(&grid);
    let (step, lo) = quanta.of_tile(min, max);
    let mut learnt = vec![(
        tile,
        Edges {
            sides: std::array::from_fn(|side| mesh.edge(side)),
            step,
        },
    )];
    // Each side's step: the coarser of this tile's and the neighbour's.
    let mut side_step = [step; 4];
    for (side, slot) in side_step.iter_mut().enumerate() {
        let Some(n) = neighbour(tile, side) else {
            continue;
        };
        let theirs = known(n).unwrap_or_else(|| {
            let (_, their_grid, their_mesh) = meshed(n, surface, placement, data_box, budget);
            let (tmin, tmax) = range(&their_grid);
            let e = Edges {
                sides: std::array::from_fn(|side| their_mesh.edge(side)),
                step: quanta.of_tile(tmin, tmax).0,
            };
            learnt.push((n, e.clone()));
            e
        });
        mesh.add_edge_vertices(side, &theirs.sides[(side + 2) % 4]);
        *slot = step.max(theirs.step);
    }
    let n = CELLS as u32;
    let hi = lo + f64::from(QUANTIZED_MAX) * step;
    let mut h = Vec::with_capacity(mesh.vertices.len());
    let mut heights = Vec::with_capacity(mesh.vertices.len());
    for &[i, j] in &mesh.vertices {
        let on = [j == 0, i == n, j == n, i == 0];
        let sides = on.iter().filter(|&&b| b).count();
        let q = if sides >= 2 {
            quanta.corner
        } else {
            (0..4)
                .filter(|&k| on[k])
                .map(|k| side_step[k])
                .fold(step, f64::max)
        };
        let raw = grid[j as usize * GRID + i as usize];
        let rounded = (raw / q).round() * q;
        let code = ((rounded - lo) / step)
            .round()
            .clamp(0.0, f64::from(QUANTIZED_MAX)) as u16;
        h.push(code);
        heights.push(quantized_mesh::dequantize_height(lo as f32, hi as f32, code));
    }
    let grid_code = |k: u32| geodetic_mesh::grid_code(k as usize);
    let u: Vec<u16> = mesh.vertices.iter().map(|v| grid_code(v[0])).collect();
    let v: Vec<u16> = mesh.vertices.iter().map(|v| grid_code(v[1])).collect();
    // Normals from the unquantized grid and its apron (the same at a shared vertex in
    // both tiles); positions from the heights a decoder reads.
    let ecef_apron: Vec<[f64; 3]> = (0..APRON * APRON)
        .map(|k| geodetic::ecef(sample.lon_lat[k][0], sample.lon_lat[k][1], sample.raw[k]))
        .collect();
    let normals: Vec<[u8; 2]> = mesh
        .vertices
        .iter()
        .map(|&[i, j]| {
            let k = GridSample::index(i as usize, j as usize);
            geodetic_mesh::apron_normal(&ecef_apron, &sample.lon_lat, k)
        })
        .collect();
    let points: Vec<[f64; 3]> = mesh
        .vertices
        .iter()
        .zip(&heights)
        .map(|(&[i, j], &hh)| {
            let [lon, lat] = sample.lon_lat[GridSample::index(i as usize, j as usize)];
            geodetic::ecef(lon, lat, hh)
        })
        .collect();
    let (vlo, vhi) = range(&heights);
    let header = geodetic_mesh::header_of(&tile, &points, lo as f32, hi as f32, (vlo + vhi) / 2.0);
    let locate = Locator::new(&u, &v, &mesh.triangles);
    let (resampling, error, measured, block_error) = geodetic_mesh::measure(
        &tile,
        |lon, lat| locate.height(&tile, &u, &v, &heights, &mesh.triangles, lon, lat),
        surface,
        placement,
        data_box,
    );
    Ok((
        TinTile {
        tile,
        data: TileData {
            header,
            u,
            v,
            h,
            triangles: mesh.triangles,
            normals: Some(normals),
            metadata: serde_json::Value::Null,
        },
        resampling,
        error,
        measured,
        block_error,
    },
        learnt,
    ))
}

/// Which triangles may hold a point: buckets of a 64 × 64 grid over `(u, v)`; and, for the
/// row of points last asked (one `v`: a geographic row of samples), the TIN cut along it.
struct Locator {
    buckets: Vec<Vec<u32>>,
    /// The triangle the last point was in: the next point (along a row of samples) is
    /// most often in it too.
    last: std::cell::Cell<u32>,
    /// The TIN along the line `v` last asked: a measurement asks every sample of a row in
    /// turn, and one cut of the row's triangles answers them all by a walk, where finding
    /// each point's triangle costs tens of barycentric tests.
    row: std::cell::RefCell<Row>,
}

/// The TIN along one line `v = const`: the pieces the triangles it crosses cut it into, in
/// order of `u`, each linear in `u`.
#[derive(Default)]
struct Row {
    v: Option<f64>,
    spans: Vec<Span>,
    /// The span the last point was in.
    at: usize,
}

/// One triangle's piece of a row: from `u0` (height `h0`) to `u1`, rising `slope` per
/// unit of `u`.
#[derive(Clone, Copy)]
struct Span {
    u0: f64,
    u1: f64,
    h0: f64,
    slope: f64,
}

impl Span {
    fn holds(&self, fu: f64) -> bool {
        self.u0 <= fu && fu <= self.u1
    }
}

const BUCKETS: usize = 64;

impl Locator {
    fn new(u: &[u16], v: &[u16], triangles: &[[u32; 3]]) -> Locator {
        let mut buckets = vec![Vec::new(); BUCKETS * BUCKETS];
        let cell = |c: u16| (usize::from(c) * BUCKETS / (usize::from(QUANTIZED_MAX) + 1)).min(BUCKETS - 1);
        for (k, t) in triangles.iter().enumerate() {
            let us = t.map(|i| u[i as usize]);
            let vs = t.map(|i| v[i as usize]);
            let (i0, i1) = (cell(*us.iter().min().unwrap_or(&0)), cell(*us.iter().max().unwrap_or(&0)));
            let (j0, j1) = (cell(*vs.iter().min().unwrap_or(&0)), cell(*vs.iter().max().unwrap_or(&0)));
            for j in j0..=j1 {
                for i in i0..=i1 {
                    buckets[j * BUCKETS + i].push(k as u32);
                }
            }
        }
        Locator {
            buckets,
            last: std::cell::Cell::new(0),
            row: std::cell::RefCell::new(Row::default()),
        }
    }

    /// The pieces of the line `v = fv` in the triangles the buckets of its row hold,
    /// sorted by `u`. The mesh is conforming, so they meet end to end; a triangle that the
    /// line only touches at a point gives none.
    fn cut_row(
        &self,
        fv: f64,
        u: &[u16],
        v: &[u16],
        heights: &[f64],
        triangles: &[[u32; 3]],
    ) -> Vec<Span> {
        let q = f64::from(QUANTIZED_MAX);
        let j = ((fv / (q + 1.0) * BUCKETS as f64) as usize).min(BUCKETS - 1);
        let mut ks: Vec<u32> = self.buckets[j * BUCKETS..(j + 1) * BUCKETS]
            .iter()
            .flatten()
            .copied()
            .collect();
        ks.sort_unstable();
        ks.dedup();
        let mut spans = Vec::with_capacity(ks.len());
        for k in ks {
            let Some(t) = triangles.get(k as usize) else {
                continue;
            };
            let p = t.map(|i| {
                (
                    f64::from(u[i as usize]),
                    f64::from(v[i as usize]),
                    heights[i as usize],
                )
            });
            let (mut lo, mut hi) = ((f64::INFINITY, 0.0), (f64::NEG_INFINITY, 0.0));
            for (a, b) in [(p[0], p[1]), (p[1], p[2]), (p[2], p[0])] {
                let mut meet = |x: f64, h: f64| {
                    if x < lo.0 {
                        lo = (x, h);
                    }
                    if x > hi.0 {
                        hi = (x, h);
                    }
                };
                if a.1 == fv {
                    meet(a.0, a.2);
                }
                if (a.1 < fv && fv < b.1) || (b.1 < fv && fv < a.1) {
                    let t = (fv - a.1) / (b.1 - a.1);
                    meet(a.0 + t * (b.0 - a.0), a.2 + t * (b.2 - a.2));
                }
            }
            if lo.0 < hi.0 {
                spans.push(Span {
                    u0: lo.0,
                    u1: hi.0,
                    h0: lo.1,
                    slope: (hi.1 - lo.1) / (hi.0 - lo.0),
                });
            }
        }
        spans.sort_by(|a, b| a.u0.total_cmp(&b.u0));
        spans
    }

    /// The height the tile draws at `(lon, lat)`: linear in `(u, v)` over the triangle
    /// holding it (the nearest by barycentric margin, for a point on a shared edge).
    #[allow(clippy::too_many_arguments)]
    fn height(
        &self,
        tile: &GeodeticTile,
        u: &[u16],
        v: &[u16],
        heights: &[f64],
        triangles: &[[u32; 3]],
        lon: f64,
        lat: f64,
    ) -> f64 {
        let [w, s, e, n] = tile.bounds();
        let q = f64::from(QUANTIZED_MAX);
        let fu = ((lon - w) / (e - w) * q).clamp(0.0, q);
        let fv = ((lat - s) / (n - s) * q).clamp(0.0, q);
        self.along_row(fu, fv, u, v, heights, triangles)
            .unwrap_or_else(|| self.search(fu, fv, u, v, heights, triangles))
    }

    /// The height at `(fu, fv)` from the cut of the row `v = fv` (made when the row
    /// changes): the span holding `fu`, from the last one on. `None` when no span holds
    /// it (a point the row's triangles only touch).
    fn along_row(
        &self,
        fu: f64,
        fv: f64,
        u: &[u16],
        v: &[u16],
        heights: &[f64],
        triangles: &[[u32; 3]],
    ) -> Option<f64> {
        let mut row = self.row.borrow_mut();
        if row.v.map(f64::to_bits) != Some(fv.to_bits()) {
            row.spans = self.cut_row(fv, u, v, heights, triangles);
            row.v = Some(fv);
            row.at = 0;
        }
        let found = match row.spans.get(row.at) {
            Some(span) if span.holds(fu) => Some(row.at),
            _ => {
                let i = row.spans.partition_point(|span| span.u0 <= fu);
                i.checked_sub(1).filter(|&i| row.spans[i].holds(fu))
            }
        };
        let i = found?;
        row.at = i;
        let span = row.spans[i];
        Some(span.h0 + (fu - span.u0) * span.slope)
    }

    /// The height at `(fu, fv)` by finding its triangle: the first of the bucket's that
    /// holds it, else the nearest by barycentric margin.
    fn search(
        &self,
        fu: f64,
        fv: f64,
        u: &[u16],
        v: &[u16],
        heights: &[f64],
        triangles: &[[u32; 3]],
    ) -> f64 {
        let q = f64::from(QUANTIZED_MAX);
        let cell = |f: f64| ((f / (q + 1.0) * BUCKETS as f64) as usize).min(BUCKETS - 1);
        let mut best: Option<(f64, f64)> = None;
        let hint = self.last.get();
        let bucket = &self.buckets[cell(fv) * BUCKETS + cell(fu)];
        for &k in std::iter::once(&hint).chain(bucket) {
            if k as usize >= triangles.len() {
                continue;
            }
            let t = triangles[k as usize];
            let p = t.map(|i| [f64::from(u[i as usize]), f64::from(v[i as usize])]);
            let area = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
            if area == 0.0 {
                continue;
            }
            let bary = |a: [f64; 2], b: [f64; 2]| {
                ((b[0] - a[0]) * (fv - a[1]) - (b[1] - a[1]) * (fu - a[0])) / area
            };
            let (l0, l1, l2) = (bary(p[1], p[2]), bary(p[2], p[0]), bary(p[0], p[1]));
            let margin = l0.min(l1).min(l2);
            let value = l0 * heights[t[0] as usize]
                + l1 * heights[t[1] as usize]
                + l2 * heights[t[2] as usize];
            if best.is_none_or(|(m, _)| margin > m) {
                best = Some((margin, value));
            }
            if margin >= 0.0 {
                self.last.set(k);
                break;
            }
        }
        best.map_or(f64::INFINITY, |(_, value)| value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Walking a row's cut gives the height finding each point's triangle gives, on
        /// RTINs of random grids at random budgets: at random points, at rows through
        /// vertices, and at the edges of the tile.
        #[test]
        fn a_row_walk_draws_what_the_triangle_search_draws(
            k in 1u32..5,
            seed in any::<u64>(),
            budget in 0.0f64..30.0,
            rows in proptest::collection::vec((0.0f64..=1.0, any::<bool>()), 1..12),
            cols in proptest::collection::vec(0.0f64..=1.0, 1..40),
        ) {
            let n = 1usize << k;
            let mut x = seed | 1;
            let heights: Vec<f64> = (0..(n + 1) * (n + 1))
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    (x % 10_000) as f64 / 100.0
                })
                .collect();
            let grid = crate::mesh::rtin::Grid::new(n, &heights).unwrap();
            let mesh = crate::mesh::rtin::Rtin::new(&grid).mesh(budget);
            let q = f64::from(QUANTIZED_MAX);
            let scale = |i: u32| (f64::from(i) * q / n as f64).round() as u16;
            let u: Vec<u16> = mesh.vertices.iter().map(|p| scale(p[0])).collect();
            let v: Vec<u16> = mesh.vertices.iter().map(|p| scale(p[1])).collect();
            let h: Vec<f64> = mesh
                .vertices
                .iter()
                .map(|p| heights[p[1] as usize * (n + 1) + p[0] as usize])
                .collect();
            let locate = Locator::new(&u, &v, &mesh.triangles);
            let mut walked = 0;
            for &(fv, on_vertex) in &rows {
                // A row through a line of vertices, or anywhere.
                let fv = if on_vertex { f64::from(scale((fv * n as f64).round() as u32)) } else { fv * q };
                let mut fus: Vec<f64> = cols.iter().map(|c| c * q).chain([0.0, q]).collect();
                fus.sort_by(f64::total_cmp);
                for fu in fus {
                    let searched = locate.search(fu, fv, &u, &v, &h, &mesh.triangles);
                    if let Some(along) = locate.along_row(fu, fv, &u, &v, &h, &mesh.triangles) {
                        walked += 1;
                        prop_assert!(
                            (along - searched).abs() <= 1e-9 * (1.0 + searched.abs()),
                            "at ({}, {}): the row gives {} where the triangle gives {}", fu, fv, along, searched
                        );
                    }
                }
            }
            // Every point of a row is in some span (the spans tile the row).
            prop_assert_eq!(walked, rows.len() * (cols.len() + 2));
        }
    }

    /// Regression (found by `tests/tin_tiles.rs`): a flat tile at 500 m got a step of
    /// 2^-20 m, and a base the binary32 header could not hold, so two tiles decoded a
    /// shared vertex 2e-6 m apart. Every tile's base and top are now exact in binary32,
    /// and no tile's step passes the corner step.
    #[test]
    fn tile_ranges_are_exact_in_binary32() {
        for (gmin, gmax) in [(0.0, 500.0), (-110.0, 8938.0), (10.0, 500.0), (-1e6, 1e6)] {
            let q = Quanta::for_range(gmin, gmax);
            for (min, max) in [(500.0, 500.0), (gmin, gmin), (gmax, gmax), (gmin, gmax)] {
                let (s, lo) = q.of_tile(min, max);
                let hi = lo + f64::from(QUANTIZED_MAX) * s;
                assert_eq!(f64::from(lo as f32), lo, "{min}..{max} in {gmin}..{gmax}");
                assert_eq!(f64::from(hi as f32), hi, "{min}..{max} in {gmin}..{gmax}");
                assert!(lo <= min - q.corner && hi >= max + q.corner);
                assert!(s <= q.corner, "step {s} past the corner step {}", q.corner);
            }
        }
    }
}
