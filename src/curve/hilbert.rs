//! The Hilbert curve, as seed 000 §4 builds it: four pattern types and four production rules.
//!
//! A Hilbert pattern visits the four quadrants of a square in one of four orientations, the
//! paper's types I–IV. Each quadrant is itself filled by a pattern whose type the *production
//! rules* give:
//!
//! ```text
//!   Rule 1   I  ->  III  I   I   IV        type I   visits  NW, SW, SE, NE
//!   Rule 2   II ->  IV   II  II  III       type II  visits  SE, NE, NW, SW
//!   Rule 3   III->  I    III III II        type III visits  NW, NE, SE, SW
//!   Rule 4   IV ->  II   IV  IV  I         type IV  visits  SE, SW, NW, NE
//! ```
//!
//! (`x` grows east and `y` grows south, so "SW" is quadrant `(0, 1)`.) Type I is the identity
//! orientation; III is its transpose (swap x and y), IV its anti-transpose and II its half
//! turn. These four transforms form the Klein group, which is why the rules close. The paper
//! leaves the root's type to be deduced from the data. fmrh fixes it: **the root is type I**,
//! so the curve starts in the north-west block and ends in the north-east one.
//!
//! The rules are a state machine: the state is the current type, and each level of the tree
//! turns one quadrant into one base-4 digit of the index and a next state. [`hilbert_encode`] and
//! [`hilbert_decode`] run that machine four levels at a time through two 1024-entry tables
//! (2 KiB each) built at compile time, so a key costs `ceil(order / 4)` table look-ups. It uses
//! no recursion and no per-bit branches.
//!
//! The curve is *prefix-consistent*: the index of a cell at order `n` shifted right by two bits
//! is the index of its parent cell at order `n - 1`. So a quadtree node covers one contiguous run
//! of the finest-level curve, and its [`HilbertKey`] is the first index of that run.

/// The paper's four Hilbert pattern types (seed 000 §4.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HilbertType {
    /// The identity orientation: NW, SW, SE, NE.
    I,
    /// Half turn of I: SE, NE, NW, SW.
    II,
    /// Transpose of I: NW, NE, SE, SW.
    III,
    /// Anti-transpose of I: SE, SW, NW, NE.
    IV,
}

impl HilbertType {
    /// The four types, in the order of their numbering.
    pub const ALL: [HilbertType; 4] = [
        HilbertType::I,
        HilbertType::II,
        HilbertType::III,
        HilbertType::IV,
    ];

    /// The quadrants `(dx, dy)` in visiting order (`dx = 1`: east half, `dy = 1`: south half).
    pub const fn quadrant_order(self) -> [(u8, u8); 4] {
        match self {
            HilbertType::I => [(0, 0), (0, 1), (1, 1), (1, 0)],
            HilbertType::II => [(1, 1), (1, 0), (0, 0), (0, 1)],
            HilbertType::III => [(0, 0), (1, 0), (1, 1), (0, 1)],
            HilbertType::IV => [(1, 1), (0, 1), (0, 0), (1, 0)],
        }
    }

    /// The production rule: the types of the four children, in visiting order.
    pub const fn child_types(self) -> [HilbertType; 4] {
        use HilbertType::*;
        match self {
            I => [III, I, I, IV],
            II => [IV, II, II, III],
            III => [I, III, III, II],
            IV => [II, IV, IV, I],
        }
    }

    const fn index(self) -> usize {
        match self {
            HilbertType::I => 0,
            HilbertType::II => 1,
            HilbertType::III => 2,
            HilbertType::IV => 3,
        }
    }
}

/// The largest order (bits per coordinate) the functions accept.
pub const MAX_ORDER: u32 = 32;

