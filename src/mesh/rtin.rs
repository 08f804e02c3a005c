//! A right-triangulated irregular network (RTIN) over a square grid of heights, within an
//! error budget, and the edges two neighbouring grids agree on.
//!
//! **The hierarchy.** A square of `cells × cells` grid cells (`cells` a power of two) is cut
//! along a diagonal into two right isosceles triangles; a triangle is split by the line
//! from its right angle to the midpoint of its hypotenuse into two halves like it, down to
//! triangles whose legs are one cell (Evans, Kirkpatrick & Townsend 2001, in the order of
//! mapbox/martini). A mesh is a set of leaves of this hierarchy. It is *conforming* (no
//! vertex of one triangle lies inside another's edge) when a triangle is split exactly when
//! the triangle across its hypotenuse (its *diamond* partner) is.
//!
//! **Errors that are exact.** A triangle's error here is the largest vertical distance
//! between the plane through its three corners and every grid point in it (closed), not
//! martini's estimate from hypotenuse midpoints alone, which misses a peak inside a
//! triangle. The error of a split point (a hypotenuse midpoint) is the largest error of
//! both triangles of its diamond and of every split point below them; a triangle is split
//! when the error of its split point passes the budget. So a triangle that is not split is
//! within the budget at every grid point it holds, the split errors never decrease up the
//! hierarchy, and the mesh is conforming. It is linear over each finest triangle of the
//! full grid (legs one cell), as the grid's own surface is, so the budget holds between
//! grid points too.
//!
//! **Edges two grids agree on.** In a hierarchy, a split anywhere can force splits far
//! away (through diamonds, and through them across the grid's edge into the next grid and
//! beyond), so two grids meshed on their own do not in general put the same vertices on
//! the edge they share, and a rule that made them agree would have to look several grids
//! away. Instead each grid is meshed on its own ([`Rtin::mesh`]), and then every edge gets
//! the union of both sides' vertices on it ([`RtinMesh::add_edge_vertices`]): a vertex the
//! other side needs is added to the one triangle of this side that has the edge's piece
//! holding it, which becomes a fan. Both grids then have the same vertices on the shared
//! edge, at the same heights (the grids' own there), with no T-junction. A fan's planes
//! take true heights at the new vertices, so a fan triangle is within twice the budget of
//! the grid; callers measure what they report.
//!
//! Nothing here knows tiles, longitudes or files: grid coordinates `(i, j)` with `i`
//! along a row and `j` across rows, and heights in any unit.

/// The sides of a grid, in the order [`RtinMesh::edge`] numbers them: `j = 0`, `i = cells`,
/// `j = cells`, `i = 0`.
pub const SIDES: usize = 4;

/// Heights over a `cells × cells` grid: `(cells + 1)²` values, row-major, grid point
/// `(i, j)` at index `j·(cells + 1) + i`.
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    cells: usize,
    heights: &'a [f64],
}

impl<'a> Grid<'a> {
    /// The grid `cells` a side; `None` unless `cells` is a power of two from 2 up and
    /// `heights` holds `(cells + 1)²` values.
    pub fn new(cells: usize, heights: &'a [f64]) -> Option<Grid<'a>> {
        (cells >= 2 && cells.is_power_of_two() && heights.len() == (cells + 1) * (cells + 1))
            .then_some(Grid { cells, heights })
    }

    fn at(&self, p: [i32; 2]) -> f64 {
        self.heights[p[1] as usize * (self.cells + 1) + p[0] as usize]
    }
}

/// A triangle of the hierarchy: hypotenuse `a`–`b`, right angle at `c`, in grid
/// coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Triangle {
    a: [i32; 2],
    b: [i32; 2],
    c: [i32; 2],
}

impl Triangle {
    /// The grid's two halves, the roots of the hierarchy.
    fn roots(cells: usize) -> [Triangle; 2] {
        let n = cells as i32;
        [
            Triangle {
                a: [0, 0],
                b: [n, n],
                c: [n, 0],
            },
            Triangle {
                a: [n, n],
                b: [0, 0],
                c: [0, n],
            },
        ]
    }

