//! The residual streams of the predicted encodings: pco's (formats 2 to 6) or the binned
//! tANS stream of [`tans`] (format 7), one entry each way for each kind of residual. The
//! encodings around them know only that residuals come back; which coder wrote a payload's
//! is its encoding id's business (`container.md` §7: ids 2, 4–8 are pco, 9–14 the same
//! shapes with tANS).
//!
//! **Lattice residuals** (`i64`: an index less its prediction) go into tANS as a common
//! factor `f` (LEB128, `1 ≤ f < 2^32`) and the zigzag codes of `r / f` as `i32`. The factor
//! is the residuals' greatest common divisor: a source stored on a coarser step than the
//! lattice the codec finds (Puget Sound 4k lies on 25.6 m but on no step coarser than
//! 0.1 m the codec tries) costs `log₂ f` bits a residual less. Where a quotient does not fit an
//! `i32` (a cliff of more than 2^31 steps, or wrapped residuals of hostile heights), the
//! residuals go to pco as before, under the pco id: every block still has an encoding.
//!
//! **Float residuals** (`u32` zigzag codes of ordered bits) go into either as they are.
//!
//! The tANS decoder's table is one per thread, kept from payload to payload, so that a warm
//! decoder allocates nothing.

use std::cell::RefCell;

use pco::standalone::simple_compress;
use pco::{ChunkConfig, DeltaSpec};

use super::voids::varint;
use super::{pco_decode, tans, unzigzag, with_scratch, zigzag, DecodeError};

/// The coder of a payload's residual streams.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coder {
    /// pco (pcodec), every format from 2 on: encodings 2 and 4 to 8.
    #[default]
    Pco,
    /// The binned tANS stream of [`tans`], format 7 on: encodings 9 to 14, with pco where a
    /// block's lattice residuals do not fit (see the module's text).
    Tans,
}

/// The codes of `residuals` in a stream of `coder`, and the coder that took them (pco when
/// tANS was asked for but a residual over the common factor does not fit an `i32`).
pub(super) fn code_lattice(coder: Coder, residuals: &[i64]) -> Option<(Coder, Vec<u8>)> {
    if coder == Coder::Tans {
        if let Some(bytes) = tans_lattice(residuals) {
            return Some((Coder::Tans, bytes));
        }
    }
    Some((Coder::Pco, pco(residuals)?))
}

/// The codes of `residuals` (zigzag codes) in a stream of `coder`.
pub(super) fn code_float(coder: Coder, residuals: &[u32]) -> Option<Vec<u8>> {
    match coder {
        Coder::Pco => pco(residuals),
        Coder::Tans => {
            let mut out = Vec::with_capacity(residuals.len() + 16);
            tans::encode(residuals, &mut out);
            Some(out)
        }
    }
}

/// Decodes exactly `out.len()` lattice residuals from `stream` (all of it), written by `coder`.
pub(super) fn read_lattice(
    coder: Coder,
    stream: &[u8],
    out: &mut [i64],
) -> Result<(), DecodeError> {
    match coder {
        Coder::Pco => pco_decode(stream, out),
        Coder::Tans => {
            let (f, at) = tans::read_varint(stream)
                .filter(|&(f, _)| (1..=u64::from(u32::MAX)).contains(&f))
                .ok_or(DecodeError::Factor)?;
            // The codes as they are, then widened and scaled in a loop of their own, which
            // the compiler vectorises: in the decoder's loop, the widening was a quarter of
            // a code's instructions, and that loop is bound by how many it issues.
            with_scratch(out.len(), |codes: &mut [u32]| {
                with_decoder(|d| d.decode(&stream[at..], codes, |v| v)).map_err(DecodeError::Tans)?;
                widen(codes, f as u32, out);
                Ok(())
            })
        }
    }
}

