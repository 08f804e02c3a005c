//! Meshes of a scene: each block's surface as triangles, crack-free where blocks of
//! different resolutions meet.
//!
//! **The surface.** A block draws the surface of `format-spec/model.md` §4: its grid (every
//! `s`-th sample of its footprint, `s` its stride) split along each cell's north-west to
//! south-east diagonal. Meshing it as it is leaves cracks: where a block meets a coarser
//! one, its edge has vertices the coarser edge lacks, at heights off the coarser edge's
//! line (CesiumJS issues #7555, #5566 and #9798 are such cracks).
//!
//! **Stitching** ([`Cracks::Stitch`], the default) makes the meshes *conforming*: two blocks
//! that share a piece of edge have the same vertices along it, at the same heights, so the
//! triangles on either side meet edge to edge with no T-junction. For each piece of edge
//! two blocks share, the *dominant* one (the larger stride; of equal strides, the one
//! given first) gives the vertices: its grid points along the piece, and the piece's ends.
//! A finer block so drops the edge vertices its coarser neighbour lacks; a coarser block
//! gains a vertex where a much finer block's corner lies on its edge (a level difference
//! past `log2(b-1)`), and where tiles' grids are offset. A vertex's height is the surface,
//! at that point, of the dominant block of all those holding it, so every block holding it
//! draws it at the same height. The ring of cells along a changed edge is triangulated
//! again, between the edge's vertices and the grid one cell in (`triangulate`); cells off
//! the ring keep the surface's own triangles, and a block none of whose edges changed is
//! its surface exactly.
//!
//! *What the heights promise.* A vertex's height is the dominant block's surface at a sample
//! position, so it is within that block's `e*` of the source (for a valid sample): its own
//! block's error, but on an edge stitched to a coarser block, the coarser block's error.
//! Grid points along that edge are the sample's stored height in both blocks; only the
//! finer block's corners, where they lie between the coarser block's grid points, move.
//!
//! **Skirts** ([`Cracks::Skirts`]) keep every block's own surface and hang a curtain
//! below each edge that meets another block, as deep as the edge lies above the other
//! block's surface at the most, measured at every sample along it. Both surfaces are linear
//! between samples, so the curtain's foot is nowhere above the neighbour's surface, and each
//! side's curtain closes the gaps where its edge is the higher: no crack is seen from above.
//! (A bound from the errors, `e*` of both blocks, would need no measuring but fails at voids,
//! whose stand-ins no error bounds.) Skirts leave T-junctions and overlap.
//!
//! Nothing here reads a file or knows what a level or a key is: a caller hands over each
//! block's rectangle, stride and grid ([`GridBlock`]), from a scene of one file or a
//! dataset's scene across tiles, in one sample frame.

pub mod fractal;
pub mod rtin;
mod lines;
mod triangulate;

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::Result;
use crate::model::SampleRect;
use crate::scene::surface::GridBlock;
use crate::scene::TerrainFrame;
#[cfg(any(test, feature = "testing"))]
use crate::scene::WorldFrame;

use lines::Lines;
use triangulate::Triangles;

/// How a mesh closes the gaps between blocks of different resolutions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Cracks {
    /// Conforming edges: the finer side takes the coarser side's vertices (the default).
    #[default]
    Stitch,
    /// Every block its own surface, with a curtain below each edge that meets a block.
    Skirts,
}

/// A vertex of a block's mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshVertex {
    /// Sample column.
    pub col: u64,
    /// Sample row.
    pub row: u64,
    /// Height in metres, as the surface evaluates it (binary64).
    pub height: f64,
    /// A skirt's lower vertex (below the surface).
    pub skirt: bool,
}

