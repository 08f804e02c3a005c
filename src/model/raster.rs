//! The mended raster: the data grid with every void given a stand-in height, plus a validity
//! bitset that says which heights are real.
//!
//! A node's grid is a point-decimation of this raster, so the stand-ins decide what a coarse
//! node draws over and around a void. Errors are measured only at valid samples, so a stand-in
//! never counts as terrain. Still, it must not invent a spike, and it must not give an infinite
//! error along a data edge. The rule (format-spec §"Void mending"):
//!
//! 1. A void sample takes the height of the **nearest valid sample in its own row or column**
//!    (distance in samples; ties go to west, then east, then north, then south).
//! 2. A void sample whose row and column hold no valid sample at all takes the value rule 1
//!    gave the nearest sample in its row that lies in a column holding valid data (ties go
//!    west).
//! 3. If the grid has no valid sample, every sample is 0.
//! 4. **Padding** (outside the data rectangle) takes the mended value of the nearest sample of
//!    the rectangle: coordinates are clamped.
//!
//! Every stand-in is therefore a real height from the same grid, and no surface built on
//! stand-ins leaves the range of the valid data. The rule does not depend on the level, so
//! node grids stay nested and same-level neighbours agree on their shared edges. The raster is
//! built in place from the heightfield's own buffer, so the padded domain costs no memory. The
//! work is O(samples), plus four bytes per void sample while mending.

use super::domain::SampleRect;
use crate::heightfield::Heightfield;

/// The data grid with voids mended, and which samples are valid.
#[derive(Clone, Debug)]
pub struct MendedRaster {
    width: u32,
    height: u32,
    values: Vec<f32>,
    valid: Vec<u64>,
    void_count: u64,
    /// How far a stored height may be from its source (`Q/2` of a storage precision, else
    /// 0): measuring adds it to every node error (see [`super::precision`]).
    storage_error: f64,
}

const NONE: u32 = u32::MAX;

impl MendedRaster {
    /// Mends `heightfield` in place (see the module docs for the rule).
    pub fn new(heightfield: Heightfield) -> MendedRaster {
        let (width, height) = (heightfield.width(), heightfield.height());
        let mut values = heightfield.into_samples();
        let mut valid = vec![0u64; values.len().div_ceil(64)];
        let mut void_count = 0u64;
        for (i, v) in values.iter().enumerate() {
            if v.is_nan() {
                void_count += 1;
            } else {
                valid[i / 64] |= 1 << (i % 64);
            }
        }
        if void_count > 0 {
            mend(
                &mut values,
                &valid,
                width as usize,
                height as usize,
                void_count,
            );
        }
        MendedRaster {
            width,
            height,
            values,
            valid,
            void_count,
            storage_error: 0.0,
        }
    }

    /// The raster whose heights are stored within `storage_error` of their source.
    pub fn with_storage_error(mut self, storage_error: f64) -> MendedRaster {
        self.storage_error = storage_error;
        self
    }

    /// How far a stored height may be from its source.
    pub fn storage_error(&self) -> f64 {
        self.storage_error
    }

    /// Data samples along a row.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Data samples down a column.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Void samples in the data rectangle.
    pub fn void_count(&self) -> u64 {
        self.void_count
    }

    /// Valid samples in the data rectangle.
    pub fn valid_count(&self) -> u64 {
        self.values.len() as u64 - self.void_count
    }

    /// The mended height at `(col, row)`; outside the data rectangle, the nearest data
    /// sample's (padding, rule 4).
    #[inline]
    pub fn value(&self, col: u64, row: u64) -> f32 {
        let c = col.min(u64::from(self.width - 1)) as usize;
        let r = row.min(u64::from(self.height - 1)) as usize;
        self.values[r * self.width as usize + c]
    }

    /// Whether `(col, row)` holds a real height (false for voids and padding).
    #[inline]
    pub fn is_valid(&self, col: u64, row: u64) -> bool {
        if col >= u64::from(self.width) || row >= u64::from(self.height) {
            return false;
        }
        let i = row as usize * self.width as usize + col as usize;
        (self.valid[i / 64] >> (i % 64)) & 1 == 1
    }