/// One level of the state machine: in state `t`, quadrant `(dx, dy)` has digit `d` and the
/// child is of type `next`. Returned as `(d, next)`, indexes as in [`HilbertType::index`].
const fn step(t: usize, dx: u8, dy: u8) -> (u16, u16) {
    let order = HilbertType::ALL[t].quadrant_order();
    let children = HilbertType::ALL[t].child_types();
    let mut d = 0;
    while d < 4 {
        if order[d].0 == dx && order[d].1 == dy {
            return (d as u16, children[d].index() as u16);
        }
        d += 1;
    }
    panic!("quadrant_order is a permutation of the four quadrants");
}

/// `ENCODE[t << 8 | xc << 4 | yc]` = `(digits << 2) | next`: four levels at once, `xc` and
/// `yc` being four bits of each coordinate (most significant first), `digits` eight bits of
/// index.
static ENCODE: [u16; 1024] = build_encode();
/// `DECODE[t << 8 | digits]` = `(xc << 6) | (yc << 2) | next`.
static DECODE: [u16; 1024] = build_decode();

const fn build_encode() -> [u16; 1024] {
    let mut table = [0u16; 1024];
    let mut i = 0;
    while i < 1024 {
        let (mut t, xc, yc) = (i >> 8, (i >> 4) & 15, i & 15);
        let mut digits = 0u16;
        let mut bit = 4;
        while bit > 0 {
            bit -= 1;
            let (d, next) = step(t, ((xc >> bit) & 1) as u8, ((yc >> bit) & 1) as u8);
            digits = (digits << 2) | d;
            t = next as usize;
        }
        table[i] = (digits << 2) | t as u16;
        i += 1;
    }
    table
}

const fn build_decode() -> [u16; 1024] {
    let mut table = [0u16; 1024];
    let mut i = 0;
    while i < 1024 {
        let (mut t, digits) = (i >> 8, i & 255);
        let (mut xc, mut yc) = (0u16, 0u16);
        let mut level = 4;
        while level > 0 {
            level -= 1;
            let d = (digits >> (2 * level)) & 3;
            let (dx, dy) = HilbertType::ALL[t].quadrant_order()[d];
            xc = (xc << 1) | dx as u16;
            yc = (yc << 1) | dy as u16;
            t = HilbertType::ALL[t].child_types()[d].index();
        }
        table[i] = (xc << 6) | (yc << 2) | t as u16;
        i += 1;
    }
    table
}

/// Levels are processed four at a time from the top, so an order that is not a multiple of
/// four is padded with zero levels above it. Quadrant `(0, 0)` is digit 0 in types I and III,
/// and leads from III to I and from I to III. So a padding of odd length starts in III and ends
/// in I, exactly where an unpadded walk would start.
#[inline]
fn chunks_and_start(order: u32) -> (u32, usize) {
    let chunks = order.div_ceil(4);
    let pad = chunks * 4 - order;
    let start = if pad % 2 == 1 {
        HilbertType::III.index()
    } else {
        HilbertType::I.index()
    };
    (chunks, start)
}

/// The Hilbert index of cell `(x, y)` on a `2^order × 2^order` grid (root of type I).
///
/// `order` must be at most 32; bits of `x` and `y` above `order` are ignored.
#[inline]
pub fn hilbert_encode(order: u32, x: u32, y: u32) -> u64 {
    debug_assert!(order <= MAX_ORDER);
    let (chunks, mut state) = chunks_and_start(order);
    let (x, y) = (u64::from(x), u64::from(y));
    let mut d = 0u64;
    let mut c = chunks;
    while c > 0 {
        c -= 1;
        let shift = 4 * c;
        let xc = ((x >> shift) & 15) as usize;
        let yc = ((y >> shift) & 15) as usize;
        let e = ENCODE[(state << 8) | (xc << 4) | yc];
        d = (d << 8) | u64::from(e >> 2);
        state = usize::from(e & 3);
    }
    if order < 32 {
        d & ((1u64 << (2 * order)) - 1)
    } else {
        d
    }
}