    /// The midpoint of its hypotenuse, where it splits; `None` for a triangle with legs of
    /// one cell (its hypotenuse is a cell's diagonal, with no grid point in the middle).
    fn split_point(&self) -> Option<[i32; 2]> {
        let (sx, sy) = (self.a[0] + self.b[0], self.a[1] + self.b[1]);
        (sx % 2 == 0 && sy % 2 == 0).then_some([sx / 2, sy / 2])
    }

    /// Its two halves (mapbox/martini's order).
    fn children(&self, m: [i32; 2]) -> [Triangle; 2] {
        [
            Triangle {
                a: self.c,
                b: self.a,
                c: m,
            },
            Triangle {
                a: self.b,
                b: self.c,
                c: m,
            },
        ]
    }

    /// The largest `|height - plane|` over the grid points in the closed triangle, the
    /// plane through its corners' heights; infinite where a height is NaN.
    fn error(&self, grid: &Grid<'_>) -> f64 {
        plane_error(grid, [self.a, self.b, self.c])
    }
}

/// The largest `|height - plane|` over the grid points in the closed triangle `corners`,
/// the plane through the corners' heights; infinite where a height is NaN.
fn plane_error(grid: &Grid<'_>, corners: [[i32; 2]; 3]) -> f64 {
    let [a, b, c] = corners.map(|p| [i64::from(p[0]), i64::from(p[1])]);
    let area = cross(a, b, c);
    if area == 0 {
        return 0.0;
    }
    let [ha, hb, hc] = corners.map(|p| grid.at(p));
    let (x0, x1) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
    let (y0, y1) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
    let inv = 1.0 / area as f64;
    let mut worst = 0.0f64;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = [x, y];
            let (wa, wb, wc) = (cross(b, c, p), cross(c, a, p), cross(a, b, p));
            let inside = if area > 0 {
                wa >= 0 && wb >= 0 && wc >= 0
            } else {
                wa <= 0 && wb <= 0 && wc <= 0
            };
            if !inside {
                continue;
            }
            let plane = (wa as f64 * ha + wb as f64 * hb + wc as f64 * hc) * inv;
            let d = (grid.at([x as i32, y as i32]) - plane).abs();
            // NaN (a hole in what the caller gave) must split, never pass.
            worst = if d.is_nan() { f64::INFINITY } else { worst.max(d) };
        }
    }
    worst
}

/// Twice the signed area of `o, p, q`: positive when they turn counter-clockwise (`i`
/// right, `j` up).
fn cross(o: [i64; 2], p: [i64; 2], q: [i64; 2]) -> i64 {
    (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])
}

/// The split errors of a grid ([`Rtin::new`]), from which meshes within any budget are cut.
#[derive(Clone, Debug)]
pub struct Rtin {
    cells: usize,
    /// The error of each split point, over the grid (0 where none).
    errors: Vec<f64>,
}

/// A mesh cut from an [`Rtin`]: vertices in grid coordinates (`0..=cells` each way), each
/// once, and triangles over them, each counter-clockwise with `i` right and `j` up.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RtinMesh {
    /// Cells along a side of the grid it was cut from.
    pub cells: u32,
    pub vertices: Vec<[u32; 2]>,
    pub triangles: Vec<[u32; 3]>,
}

