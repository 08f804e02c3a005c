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
//! A **coarse grid** (a node above the finest level) holds the node's `b × b` point
//! decimation of mended heights, *clipped to the data*: [`grid_dims`] gives the `gw × gh`
//! samples stored, row-major little-endian `f32`. A grid column lies east of the data
//! when its sample column is past `width - 1`. All such columns repeat the data's east edge
//! (padding clamps), so only the first of them is stored, and grid column `i` reads stored
//! column `min(i, gw - 1)`. Rows likewise. If the node record's
//! [`super::NODE_GRID_HAS_VOIDS`] flag is set, a bitmap of `ceil(gw·gh / 8)` bytes follows
//! (bit `k % 8` of byte `k / 8` set when stored sample `k` stands for a void or for padding).
//!
//! Payloads start on any byte in 2.x and on multiples of [`super::PAYLOAD_ALIGN`] bytes in
//! 1.x ([`super::payload_align`]), and the bytes between them are zero. A record finds its payload by a [`PayloadRef`]: offset, length and CRC.
//!
//! **Stored form.** Format 1.x stores the layouts above as they are. Format 2 stores them
//! coded ([`crate::codec`]): a block as `u32` length of the samples' encoding, the samples'
//! encoding (rows of `width`), then the stand-ins' encoding (one row) if there are voids; a
//! grid as `u32` length of the heights' encoding, the heights' encoding (rows of `gw`), then
//! the void bitmap as it is (format 5: behind a flag, raw or as runs, [`crate::codec::voids`]). [`store_block`] and [`store_grid`] code; [`load_block`] and
//! [`load_grid`] give back the layout above, which the views read. The CRC covers the stored
//! bytes, so damage is caught before any decoding.
//!
//! **Against the parent (format 4).** A block may instead code its samples against its
//! parent node's decoded grid ([`store_block_against`], [`load_block_against`],
//! [`crate::codec::parent`]): the quarter of its samples the grid holds are stored once, in
//! the grid. The block record names that node; [`grid_axes`] and [`block_axes`] say where
//! each one's samples lie, which is all the prediction needs.

use std::borrow::Cow;
use std::ops::Range;

use serde::Serialize;
use zerocopy::byteorder::little_endian::F32;
use zerocopy::FromBytes;

use super::VOID_BITS;
use crate::codec;
use crate::codec::parent::{Axes, Parent};
use crate::model::domain::MAX_BLOCK_SIZE;
use crate::model::{Domain, SampleRect};

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

/// How a writer codes a payload's values (§7).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Coding {
    /// One more lattice step the codec tries: the file's storage precision.
    pub step: Option<f64>,
    /// Store every code raw (encoding 0): larger payloads with nothing to decode. What
    /// measuring the codec's cost compares with; `fmrh build` never writes it.
    pub raw: bool,
    /// Against a parent, pick between the two predictions by an estimate and code one
    /// ([`codec::parent::encode_against_quick`]): what a commit does, where coding is most
    /// of its time. A build codes both and keeps the smaller.
    pub quick: bool,
}

impl Coding {
    /// `samples` at `at` coded against `parent` (both predictions tried, or one chosen by
    /// an estimate when `quick`); `None` when that does not apply, or the coding is raw.
    fn code_against(&self, samples: &[f32], at: Axes<'_>, parent: Parent<'_>) -> Option<Vec<u8>> {
        if self.raw {
            None
        } else if self.quick {
            codec::parent::encode_against_quick(samples, at, parent, self.step)
        } else {
            codec::parent::encode_against(samples, at, parent, self.step)
        }
    }

    fn code(&self, samples: &[f32], width: usize) -> Vec<u8> {
        if self.raw {
            codec::encode_raw(samples)
        } else {
            codec::encode_on(samples, width, self.step)
        }
    }
}

/// Format 2: the stored (coded) form of a block's layout `raw` (see the module docs), coded
/// as `coding` says.
pub fn store_block(
    raw: &[u8],
    width: u32,
    height: u32,
    void_count: u32,
    coding: Coding,
) -> Vec<u8> {
    store_block_with(raw, (width, height, void_count), coding, |samples| {
        Some(coding.code(samples, width.max(1) as usize))
    })
    .unwrap_or_default()
}

