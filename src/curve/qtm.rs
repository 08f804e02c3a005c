//! The Quaternary Triangular Mesh (QTM, seed 003; Dutton 1996): the globe as an octahedron
//! whose eight faces split recursively into four triangles, addressed by codes and ordered
//! along a curve that follows the triangle recursion.
//!
//! **Octants.** The octahedron's vertices are the two poles and the equator at longitudes 0°,
//! 90°, 180° and 270° (−90°). Octant `k` (`0..=3`) is the northern face over longitudes
//! `90k..90(k+1)` east of Greenwich (measured in `[0, 360)`); octant `4 + k` is the southern
//! face below it. A point on the equator belongs to the northern octant, one on a meridian
//! of 0°, 90°, 180° or 270° to the octant east of it (for [`QtmCell::locate`]; containment,
//! [`QtmCell::contains`], is closed, so such points lie in both).
//!
//! **Subdivision in Dutton's ZOT plane.** Each octant is mapped to the right triangle
//! `u ≥ 0, v ≥ 0, u + v ≤ 1` by Dutton's *zenithial orthotriangular* projection:
//! `u + v = t`, the colatitude from the octant's pole as a fraction of 90°, and
//! `v / (u + v) = s`, the longitude from the octant's west edge as a fraction of 90°. The
//! pole is `(0, 0)`; the octant's equator edge is `u + v = 1`. A triangle splits into four
//! by the midpoints of its edges *in this plane*, so level `L` is a regular grid: the square
//! cells of side `2^-L`, each cut along its `u + v` diagonal into an **upright** triangle
//! (the one nearer the pole, oriented as the octant) and an **inverted** one. Locating a
//! point is then two floors, at any level.
//!
//! *Where seed 003 is vague.* It says a triangle is split by averaging the latitudes and
//! longitudes of its vertices. That agrees with the ZOT split on the octant's edges and on
//! every parallel, but not inside: the midpoint of (45° N, 0°) and (0°, 45° E) is
//! (22.5° N, 22.5° E) by averaging and (22.5° N, 30° E) in the ZOT plane, and the averaged
//! split does not give triangles whose children tile them as the same four-way split (a cell
//! touching the pole is a rectangle in longitude and latitude). fmrh subdivides in the ZOT
//! plane, as Dutton's own QTM does; its cells' edges are straight in that plane, and every
//! vertex of level `L` is a vertex of all finer levels. The tests check the cells tile each
//! octant exactly and nest.
//!
//! **Codes** ([`QtmCell::code`]): the octant, then one digit per level naming the child, as
//! Dutton numbers them: `0` the central (inverted) child, `1` the corner at the cell's right
//! angle, `2` the corner along its `u` leg and `3` along its `v` leg.
//!
//! **The curve** ([`QtmCell::curve_index`]). The octants are visited in a ring, the northern
//! four eastward from 0° and the southern four westward back (`0 1 2 3 7 6 5 4`), each entered
//! and left at a vertex it shares with the octant before and after. Inside a triangle entered
//! at vertex `P` and left at `Q` (the third vertex `R`), the children are visited as a
//! Sierpiński-like curve: the corner at `P` (entered at `P`, left at the midpoint of `PQ`),
//! the centre (left at the midpoint of `PR`), the corner at `R` (left at the midpoint of
//! `QR`), the corner at `Q` (left at `Q`); each child recursively so. Consecutive cells of
//! any level therefore **share at least a vertex**, and a parent's children are one
//! contiguous run (`index >> 2` is the parent's index): a region of the globe is a few index
//! ranges. They cannot all share an *edge*: the three corners of a split touch each other
//! only at vertices and the centre meets each of them along an edge, so no order of the four
//! children steps across edges only. About two thirds of consecutive pairs share an edge
//! (the tests count them).
//!
//! This module knows nothing of heights or files: only longitudes, latitudes and cells.

use std::fmt;

/// The deepest level of a [`QtmCell`]: a cell's grid coordinates fit a `u32` and its curve
/// index (3 bits of octant, 2 a level) a `u64`.
pub const QTM_MAX_LEVEL: u8 = 30;

/// The octants in the order the curve visits them.
const RING: [u8; 8] = [0, 1, 2, 3, 7, 6, 5, 4];

/// A point of the ZOT plane at scale `2^level`, in grid units.
type Pt = (i64, i64);