impl Rtin {
    /// The split errors of `grid`.
    pub fn new(grid: &Grid<'_>) -> Rtin {
        let side = grid.cells + 1;
        // Every triangle with a split point, level by level from the roots.
        let mut levels: Vec<Vec<Triangle>> = vec![Triangle::roots(grid.cells).to_vec()];
        loop {
            let next: Vec<Triangle> = levels[levels.len() - 1]
                .iter()
                .filter_map(|t| Some(t.children(t.split_point()?)))
                .flatten()
                .filter(|t| t.split_point().is_some())
                .collect();
            if next.is_empty() {
                break;
            }
            levels.push(next);
        }
        let index = |p: [i32; 2]| p[1] as usize * side + p[0] as usize;
        let mut errors = vec![0.0f64; side * side];
        // Smallest first, so that a triangle's children's split errors are complete (both
        // triangles of their diamonds counted) when it takes them.
        for level in levels.iter().rev() {
            for t in level {
                let Some(m) = t.split_point() else { continue };
                let mut e = t.error(grid);
                for child in t.children(m) {
                    if let Some(cm) = child.split_point() {
                        e = e.max(errors[index(cm)]);
                    }
                }
                let slot = &mut errors[index(m)];
                *slot = slot.max(e);
            }
        }
        Rtin {
            cells: grid.cells,
            errors,
        }
    }

    /// The coarsest mesh of the hierarchy whose every triangle is within `budget` of every
    /// grid point it holds (a budget below 0, or NaN, keeps every grid point).
    pub fn mesh(&self, budget: f64) -> RtinMesh {
        let side = self.cells + 1;
        let mut mesh = RtinMesh {
            cells: self.cells as u32,
            ..RtinMesh::default()
        };
        let mut numbers = vec![u32::MAX; side * side];
        let mut stack = Triangle::roots(self.cells).to_vec();
        while let Some(t) = stack.pop() {
            if let Some(m) = t.split_point() {
                let e = self.errors[m[1] as usize * side + m[0] as usize];
                // NaN budgets and errors split: only a known error within budget stops.
                let within = e <= budget;
                if !within {
                    stack.extend(t.children(m));
                    continue;
                }
            }
            let mut corner = |p: [i32; 2]| {
                let slot = &mut numbers[p[1] as usize * side + p[0] as usize];
                if *slot == u32::MAX {
                    mesh.vertices.push([p[0] as u32, p[1] as u32]);
                    *slot = (mesh.vertices.len() - 1) as u32;
                }
                *slot
            };
            let (a, b, c) = (corner(t.a), corner(t.b), corner(t.c));
            let turn = cross(
                [i64::from(t.a[0]), i64::from(t.a[1])],
                [i64::from(t.b[0]), i64::from(t.b[1])],
                [i64::from(t.c[0]), i64::from(t.c[1])],
            );
            mesh.triangles
                .push(if turn > 0 { [a, b, c] } else { [a, c, b] });
        }
        mesh
    }
}