/// One block's mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockMesh {
    /// The block's index among those given.
    pub block: usize,
    /// Its vertices.
    pub vertices: Vec<MeshVertex>,
    /// Unit normals of the surface at each vertex in the world frame's axes (east, south,
    /// up); a skirt vertex has its surface vertex's. A vertex blocks share has one normal,
    /// from the triangles of all of them.
    pub normals: Vec<[f64; 3]>,
    /// Triangles, counter-clockwise seen from above (from outside, for a skirt).
    pub triangles: Vec<[u32; 3]>,
    /// Whether an edge's vertices differ from the block's own grid (0 north, 1 east, 2
    /// south, 3 west).
    pub stitched: [bool; 4],
    /// The depth of the skirt below each edge, in metres (0: none).
    pub skirts: [f64; 4],
    /// The largest vertical distance, in metres, between the mesh and the block's grid
    /// points, measured at every grid point: 0 for a mesh of the grid itself, at most the
    /// budget for a TIN ([`build_tin_in`]).
    pub tin_error: f64,
}

/// The meshes of `blocks` (disjoint, meeting only along edges) in the world frame `frame`,
/// their cracks closed as `cracks` says; a block without area has none.
#[cfg(any(test, feature = "testing"))]
pub fn build(
    blocks: &[GridBlock<'_>],
    frame: &WorldFrame,
    cracks: Cracks,
) -> Result<Vec<BlockMesh>> {
    build_in(blocks, &TerrainFrame::Flat(*frame), cracks)
}

/// [`build`] with the samples placed by `frame`, flat or on the globe: the meshes are the
/// same (they are made in samples), only the normals are taken in `frame`'s world.
pub fn build_in(
    blocks: &[GridBlock<'_>],
    frame: &TerrainFrame,
    cracks: Cracks,
) -> Result<Vec<BlockMesh>> {
    build_with(blocks, frame, cracks, None)
}

/// [`build_in`] with each block a TIN within `budget` metres of its grid: the coarsest
/// right-triangulated irregular network ([`rtin`]) of the block's grid whose every triangle
/// is within `budget` of every grid point it holds, measured ([`BlockMesh::tin_error`]).
/// A block whose grid is not a square of `2^k` cells (one clipped at the data's edge) keeps
/// its grid's triangles.
///
/// *Cracks.* Two neighbouring TINs keep different vertices along the edge they share, so
/// the gaps are closed with skirts, measured against the neighbour's TIN: each edge hangs a
/// curtain as deep as it lies above the neighbour's edge at the most, taken at every sample
/// along it (both edges are linear between samples, so that is exact). Stitching TINs
/// edge to edge (a shared edge's vertices forced into both sides' hierarchies) is not done:
/// [`rtin`] says why a hierarchy's splits make that a matter of blocks far away.
pub fn build_tin_in(
    blocks: &[GridBlock<'_>],
    frame: &TerrainFrame,
    budget: f64,
) -> Result<Vec<BlockMesh>> {
    if !(budget >= 0.0 && budget.is_finite()) {
        return Err(crate::error::Error::InvalidArgument(format!(
            "a TIN's max error must be a finite number of metres from 0 up, not {budget}"
        )));
    }
    build_with(blocks, frame, Cracks::Skirts, Some(budget))
}

fn build_with(
    blocks: &[GridBlock<'_>],
    frame: &TerrainFrame,
    cracks: Cracks,
    tin: Option<f64>,
) -> Result<Vec<BlockMesh>> {
    for (i, b) in blocks.iter().enumerate() {
        b.check(i)?;
    }
    let with_area: Vec<usize> = (0..blocks.len())
        .filter(|&i| blocks[i].has_area())
        .collect();
    let rects: Vec<SampleRect> = with_area.iter().map(|&i| blocks[i].rect).collect();
    let lines = Lines::new(&rects);
    let inputs: Vec<GridBlock<'_>> = with_area.iter().map(|&i| blocks[i]).collect();
    let mesher = Mesher {
        blocks: &inputs,
        lines: &lines,
        cracks,
    };
    let unskirted: Vec<BlockMesh> = match tin {
        None => (0..inputs.len())
            .into_par_iter()
            .map(|i| {
                let (mut m, ring) = mesher.block(i);
                if cracks == Cracks::Skirts {
                    mesher.hang_skirts(i, &ring, &mut m);
                }
                m
            })
            .collect(),
        Some(budget) => {
            let tins: Vec<BlockMesh> = (0..inputs.len())
                .into_par_iter()
                .map(|i| mesher.tin_block(i, budget))
                .collect();
            // Skirts against the neighbours' TINs, once every TIN is cut.
            let profiles: Vec<[EdgeProfile; 4]> = tins
                .iter()
                .map(|m| std::array::from_fn(|e| EdgeProfile::of(m, &inputs[m.block].rect, e)))
                .collect();
            tins.into_par_iter()
                .map(|mut m| {
                    mesher.hang_tin_skirts(&mut m, &profiles);
                    m
                })
                .collect()
        }
    };
    let mut meshes: Vec<(BlockMesh, Vec<DVec3>)> = unskirted
        .into_par_iter()
        .map(|mut m| {
            m.block = with_area[m.block];
            let sums = face_normals(&m, frame);
            (m, sums)
        })
        .collect();
    // A vertex on a block's edge gets the normal of every triangle around it, whichever
    // block holds the triangle, so shading is as seamless as the geometry.
    let mut shared: HashMap<(u64, u64), DVec3> = HashMap::new();
    for (m, sums) in &meshes {
        for (v, n) in m.vertices.iter().zip(sums) {
            if !v.skirt && on_edge(&blocks[m.block].rect, v) {
                *shared.entry((v.col, v.row)).or_default() += *n;
            }
        }
    }
    for (m, sums) in &mut meshes {
        let rect = blocks[m.block].rect;
        let mut normals = Vec::with_capacity(m.vertices.len());
        for (v, n) in m.vertices.iter().zip(sums.iter()) {
            let sum = if on_edge(&rect, v) {
                shared.get(&(v.col, v.row)).copied().unwrap_or(*n)
            } else {
                *n
            };
            let unit = sum.try_normalize().unwrap_or(DVec3::Z);
            normals.push(unit.to_array());
        }
        m.normals = normals;
    }
    Ok(meshes.into_iter().map(|(m, _)| m).collect())
}

fn on_edge(rect: &SampleRect, v: &MeshVertex) -> bool {
    v.col == rect.col0 || v.col == rect.col1 || v.row == rect.row0 || v.row == rect.row1
}

/// The area-weighted sum of the normals of the surface triangles around each vertex (skirt
/// vertices: their surface vertex's, filled in afterwards by position).
fn face_normals(m: &BlockMesh, frame: &TerrainFrame) -> Vec<DVec3> {
    let point = |v: &MeshVertex| frame.point(v.col as f64, v.row as f64, v.height);
    let mut sums = vec![DVec3::ZERO; m.vertices.len()];
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| &m.vertices[i as usize]);
        if a.skirt || b.skirt || c.skirt {
            continue;
        }
        // Counter-clockwise from above in a frame whose y points south: the cross product
        // of the edges points down, so the upward normal is its opposite.
        let n = -(point(b) - point(a)).cross(point(c) - point(a));
        // ECEF is right-handed and east-south-up (the flat frame's axes) is not, so where
        // columns run east and rows south the product above points the other way on the
        // globe: turned over, so that normals point away from the Earth.
        let n = match frame {
            TerrainFrame::Globe(g) if g.dlon * g.dlat < 0.0 => -n,
            _ => n,
        };
        for i in t {
            sums[*i as usize] += n;
        }
    }
    let mut top: HashMap<(u64, u64), DVec3> = HashMap::new();
    for (v, n) in m.vertices.iter().zip(&sums) {
        if !v.skirt {
            top.insert((v.col, v.row), *n);
        }
    }
    for (v, n) in m.vertices.iter().zip(sums.iter_mut()) {
        if v.skirt {
            *n = top.get(&(v.col, v.row)).copied().unwrap_or(DVec3::Z);
        }
    }
    sums
}

/// The points `lo, lo + s, ...` up to `hi`, and `hi`.
fn lattice(lo: u64, hi: u64, s: u64) -> Vec<u64> {
    let mut out: Vec<u64> = (0..=(hi - lo) / s).map(|k| lo + k * s).collect();
    if out.last() != Some(&hi) {
        out.push(hi);
    }
    out
}

struct Mesher<'a, 'g> {
    blocks: &'a [GridBlock<'g>],
    lines: &'a Lines,
    cracks: Cracks,
}

impl Mesher<'_, '_> {
    /// Whether block `a` gives the vertices of an edge it shares with `b`.
    fn dominates(&self, a: usize, b: usize) -> bool {
        let (sa, sb) = (self.blocks[a].stride, self.blocks[b].stride);
        sa > sb || (sa == sb && a <= b)
    }

    /// The height every block holding sample `(col, row)` (on some block's edge) draws
    /// there: the dominant holder's surface.
    fn shared_height(&self, col: u64, row: u64, holders: &mut Vec<usize>) -> f64 {
        self.lines.holding(col, row, holders);
        let mut best: Option<usize> = None;
        for &h in holders.iter() {
            if best.is_none_or(|b| self.dominates(h, b)) {
                best = Some(h);
            }
        }
        match best {
            Some(b) => self.blocks[b].height_at(col, row),
            None => f64::NAN,
        }
    }

    /// The positions along edge `e` of block `x` (increasing), stitched: each piece shared
    /// with a block takes the dominant one's grid points; the rest keeps the block's own.
    fn edge_positions(&self, x: usize, e: usize) -> Vec<u64> {
        let b = &self.blocks[x];
        let r = &b.rect;
        let horizontal = e.is_multiple_of(2);
        let (lo, hi) = if horizontal {
            (r.col0, r.col1)
        } else {
            (r.row0, r.row1)
        };
        // A block's grid points strictly inside (a, z).
        let inside = |d: usize, a: u64, z: u64, out: &mut Vec<u64>| {
            let g = &self.blocks[d];
            let (origin, s) = if horizontal {
                (g.rect.col0, g.stride)
            } else {
                (g.rect.row0, g.stride)
            };
            let mut t = origin + ((a - origin) / s + 1) * s;
            while t < z {
                out.push(t);
                t += s;
            }
        };
        let mut out = vec![lo];
        let mut t = lo;
        if self.cracks == Cracks::Stitch {
            for span in self.lines.across(r, e) {
                if t < span.lo {
                    inside(x, t, span.lo, &mut out);
                    out.push(span.lo);
                }
                let d = if self.dominates(x, span.block) {
                    x
                } else {
                    span.block
                };
                inside(d, span.lo, span.hi, &mut out);
                out.push(span.hi);
                t = span.hi;
            }
        }
        if t < hi {
            inside(x, t, hi, &mut out);
            out.push(hi);
        }
        out.dedup();
        out
    }

    /// The mesh of block `x`, and the indices of its edges' vertices, each edge going
    /// clockwise round the block (skirts are hung by the caller).
    fn block(&self, x: usize) -> (BlockMesh, [Vec<u32>; 4]) {
        let b = &self.blocks[x];
        let r = b.rect;
        let cols = lattice(r.col0, r.col1, b.stride);
        let rows = lattice(r.row0, r.row1, b.stride);
        let edges: [Vec<u64>; 4] = std::array::from_fn(|e| self.edge_positions(x, e));
        let stitched = [
            edges[0] != cols,
            edges[1] != rows,
            edges[2] != cols,
            edges[3] != rows,
        ];
        let mut tri = Triangles::new(cols.clone(), rows.clone(), |c, rw| b.height_at(c, rw));
        // The edges' vertices, each going clockwise round the block (north west to east,
        // east north to south, south east to west, west south to north), at the heights
        // every block holding them draws.
        let mut holders = Vec::new();
        let mut height = |c: u64, rw: u64| match self.cracks {
            Cracks::Stitch => self.shared_height(c, rw, &mut holders),
            Cracks::Skirts => b.height_at(c, rw),
        };
        let ring: [Vec<u32>; 4] = std::array::from_fn(|e| {
            let mut points: Vec<(u64, u64)> = match e {
                0 => edges[0].iter().map(|&c| (c, r.row0)).collect(),
                1 => edges[1].iter().map(|&rw| (r.col1, rw)).collect(),
                2 => edges[2].iter().rev().map(|&c| (c, r.row1)).collect(),
                _ => edges[3].iter().rev().map(|&rw| (r.col0, rw)).collect(),
            };
            points.dedup();
            points
                .into_iter()
                .map(|(c, rw)| tri.boundary_vertex(c, rw, &mut height))
                .collect()
        });
        tri.fill(&ring, stitched.iter().any(|&s| s));
        (tri.finish(x, stitched), ring)
    }

    /// Block `x` as the coarsest RTIN of its grid within `budget` (its grid's own triangles
    /// where the grid is not a square of `2^k` cells), without skirts.
    fn tin_block(&self, x: usize, budget: f64) -> BlockMesh {
        let b = &self.blocks[x];
        let r = b.rect;
        let s = b.stride;
        let (across, down) = (r.col1 - r.col0, r.row1 - r.row0);
        let cells = across / s;
        let square = across == down
            && across.is_multiple_of(s)
            && cells >= 2
            && cells.is_power_of_two()
            && u64::from(b.grid_width) > cells
            && u64::from(b.grid_height) > cells;
        if !square {
            return self.block(x).0;
        }
        let (n, w) = (cells as usize, b.grid_width as usize);
        let heights: Vec<f64> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| (i, j)))
            .map(|(i, j)| f64::from(b.heights[j * w + i]))
            .collect();
        let Some(grid) = rtin::Grid::new(n, &heights) else {
            return self.block(x).0;
        };
        let tin = rtin::Rtin::new(&grid).mesh(budget);
        let tin_error = tin.max_error(&grid);
        let vertices = tin
            .vertices
            .iter()
            .map(|&[i, j]| MeshVertex {
                col: r.col0 + u64::from(i) * s,
                row: r.row0 + u64::from(j) * s,
                height: heights[j as usize * (n + 1) + i as usize],
                skirt: false,
            })
            .collect();
        BlockMesh {
            block: x,
            vertices,
            normals: Vec::new(),
            // Counter-clockwise with `i` right and `j` up is clockwise from above, where
            // rows run south: turned over.
            triangles: tin.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect(),
            stitched: [false; 4],
            skirts: [0.0; 4],
            tin_error,
        }
    }

    /// Skirts below each edge of TIN `mesh` that meets another block, as deep as its edge
    /// lies above the other block's edge (`profiles`, by block) at the most, at every
    /// sample along the piece they share.
    fn hang_tin_skirts(&self, mesh: &mut BlockMesh, profiles: &[[EdgeProfile; 4]]) {
        let x = mesh.block;
        for e in 0..4 {
            let own = &profiles[x][e];
            let mut depth = 0.0f64;
            for span in self.lines.across(&self.blocks[x].rect, e) {
                let other = &profiles[span.block][(e + 2) % 4];
                for t in span.lo..=span.hi {
                    depth = depth.max(own.height(t) - other.height(t));
                }
            }
            if depth > 0.0 && depth.is_finite() {
                hang_curtain(mesh, e, &own.clockwise(e), depth);
            }
        }
    }

    /// Skirts below each edge of block `x` that meets another block, as deep as the block's
    /// edge lies above the other's surface at the most (0: no skirt).
    fn hang_skirts(&self, x: usize, ring: &[Vec<u32>; 4], mesh: &mut BlockMesh) {
        let b = &self.blocks[x];
        for (e, edge) in ring.iter().enumerate() {
            let mut depth = 0.0f64;
            for span in self.lines.across(&b.rect, e) {
                let other = &self.blocks[span.block];
                for t in span.lo..=span.hi {
                    let (col, row) = match e {
                        0 => (t, b.rect.row0),
                        1 => (b.rect.col1, t),
                        2 => (t, b.rect.row1),
                        _ => (b.rect.col0, t),
                    };
                    depth = depth.max(b.height_at(col, row) - other.height_at(col, row));
                }
            }
            if depth > 0.0 && depth.is_finite() {
                hang_curtain(mesh, e, edge, depth);
            }
        }
    }
}