    /// The original sample at `(col, row)`: its height, or `None` for a void (or outside).
    pub fn original(&self, col: u64, row: u64) -> Option<f32> {
        self.is_valid(col, row).then(|| self.value(col, row))
    }

    /// One row of mended heights.
    #[inline]
    pub fn row(&self, row: u64) -> &[f32] {
        let w = self.width as usize;
        &self.values[row as usize * w..(row as usize + 1) * w]
    }

    /// Calls `f(first, last)` for each maximal run of valid samples in row `row` between
    /// columns `col0..=col1` (inclusive). Columns must lie inside the data rectangle.
    #[inline]
    pub fn for_each_valid_run(&self, row: u64, col0: u64, col1: u64, mut f: impl FnMut(u64, u64)) {
        let base = row as usize * self.width as usize;
        let (start, end) = (base + col0 as usize, base + col1 as usize + 1);
        let mut i = start;
        while i < end {
            let off = i % 64;
            let word = self.valid[i / 64] >> off;
            if word & 1 == 0 {
                // Void at i: jump to the next valid bit of this word, or to the next word.
                i += if word == 0 {
                    64 - off
                } else {
                    word.trailing_zeros() as usize
                };
                continue;
            }
            let run_start = i;
            loop {
                let off = i % 64;
                // Bits shifted in from above are 0, so `!` turns them into a stop: `ones` is
                // at most the rest of this word.
                let ones = (!(self.valid[i / 64] >> off)).trailing_zeros() as usize;
                i += ones;
                if ones < 64 - off || i >= end {
                    break;
                }
            }
            f((run_start - base) as u64, (i.min(end) - 1 - base) as u64);
        }
    }

    /// Counts valid samples in row `row`, columns `col0..=col1` (inside the data rectangle).
    #[inline]
    pub fn count_valid(&self, row: u64, col0: u64, col1: u64) -> u64 {
        let base = row as usize * self.width as usize;
        let (mut i, end) = (base + col0 as usize, base + col1 as usize + 1);
        let mut n = 0u64;
        while i < end {
            let off = i % 64;
            let take = (64 - off).min(end - i);
            let mask = if take == 64 {
                u64::MAX
            } else {
                (1u64 << take) - 1
            };
            n += u64::from(((self.valid[i / 64] >> off) & mask).count_ones());
            i += take;
        }
        n
    }

    /// The original heightfield back, voids as `NaN`: the raster is lossless.
    pub fn to_heightfield(&self) -> Heightfield {
        let mut samples = self.values.clone();
        for (i, v) in samples.iter_mut().enumerate() {
            if (self.valid[i / 64] >> (i % 64)) & 1 == 0 {
                *v = f32::NAN;
            }
        }
        Heightfield::new(self.width, self.height, samples)
            .expect("a mended raster holds a valid heightfield")
    }
}

