//! Payloads: the bytes of a physical block and of a coarse node grid. This room teaches what
//! the bytes are (the *layouts*, read in place by [`BlockView`] and [`GridView`]); its two
//! neighbours say where a payload's samples lie (`place`: [`Placement`], [`ParentGrid`]) and how a layout is stored coded
//! (`coding`: one entry each way, [`encode`] and [`decode`], against a parent's grid
//! included).
//!
//! A **physical block** holds the full-resolution samples of one finest-level footprint
//! clipped to the data rectangle: `width × height` little-endian `f32`, row-major from the
//! north-west, voids as the canonical NaN ([`super::VOID_BITS`]). The *stand-ins* follow:
//! one `f32` per void, in row-major order, holding the mended height the model uses there.
//! Mending is not local (a void takes the nearest valid sample in its row or column, which may
//! lie blocks away), so the stand-ins are what lets a reader draw a block alone.
//!
//! A **coarse grid** (a node above the finest level) holds the node's `b × b` point
//! decimation of mended heights, *clipped to the data*: [`crate::model::Domain::grid_dims`]
//! gives the `gw × gh` samples stored, row-major little-endian `f32`. A grid column lies east
//! of the data when its sample column is past `width - 1`. All such columns repeat the data's
//! east edge (padding clamps), so only the first of them is stored, and grid column `i` reads
//! stored column `min(i, gw - 1)`. Rows likewise. If the node record's
//! [`super::NODE_GRID_HAS_VOIDS`] flag is set, a bitmap of `ceil(gw·gh / 8)` bytes follows
//! (bit `k % 8` of byte `k / 8` set when stored sample `k` stands for a void or for padding).
//!
//! Payloads start on any byte in 2.x and on multiples of [`super::PAYLOAD_ALIGN`] bytes in
//! 1.x ([`super::payload_align`]), and the bytes between them are zero. A record finds its
//! payload by a [`PayloadRef`]: offset, length and CRC.
//!
//! **Stored form.** Format 1.x stores the layouts as they are; format 2 and later store them
//! coded (`coding`, `format-spec/container.md` §7). The CRC covers the stored bytes, so
//! damage is caught before any decoding.

mod coding;
mod place;

use std::ops::Range;

use serde::Serialize;
use zerocopy::byteorder::little_endian::F32;
use zerocopy::FromBytes;

pub use coding::{decode, encode, max_stored_len, Codes, Coding};
pub use place::{ParentGrid, Placement};
#[cfg(any(test, feature = "testing"))]
pub use place::{block_axes, grid_axes, kept_heights, kept_width};

use super::VOID_BITS;

/// Where a payload is: its byte offset in the container, its length, and the CRC-32 of its
/// bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize)]
pub struct PayloadRef {
    /// Byte offset in the container.
    pub offset: u64,
    /// Bytes.
    pub len: u32,
    /// CRC-32 of the bytes.
    pub crc: u32,
}

impl PayloadRef {
    /// The reference of `bytes` placed at `offset`. `None` when they are 4 GiB or more.
    pub fn of(offset: u64, bytes: &[u8]) -> Option<PayloadRef> {
        Some(PayloadRef {
            offset,
            len: u32::try_from(bytes.len()).ok()?,
            crc: super::crc32(bytes),
        })
    }

    /// The byte just past it (saturating).
    #[inline]
    pub fn end(&self) -> u64 {
        self.offset.saturating_add(u64::from(self.len))
    }

    /// The pages of `page_size` bytes it touches (none when empty).
    #[inline]
    pub fn pages(&self, page_size: u32) -> Range<u64> {
        let p = u64::from(page_size);
        if self.len == 0 {
            return 0..0;
        }
        self.offset / p..self.end().div_ceil(p)
    }
}