/// A block's stored form: the samples' code from `code_samples` (`None`: it does not apply),
/// then the stand-ins coded as `coding` says.
fn store_block_with(
    raw: &[u8],
    (width, height, void_count): (u32, u32, u32),
    coding: Coding,
    code_samples: impl FnOnce(&[f32]) -> Option<Vec<u8>>,
) -> Option<Vec<u8>> {
    let n = width as usize * height as usize;
    let floats: Vec<f32> = raw
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let (samples, stand_ins) = floats.split_at(n.min(floats.len()));
    let a = code_samples(samples)?;
    let mut out = Vec::with_capacity(4 + a.len() + 8);
    out.extend_from_slice(&u32::try_from(a.len()).ok()?.to_le_bytes());
    out.extend_from_slice(&a);
    if void_count > 0 && !stand_ins.is_empty() {
        out.extend_from_slice(&coding.code(stand_ins, stand_ins.len()));
    }
    Some(out)
}

/// Format 2: a block's layout from its stored form, or why it does not decode.
pub fn load_block(
    stored: &[u8],
    width: u32,
    height: u32,
    void_count: u32,
) -> Result<Vec<u8>, String> {
    load_block_with(stored, width, height, void_count, |a, samples| {
        codec::decode(a, width.max(1) as usize, samples).map_err(|e| e.to_string())
    })
}

/// Format 4: the stored form of a block's layout `raw` whose samples lie at `at`, with its
/// samples coded against `parent`'s grid ([`codec::parent`]) and its stand-ins as
/// [`store_block`] codes them. `None` when the block does not lie inside the parent, a
/// sample the parent holds differs from the parent's height, or `coding` is raw.
pub fn store_block_against(
    raw: &[u8],
    shape: (u32, u32, u32),
    coding: Coding,
    at: Axes<'_>,
    parent: Parent<'_>,
) -> Option<Vec<u8>> {
    store_block_with(raw, shape, coding, |samples| {
        coding.code_against(samples, at, parent)
    })
}

/// Format 4: a block's layout from its stored form when its samples (at `at`) are coded
/// against `parent`'s grid, or why it does not decode.
pub fn load_block_against(
    stored: &[u8],
    (width, height, void_count): (u32, u32, u32),
    at: Axes<'_>,
    parent: Parent<'_>,
) -> Result<Vec<u8>, String> {
    load_block_with(stored, width, height, void_count, |a, samples| {
        codec::parent::decode_against(a, at, parent, samples).map_err(|e| e.to_string())
    })
}

/// A block's layout from its stored form, its samples decoded by `samples_from`.
fn load_block_with(
    stored: &[u8],
    width: u32,
    height: u32,
    void_count: u32,
    samples_from: impl FnOnce(&[u8], &mut [f32]) -> Result<(), String>,
) -> Result<Vec<u8>, String> {
    check_shape(width, height)?;
    let n = width as usize * height as usize;
    if void_count as usize > n {
        return Err(format!("{void_count} voids in {width} x {height} samples"));
    }
    let (a, b) = split_stored(stored)?;
    let mut floats = vec![0f32; n + void_count as usize];
    let (samples, stand_ins) = floats.split_at_mut(n);
    samples_from(a, samples).map_err(|e| format!("samples: {e}"))?;
    if void_count > 0 {
        codec::decode(b, void_count as usize, stand_ins).map_err(|e| format!("stand-ins: {e}"))?;
    } else if !b.is_empty() {
        return Err(format!(
            "{} bytes after the samples of a block without voids",
            b.len()
        ));
    }
    Ok(floats.iter().flat_map(|v| v.to_le_bytes()).collect())
}

/// Where the samples of a physical block lie: its columns and rows (its footprint clipped
/// to the data, `rect`).
pub fn block_axes(rect: &SampleRect) -> (Vec<u64>, Vec<u64>) {
    (
        (rect.col0..=rect.col1).collect(),
        (rect.row0..=rect.row1).collect(),
    )
}

/// Where the stored samples of the grid of node `(x, y)` at `level` lie: the sample column
/// of each of its `gw` stored columns and the row of each of its `gh` rows, a sample past the
/// data's edge clamped to it (see [`grid_dims`]).
pub fn grid_axes(domain: &Domain, level: u8, x: u32, y: u32) -> (Vec<u64>, Vec<u64>) {
    let fp = domain.footprint(level, x, y);
    let s = domain.stride(level);
    let (gw, gh) = grid_dims(domain, level, x, y);
    let data = domain.data_rect();
    (
        (0..u64::from(gw))
            .map(|i| (fp.col0 + i * s).min(data.col1))
            .collect(),
        (0..u64::from(gh))
            .map(|j| (fp.row0 + j * s).min(data.row1))
            .collect(),
    )
}

