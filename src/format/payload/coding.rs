//! The stored form of a payload (format 2 and later, `container.md` §7), one entry each way:
//! [`encode`] turns a layout into its stored bytes, [`decode`] the stored bytes back into the
//! layout, either alone or against the grid a payload is coded against ([`ParentGrid`]). The
//! codecs themselves ([`crate::codec`]) know nothing of blocks, grids or voids' stand-ins;
//! this is where a layout's parts meet them.
//!
//! A block is stored as a `u32` length of its samples' code, the samples' code (rows of
//! `width`; against its parent: encodings 5 to 8), then the stand-ins' code (one row) if it
//! has voids. A grid is stored as a `u32` length of its heights' code, the heights' code
//! (rows of `gw`, or of `kw` kept columns when thinned by area; against its parent: 5 to 8),
//! then the void bitmap (behind a void flag since format 5, raw before).

use std::borrow::Cow;

use super::place::{kept_heights, kept_width, ParentGrid, Placement};
use crate::codec;
use crate::codec::parent::{Axes, Parent};
use crate::model::domain::MAX_BLOCK_SIZE;

/// `layout` placed by `placement`, stored as `coding` says: coded alone when `against` is
/// `None` (always `Some`), else coded against that grid, `None` when that does not apply
/// (the payload does not lie inside the grid, a sample the grid holds differs from the
/// grid's height, or `coding` is raw). A writer codes both ways and keeps the smaller.
pub fn encode(
    layout: &[u8],
    placement: &Placement,
    coding: Coding,
    against: Option<&ParentGrid>,
) -> Option<Vec<u8>> {
    let (w, h) = placement.dims();
    let code = |values: &[f32], width: u32| -> Option<Vec<u8>> {
        match against {
            None => Some(coding.code(values, width.max(1) as usize)),
            Some(p) => {
                let (cols, rows) = placement.axes();
                coding.code_against(
                    values,
                    Axes {
                        cols: &cols,
                        rows: &rows,
                    },
                    p.parent(),
                )
            }
        }
    };
    match *placement {
        Placement::Block { void_count, .. } => {
            store_block_with(layout, (w, h, void_count), coding, |s| code(s, w))
        }
        Placement::Grid { thin, .. } => {
            store_grid_with(layout, (w, h), thin, |s| code(s, kept_width(w, thin)))
        }
    }
}

/// The codes a file's version admits (§7, §8). A code outside them is a corrupt payload,
/// even one this reader could decode: a file of an older major was written before the code
/// existed, so it cannot hold one undamaged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codes {
    /// Formats 2.0 to 6.x: encodings 0 to 8, every residual stream by pco.
    Pco,
    /// Format 7.0 and later: encodings 0 to 15, residual streams by pco or tANS.
    PcoOrTans,
}

impl Codes {
    /// The codes a file of major version `major` (2 or later) admits.
    pub fn of_major(major: u16) -> Codes {
        if major >= 7 {
            Codes::PcoOrTans
        } else {
            Codes::Pco
        }
    }

    /// Refuses `code` (a code: its id byte, then its body) when its id is not one of these.
    /// An id no version has is left to the codec, which refuses it too.
    fn admit(self, code: &[u8]) -> Result<(), String> {
        match (self, codec::Encoding::of(code)) {
            (Codes::Pco, Some(e)) if e.coder() == codec::Coder::Tans => Err(format!(
                "encoding {} in a file older than format 7, whose codes are 0 to 8",
                e as u8
            )),
            _ => Ok(()),
        }
    }
}

/// The layout of the payload placed by `placement` from its stored bytes `stored`, decoded
/// against `against` when it is coded against a grid (the caller knows from its record), or
/// why it does not decode; a code that `codes` (from the file's version) does not admit is
/// refused. Hostile bytes are an error, never a panic, and nothing is sized from them: the
/// shapes come from `placement`, checked against a block's largest.
pub fn decode(
    stored: &[u8],
    placement: &Placement,
    against: Option<&ParentGrid>,
    codes: Codes,
) -> Result<Vec<u8>, String> {
    let (w, h) = placement.dims();
    let values = |a: &[u8], out: &mut [f32], width: u32| -> Result<(), String> {
        codes.admit(a)?;
        match against {
            None => codec::decode(a, width.max(1) as usize, out).map_err(|e| e.to_string()),
            Some(p) => {
                let (cols, rows) = placement.axes();
                codec::parent::decode_against(
                    a,
                    Axes {
                        cols: &cols,
                        rows: &rows,
                    },
                    p.parent(),
                    out,
                )
                .map_err(|e| e.to_string())
            }
        }
    };
    match *placement {
        Placement::Block { void_count, .. } => {
            load_block_with(stored, (w, h, void_count), codes, |a, s| values(a, s, w))
        }
        Placement::Grid {
            has_voids,
            flagged_bitmap,
            thin,
            ..
        } => load_grid_with(stored, (w, h), (has_voids, flagged_bitmap), thin, |a, s| {
            values(a, s, kept_width(w, thin))
        }),
    }
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
    /// The coder of the residual streams: pco (encodings 2, 4–8) or tANS (9–14, format 7).
    pub coder: codec::Coder,
}

