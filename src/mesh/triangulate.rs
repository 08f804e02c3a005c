//! Triangles of one block: its grid's cells split along the north-west to south-east
//! diagonal, and, where an edge's vertices differ from the grid's, the ring of cells along
//! the edges triangulated again between the edge and the grid one cell in.
//!
//! The ring is four trapezoids: each edge's vertices (outer) and the grid points one cell
//! in (inner) lie on two parallel lines, and any walk that advances along one line or the
//! other, both in order, tiles the trapezoid with triangles (each has one side on a line and
//! its third corner on the other, and no two cross). The walk advances the line whose next
//! vertex comes first; on a tie it takes the turn that splits a plain cell along its
//! north-west to south-east diagonal, so a ring whose edge kept its grid points draws the
//! surface's own triangles, but for the north-east and south-west corner cells, split
//! the other way. A block one cell thick has no inner line: its outline (a rectangle with
//! vertices along its sides) is convex and is cut by clipping ears whose new side does not run
//! along the outline.

use std::collections::HashMap;

use super::{BlockMesh, MeshVertex};

/// The triangles of one block under construction.
pub(super) struct Triangles {
    cols: Vec<u64>,
    rows: Vec<u64>,
    vertices: Vec<MeshVertex>,
    /// The vertices on the block's edges, by sample.
    boundary: HashMap<(u64, u64), u32>,
    triangles: Vec<[u32; 3]>,
}

impl Triangles {
    /// A block whose grid lines are `cols` and `rows` (its own, clipped to the data), its
    /// inner grid points at the heights `height` gives.
    pub fn new(cols: Vec<u64>, rows: Vec<u64>, height: impl Fn(u64, u64) -> f64) -> Triangles {
        let mut vertices = Vec::new();
        for &row in &rows[1..rows.len() - 1] {
            for &col in &cols[1..cols.len() - 1] {
                vertices.push(MeshVertex {
                    col,
                    row,
                    height: height(col, row),
                    skirt: false,
                });
            }
        }
        Triangles {
            cols,
            rows,
            vertices,
            boundary: HashMap::new(),
            triangles: Vec::new(),
        }
    }

    /// The index of the edge vertex at `(col, row)`, added at `height(col, row)` if new.
    pub fn boundary_vertex(
        &mut self,
        col: u64,
        row: u64,
        height: &mut impl FnMut(u64, u64) -> f64,
    ) -> u32 {
        if let Some(&i) = self.boundary.get(&(col, row)) {
            return i;
        }
        let i = self.vertices.len() as u32;
        self.vertices.push(MeshVertex {
            col,
            row,
            height: height(col, row),
            skirt: false,
        });
        self.boundary.insert((col, row), i);
        i
    }

    /// The index of grid point `(i, j)` (an inner one, or one on an edge already added).
    fn grid(&self, i: usize, j: usize) -> u32 {
        let (n, m) = (self.cols.len() - 1, self.rows.len() - 1);
        if i > 0 && i < n && j > 0 && j < m {
            ((j - 1) * (n - 1) + (i - 1)) as u32
        } else {
            self.boundary[&(self.cols[i], self.rows[j])]
        }
    }

