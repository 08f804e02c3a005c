//! Payloads: the bytes of a physical block and of a coarse node grid, and the views that read
//! them without copying.
//!
//! A **physical block** holds the full-resolution samples of one finest-level footprint
//! clipped to the data rectangle: `width × height` little-endian `f32`, row-major from the
//! north-west, voids as the canonical NaN ([`super::VOID_BITS`]). The *stand-ins* follow:
//! one `f32` per void, in row-major order, holding the mended height the model uses there.
//! Mending is not local (a void takes the nearest valid sample in its row or column, which may
//! lie blocks away), so the stand-ins are what lets a reader draw a block alone.
//!
//! A **coarse grid** (a node above the finest level) holds `b × b` little-endian `f32` of
//! mended heights, the node's point decimation. If the node record's
//! [`super::NODE_GRID_HAS_VOIDS`] flag is set, a bitmap of `ceil(b² / 8)` bytes follows (bit
//! `i % 8` of byte `i / 8` set when grid sample `i` is a void or padding).
//!
//! Payloads start on multiples of [`super::PAYLOAD_ALIGN`] bytes, and the bytes between them
//! are zero.

use zerocopy::byteorder::little_endian::F32;
use zerocopy::FromBytes;

/// Bytes of a physical block's payload.
pub fn block_len(width: u32, height: u32, void_count: u32) -> u64 {
    4 * (u64::from(width) * u64::from(height) + u64::from(void_count))
}

/// Bytes of a coarse grid's payload.
pub fn grid_len(block_size: u32, has_voids: bool) -> u64 {
    let n = u64::from(block_size) * u64::from(block_size);
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

    /// The heights a renderer draws: samples with each void replaced by its stand-in.
    pub fn mended(&self) -> Vec<f32> {
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
    /// Samples a side (`b`).
    pub size: u32,
    heights: &'a [F32],
    void_bitmap: Option<&'a [u8]>,
}

impl<'a> GridView<'a> {
    /// Views `bytes` as a `size × size` grid; `None` if the length disagrees.
    pub fn new(bytes: &'a [u8], size: u32, has_voids: bool) -> Option<Self> {
        if bytes.len() as u64 != grid_len(size, has_voids) {
            return None;
        }
        let n = size as usize * size as usize;
        let (h, rest) = bytes.split_at(4 * n);
        Some(GridView {
            size,
            heights: <[F32]>::ref_from_bytes(h).ok()?,
            void_bitmap: has_voids.then_some(rest),
        })
    }

    /// The mended heights, row-major from the north-west. Zero-copy.
    pub fn heights(&self) -> &'a [F32] {
        self.heights
    }

    /// Whether grid sample `i` (row-major) stands in for a void or padding.
    pub fn is_void(&self, i: usize) -> bool {
        self.void_bitmap
            .is_some_and(|b| b.get(i / 8).is_some_and(|byte| byte >> (i % 8) & 1 == 1))
    }
}