/// Rules 1–3 of the module docs, in place. `valid` marks the real samples; void slots of
/// `values` are overwritten.
impl MendedRaster {
    /// Replaces the samples of the rectangle at `(col0, row0)` with `patch` (NaN = void), and
    /// mends again. The caller has checked that the rectangle lies inside the grid.
    ///
    /// Returns the rectangles whose mended heights or validity may have changed: the patch's,
    /// and, when voids are involved, the bounding box of the stand-ins elsewhere that took a
    /// new value (mending is not local: a void takes its height from anywhere along its row
    /// or column). Without voids before or after, only the patch is written, in
    /// O(patch); otherwise the raster is mended again from scratch, in O(samples), so that
    /// the result is exactly [`MendedRaster::new`] of the new samples.
    pub fn replace(&mut self, col0: u64, row0: u64, patch: &Heightfield) -> Vec<SampleRect> {
        let (pw, ph) = (u64::from(patch.width()), u64::from(patch.height()));
        debug_assert!(col0 + pw <= u64::from(self.width) && row0 + ph <= u64::from(self.height));
        let rect = SampleRect {
            col0,
            row0,
            col1: col0 + pw - 1,
            row1: row0 + ph - 1,
        };
        let w = self.width as usize;
        if self.void_count == 0 && patch.void_count() == 0 {
            for (j, src) in patch.samples().chunks_exact(pw as usize).enumerate() {
                let at = (row0 as usize + j) * w + col0 as usize;
                self.values[at..at + src.len()].copy_from_slice(src);
            }
            return vec![rect];
        }
        let mut samples = self.to_heightfield().into_samples();
        for (j, src) in patch.samples().chunks_exact(pw as usize).enumerate() {
            let at = (row0 as usize + j) * w + col0 as usize;
            samples[at..at + src.len()].copy_from_slice(src);
        }
        let old = std::mem::replace(
            self,
            MendedRaster::new(
                Heightfield::new(self.width, self.height, samples)
                    .expect("same size as a valid heightfield, finite patch"),
            )
            .with_storage_error(self.storage_error),
        );
        // Stand-ins that changed outside the patch.
        let mut changed: Option<SampleRect> = None;
        for (i, (&a, &b)) in old.values.iter().zip(&self.values).enumerate() {
            if a.to_bits() == b.to_bits() {
                continue;
            }
            let (c, r) = ((i % w) as u64, (i / w) as u64);
            if rect.contains(c, r) {
                continue;
            }
            changed = Some(match changed {
                None => SampleRect {
                    col0: c,
                    row0: r,
                    col1: c,
                    row1: r,
                },
                Some(x) => SampleRect {
                    col0: x.col0.min(c),
                    row0: x.row0.min(r),
                    col1: x.col1.max(c),
                    row1: x.row1.max(r),
                },
            });
        }
        std::iter::once(rect).chain(changed).collect()
    }
}