/// Encodes a physical block from its `count` samples in row-major order, each
/// `(height, valid)`: a valid sample is stored as is, a void as [`VOID_BITS`] with `height`
/// (its mended stand-in) appended after the samples.
pub fn encode_block(samples: impl Iterator<Item = (f32, bool)>, count: usize) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(4 * count);
    let mut stand_ins = Vec::new();
    for (v, valid) in samples {
        if valid {
            bytes.extend_from_slice(&v.to_le_bytes());
        } else {
            bytes.extend_from_slice(&VOID_BITS.to_le_bytes());
            stand_ins.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes.extend_from_slice(&stand_ins);
    bytes
}

/// Encodes a coarse grid stored as `heights` (its clipped `gw × gh` samples, row-major), with
/// the void bitmap of `void` when `has_voids`.
pub fn encode_grid(heights: &[f32], void: &[bool], has_voids: bool) -> Vec<u8> {
    let n = heights.len() as u64;
    let mut bytes = Vec::with_capacity(usize::try_from(grid_bytes(n, has_voids)).unwrap_or(0));
    for h in heights {
        bytes.extend_from_slice(&h.to_le_bytes());
    }
    if has_voids {
        let mut bitmap = vec![0u8; heights.len().div_ceil(8)];
        for (i, _) in void.iter().enumerate().filter(|(_, &v)| v) {
            bitmap[i / 8] |= 1 << (i % 8);
        }
        bytes.extend_from_slice(&bitmap);
    }
    bytes
}

/// Bytes of a physical block's payload.
pub fn block_len(width: u32, height: u32, void_count: u32) -> u64 {
    4 * (u64::from(width) * u64::from(height) + u64::from(void_count))
}

/// Bytes of a coarse grid's payload of `gw × gh` stored samples.
pub fn grid_len(gw: u32, gh: u32, has_voids: bool) -> u64 {
    grid_bytes(u64::from(gw) * u64::from(gh), has_voids)
}

fn grid_bytes(n: u64, has_voids: bool) -> u64 {
    4 * n + if has_voids { n.div_ceil(8) } else { 0 }
}

/// A physical block's payload, read in place.
#[derive(Clone, Copy, Debug)]
pub struct BlockView<'a> {
    /// Samples along a row.
    pub width: u32,
    /// Samples down a column.
    pub height: u32,
    samples: &'a [F32],
    stand_ins: &'a [F32],
}

impl<'a> BlockView<'a> {
    /// Views `bytes` as a `width × height` block with `void_count` stand-ins; `None` if the
    /// length disagrees.
    pub fn new(bytes: &'a [u8], width: u32, height: u32, void_count: u32) -> Option<Self> {
        if bytes.len() as u64 != block_len(width, height, void_count) {
            return None;
        }
        let all = <[F32]>::ref_from_bytes(bytes).ok()?;
        let (samples, stand_ins) = all.split_at(width as usize * height as usize);
        Some(BlockView {
            width,
            height,
            samples,
            stand_ins,
        })
    }

    /// The samples as stored, row-major: voids are NaN. Zero-copy.
    pub fn samples(&self) -> &'a [F32] {
        self.samples
    }

    /// The stand-ins of the voids, in row-major order. Zero-copy.
    pub fn stand_ins(&self) -> &'a [F32] {
        self.stand_ins
    }

    /// The sample at `(col, row)` of the block: `None` for a void.
    pub fn get(&self, col: u32, row: u32) -> Option<f32> {
        let v = self.samples[row as usize * self.width as usize + col as usize].get();
        (!v.is_nan()).then_some(v)
    }

    /// [`BlockView::mended`], shared: collected straight into the `Arc` when there are no
    /// voids (one copy, not two).
    pub fn mended_shared(&self) -> std::sync::Arc<[f32]> {
        if self.stand_ins.is_empty() {
            return self.samples.iter().map(|s| s.get()).collect();
        }
        std::sync::Arc::from(self.mended())
    }

    /// The heights a renderer draws: samples with each void replaced by its stand-in.
    pub fn mended(&self) -> Vec<f32> {
        if self.stand_ins.is_empty() {
            // No voids (most blocks): the samples as they are, a copy.
            return self.samples.iter().map(|s| s.get()).collect();
        }
        let mut stand_ins = self.stand_ins.iter();
        self.samples
            .iter()
            .map(|s| {
                let v = s.get();
                if v.is_nan() {
                    stand_ins.next().map_or(v, |x| x.get())
                } else {
                    v
                }
            })
            .collect()
    }
}

/// A coarse grid's payload, read in place.
#[derive(Clone, Copy, Debug)]
pub struct GridView<'a> {
    /// Samples a side of the full grid (`b`).
    pub size: u32,
    /// Stored columns.
    pub stored_width: u32,
    /// Stored rows.
    pub stored_height: u32,
    heights: &'a [F32],
    void_bitmap: Option<&'a [u8]>,
}

