//! Windows and blocks as the cut, read-within and flight tests compare them.

use fmrh::types::SampleRect;
use fmrh::Block;

/// The window of a `w × h` grid whose corners are the fractions `a` = (col, col, row, row)
/// of its sides, in either order.
pub fn window(w: u32, h: u32, a: (f64, f64, f64, f64)) -> SampleRect {
    let pick = |t: f64, n: u32| ((t * f64::from(n - 1)).floor() as u64).min(u64::from(n - 1));
    let (c0, c1) = (pick(a.0, w), pick(a.1, w));
    let (r0, r1) = (pick(a.2, h), pick(a.3, h));
    SampleRect {
        col0: c0.min(c1),
        row0: r0.min(r1),
        col1: c0.max(c1),
        row1: r0.max(r1),
    }
}

/// The same block: rectangle, level, tile, error, stride, and heights bit for bit.
pub fn same_block(a: &Block, b: &Block) -> bool {
    a.rect == b.rect
        && a.level == b.level
        && a.tile == b.tile
        && a.error == b.error
        && a.stride == b.stride
        && a.heights.len() == b.heights.len()
        && a.heights
            .iter()
            .zip(b.heights.iter())
            .all(|(x, y)| x.to_bits() == y.to_bits())
}
