//! Fuzz target: block codecs. The first two bytes give a block's width and rows (1..=64).
//! Then, by the third byte's low bit, either the rest is an encoded block (and a stored block
//! and grid payload), which must decode or fail with an error (never panic, never write past
//! the block), or the rest is samples
//! (`f32` bits, or lattice values), which must encode and decode back bit for bit.
//!
//! cargo fuzz run --sanitizer none codec

#![no_main]

use libfuzzer_sys::fuzz_target;

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
        let _ = fmrh::format::payload::load_block(rest, w, h, voids);
        let _ = fmrh::format::payload::load_grid(rest, w, h, mode & 2 != 0);
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
    let bytes = fmrh::codec::encode(&samples, width);
    let mut out = vec![0.0f32; n];
    fmrh::codec::decode(&bytes, width, &mut out).expect("an encoding decodes");
    for (a, b) in samples.iter().zip(&out) {
        assert_eq!(a.to_bits(), b.to_bits());
    }
});