/// A QTM cell: an octant and a triangle of its level-`level` grid.
///
/// `(i, j)` is the grid square (`i` along `u`, `j` along `v`); an upright cell has vertices
/// `(i, j)`, `(i + 1, j)`, `(i, j + 1)` and `i + j ≤ 2^level − 1`; an inverted one
/// `(i + 1, j + 1)`, `(i, j + 1)`, `(i + 1, j)` and `i + j ≤ 2^level − 2`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct QtmCell {
    octant: u8,
    level: u8,
    i: u32,
    j: u32,
    up: bool,
}

/// A cell's vertex in longitude and latitude (degrees; longitudes in `(-180, 180]`, the
/// poles' longitude 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LonLat {
    /// Longitude, degrees east.
    pub lon: f64,
    /// Latitude, degrees north.
    pub lat: f64,
}

/// Whether `octant` is a northern one.
fn north(octant: u8) -> bool {
    octant < 4
}

/// Longitude in `[0, 360)`.
fn lon360(lon: f64) -> f64 {
    let l = lon.rem_euclid(360.0);
    if l >= 360.0 {
        0.0
    } else {
        l
    }
}

/// `(u, v)` of `(lon, lat)` in `octant`'s ZOT frame, unit scale; `None` when the point is
/// not on that octant's face (its hemisphere or its longitudes, edges included).
fn zot(octant: u8, lon: f64, lat: f64) -> Option<(f64, f64)> {
    if !(lon.is_finite() && lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
        return None;
    }
    let t = if north(octant) {
        if lat < 0.0 {
            return None;
        }
        (90.0 - lat) / 90.0
    } else {
        if lat > 0.0 {
            return None;
        }
        (90.0 + lat) / 90.0
    };
    if t == 0.0 {
        return Some((0.0, 0.0));
    }
    let west = 90.0 * f64::from(octant % 4);
    let mut l = lon360(lon);
    // The octant east of Greenwich's antimeridian-side edge: 360° is its east edge.
    if octant % 4 == 3 && l == 0.0 {
        l = 360.0;
    }
    let s = (l - west) / 90.0;
    if !(0.0..=1.0).contains(&s) {
        return None;
    }
    Some((t * (1.0 - s), t * s))
}

impl QtmCell {
    /// Octant `octant` (`0..=7`) as a level-0 cell.
    pub fn octant_cell(octant: u8) -> Option<QtmCell> {
        QtmCell::new(octant, 0, 0, 0, true)
    }

    /// The cell of `octant` at `level` with grid square `(i, j)`, upright or inverted;
    /// `None` when that is no cell.
    pub fn new(octant: u8, level: u8, i: u32, j: u32, up: bool) -> Option<QtmCell> {
        if octant > 7 || level > QTM_MAX_LEVEL {
            return None;
        }
        let n = 1u64 << level;
        let sum = u64::from(i) + u64::from(j);
        let fits = if up { sum < n } else { sum + 1 < n };
        fits.then_some(QtmCell {
            octant,
            level,
            i,
            j,
            up,
        })
    }

    /// The octant, `0..=7`.
    pub fn octant(&self) -> u8 {
        self.octant
    }

    /// The level: 0 for an octant.
    pub fn level(&self) -> u8 {
        self.level
    }

    /// The grid square `(i, j)` and whether the cell is the upright one.
    pub fn grid(&self) -> (u32, u32, bool) {
        (self.i, self.j, self.up)
    }

    /// The cell of `level` holding the point at longitude `lon`, latitude `lat` (degrees);
    /// `None` for a non-finite point, a latitude past a pole or a level past
    /// [`QTM_MAX_LEVEL`]. Points on edges go to one cell by the rules in the module doc.
    pub fn locate(lon: f64, lat: f64, level: u8) -> Option<QtmCell> {
        if level > QTM_MAX_LEVEL || !lon.is_finite() || !(-90.0..=90.0).contains(&lat) {
            return None;
        }
        let k = ((lon360(lon) / 90.0).floor() as u8).min(3);
        let octant = if lat >= 0.0 { k } else { 4 + k };
        let (u, v) = zot(octant, lon, lat)?;
        let n = (1u64 << level) as f64;
        let (gu, gv) = (u * n, v * n);
        let last = (1u64 << level) - 1;
        let i = (gu.floor().max(0.0) as u64).min(last);
        let j = (gv.floor().max(0.0) as u64).min(last - i);
        let up = (gu - i as f64) + (gv - j as f64) <= 1.0 || i + j == last;
        QtmCell::new(octant, level, i as u32, j as u32, up)
    }