impl Coding {
    /// `samples` at `at` coded against `parent` (both predictions tried, or one chosen by
    /// an estimate when `quick`); `None` when that does not apply, or the coding is raw.
    fn code_against(&self, samples: &[f32], at: Axes<'_>, parent: Parent<'_>) -> Option<Vec<u8>> {
        if self.raw {
            None
        } else if self.quick {
            codec::parent::encode_against_quick(samples, at, parent, self.step, self.coder)
        } else {
            codec::parent::encode_against(samples, at, parent, self.step, self.coder)
        }
    }

    fn code(&self, samples: &[f32], width: usize) -> Vec<u8> {
        if self.raw {
            codec::encode_raw(samples)
        } else {
            codec::encode_on(samples, width, self.step, self.coder)
        }
    }
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

/// A block's layout from its stored form, its samples decoded by `samples_from`, its
/// stand-ins alone (a code `codes` admits).
fn load_block_with(
    stored: &[u8],
    (width, height, void_count): (u32, u32, u32),
    codes: Codes,
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
        codes
            .admit(b)
            .and_then(|()| {
                codec::decode(b, void_count as usize, stand_ins).map_err(|e| e.to_string())
            })
            .map_err(|e| format!("stand-ins: {e}"))?;
    } else if !b.is_empty() {
        return Err(format!(
            "{} bytes after the samples of a block without voids",
            b.len()
        ));
    }
    Ok(layout_bytes(&floats, &[]))
}