/// Where the stored heights of a grid thinned by `2^thin` lie ([`grid_axes`], its columns
/// the kept ones, [`kept_axis`]): what a payload coded against it sees, and what its own
/// heights are coded at.
pub fn stored_grid_axes(
    domain: &Domain,
    level: u8,
    x: u32,
    y: u32,
    thin: u8,
) -> (Vec<u64>, Vec<u64>) {
    let (cols, rows) = grid_axes(domain, level, x, y);
    if thin == 0 {
        return (cols, rows);
    }
    (kept_axis(&cols, thin), rows)
}

/// The kept columns' heights of a row-major grid layout `heights` of `gw` columns thinned by
/// `2^thin` (all of them when `thin` is 0).
pub fn kept_heights(heights: &[f32], gw: u32, thin: u8) -> Vec<f32> {
    if thin == 0 {
        return heights.to_vec();
    }
    let kept: Vec<usize> = crate::model::thinning::kept_columns(gw, 1 << thin)
        .map(|i| i as usize)
        .collect();
    heights
        .chunks_exact(gw.max(1) as usize)
        .flat_map(|row| kept.iter().filter_map(move |&i| row.get(i).copied()))
        .collect()
}

/// Format 2: the stored form of a grid's layout `raw` of `gw × gh` heights (see the module
/// docs), trying the lattice `step` as [`store_block`] does. Format 6: with `thin` > 0 only
/// the kept columns of the layout's heights are coded ([`crate::model::thinning`]).
pub fn store_grid(raw: &[u8], (gw, gh): (u32, u32), thin: u8, coding: Coding) -> Vec<u8> {
    let kw = kept_width(gw, thin);
    store_grid_with(raw, (gw, gh), thin, |heights| {
        Some(coding.code(heights, kw.max(1) as usize))
    })
    .unwrap_or_default()
}

/// How many columns a grid of `gw` stored columns thinned by `2^thin` keeps.
pub fn kept_width(gw: u32, thin: u8) -> u32 {
    crate::model::thinning::kept_count(gw, 1 << thin)
}

/// The sample columns a grid stored thinned by `2^thin` keeps, of its columns `cols`
/// ([`grid_axes`]).
pub fn kept_axis(cols: &[u64], thin: u8) -> Vec<u64> {
    let gw = u32::try_from(cols.len()).unwrap_or(u32::MAX);
    crate::model::thinning::kept_columns(gw, 1 << thin)
        .filter_map(|i| cols.get(i as usize).copied())
        .collect()
}

/// Format 5: the stored form of a grid's layout `raw` of `gw × gh` heights at `at`, its
/// heights coded against `parent`'s grid ([`codec::parent`]) and its bitmap as
/// [`store_grid`] stores it. `None` when the grid does not lie inside the parent, a height
/// the parent holds differs from the parent's, or `coding` is raw. Format 6: a grid thinned
/// by `2^thin` codes its kept columns, which `at` names ([`kept_axis`]), and a parent
/// stored thinned is its kept columns too.
pub fn store_grid_against(
    raw: &[u8],
    (gw, gh): (u32, u32),
    thin: u8,
    coding: Coding,
    at: Axes<'_>,
    parent: Parent<'_>,
) -> Option<Vec<u8>> {
    store_grid_with(raw, (gw, gh), thin, |heights| {
        coding.code_against(heights, at, parent)
    })
}

/// A grid's stored form: the code from `code_heights` (`None`: it does not apply) of its
/// heights (their kept columns when thinned by `2^thin`), then the void bitmap as it is.
fn store_grid_with(
    raw: &[u8],
    (gw, gh): (u32, u32),
    thin: u8,
    code_heights: impl FnOnce(&[f32]) -> Option<Vec<u8>>,
) -> Option<Vec<u8>> {
    let n = gw as usize * gh as usize;
    let heights: Vec<f32> = raw[..(4 * n).min(raw.len())]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    // A square grid codes its layout's heights as they are, without a copy.
    let heights = if thin == 0 {
        heights
    } else {
        kept_heights(&heights, gw, thin)
    };
    let a = code_heights(&heights)?;
    let mut out = Vec::with_capacity(5 + a.len() + raw.len().saturating_sub(4 * n));
    out.extend_from_slice(&u32::try_from(a.len()).ok()?.to_le_bytes());
    out.extend_from_slice(&a);
    // Format 5: the bitmap behind a flag, as runs where that is smaller.
    if let Some(bitmap) = raw.get(4 * n..).filter(|b| !b.is_empty()) {
        crate::codec::voids::write(bitmap, n, gw.max(1) as usize, true, &mut out);
    }
    Some(out)
}