    /// The cell's vertices in the ZOT grid at its own level: the right angle, the end of the
    /// `u` leg, the end of the `v` leg.
    fn grid_vertices(&self) -> [Pt; 3] {
        let (i, j) = (i64::from(self.i), i64::from(self.j));
        if self.up {
            [(i, j), (i + 1, j), (i, j + 1)]
        } else {
            [(i + 1, j + 1), (i, j + 1), (i + 1, j)]
        }
    }

    /// The longitude and latitude of grid point `p` of this cell's octant at its level.
    fn lon_lat(&self, p: Pt) -> LonLat {
        let n = (1u64 << self.level) as f64;
        let (gu, gv) = (p.0 as f64, p.1 as f64);
        let t = (gu + gv) / n;
        let lat = 90.0 - 90.0 * t;
        let lat = if north(self.octant) { lat } else { -lat };
        if gu + gv == 0.0 {
            return LonLat { lon: 0.0, lat };
        }
        let lon = 90.0 * f64::from(self.octant % 4) + 90.0 * gv / (gu + gv);
        let lon = if lon > 180.0 { lon - 360.0 } else { lon };
        LonLat { lon, lat }
    }

    /// The cell's three vertices in longitude and latitude: the right angle, the end of the
    /// `u` leg, the end of the `v` leg.
    pub fn vertices(&self) -> [LonLat; 3] {
        self.grid_vertices().map(|p| self.lon_lat(p))
    }

    /// Whether the point at `lon`, `lat` lies in the cell, its edges included.
    pub fn contains(&self, lon: f64, lat: f64) -> bool {
        let Some((u, v)) = zot(self.octant, lon, lat) else {
            return false;
        };
        let n = (1u64 << self.level) as f64;
        let (gu, gv) = (u * n, v * n);
        let (i, j) = (f64::from(self.i), f64::from(self.j));
        // A billionth of a cell of slack for the rounding of the projection.
        let eps = 1e-9;
        if self.up {
            gu >= i - eps && gv >= j - eps && gu + gv <= i + j + 1.0 + eps
        } else {
            gu <= i + 1.0 + eps && gv <= j + 1.0 + eps && gu + gv >= i + j + 1.0 - eps
        }
    }

    /// The cell one level up; `None` for an octant.
    pub fn parent(&self) -> Option<QtmCell> {
        if self.level == 0 {
            return None;
        }
        let (pi, pj) = (self.i / 2, self.j / 2);
        let odd = (self.i % 2, self.j % 2);
        let up = if self.up {
            odd != (1, 1)
        } else {
            odd == (0, 0)
        };
        QtmCell::new(self.octant, self.level - 1, pi, pj, up)
    }

    /// The four children, by digit: `[centre, corner at the right angle, corner along u,
    /// corner along v]`; `None` at [`QTM_MAX_LEVEL`].
    pub fn children(&self) -> Option<[QtmCell; 4]> {
        if self.level >= QTM_MAX_LEVEL {
            return None;
        }
        let (i, j, l, o) = (2 * self.i, 2 * self.j, self.level + 1, self.octant);
        let c = |i, j, up| QtmCell {
            octant: o,
            level: l,
            i,
            j,
            up,
        };
        Some(if self.up {
            [
                c(i, j, false),
                c(i, j, true),
                c(i + 1, j, true),
                c(i, j + 1, true),
            ]
        } else {
            [
                c(i + 1, j + 1, true),
                c(i + 1, j + 1, false),
                c(i, j + 1, false),
                c(i + 1, j, false),
            ]
        })
    }

    /// Which child of its parent the cell is (`0..=3`, as [`QtmCell::children`] orders
    /// them); `None` for an octant.
    pub fn digit(&self) -> Option<u8> {
        let parent = self.parent()?;
        let children = parent.children()?;
        children.iter().position(|c| c == self).map(|d| d as u8)
    }

