//! Fuzz target: block codecs. The first two bytes give a block's width and rows (1..=64).
//! Then, by the third byte's low bit, either the rest is an encoded block (and a stored block
//! and grid payload, and a block coded against a parent grid), which must decode or fail with
//! an error (never panic, never write past the block; the stored forms with the codes of a
//! format 7 file, or by bit 6 of an older one's), or the rest is samples
//! (`f32` bits, or lattice values), which must encode and decode back bit for bit, alone and
//! against a parent grid holding every other sample (format 4), their residuals coded by pco
//! or, by the third byte's bit 2, by format 7's tANS stream (encodings 9 to 14). Both ways,
//! the same bytes also go through the binned tANS coder alone (`codec::tans`): as a stream of
//! `width × rows` codes, which must decode or fail, and whose codes, when it decodes, must
//! code and decode back; and the samples' bits as codes, which must round-trip.
//!
//! cargo fuzz run --sanitizer none codec

#![no_main]

use fmrh::codec::parent::{decode_against, encode_against, Axes, Parent};
use fmrh::codec::{tans, Coder};
use fmrh::format::payload::{self, ParentGrid, Placement};
use libfuzzer_sys::fuzz_target;

/// Every other coordinate of `0..n`, and the last (a parent's axis, clamped at the edge).
fn parent_axis(n: usize) -> Vec<u64> {
    let mut a: Vec<u64> = (0..n as u64).step_by(2).collect();
    if (n - 1) % 2 == 1 {
        a.push(n as u64 - 1);
    }
    a
}

/// The parent's heights: the child's samples it holds, voids mended to 0.
fn parent_heights(samples: &[f32], width: usize, pc: &[u64], pr: &[u64]) -> Vec<f32> {
    pr.iter()
        .flat_map(|&r| {
            pc.iter().map(move |&c| {
                let v = samples[r as usize * width + c as usize];
                if v.is_nan() {
                    0.0
                } else {
                    v
                }
            })
        })
        .collect()
}

/// Codes `codes` with the tANS coder and decodes them back, panicking on any difference.
fn codes_round_trip(codes: &[u32]) {
    let mut stream = Vec::new();
    tans::encode(codes, &mut stream);
    let mut back = vec![0u32; codes.len()];
    tans::Decoder::default()
        .decode(&stream, &mut back, |v| v)
        .expect("the coder's own stream decodes");
    assert_eq!(back, codes);
}

fuzz_target!(|data: &[u8]| {
    let [w, r, mode, rest @ ..] = data else {
        return;
    };
    let (width, rows) = (usize::from(w % 64) + 1, usize::from(r % 64) + 1);
    if mode & 1 == 0 {
        let mut out = vec![0.0f32; width * rows];
        let _ = fmrh::codec::decode(rest, width, &mut out);
        // The stored payload forms around the codes (format 2.0, container.md §7).
        let (w, h) = (width as u32, rows as u32);
        let voids = u32::from(mode >> 2) % (w * h + 1);
        let rect = fmrh::model::SampleRect {
            col0: 0,
            row0: 0,
            col1: u64::from(w) - 1,
            row1: u64::from(h) - 1,
        };
        let block = Placement::block(rect, voids);
        // Bit 6: the codes of a file older than format 7 (tANS codes refused), else 7's.
        let codes = if mode & 64 != 0 { payload::Codes::Pco } else { payload::Codes::PcoOrTans };
        let _ = payload::decode(rest, &block, None, codes);
        // Format 6: grids thinned by up to 2^7 (the decoder refuses what a grid cannot hold):
        // the root of a w x h grid in blocks of 65.
        let thin = (mode >> 3) & 7;
        if let Ok(domain) = fmrh::model::Domain::new(w, h, 65) {
            let grid = Placement::Grid {
                domain,
                level: 0,
                x: 0,
                y: 0,
                has_voids: mode & 2 != 0,
                flagged_bitmap: mode & 4 != 0,
                thin,
            };
            let _ = payload::decode(rest, &grid, None, codes);
        }
        let (cols, rows_at): (Vec<u64>, Vec<u64>) =
            ((0..width as u64).collect(), (0..rows as u64).collect());
        let (pc, pr) = (parent_axis(width), parent_axis(rows));
        let heights: Vec<f32> = (0..pc.len() * pr.len())
            .map(|i| f32::from(rest.get(i).copied().unwrap_or(0)))
            .collect();
        let at = Axes { cols: &cols, rows: &rows_at };
        let parent = Parent { at: Axes { cols: &pc, rows: &pr }, heights: &heights };
        let _ = decode_against(rest, at, parent, &mut out);
        if let Some(p) = ParentGrid::from_parts(pc.clone(), pr.clone(), heights.clone()) {
            let _ = payload::decode(rest, &block, Some(&p), codes);
        }
        let mut codes = vec![0u32; width * rows];
        if tans::Decoder::default().decode(rest, &mut codes, |v| v).is_ok() {
            codes_round_trip(&codes);
        }
        return;
    }
    let n = width * rows;
    let samples: Vec<f32> = (0..n)
        .map(|i| {
            let b = rest.get(4 * i..4 * i + 4).map_or(0, |b| {
                u32::from_le_bytes([b[0], b[1], b[2], b[3]])
            });
            if mode & 2 != 0 {
                // Lattice values, some voids: the lattice path.
                if b % 13 == 0 {
                    f32::from_bits(fmrh::codec::VOID_BITS)
                } else {
                    ((b % 100_000) as f32 - 50_000.0) * 0.1
                }
            } else {
                f32::from_bits(b)
            }
        })
        .collect();
    codes_round_trip(&samples.iter().map(|v| v.to_bits()).collect::<Vec<u32>>());
    let coder = if mode & 4 != 0 { Coder::Tans } else { Coder::Pco };
    let bytes = fmrh::codec::encode_on(&samples, width, None, coder);
    let mut out = vec![0.0f32; n];
    fmrh::codec::decode(&bytes, width, &mut out).expect("an encoding decodes");
    for (a, b) in samples.iter().zip(&out) {
        assert_eq!(a.to_bits(), b.to_bits());
    }
    let (cols, rows_at): (Vec<u64>, Vec<u64>) =
        ((0..width as u64).collect(), (0..rows as u64).collect());
    let (pc, pr) = (parent_axis(width), parent_axis(rows));
    let heights = parent_heights(&samples, width, &pc, &pr);
    let at = Axes { cols: &cols, rows: &rows_at };
    let parent = Parent { at: Axes { cols: &pc, rows: &pr }, heights: &heights };
    // Refused only for a NaN that is not the canonical void.
    let odd_nan = samples
        .iter()
        .any(|v| v.is_nan() && v.to_bits() != fmrh::codec::VOID_BITS);
    match encode_against(&samples, at, parent, None, coder) {
        Some(bytes) => {
            let mut back = vec![0.0f32; n];
            decode_against(&bytes, at, parent, &mut back).expect("an encoding decodes");
            for (a, b) in samples.iter().zip(&back) {
                assert_eq!(a.to_bits(), b.to_bits());
            }
        }
        None => assert!(odd_nan, "a child of its parent was refused"),
    }
});
