//! Seed 001's block-quadtree code and its non-pointer index.
//!
//! A node's code is two bits per level below the root, most significant pair first. Each pair
//! names the child in seed 001's order: **SW = 00, NW = 01, SE = 10, NE = 11**. So the high bit of
//! a pair says "east half" and the low bit "north half". The paper writes the root as `00` and
//! prefixes every code with it; [`MortonKey::to_paper_string`] and
//! [`MortonKey::from_paper_str`] speak that notation.
//!
//! The *non-pointer index* (seed 001 eqs. 1–9) finds a block's bounds from its code alone. Let
//! `W` be the side of the whole terrain. The east bits, weighted `W/2, W/4, ...` from the top
//! pair down, sum to the left edge, and the north bits sum to the bottom edge. The right and top
//! edges are one block side (`W >> depth`) further. [`MortonKey::bounds`] computes this with a
//! bit de-interleave, a shift and a multiply. As in the paper, the origin is the **south-west**
//! corner and `y` grows north. This differs from the raster's north-up rows, and
//! [`MortonKey::from_node`] converts between the two.

/// A quadtree node named by its level and its seed-001 code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MortonKey {
    level: u8,
    code: u64,
}

/// A node's bounds in seed 001's frame: origin at the south-west corner, `y` growing north.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MortonBounds {
    /// West edge.
    pub left: u64,
    /// East edge (`left + side`).
    pub right: u64,
    /// South edge.
    pub bottom: u64,
    /// North edge (`bottom + side`).
    pub top: u64,
}

/// Spreads the low 32 bits of `v` to the even bit positions of a `u64`.
#[inline]
fn spread(v: u32) -> u64 {
    let mut v = u64::from(v);
    v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
    v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
    v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
    v = (v | (v << 2)) & 0x3333_3333_3333_3333;
    v = (v | (v << 1)) & 0x5555_5555_5555_5555;
    v
}

/// Gathers the even bit positions of `v` into the low 32 bits; inverse of [`spread`].
#[inline]
fn gather(v: u64) -> u32 {
    let mut v = v & 0x5555_5555_5555_5555;
    v = (v | (v >> 1)) & 0x3333_3333_3333_3333;
    v = (v | (v >> 2)) & 0x0F0F_0F0F_0F0F_0F0F;
    v = (v | (v >> 4)) & 0x00FF_00FF_00FF_00FF;
    v = (v | (v >> 8)) & 0x0000_FFFF_0000_FFFF;
    v = (v | (v >> 16)) & 0x0000_0000_FFFF_FFFF;
    v as u32
}

impl MortonKey {
    /// The deepest level a key can name (two bits a level in a `u64`).
    pub const MAX_LEVEL: u8 = 32;

    /// The key of the node at `level` whose position is column `x`, row `row` (rows counted
    /// from the north, as in the raster). `level <= 32`, `x, row < 2^level`.
    pub fn from_node(level: u8, x: u32, row: u32) -> MortonKey {
        debug_assert!(level <= Self::MAX_LEVEL);
        let side = 1u64 << level;
        debug_assert!(u64::from(x) < side && u64::from(row) < side);
        let north = (side - 1 - u64::from(row)) as u32;
        MortonKey {
            level,
            code: (spread(x) << 1) | spread(north),
        }
    }

    /// The key for a raw code of `2 * level` bits (SW = 00, NW = 01, SE = 10, NE = 11). `None` if
    /// the code has bits above `2 * level` or the level is too deep.
    pub fn from_code(level: u8, code: u64) -> Option<MortonKey> {
        if level > Self::MAX_LEVEL || (level < 32 && code >> (2 * u32::from(level)) != 0) {
            return None;
        }
        Some(MortonKey { level, code })
    }

    /// Parses seed 001's notation: the root's `00` followed by one pair per level. For
    /// example `"000010"` is root `00`, then its SW child `00`, then that child's SE child `10`.
    /// `None` if the text is not `0`/`1` pairs, does not start with the root's `00`, or is
    /// deeper than [`Self::MAX_LEVEL`].
    pub fn from_paper_str(text: &str) -> Option<MortonKey> {
        let bytes = text.as_bytes();
        if bytes.len() < 2 || !bytes.len().is_multiple_of(2) || &bytes[..2] != b"00" {
            return None;
        }
        let level = u8::try_from(bytes.len() / 2 - 1).ok()?;
        if level > Self::MAX_LEVEL {
            return None;
        }
        let mut code = 0u64;
        for &b in &bytes[2..] {
            let bit = match b {
                b'0' => 0,
                b'1' => 1,
                _ => return None,
            };
            code = (code << 1) | bit;
        }
        Some(MortonKey { level, code })
    }

    /// Seed 001's notation: `00` for the root, then one pair per level.
    pub fn to_paper_string(&self) -> String {
        let mut s = String::with_capacity(2 + 2 * usize::from(self.level));
        s.push_str("00");
        for i in (0..2 * u32::from(self.level)).rev() {
            s.push(if (self.code >> i) & 1 == 1 { '1' } else { '0' });
        }
        s
    }

    /// Depth below the root (the root is level 0; seed 001 counts it as level 1).
    pub fn level(&self) -> u8 {
        self.level
    }

    /// The interleaved code, `2 * level` bits.
    pub fn code(&self) -> u64 {
        self.code
    }

    /// The node's column among the `2^level` of its level (from the west).
    pub fn x(&self) -> u32 {
        gather(self.code >> 1)
    }

    /// The node's row among the `2^level` of its level, counted from the **north** (raster
    /// rows).
    pub fn row(&self) -> u32 {
        let side = 1u64 << self.level;
        (side - 1 - u64::from(gather(self.code))) as u32
    }

    /// Seed 001's non-pointer index: the node's bounds when the whole terrain is `side` units
    /// wide, by bit operations on the code alone. `side` must be a multiple of `2^level` (for
    /// fmrh's domain it is `2^L · (b - 1)` cells).
    pub fn bounds(&self, side: u64) -> MortonBounds {
        let block = side >> self.level;
        debug_assert_eq!(
            block << self.level,
            side,
            "side must be a multiple of 2^level"
        );
        let left = u64::from(gather(self.code >> 1)) * block;
        let bottom = u64::from(gather(self.code)) * block;
        MortonBounds {
            left,
            right: left + block,
            bottom,
            top: bottom + block,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_and_gather_invert() {
        for v in [0u32, 1, 2, 0xFFFF_FFFF, 0x1234_5678, 0x8000_0001] {
            assert_eq!(gather(spread(v)), v);
        }
    }

    #[test]
    fn root_children_follow_seed_001() {
        // Root children: SW 0000, NW 0001, SE 0010, NE 0011 (rows from the north: SW is row 1).
        assert_eq!(MortonKey::from_node(1, 0, 1).to_paper_string(), "0000");
        assert_eq!(MortonKey::from_node(1, 0, 0).to_paper_string(), "0001");
        assert_eq!(MortonKey::from_node(1, 1, 1).to_paper_string(), "0010");
        assert_eq!(MortonKey::from_node(1, 1, 0).to_paper_string(), "0011");
    }

    #[test]
    fn paper_strings_round_trip() {
        for s in ["00", "0010", "001000", "00101101", "0011111111"] {
            assert_eq!(
                MortonKey::from_paper_str(s)
                    .map(|k| k.to_paper_string())
                    .as_deref(),
                Some(s)
            );
        }
        for bad in ["", "0", "01", "10", "0012", "001", "00ab"] {
            assert!(MortonKey::from_paper_str(bad).is_none(), "{bad:?}");
        }
    }
}