impl RtinMesh {
    /// The largest vertical distance between the mesh and `grid` (the grid it was cut
    /// from) at any grid point, each taken against the plane of a triangle holding it:
    /// measured afresh, not read from the split errors.
    pub fn max_error(&self, grid: &Grid<'_>) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let corners =
                    t.map(|i| self.vertices[i as usize]).map(|[i, j]| [i as i32, j as i32]);
                plane_error(grid, corners)
            })
            .fold(0.0, f64::max)
    }

    /// Where a vertex lies along side `side` ([`SIDES`]), if it lies on it.
    fn along(&self, side: usize, v: [u32; 2]) -> Option<u32> {
        let n = self.cells;
        match side {
            0 => (v[1] == 0).then_some(v[0]),
            1 => (v[0] == n).then_some(v[1]),
            2 => (v[1] == n).then_some(v[0]),
            3 => (v[0] == 0).then_some(v[1]),
            _ => None,
        }
    }

    /// The positions along side `side` ([`SIDES`]: `i` on the sides `j = 0` and `j =
    /// cells`, `j` on the others) of the mesh's vertices on it, ascending.
    pub fn edge(&self, side: usize) -> Vec<u32> {
        let mut out: Vec<u32> = self
            .vertices
            .iter()
            .filter_map(|&v| self.along(side, v))
            .collect();
        out.sort_unstable();
        out
    }

    /// Adds the vertices at `positions` along side `side` that the mesh lacks (positions
    /// past the side are ignored): each goes into the triangle with the piece of the side
    /// holding it, which is split in two, so that triangles grow into a fan. The mesh stays
    /// conforming: the side is the grid's boundary, where no other triangle is.
    pub fn add_edge_vertices(&mut self, side: usize, positions: &[u32]) {
        let n = self.cells;
        let point = |p: u32| match side {
            0 => [p, 0],
            1 => [n, p],
            2 => [p, n],
            _ => [0, p],
        };
        let have: std::collections::BTreeSet<u32> = self.edge(side).into_iter().collect();
        for &p in positions {
            if p > n || have.contains(&p) || side >= SIDES {
                continue;
            }
            // The triangle with an edge along the side spanning `p`.
            let found = self.triangles.iter().enumerate().find_map(|(k, t)| {
                (0..3).find_map(|e| {
                    let (x, y) = (t[e], t[(e + 1) % 3]);
                    let (px, py) = (
                        self.along(side, self.vertices[x as usize])?,
                        self.along(side, self.vertices[y as usize])?,
                    );
                    (px.min(py) < p && p < px.max(py)).then_some((k, e))
                })
            });
            let Some((k, e)) = found else { continue };
            self.vertices.push(point(p));
            let new = (self.vertices.len() - 1) as u32;
            let t = self.triangles[k];
            let (x, y, z) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
            // `x, y, z` counter-clockwise with `x-y` on the side: `x, new, z` and `new, y, z`
            // keep the turn.
            self.triangles[k] = [x, new, z];
            self.triangles.push([new, y, z]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_of(cells: usize, f: impl Fn(usize, usize) -> f64) -> Vec<f64> {
        (0..=cells)
            .flat_map(|j| (0..=cells).map(move |i| (i, j)))
            .map(|(i, j)| f(i, j))
            .collect()
    }

    #[test]
    fn a_plane_is_two_triangles() {
        let heights = grid_of(16, |i, j| 3.0 * i as f64 - 2.0 * j as f64);
        let mesh = Rtin::new(&Grid::new(16, &heights).unwrap()).mesh(1e-9);
        assert_eq!(mesh.triangles.len(), 2);
        assert_eq!(mesh.vertices.len(), 4);
    }

    #[test]
    fn a_negative_budget_keeps_every_point() {
        let heights = grid_of(8, |i, j| ((i * 7 + j * 13) % 5) as f64);
        let mesh = Rtin::new(&Grid::new(8, &heights).unwrap()).mesh(-1.0);
        assert_eq!(mesh.vertices.len(), 81);
        assert_eq!(mesh.triangles.len(), 128);
    }

    #[test]
    fn a_nan_is_never_within_budget() {
        let heights = grid_of(8, |i, j| if (i, j) == (3, 5) { f64::NAN } else { 0.0 });
        let mesh = Rtin::new(&Grid::new(8, &heights).unwrap()).mesh(1e9);
        assert!(mesh.vertices.contains(&[3, 5]));
    }

    /// A single spike inside a big triangle, not at any hypotenuse midpoint: martini's
    /// estimate, which looks at midpoints only, would miss it at the top levels.
    #[test]
    fn a_peak_off_every_midpoint_is_found() {
        let heights = grid_of(16, |i, j| if (i, j) == (11, 3) { 10.0 } else { 0.0 });
        let mesh = Rtin::new(&Grid::new(16, &heights).unwrap()).mesh(1.0);
        assert!(mesh.vertices.contains(&[11, 3]));
    }

    #[test]
    fn edge_vertices_are_added_as_fans() {
        let heights = grid_of(8, |_, _| 0.0);
        let mut mesh = Rtin::new(&Grid::new(8, &heights).unwrap()).mesh(0.5);
        assert_eq!(mesh.edge(0), vec![0, 8]);
        mesh.add_edge_vertices(0, &[2, 4, 5]);
        assert_eq!(mesh.edge(0), vec![0, 2, 4, 5, 8]);
        assert_eq!(mesh.triangles.len(), 5);
    }
}