fn mend(values: &mut [f32], valid: &[u64], w: usize, h: usize, void_count: u64) {
    let is_valid = |i: usize| (valid[i / 64] >> (i % 64)) & 1 == 1;
    // Distance of the best candidate so far, for each void in row-major order.
    let mut best = vec![u32::MAX; void_count as usize];

    // Pass 1, north to south: west, east and north candidates.
    let mut above = vec![NONE; w]; // row of the last valid sample seen in each column
    let mut east = vec![NONE; w]; // per row: column of the nearest valid sample at or east
    let mut k = 0usize;
    for y in 0..h {
        let row = y * w;
        let mut next = NONE;
        for x in (0..w).rev() {
            if is_valid(row + x) {
                next = x as u32;
            }
            east[x] = next;
        }
        let mut west = NONE;
        for x in 0..w {
            let i = row + x;
            if is_valid(i) {
                west = x as u32;
                above[x] = y as u32;
                continue;
            }
            let mut dist = u32::MAX;
            let mut value = 0.0f32;
            if west != NONE {
                dist = x as u32 - west;
                value = values[row + west as usize];
            }
            if east[x] != NONE && east[x] - (x as u32) < dist {
                dist = east[x] - x as u32;
                value = values[row + east[x] as usize];
            }
            if above[x] != NONE && y as u32 - above[x] < dist {
                dist = y as u32 - above[x];
                value = values[above[x] as usize * w + x];
            }
            if dist != u32::MAX {
                values[i] = value;
            }
            best[k] = dist;
            k += 1;
        }
    }

    // Pass 2, south to north: south candidates (they lose ties).
    let mut below = vec![NONE; w];
    for y in (0..h).rev() {
        let row = y * w;
        for x in (0..w).rev() {
            let i = row + x;
            if is_valid(i) {
                below[x] = y as u32;
                continue;
            }
            k -= 1;
            if below[x] != NONE && below[x] - (y as u32) < best[k] {
                best[k] = below[x] - y as u32;
                values[i] = values[below[x] as usize * w + x];
            }
        }
    }

    // Rule 2: samples whose row and column are both void. Their column holds no valid sample;
    // take the nearest column (ties west) that does, in the same row (rule 1 mended it).
    if best.contains(&u32::MAX) {
        let column_has_valid: Vec<bool> = below.iter().map(|&r| r != NONE).collect();
        if !column_has_valid.contains(&true) {
            values.iter_mut().for_each(|v| *v = 0.0); // rule 3
            return;
        }
        let mut nearest = vec![0u32; w];
        let mut west = NONE;
        for x in 0..w {
            if column_has_valid[x] {
                west = x as u32;
            }
            nearest[x] = west;
        }
        let mut east = NONE;
        for x in (0..w).rev() {
            if column_has_valid[x] {
                east = x as u32;
            }
            let x32 = x as u32;
            if east != NONE && (nearest[x] == NONE || east - x32 < x32 - nearest[x]) {
                nearest[x] = east;
            }
        }
        let mut k = 0usize;
        for y in 0..h {
            let row = y * w;
            for x in 0..w {
                if is_valid(row + x) {
                    continue;
                }
                if best[k] == u32::MAX {
                    values[row + x] = values[row + nearest[x] as usize];
                }
                k += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raster(w: u32, h: u32, v: &[f32]) -> MendedRaster {
        MendedRaster::new(Heightfield::new(w, h, v.to_vec()).unwrap())
    }

    const N: f32 = f32::NAN;

    #[test]
    fn nearest_in_row_or_column() {
        #[rustfmt::skip]
        let r = raster(5, 3, &[
            1.0, N,   N,   N,   9.0,
            N,   N,   N,   N,   N,
            2.0, N,   5.0, N,   N,
        ]);
        // (1,0): west 1 at distance 1 beats east 9 at 3.
        assert_eq!(r.value(1, 0), 1.0);
        // (2,0): west at 2 and east at 2 tie: west wins.
        assert_eq!(r.value(2, 0), 1.0);
        // (3,0): east at 1.
        assert_eq!(r.value(3, 0), 9.0);
        // (2,1): the row is all void; north (2,0) is void too; south 5.0 at 1.
        assert_eq!(r.value(2, 1), 5.0);
        // (0,1): north 1.0 and south 2.0 both at distance 1: north wins.
        assert_eq!(r.value(0, 1), 1.0);
        // (4,2): west 5.0 at 2, north 9.0 at 2: west wins.
        assert_eq!(r.value(4, 2), 5.0);
        assert_eq!(r.void_count(), 11);
        assert!(!r.is_valid(1, 0) && r.is_valid(2, 2));
    }

    #[test]
    fn rows_and_columns_all_void_use_rule_two() {
        #[rustfmt::skip]
        let r = raster(3, 3, &[
            N, N, N,
            N, N, 7.0,
            N, N, N,
        ]);
        // (0,0): row 0 and column 0 hold no valid sample; nearest column with data is 2,
        // whose row-0 value rule 1 mended to 7 (south).
        assert_eq!(r.value(0, 0), 7.0);
        assert_eq!(r.value(1, 2), 7.0);
    }

    #[test]
    fn all_void_is_zero_and_padding_clamps() {
        let r = raster(2, 2, &[N, N, N, N]);
        assert_eq!(r.value(0, 0), 0.0);
        assert_eq!(r.valid_count(), 0);
        let r = raster(2, 1, &[3.0, 4.0]);
        assert_eq!(r.value(100, 100), 4.0);
        assert!(!r.is_valid(2, 0));
    }

    #[test]
    fn runs_and_counts_match_bits() {
        let mut v = vec![1.0f32; 300];
        for i in [0usize, 5, 63, 64, 65, 127, 128, 200, 299] {
            v[i] = N;
        }
        let r = raster(150, 2, &v);
        for row in 0..2u64 {
            for (a, b) in [(0u64, 149u64), (3, 70), (64, 64), (100, 149)] {
                let mut runs = vec![];
                r.for_each_valid_run(row, a, b, |s, e| runs.push((s, e)));
                let mut expect = vec![];
                let mut x = a;
                while x <= b {
                    if r.is_valid(x, row) {
                        let s = x;
                        while x < b && r.is_valid(x + 1, row) {
                            x += 1;
                        }
                        expect.push((s, x));
                    }
                    x += 1;
                }
                assert_eq!(runs, expect, "row {row} {a}..={b}");
                let n = (a..=b).filter(|&x| r.is_valid(x, row)).count() as u64;
                assert_eq!(r.count_valid(row, a, b), n);
            }
        }
    }
}