/// The little-endian bytes of `heights` then `tail`: a layout (a copy, not a loop a byte at
/// a time).
fn layout_bytes(heights: &[f32], tail: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 * heights.len() + tail.len());
    if cfg!(target_endian = "little") {
        out.extend_from_slice(zerocopy::IntoBytes::as_bytes(heights));
    } else {
        out.extend(heights.iter().flat_map(|v| v.to_le_bytes()));
    }
    out.extend_from_slice(tail);
    out
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
        codec::voids::write(bitmap, n, gw.max(1) as usize, true, &mut out);
    }
    Some(out)
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
        (true, true, Some((&flag, rest))) if flag != codec::voids::NONE => {
            let (m, rest) = codec::voids::read(flag, rest, n, gw as usize)
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
    Ok(layout_bytes(&heights, &bitmap))
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

#[cfg(test)]
mod stored_tests {
    use super::super::{encode_block, encode_grid};
    use super::*;
    use crate::model::{Domain, SampleRect};

    const ALL: Codes = Codes::PcoOrTans;

    fn block(w: u64, h: u64, void_count: u32) -> Placement {
        Placement::block(
            SampleRect {
                col0: 0,
                row0: 0,
                col1: w - 1,
                row1: h - 1,
            },
            void_count,
        )
    }

    /// The root grid of 7 x 17 samples in blocks of 9: stored 5 x 9 (the fifth column the
    /// clamp column), with a bitmap behind a void flag when `flagged`.
    fn grid(has_voids: bool, flagged_bitmap: bool) -> Placement {
        Placement::Grid {
            domain: Domain::new(7, 17, 9).expect("a domain"),
            level: 0,
            x: 0,
            y: 0,
            has_voids,
            flagged_bitmap,
            thin: 0,
        }
    }

    /// Regression (found by the open_verify fuzz target): a damaged block record's void count
    /// or shape made the decoder size a buffer from it (gigabytes) before anything was read.
    #[test]
    fn shapes_from_records_are_checked_before_allocating() {
        let raw = encode_block((0..81).map(|i| (i as f32, true)), 81);
        let stored = encode(&raw, &block(9, 9, 0), Coding::default(), None).expect("codes");
        assert_eq!(
            decode(&stored, &block(9, 9, 0), None, ALL).expect("decodes"),
            raw
        );
        // Refused by the shape check itself, not later by a decoder that had allocated.
        let refused = |r: Result<Vec<u8>, String>, why: &str| {
            assert!(r.as_ref().is_err_and(|e| e.contains(why)), "{r:?}")
        };
        refused(decode(&stored, &block(9, 9, u32::MAX), None, ALL), "voids in");
        refused(decode(&stored, &block(9, 9, 82), None, ALL), "voids in");
        refused(decode(&stored, &block(1 << 20, 9, 0), None, ALL), "a side");
        let never = |_: &[u8], _: &mut [f32]| -> Result<(), String> { unreachable!() };
        refused(load_block_with(&stored, (0, 9, 0), ALL, never), "a side");
        refused(
            load_grid_with(&stored, (u32::MAX, u32::MAX), (true, true), 0, never),
            "a side",
        );
    }

    /// Blocks and grids, voids among them, stored by either coder, decode to their layout.
    #[test]
    fn stored_forms_round_trip() {
        for coder in [codec::Coder::Pco, codec::Coder::Tans] {
            let coding = Coding {
                coder,
                ..Coding::default()
            };
            let samples: Vec<(f32, bool)> = (0..9 * 7)
                .map(|i| ((i % 9) as f32 * 0.5 + (i / 9) as f32, i % 11 != 3))
                .collect();
            let voids = u32::try_from(samples.iter().filter(|s| !s.1).count()).expect("63 at most");
            let raw = encode_block(samples.into_iter(), 63);
            let at = block(9, 7, voids);
            let stored = encode(&raw, &at, coding, None).expect("codes");
            assert!(stored.len() < raw.len());
            assert_eq!(decode(&stored, &at, None, ALL).expect("decodes"), raw);
            let (gw, gh) = grid(true, true).dims();
            assert_eq!((gw, gh), (5, 9));
            let n = (gw * gh) as usize;
            let heights: Vec<f32> = (0..n).map(|i| i as f32).collect();
            let void: Vec<bool> = (0..n).map(|i| i % 7 == 0).collect();
            let raw = encode_grid(&heights, &void, true);
            let stored = encode(&raw, &grid(true, true), coding, None).expect("codes");
            assert_eq!(
                decode(&stored, &grid(true, true), None, ALL).expect("decodes"),
                raw
            );
            assert!(
                decode(&stored, &grid(false, true), None, ALL).is_err(),
                "the bitmap is not expected"
            );
            let mut longer = stored.clone();
            longer.push(0);
            assert!(decode(&longer, &grid(true, true), None, ALL).is_err());
            // Before format 5 the bitmap followed raw, with no flag.
            let a = u32::from_le_bytes(stored[..4].try_into().expect("a length")) as usize;
            let mut old = stored[..4 + a].to_vec();
            old.extend_from_slice(&raw[4 * n..]);
            assert_eq!(
                decode(&old, &grid(true, false), None, ALL).expect("decodes"),
                raw
            );
            assert!(decode(&old, &grid(true, true), None, ALL).is_err());
        }
    }

    /// A file older than format 7 admits codes 0 to 8 only: a tANS code in it (samples,
    /// stand-ins or a grid's heights) is a corrupt payload, even though this reader could
    /// decode it; the same bytes decode in a 7.x file, and pco codes decode in both.
    #[test]
    fn a_tans_code_in_an_older_file_is_refused() {
        let samples: Vec<(f32, bool)> = (0..9 * 9)
            .map(|i| ((i % 9) as f32 * 0.25 + (i / 9) as f32, i % 13 != 5))
            .collect();
        let voids = u32::try_from(samples.iter().filter(|s| !s.1).count()).expect("81 at most");
        let raw = encode_block(samples.into_iter(), 81);
        let at = block(9, 9, voids);
        let (gw, gh) = grid(false, false).dims();
        let heights: Vec<f32> = (0..gw * gh).map(|i| (i % 5) as f32 * 0.5).collect();
        let raw_grid = encode_grid(&heights, &vec![false; heights.len()], false);
        for coder in [codec::Coder::Pco, codec::Coder::Tans] {
            let coding = Coding {
                coder,
                ..Coding::default()
            };
            let stored = encode(&raw, &at, coding, None).expect("codes");
            let stored_grid = encode(&raw_grid, &grid(false, false), coding, None).expect("codes");
            let a = u32::from_le_bytes(stored[..4].try_into().expect("a length")) as usize;
            let ids = [stored[4], stored[4 + a], stored_grid[4]];
            let tans = ids.map(|id| id >= 9);
            assert_eq!(tans, [coder == codec::Coder::Tans; 3], "ids {ids:?}");
            assert_eq!(decode(&stored, &at, None, ALL).expect("decodes"), raw);
            assert_eq!(
                decode(&stored_grid, &grid(false, false), None, ALL).expect("decodes"),
                raw_grid
            );
            for (r, what) in [
                (decode(&stored, &at, None, Codes::Pco), "samples"),
                (decode(&stored_grid, &grid(false, false), None, Codes::Pco), "heights"),
            ] {
                match coder {
                    codec::Coder::Pco => assert!(r.is_ok(), "{r:?}"),
                    codec::Coder::Tans => assert!(
                        r.as_ref()
                            .is_err_and(|e| e.starts_with(what) && e.contains("older than format 7")),
                        "{r:?}"
                    ),
                }
            }
        }
        // Pco samples beside tANS stand-ins: the stand-ins alone are refused.
        let pco = encode(&raw, &at, Coding::default(), None).expect("codes");
        let tans = encode(
            &raw,
            &at,
            Coding {
                coder: codec::Coder::Tans,
                ..Coding::default()
            },
            None,
        )
        .expect("codes");
        let (pa, ta) = (
            u32::from_le_bytes(pco[..4].try_into().expect("a length")) as usize,
            u32::from_le_bytes(tans[..4].try_into().expect("a length")) as usize,
        );
        let mut mixed = pco[..4 + pa].to_vec();
        mixed.extend_from_slice(&tans[4 + ta..]);
        assert_eq!(decode(&mixed, &at, None, ALL).expect("decodes"), raw);
        let r = decode(&mixed, &at, None, Codes::Pco);
        assert!(
            r.as_ref().is_err_and(|e| e.starts_with("stand-ins")),
            "{r:?}"
        );
        assert_eq!(Codes::of_major(6), Codes::Pco);
        assert_eq!(Codes::of_major(7), Codes::PcoOrTans);
    }
}
