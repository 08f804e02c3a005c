//! The coder study's own pieces (`FMRH_CODER_STUDY=1 cargo bench --bench decode`, issue 44):
//! the residuals as the coder takes them, encoding 2's planar rebuild, and the coder fused
//! with that rebuild. The coder itself is `fmrh::codec::tans` (the binned tANS stream planned
//! for format 7, `docs/format-7-plan.md`); this asks, beside it, whether decoding each
//! residual where the planar rebuild consumes it (one loop, no buffer between,
//! [`decode_planar`]) beats running the two one after the other (the coder, then
//! [`planar`]). Measured: no.

use fmrh::codec::tans::Decoder;

/// A lattice residual's code: zigzag, small for small residuals either way.
pub fn zigzag(x: i64) -> u64 {
    ((x << 1) ^ (x >> 63)) as u64
}

/// The residual of a code below 2^32 ([`zigzag`]'s inverse).
#[inline(always)]
pub fn residual(z: u32) -> i64 {
    i64::from((z >> 1) as i32 ^ -((z & 1) as i32))
}

/// [`Decoder::decode`] of lattice residuals fused with [`planar`]'s rebuild: each code
/// becomes its residual (`zigzag⁻¹ · factor`), then its sample, in one loop, so that the
/// coder's chain (its bit position) and the planar sum's run side by side. `above` is a
/// row of `w` zeros on entry.
pub fn decode_planar(
    decoder: &mut Decoder,
    stream: &[u8],
    factor: i64,
    w: usize,
    q: f64,
    above: &mut [i64],
    out: &mut [f32],
) {
    let (mut left, mut up_left, mut c) = (0i64, 0i64, 0usize);
    let decoded = decoder.decode(stream, out, |z| {
        if c == 0 {
            (left, up_left) = (0, 0);
        }
        let up = above[c];
        let k = left + up - up_left + residual(z) * factor;
        (up_left, left) = (up, k);
        above[c] = k;
        c += 1;
        if c == w {
            c = 0;
        }
        (k as f64 * q) as f32
    });
    decoded.expect("a stream the coder wrote");
}

/// Encoding 2's rebuild of `w`-wide rows from their residuals `r`, the samples `k · q`: the
/// planar predictor (left + up − up-left, zeros outside), one pass a row after the residuals
/// are decoded, as the codec runs it after pco. `above` is a row of `w` zeros on entry.
pub fn planar(r: &[i64], w: usize, q: f64, above: &mut [i64], out: &mut [f32]) {
    for (r, o) in r.chunks(w).zip(out.chunks_mut(w)) {
        let (mut left, mut up_left) = (0i64, 0i64);
        for ((&r, o), a) in r.iter().zip(o).zip(above.iter_mut()) {
            let up = *a;
            let k = left + up - up_left + r;
            (up_left, left) = (up, k);
            *a = k;
            *o = (k as f64 * q) as f32;
        }
    }
}