    /// The cell's code: its octant and a digit per level.
    pub fn code(&self) -> QtmCode {
        let mut digits = 0u64;
        let mut cell = *self;
        let mut shift = 0;
        while let Some(d) = cell.digit() {
            digits |= u64::from(d) << shift;
            shift += 2;
            cell = match cell.parent() {
                Some(p) => p,
                None => break,
            };
        }
        QtmCode {
            octant: self.octant,
            level: self.level,
            digits,
        }
    }

    /// The cell a code names.
    pub fn from_code(code: QtmCode) -> Option<QtmCell> {
        let mut cell = QtmCell::octant_cell(code.octant)?;
        for l in (0..code.level).rev() {
            let d = (code.digits >> (2 * u32::from(l))) & 3;
            cell = cell.children()?[d as usize];
        }
        (cell.level == code.level).then_some(cell)
    }

    /// The cell's position on the curve among the `8 · 4^level` cells of its level.
    pub fn curve_index(&self) -> u64 {
        let n = 1i64 << self.level;
        let rank = RING.iter().position(|&o| o == self.octant).unwrap_or(0) as u64;
        let (mut p, mut q) = octant_ends(self.octant, n);
        let mut r = third((0, 0), (n, 0), (0, n), p, q);
        // Three times the target's centroid: integer, strictly inside it and every ancestor.
        let [a, b, c] = self.grid_vertices();
        let target = (a.0 + b.0 + c.0, a.1 + b.1 + c.1);
        let mut index = rank;
        for _ in 0..self.level {
            let children = split(p, q, r);
            let d = children
                .iter()
                .position(|t| inside_scaled(t, target))
                .unwrap_or(0);
            index = (index << 2) | d as u64;
            (p, q, r) = children[d];
        }
        index
    }

    /// The cell at position `index` of level `level`'s curve; `None` past its end.
    pub fn from_curve_index(level: u8, index: u64) -> Option<QtmCell> {
        if level > QTM_MAX_LEVEL {
            return None;
        }
        let rank = index >> (2 * u32::from(level));
        let octant = *RING.get(usize::try_from(rank).ok()?)?;
        let n = 1i64 << level;
        let (mut p, mut q) = octant_ends(octant, n);
        let mut r = third((0, 0), (n, 0), (0, n), p, q);
        for l in (0..level).rev() {
            let d = (index >> (2 * u32::from(l))) & 3;
            (p, q, r) = split(p, q, r)[d as usize];
        }
        let i = p.0.min(q.0).min(r.0);
        let j = p.1.min(q.1).min(r.1);
        let up = [p, q, r].contains(&(i, j));
        QtmCell::new(
            octant,
            level,
            u32::try_from(i).ok()?,
            u32::try_from(j).ok()?,
            up,
        )
    }

    /// The curve indices of this cell's descendants at `level` (at least the cell's own
    /// level): one contiguous run, `start..end`.
    pub fn curve_range(&self, level: u8) -> std::ops::Range<u64> {
        let shift = 2 * u32::from(level.saturating_sub(self.level));
        let start = self.curve_index() << shift;
        start..start + (1u64 << shift)
    }
}

/// Where the curve enters and leaves `octant` (grid points at scale `n`): each octant is
/// entered at the vertex it shares with the one before it in [`RING`] and left at the one
/// it shares with the next.
fn octant_ends(octant: u8, n: i64) -> (Pt, Pt) {
    let (pole, a, b) = ((0, 0), (n, 0), (0, n));
    match octant {
        // North, eastward: 0° equator -> pole -> 180° -> pole -> 360°.
        0 => (a, pole),
        1 => (pole, b),
        2 => (a, pole),
        3 => (pole, b),
        // South, westward: 360° -> pole -> 180° -> pole -> 0°.
        7 => (b, pole),
        6 => (pole, a),
        5 => (b, pole),
        _ => (pole, a),
    }
}

/// The vertex of `{x, y, z}` that is neither `p` nor `q`.
fn third(x: Pt, y: Pt, z: Pt, p: Pt, q: Pt) -> Pt {
    [x, y, z]
        .into_iter()
        .find(|v| *v != p && *v != q)
        .unwrap_or(z)
}