/// Format 2: a grid's layout from its stored form, or why it does not decode. `flagged_bitmap`
/// (the node's flag bit 2, format 5): the bitmap follows a void flag
/// ([`crate::codec::voids`]), else it is raw.
/// Format 6: a grid thinned by `2^thin` decodes its kept columns and expands them back
/// ([`crate::model::thinning::expand_row`]).
pub fn load_grid(
    stored: &[u8],
    (gw, gh): (u32, u32),
    (has_voids, flagged_bitmap): (bool, bool),
    thin: u8,
) -> Result<Vec<u8>, String> {
    let kw = kept_width(gw, thin);
    load_grid_with(
        stored,
        (gw, gh),
        (has_voids, flagged_bitmap),
        thin,
        |a, heights| codec::decode(a, kw.max(1) as usize, heights).map_err(|e| e.to_string()),
    )
}

/// Format 5: a grid's layout from its stored form when its heights (at `at`) are coded
/// against `parent`'s grid, or why it does not decode (`flagged_bitmap` and `thin` as
/// [`load_grid`]; `at` names the kept columns, [`kept_axis`]).
pub fn load_grid_against(
    stored: &[u8],
    (gw, gh): (u32, u32),
    (has_voids, flagged_bitmap): (bool, bool),
    thin: u8,
    at: Axes<'_>,
    parent: Parent<'_>,
) -> Result<Vec<u8>, String> {
    load_grid_with(
        stored,
        (gw, gh),
        (has_voids, flagged_bitmap),
        thin,
        |a, heights| {
            codec::parent::decode_against(a, at, parent, heights).map_err(|e| e.to_string())
        },
    )
}

/// A grid's layout from its stored form, its heights decoded by `heights_from`.
fn load_grid_with(
    stored: &[u8],
    (gw, gh): (u32, u32),
    (has_voids, flagged_bitmap): (bool, bool),
    thin: u8,
    heights_from: impl FnOnce(&[u8], &mut [f32]) -> Result<(), String>,
) -> Result<Vec<u8>, String> {
    check_shape(gw, gh)?;
    if thin > 0
        && (thin > crate::model::thinning::MAX_THIN_LOG2 || (1u32 << thin) >= MAX_BLOCK_SIZE)
    {
        return Err(format!("a grid thinned by 2^{thin}"));
    }
    let n = gw as usize * gh as usize;
    let (a, tail) = split_stored(stored)?;
    let bitmap = match (has_voids, flagged_bitmap, tail.split_first()) {
        (false, _, _) => None,
        (true, false, _) => Some(Cow::Borrowed(tail)),
        (true, true, Some((&flag, rest))) if flag != crate::codec::voids::NONE => {
            let (m, rest) = crate::codec::voids::read(flag, rest, n, gw as usize)
                .map_err(|e| format!("bitmap: {e}"))?;
            if !rest.is_empty() {
                return Err(format!("{} bytes after the bitmap", rest.len()));
            }
            m.map(Cow::Owned)
        }
        (true, true, _) => return Err("no bitmap where the node record says there is".into()),
    };
    let bitmap = bitmap.unwrap_or(Cow::Borrowed(tail));
    let want = if has_voids { n.div_ceil(8) } else { 0 };
    if bitmap.len() != want {
        return Err(format!("{} bitmap bytes, {want} expected", bitmap.len()));
    }
    let kw = kept_width(gw, thin) as usize;
    let mut kept = vec![0f32; kw * gh as usize];
    heights_from(a, &mut kept).map_err(|e| format!("heights: {e}"))?;
    let heights = if thin > 0 {
        let mut full = vec![0f32; n];
        for (row, k) in full
            .chunks_exact_mut(gw as usize)
            .zip(kept.chunks_exact(kw))
        {
            crate::model::thinning::expand_row(k, 1 << thin, row);
        }
        full
    } else {
        kept
    };
    let mut out: Vec<u8> = heights.iter().flat_map(|v| v.to_le_bytes()).collect();
    out.extend_from_slice(&bitmap);
    Ok(out)
}

/// Refuses a block or grid shape no domain has, before anything is sized from it: the
/// shapes come from records, and a damaged record must not make a decoder allocate
/// gigabytes.
fn check_shape(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 || width > MAX_BLOCK_SIZE || height > MAX_BLOCK_SIZE {
        return Err(format!(
            "{width} x {height} samples: a block or grid has 1 to {MAX_BLOCK_SIZE} a side"
        ));
    }
    Ok(())
}