/// The cell `(x, y)` at Hilbert index `d` on a `2^order × 2^order` grid; inverse of
/// [`hilbert_encode`]. Bits of `d` above `2 * order` are ignored.
#[inline]
pub fn hilbert_decode(order: u32, d: u64) -> (u32, u32) {
    debug_assert!(order <= MAX_ORDER);
    let (chunks, mut state) = chunks_and_start(order);
    let d = if order < 32 {
        d & ((1u64 << (2 * order)) - 1)
    } else {
        d
    };
    let (mut x, mut y) = (0u64, 0u64);
    let mut c = chunks;
    while c > 0 {
        c -= 1;
        let digits = ((d >> (8 * c)) & 255) as usize;
        let e = DECODE[(state << 8) | digits];
        x = (x << 4) | u64::from(e >> 6);
        y = (y << 4) | u64::from((e >> 2) & 15);
        state = usize::from(e & 3);
    }
    (x as u32, y as u32)
}

/// A node's place on the multiresolution Hilbert curve.
///
/// It is the Hilbert index, on the grid of finest-level nodes, of the first finest node inside
/// this node's footprint. A node at level `l` of a tree whose finest level is `L` covers
/// `4^(L-l)` consecutive indexes starting at its key. So sorting a *cut* of the tree (a set of
/// nodes that covers the domain without overlap) by key gives the multiresolution Hilbert order
/// of seed 000 §4.2. A node and its first descendant share a key; `(key, level)` is unique.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct HilbertKey(pub u64);

impl HilbertKey {
    /// The key of node `(x, y)` at `level` in a tree whose finest level is `finest_level`.
    #[inline]
    pub fn of_node(finest_level: u8, level: u8, x: u32, y: u32) -> HilbertKey {
        debug_assert!(level <= finest_level && u32::from(finest_level) <= MAX_ORDER);
        let shift = 2 * u32::from(finest_level - level);
        HilbertKey(hilbert_encode(u32::from(level), x, y) << shift)
    }

    /// How many finest-level indexes a node at `level` covers: `4^(finest_level - level)`.
    #[inline]
    pub fn span(finest_level: u8, level: u8) -> u64 {
        1u64 << (2 * u32::from(finest_level - level))
    }

    /// The last finest-level index covered by a node at `level` with this key.
    #[inline]
    pub fn last(self, finest_level: u8, level: u8) -> u64 {
        self.0 + (Self::span(finest_level, level) - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_one_is_type_one() {
        let cells: Vec<(u32, u32)> = (0..4).map(|d| hilbert_decode(1, d)).collect();
        assert_eq!(cells, vec![(0, 0), (0, 1), (1, 1), (1, 0)]);
    }

    #[test]
    fn decode_inverts_encode_on_small_grids() {
        for order in 0..=6u32 {
            let n = 1u32 << order;
            let mut seen = vec![false; (n * n) as usize];
            for y in 0..n {
                for x in 0..n {
                    let d = hilbert_encode(order, x, y);
                    assert!(d < u64::from(n) * u64::from(n));
                    assert!(!seen[d as usize], "index {d} used twice at order {order}");
                    seen[d as usize] = true;
                    assert_eq!(hilbert_decode(order, d), (x, y));
                }
            }
        }
    }

    #[test]
    fn consecutive_indexes_are_neighbours() {
        for order in 1..=7u32 {
            let n = 1u64 << (2 * order);
            for d in 1..n {
                let (a, b) = (hilbert_decode(order, d - 1), hilbert_decode(order, d));
                let dist = a.0.abs_diff(b.0) + a.1.abs_diff(b.1);
                assert_eq!(dist, 1, "order {order}: {d} -> {a:?} {b:?}");
            }
        }
    }

    #[test]
    fn order_thirty_two_round_trips() {
        for &(x, y) in &[
            (0, 0),
            (u32::MAX, 0),
            (0, u32::MAX),
            (u32::MAX, u32::MAX),
            (123_456_789, 987_654_321),
        ] {
            assert_eq!(hilbert_decode(32, hilbert_encode(32, x, y)), (x, y));
        }
    }
}