wide! {
    /// The residuals `unzigzag(c) · f` of codes `codes` into `out`. (`|unzigzag(c)| ≤ 2^31`
    /// and `f < 2^32`: the product fits an `i64`.) A factor that fits an `i32` multiplies
    /// as one, which AVX2 does four at once.
    fn widen(codes: &[u32], f: u32, out: &mut [i64]) {
        match i32::try_from(f) {
            Ok(f) => {
                for (o, &c) in out.iter_mut().zip(codes) {
                    *o = i64::from(unzigzag(c) as i32) * i64::from(f);
                }
            }
            Err(_) => {
                for (o, &c) in out.iter_mut().zip(codes) {
                    *o = i64::from(unzigzag(c) as i32) * i64::from(f);
                }
            }
        }
    }
}

/// Decodes exactly `out.len()` float residuals (zigzag codes) from `stream` (all of it),
/// written by `coder`.
pub(super) fn read_float(coder: Coder, stream: &[u8], out: &mut [u32]) -> Result<(), DecodeError> {
    match coder {
        Coder::Pco => pco_decode(stream, out),
        Coder::Tans => {
            with_decoder(|d| d.decode(stream, out, |v| v)).map_err(DecodeError::Tans)
        }
    }
}

/// pco's stream of `numbers`, without its delta stage (the predictions are ours).
fn pco<T: pco::data_types::Number>(numbers: &[T]) -> Option<Vec<u8>> {
    let config = ChunkConfig::default().with_delta_spec(DeltaSpec::NoOp);
    simple_compress(numbers, &config).ok()
}