/// The bytes of the first coded part and what follows it.
fn split_stored(stored: &[u8]) -> Result<(&[u8], &[u8]), String> {
    let (len, rest) = stored
        .split_first_chunk::<4>()
        .ok_or_else(|| format!("{} bytes: shorter than its length field", stored.len()))?;
    let len = u32::from_le_bytes(*len) as usize;
    if len > rest.len() {
        return Err(format!("a part of {len} bytes in {} bytes", rest.len()));
    }
    Ok(rest.split_at(len))
}

/// The most bytes the stored form of a layout of `raw_len` bytes takes: the length field,
/// and each coded part's encoding id (raw coding is the fallback).
pub fn max_stored_len(raw_len: u64) -> u64 {
    raw_len + 4 + 2
}

/// Bytes of a physical block's payload.
pub fn block_len(width: u32, height: u32, void_count: u32) -> u64 {
    4 * (u64::from(width) * u64::from(height) + u64::from(void_count))
}

/// The stored columns and rows `(gw, gh)` of the grid of node `(x, y)` at `level`
/// ([`Domain::grid_dims`]).
pub fn grid_dims(domain: &Domain, level: u8, x: u32, y: u32) -> (u32, u32) {
    domain.grid_dims(level, x, y)
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
        let b = self.size;
        (0..b)
            .flat_map(|j| (0..b).map(move |i| (i, j)))
            .map(|(i, j)| self.height(i, j))
            .collect()
    }
}

#[cfg(test)]
mod stored_tests {
    use super::*;

    /// Regression (found by the open_verify fuzz target): a damaged block record's void count
    /// or shape made the decoder size a buffer from it (gigabytes) before anything was read.
    #[test]
    fn shapes_from_records_are_checked_before_allocating() {
        let raw = encode_block((0..81).map(|i| (i as f32, true)), 81);
        let stored = store_block(&raw, 9, 9, 0, Coding::default());
        assert_eq!(load_block(&stored, 9, 9, 0).expect("decodes"), raw);
        // Refused by the shape check itself, not later by a decoder that had allocated.
        let refused = |r: Result<Vec<u8>, String>, why: &str| {
            assert!(r.as_ref().is_err_and(|e| e.contains(why)), "{r:?}")
        };
        refused(load_block(&stored, 9, 9, u32::MAX), "voids in");
        refused(load_block(&stored, 9, 9, 82), "voids in");
        refused(load_block(&stored, 1 << 20, 9, 0), "a side");
        refused(load_block(&stored, 0, 9, 0), "a side");
        refused(
            load_grid(&stored, (u32::MAX, u32::MAX), (true, true), 0),
            "a side",
        );
    }

    #[test]
    fn stored_forms_round_trip() {
        let samples: Vec<(f32, bool)> = (0..9 * 7)
            .map(|i| ((i % 9) as f32 * 0.5 + (i / 9) as f32, i % 11 != 3))
            .collect();
        let voids = u32::try_from(samples.iter().filter(|s| !s.1).count()).expect("63 at most");
        let raw = encode_block(samples.into_iter(), 63);
        let stored = store_block(&raw, 9, 7, voids, Coding::default());
        assert!(stored.len() < raw.len());
        assert_eq!(load_block(&stored, 9, 7, voids).expect("decodes"), raw);
        let heights: Vec<f32> = (0..25).map(|i| i as f32).collect();
        let void: Vec<bool> = (0..25).map(|i| i % 7 == 0).collect();
        let raw = encode_grid(&heights, &void, true);
        let stored = store_grid(&raw, (5, 5), 0, Coding::default());
        assert_eq!(
            load_grid(&stored, (5, 5), (true, true), 0).expect("decodes"),
            raw
        );
        assert!(
            load_grid(&stored, (5, 5), (false, true), 0).is_err(),
            "the bitmap is not expected"
        );
        let mut longer = stored.clone();
        longer.push(0);
        assert!(load_grid(&longer, (5, 5), (true, true), 0).is_err());
        // Before format 5 the bitmap followed raw, with no flag.
        let a = u32::from_le_bytes(stored[..4].try_into().expect("a length")) as usize;
        let mut old = stored[..4 + a].to_vec();
        old.extend_from_slice(&raw[4 * 25..]);
        assert_eq!(
            load_grid(&old, (5, 5), (true, false), 0).expect("decodes"),
            raw
        );
        assert!(load_grid(&old, (5, 5), (true, true), 0).is_err());
    }
}