/// The children of the triangle entered at `p`, left at `q` (third vertex `r`), in curve
/// order, each as (entry, exit, third). The coordinates are at the finest scale, so the
/// midpoints are exact.
fn split(p: Pt, q: Pt, r: Pt) -> [(Pt, Pt, Pt); 4] {
    let mid = |a: Pt, b: Pt| ((a.0 + b.0) / 2, (a.1 + b.1) / 2);
    let (pq, pr, qr) = (mid(p, q), mid(p, r), mid(q, r));
    [(p, pq, pr), (pq, pr, qr), (pr, qr, r), (qr, q, pq)]
}

/// Whether the point `3 · c` (given as `c3`) lies inside triangle `t` (strictly: centroids
/// never lie on an edge of a triangle of the same or a coarser level).
fn inside_scaled(t: &(Pt, Pt, Pt), c3: Pt) -> bool {
    let (a, b, c) = *t;
    let s = |p: Pt| (3 * p.0, 3 * p.1);
    let (a, b, c) = (s(a), s(b), s(c));
    let cross = |o: Pt, x: Pt, y: Pt| -> i128 {
        i128::from(x.0 - o.0) * i128::from(y.1 - o.1)
            - i128::from(x.1 - o.1) * i128::from(y.0 - o.0)
    };
    let (d1, d2, d3) = (cross(a, b, c3), cross(b, c, c3), cross(c, a, c3));
    (d1 > 0 && d2 > 0 && d3 > 0) || (d1 < 0 && d2 < 0 && d3 < 0)
}

/// A QTM code: an octant and one base-4 digit per level ([`QtmCell::code`]). Written as the
/// octant (`0..=7`) then the digits, most significant first (`"3"` an octant, `"30213"` a
/// level-4 cell of it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct QtmCode {
    octant: u8,
    level: u8,
    digits: u64,
}

impl QtmCode {
    /// The octant.
    pub fn octant(&self) -> u8 {
        self.octant
    }

    /// The number of digits after the octant.
    pub fn level(&self) -> u8 {
        self.level
    }

    /// The digit at `level` (1 the first after the octant); `None` past the code's level.
    pub fn digit(&self, level: u8) -> Option<u8> {
        (level >= 1 && level <= self.level)
            .then(|| ((self.digits >> (2 * u32::from(self.level - level))) & 3) as u8)
    }

    /// Parses the written form; `None` unless it is an octant digit `0..=7` followed by at
    /// most [`QTM_MAX_LEVEL`] digits `0..=3`.
    pub fn parse(s: &str) -> Option<QtmCode> {
        let mut chars = s.chars();
        let octant = chars.next()?.to_digit(10)?;
        if octant > 7 || s.len() > 1 + usize::from(QTM_MAX_LEVEL) {
            return None;
        }
        let mut digits = 0u64;
        let mut level = 0u8;
        for c in chars {
            let d = c.to_digit(4)?;
            digits = (digits << 2) | u64::from(d);
            level += 1;
        }
        Some(QtmCode {
            octant: octant as u8,
            level,
            digits,
        })
    }
}

impl fmt::Display for QtmCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.octant)?;
        for l in 1..=self.level {
            write!(f, "{}", self.digit(l).unwrap_or(0))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ring_enters_each_octant_where_the_last_one_left() {
        // Each octant's exit vertex is the next octant's entry, as a point on the globe.
        for w in 0..8 {
            let (a, b) = (RING[w], RING[(w + 1) % 8]);
            let ca = QtmCell::octant_cell(a).unwrap();
            let cb = QtmCell::octant_cell(b).unwrap();
            let exit = ca.lon_lat(octant_ends(a, 1).1);
            let entry = cb.lon_lat(octant_ends(b, 1).0);
            let same = (exit.lat == entry.lat)
                && (exit.lat.abs() == 90.0 || lon360(exit.lon) == lon360(entry.lon));
            assert!(same, "{a} -> {b}: {exit:?} vs {entry:?}");
        }
    }

    #[test]
    fn level_one_of_octant_zero() {
        let o = QtmCell::octant_cell(0).unwrap();
        let [centre, pole, west, east] = o.children().unwrap();
        assert_eq!(
            pole.vertices()[0],
            LonLat {
                lon: 0.0,
                lat: 90.0
            }
        );
        assert!(centre.contains(45.0, 30.0));
        assert!(west.contains(10.0, 10.0) && !west.contains(80.0, 10.0));
        assert!(east.contains(80.0, 10.0));
        assert_eq!(QtmCell::locate(45.0, 89.0, 1), Some(pole));
    }
}