    /// Twice the signed area of `a, b, c` in samples, positive when they turn clockwise as
    /// seen from above (rows grow southwards).
    fn turn(&self, a: u32, b: u32, c: u32) -> i128 {
        let p = |i: u32| {
            let v = &self.vertices[i as usize];
            (i128::from(v.col), i128::from(v.row))
        };
        let (a, b, c) = (p(a), p(b), p(c));
        (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
    }

    /// Adds triangle `a, b, c`, counter-clockwise from above.
    fn push(&mut self, a: u32, b: u32, c: u32) {
        match self.turn(a, b, c) {
            0 => debug_assert!(false, "a degenerate triangle"),
            t if t > 0 => self.triangles.push([a, c, b]),
            _ => self.triangles.push([a, b, c]),
        }
    }

    /// Cells `i0..i1` by `j0..j1`, each split along its NW-SE diagonal.
    fn cells(&mut self, i0: usize, i1: usize, j0: usize, j1: usize) {
        for j in j0..j1 {
            for i in i0..i1 {
                let (nw, ne) = (self.grid(i, j), self.grid(i + 1, j));
                let (sw, se) = (self.grid(i, j + 1), self.grid(i + 1, j + 1));
                self.push(nw, ne, se);
                self.push(nw, se, sw);
            }
        }
    }

    /// Tiles the trapezoid between `outer` and `inner` (parallel, both in the order of
    /// `progress`), preferring the inner line on a tie when `inner_first`.
    fn zip(
        &mut self,
        outer: &[u32],
        inner: &[u32],
        progress: impl Fn(&MeshVertex) -> i128,
        inner_first: bool,
    ) {
        let at = |s: &Self, i: u32| progress(&s.vertices[i as usize]);
        let (mut i, mut j) = (0, 0);
        while i + 1 < outer.len() || j + 1 < inner.len() {
            let take_inner = j + 1 < inner.len()
                && (i + 1 == outer.len() || {
                    let (pi, po) = (at(self, inner[j + 1]), at(self, outer[i + 1]));
                    pi < po || (pi == po && inner_first)
                });
            if take_inner {
                self.push(outer[i], inner[j + 1], inner[j]);
                j += 1;
            } else {
                self.push(outer[i], outer[i + 1], inner[j]);
                i += 1;
            }
        }
    }

    /// Cuts the convex polygon `outline` (clockwise from above, with vertices along its
    /// sides) by clipping ears. An ear is a vertex that turns; it is clipped only if the new
    /// side it leaves does not run along a line of the outline's vertices (that side would
    /// pass through them, leaving them as T-junctions).
    fn clip_ears(&mut self, mut outline: Vec<u32>) {
        while outline.len() > 3 {
            let n = outline.len();
            let at = |k: usize| outline[k % n];
            let ear = (0..n).find(|&k| {
                let (prev, v, next) = (at(k + n - 1), at(k), at(k + 1));
                self.turn(prev, v, next) > 0
                    && self.turn(at(k + n - 2), prev, next) != 0
                    && self.turn(prev, next, at(k + 2)) != 0
            });
            let Some(k) = ear else {
                debug_assert!(false, "no ear to clip");
                return;
            };
            self.push(at(k + n - 1), at(k), at(k + 1));
            outline.remove(k);
        }
        if outline.len() == 3 && self.turn(outline[0], outline[1], outline[2]) != 0 {
            self.push(outline[0], outline[1], outline[2]);
        }
    }

    /// Triangulates the block whose edges' vertices are `ring` (north west to east, east
    /// north to south, south east to west, west south to north); `changed` when they are
    /// not the grid's own.
    pub fn fill(&mut self, ring: &[Vec<u32>; 4], changed: bool) {
        let (n, m) = (self.cols.len() - 1, self.rows.len() - 1);
        if !changed {
            self.cells(0, n, 0, m);
        } else if n >= 2 && m >= 2 {
            self.cells(1, n - 1, 1, m - 1);
            let north: Vec<u32> = (1..n).map(|i| self.grid(i, 1)).collect();
            let east: Vec<u32> = (1..m).map(|j| self.grid(n - 1, j)).collect();
            let south: Vec<u32> = (1..n).rev().map(|i| self.grid(i, m - 1)).collect();
            let west: Vec<u32> = (1..m).rev().map(|j| self.grid(1, j)).collect();
            self.zip(&ring[0], &north, |v| i128::from(v.col), true);
            self.zip(&ring[1], &east, |v| i128::from(v.row), false);
            self.zip(&ring[2], &south, |v| -i128::from(v.col), true);
            self.zip(&ring[3], &west, |v| -i128::from(v.row), false);
        } else {
            let mut outline = ring[0].clone();
            outline.extend(&ring[1][1..]);
            outline.extend(&ring[2][1..]);
            outline.extend(&ring[3][1..ring[3].len() - 1]);
            self.clip_ears(outline);
        }
    }

    /// The mesh of block `block`.
    pub fn finish(self, block: usize, stitched: [bool; 4]) -> BlockMesh {
        BlockMesh {
            block,
            normals: Vec::new(),
            vertices: self.vertices,
            triangles: self.triangles,
            stitched,
            skirts: [0.0; 4],
            tin_error: 0.0,
        }
    }
}