/// The common factor and tANS stream of `residuals`, when every quotient fits an `i32`.
fn tans_lattice(residuals: &[i64]) -> Option<Vec<u8>> {
    let f = residuals.iter().fold(0u64, |g, &r| gcd(g, r.unsigned_abs())).max(1);
    if f > u64::from(u32::MAX) {
        return None;
    }
    let f = f as i64;
    let codes = residuals
        .iter()
        .map(|&r| i32::try_from(r / f).ok().map(|q| zigzag(q as u32)))
        .collect::<Option<Vec<u32>>>()?;
    let mut out = Vec::with_capacity(codes.len() + 16);
    varint(f as u64, &mut out);
    tans::encode(&codes, &mut out);
    Some(out)
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Runs `f` with this thread's tANS decoder (its table kept from stream to stream).
fn with_decoder<R>(f: impl FnOnce(&mut tans::Decoder) -> R) -> R {
    thread_local! {
        static DECODER: RefCell<tans::Decoder> = RefCell::new(tans::Decoder::default());
    }
    DECODER.with(|d| match d.try_borrow_mut() {
        Ok(mut d) => f(&mut d),
        // Re-entered (no decoder does): a table of its own.
        Err(_) => f(&mut tans::Decoder::default()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn lattice_round_trip(coder: Coder, r: &[i64]) -> (Coder, Vec<u8>) {
        let (used, bytes) = code_lattice(coder, r).expect("codes");
        let mut back = vec![0i64; r.len()];
        read_lattice(used, &bytes, &mut back).expect("decodes");
        assert_eq!(back, r);
        (used, bytes)
    }

    #[test]
    fn the_common_factor_is_stored_and_divides_out() {
        let r: Vec<i64> = (0..500).map(|i| ((i * 37) % 11 - 5) * 256).collect();
        let (used, bytes) = lattice_round_trip(Coder::Tans, &r);
        assert_eq!(used, Coder::Tans);
        assert_eq!(&bytes[..2], &[0x80, 0x02], "f = 256 as LEB128");
        let ones: Vec<i64> = r.iter().map(|&x| x / 256).collect();
        let (_, small) = lattice_round_trip(Coder::Tans, &ones);
        assert_eq!(bytes.len(), small.len() + 1, "the factor costs its byte, nothing more");
        // All zero: a factor of one.
        let (_, zeros) = lattice_round_trip(Coder::Tans, &[0; 40]);
        assert_eq!(zeros[0], 1);
    }

    #[test]
    fn residuals_past_an_i32_go_to_pco() {
        let mut r = vec![1i64, -3, 2, 0];
        r.push(1 << 33);
        assert_eq!(lattice_round_trip(Coder::Tans, &r).0, Coder::Pco);
        r.push(i64::MIN);
        assert_eq!(lattice_round_trip(Coder::Tans, &r).0, Coder::Pco);
        // Large but with a factor that brings them into an `i32`.
        let big = [3i64 << 31, -(5 << 31), 0, 1 << 31];
        assert_eq!(lattice_round_trip(Coder::Tans, &big).0, Coder::Tans);
        // A factor of 2^32 or more is not stored.
        let huge = [3i64 << 40, -(5 << 40), 0, 1 << 40];
        assert_eq!(lattice_round_trip(Coder::Tans, &huge).0, Coder::Pco);
        // The extremes of the quotient.
        let edges = [i64::from(i32::MIN), i64::from(i32::MAX), 1, -1];
        assert_eq!(lattice_round_trip(Coder::Tans, &edges).0, Coder::Tans);
        let f = i64::from(u32::MAX);
        let widest = [i64::from(i32::MIN) * f, i64::from(i32::MAX) * f, f];
        assert_eq!(lattice_round_trip(Coder::Tans, &widest).0, Coder::Tans);
    }

    #[test]
    fn a_factor_out_of_range_is_refused() {
        let (_, good) = lattice_round_trip(Coder::Tans, &[4, -8, 12, 0]);
        assert_eq!(good[0], 4);
        let mut out = [0i64; 4];
        let body = &good[1..];
        for factor in [&[0u8][..], &[0x80, 0x80, 0x80, 0x80, 0x10], &[0x84, 0x00], &[0x80; 5]] {
            let mut bad = factor.to_vec();
            bad.extend_from_slice(body);
            assert_eq!(
                read_lattice(Coder::Tans, &bad, &mut out),
                Err(DecodeError::Factor),
                "factor bytes {factor:?}"
            );
        }
        assert_eq!(read_lattice(Coder::Tans, &[], &mut out), Err(DecodeError::Factor));
        // The largest factor reads.
        let mut top = vec![0xff, 0xff, 0xff, 0xff, 0x0f];
        top.extend_from_slice(body);
        assert!(read_lattice(Coder::Tans, &top, &mut out).is_ok());
        assert_eq!(out, [u32::MAX as i64, -2 * u32::MAX as i64, 3 * u32::MAX as i64, 0]);
    }

    proptest! {
        /// Any lattice residuals round-trip through either coder, and tANS takes them
        /// exactly when their quotients by their common factor fit an `i32`.
        #[test]
        fn any_lattice_residuals_round_trip(
            r in proptest::collection::vec(any::<i64>(), 0..300),
            shift in 0u32..64,
            factor in 1i64..1000,
            tans in any::<bool>(),
        ) {
            let r: Vec<i64> = r.iter().map(|&x| (x >> shift).wrapping_mul(factor)).collect();
            let coder = if tans { Coder::Tans } else { Coder::Pco };
            let (used, _) = lattice_round_trip(coder, &r);
            let f = r.iter().fold(0u64, |g, &x| gcd(g, x.unsigned_abs())).max(1);
            let fits = f <= u64::from(u32::MAX)
                && r.iter().all(|&x| i32::try_from(x / f as i64).is_ok());
            prop_assert_eq!(used, if tans && fits { Coder::Tans } else { Coder::Pco });
        }

        /// Any float residuals round-trip through either coder.
        #[test]
        fn any_float_residuals_round_trip(
            r in proptest::collection::vec(any::<u32>(), 0..300),
            tans in any::<bool>(),
        ) {
            let coder = if tans { Coder::Tans } else { Coder::Pco };
            let bytes = code_float(coder, &r).expect("codes");
            let mut back = vec![0u32; r.len()];
            read_float(coder, &bytes, &mut back).expect("decodes");
            prop_assert_eq!(back, r);
        }

        /// Any bytes read as lattice or float residuals of either coder decode or fail.
        #[test]
        fn any_bytes_read_or_fail(bytes in proptest::collection::vec(any::<u8>(), 0..200), n in 0usize..64) {
            for coder in [Coder::Pco, Coder::Tans] {
                let _ = read_lattice(coder, &bytes, &mut vec![0i64; n]);
                let _ = read_float(coder, &bytes, &mut vec![0u32; n]);
            }
        }
    }
}