/// Hangs a curtain `depth` below edge `e` of `mesh`, whose vertices `edge` run clockwise
/// round the block.
fn hang_curtain(mesh: &mut BlockMesh, e: usize, edge: &[u32], depth: f64) {
    mesh.skirts[e] = depth;
    let first = mesh.vertices.len() as u32;
    for &i in edge {
        let top = mesh.vertices[i as usize];
        mesh.vertices.push(MeshVertex {
            height: top.height - depth,
            skirt: true,
            ..top
        });
    }
    // The edge runs clockwise round the block; (top a, top b, bottom b) and (top a,
    // bottom b, bottom a) then face away from it.
    for k in 0..edge.len().saturating_sub(1) {
        let (a, z) = (edge[k], edge[k + 1]);
        let (a2, z2) = (first + k as u32, first + k as u32 + 1);
        mesh.triangles.push([a, z, z2]);
        mesh.triangles.push([a, z2, a2]);
    }
}

/// The vertices of a mesh along one edge of its block, by position along it (columns on
/// the north and south edges, rows on the others): the edge's height, linear between them.
struct EdgeProfile {
    /// Position, height and vertex index, by position.
    points: Vec<(u64, f64, u32)>,
}

impl EdgeProfile {
    /// Edge `e` (0 north, 1 east, 2 south, 3 west) of `mesh`, whose block covers `rect`.
    fn of(mesh: &BlockMesh, rect: &SampleRect, e: usize) -> EdgeProfile {
        let mut points: Vec<(u64, f64, u32)> = mesh
            .vertices
            .iter()
            .enumerate()
            .filter(|(_, v)| !v.skirt)
            .filter_map(|(k, v)| {
                let on = match e {
                    0 => (v.row == rect.row0).then_some(v.col),
                    1 => (v.col == rect.col1).then_some(v.row),
                    2 => (v.row == rect.row1).then_some(v.col),
                    _ => (v.col == rect.col0).then_some(v.row),
                };
                on.map(|t| (t, v.height, k as u32))
            })
            .collect();
        points.sort_by_key(|p| p.0);
        points.dedup_by_key(|p| p.0);
        EdgeProfile { points }
    }

    /// The edge's height at position `t` (NaN off its ends).
    fn height(&self, t: u64) -> f64 {
        let k = self.points.partition_point(|p| p.0 < t);
        match (self.points.get(k), k.checked_sub(1).and_then(|j| self.points.get(j))) {
            (Some(&(at, h, _)), _) if at == t => h,
            (Some(&(t1, h1, _)), Some(&(t0, h0, _))) => {
                h0 + (h1 - h0) * ((t - t0) as f64 / (t1 - t0) as f64)
            }
            _ => f64::NAN,
        }
    }

    /// The edge's vertex indices going clockwise round the block when it is edge `e`.
    fn clockwise(&self, e: usize) -> Vec<u32> {
        let ordered = self.points.iter().map(|p| p.2);
        if e < 2 {
            ordered.collect()
        } else {
            ordered.rev().collect()
        }
    }
}