impl<'a> GridView<'a> {
    /// Views `bytes` as a `b × b` grid stored as `gw × gh`; `None` if the length disagrees.
    pub fn new(bytes: &'a [u8], size: u32, (gw, gh): (u32, u32), has_voids: bool) -> Option<Self> {
        if gw == 0
            || gh == 0
            || gw > size
            || gh > size
            || bytes.len() as u64 != grid_len(gw, gh, has_voids)
        {
            return None;
        }
        let n = gw as usize * gh as usize;
        let (h, rest) = bytes.split_at(4 * n);
        Some(GridView {
            size,
            stored_width: gw,
            stored_height: gh,
            heights: <[F32]>::ref_from_bytes(h).ok()?,
            void_bitmap: has_voids.then_some(rest),
        })
    }

    /// The stored heights, row-major from the north-west. Zero-copy.
    pub fn stored(&self) -> &'a [F32] {
        self.heights
    }

    fn stored_index(&self, i: u32, j: u32) -> usize {
        let (c, r) = (i.min(self.stored_width - 1), j.min(self.stored_height - 1));
        r as usize * self.stored_width as usize + c as usize
    }

    /// The height at grid sample `(i, j)` of the full `b × b` grid.
    pub fn height(&self, i: u32, j: u32) -> f32 {
        self.heights[self.stored_index(i, j)].get()
    }

    /// Whether grid sample `(i, j)` of the full grid stands in for a void or padding.
    pub fn is_void(&self, i: u32, j: u32) -> bool {
        let k = self.stored_index(i, j);
        i >= self.stored_width
            || j >= self.stored_height
            || self
                .void_bitmap
                .is_some_and(|b| b.get(k / 8).is_some_and(|byte| byte >> (k % 8) & 1 == 1))
    }

    /// The full `b × b` grid of heights, row-major.
    pub fn expanded(&self) -> Vec<f32> {
        let b = self.size as usize;
        let (gw, gh) = (self.stored_width as usize, self.stored_height as usize);
        let mut out = Vec::with_capacity(b * b);
        // Row by row: the stored row, then its last height repeated (the clamp columns);
        // past the stored rows, the last stored row again.
        for j in 0..b {
            let r = j.min(gh.saturating_sub(1));
            let row = &self.heights[r * gw..(r + 1) * gw];
            out.extend(row.iter().take(b).map(|h| h.get()));
            let last = row.last().map_or(0.0, |h| h.get());
            out.resize((j + 1) * b, last);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A grid's expansion (row by row) is its height at every sample of the full grid,
        /// clamp columns and rows included; a block's mended heights are its samples with
        /// each void's stand-in, in order.
        #[test]
        fn expanded_and_mended_agree_with_the_samples(
            b in 1u32..20,
            gw in 1u32..20,
            gh in 1u32..20,
            voids in proptest::collection::vec(any::<bool>(), 1..400),
        ) {
            let (gw, gh) = (gw.min(b), gh.min(b));
            let n = (gw * gh) as usize;
            let bytes: Vec<u8> = (0..n).flat_map(|k| (k as f32 * 1.5).to_le_bytes()).collect();
            let g = GridView::new(&bytes, b, (gw, gh), false).expect("a grid");
            let e = g.expanded();
            prop_assert_eq!(e.len(), (b * b) as usize);
            for j in 0..b {
                for i in 0..b {
                    prop_assert_eq!(e[(j * b + i) as usize].to_bits(), g.height(i, j).to_bits());
                }
            }
            let void_at = |k: usize| voids[k % voids.len()];
            let stand_ins: Vec<f32> = (0..n).filter(|&k| void_at(k)).map(|k| -(k as f32)).collect();
            let mut bytes: Vec<u8> = (0..n)
                .flat_map(|k| if void_at(k) { f32::from_bits(VOID_BITS) } else { k as f32 }.to_le_bytes())
                .collect();
            bytes.extend(stand_ins.iter().flat_map(|v| v.to_le_bytes()));
            let v = BlockView::new(&bytes, gw, gh, u32::try_from(stand_ins.len()).expect("few")).expect("a block");
            let want: Vec<f32> = (0..n).map(|k| if void_at(k) { -(k as f32) } else { k as f32 }).collect();
            prop_assert_eq!(&*v.mended_shared(), &want[..]);
            prop_assert_eq!(v.mended(), want);
        }
    }
}
