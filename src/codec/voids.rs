//! Void bitmaps: which samples of a block or grid are voids, one bit each, stored raw or as
//! runs (format 5).
//!
//! Voids are not scattered. They are the edges of a reprojected sheet, a lake, a strip no
//! survey covered: whole rows, or the same few columns row after row. A raw bitmap costs
//! `n / 8` bytes whatever it holds: 528 bytes for a 65² block, more than many blocks' heights.
//! So a writer may store it as *runs*: each bit is first XORed with the bit one row above
//! (the first row with zeros), which turns a void column or a straight edge into a single
//! bit, and the result is stored as the lengths of its alternating runs, zeros first, as
//! LEB128 varints. On dem_hills' edge blocks this takes a few to a few tens of bytes.
//!
//! | flag | what follows |
//! |---|---|
//! | 0 | nothing: no sample is a void |
//! | 1 | the raw bitmap: `ceil(n / 8)` bytes, bit `i % 8` of byte `i / 8` for sample `i` |
//! | 2 | runs: varints `r0, r1, …` (zeros, ones, zeros, …) of the row-XORed bits, summing to exactly `n` (a run may be 0 only first) |
//!
//! A writer stores the smaller of 1 and 2 (1 on a tie). Decoding never allocates more than
//! the bitmap of the `n` samples it was told, and a run list that overshoots `n`, stops
//! short, or has a varint longer than five bytes is an error.

/// The flag of no voids.
pub const NONE: u8 = 0;
/// The flag of a raw bitmap.
pub const RAW: u8 = 1;
/// The flag of runs (format 5).
pub const RUNS: u8 = 2;

/// Appends the flag and the void bitmap `bitmap` (raw, `ceil(n / 8)` bytes, of `n` samples in
/// rows of `width`) to `out`: as runs when `runs` allows and that is smaller, else raw.
pub fn write(bitmap: &[u8], n: usize, width: usize, runs: bool, out: &mut Vec<u8>) {
    if runs {
        let coded = to_runs(bitmap, n, width.max(1));
        if coded.len() < bitmap.len() {
            out.push(RUNS);
            out.extend_from_slice(&coded);
            return;
        }
    }
    out.push(RAW);
    out.extend_from_slice(bitmap);
}

/// Reads a bitmap of `n` samples in rows of `width` that `flag` says follows at the start of
/// `body`: the raw bitmap (`None` for no voids) and the bytes after it.
pub fn read(
    flag: u8,
    body: &[u8],
    n: usize,
    width: usize,
) -> Result<(Option<Vec<u8>>, &[u8]), String> {
    match flag {
        NONE => Ok((None, body)),
        RAW => {
            if body.len() < n.div_ceil(8) {
                return Err(format!("a bitmap of {n} samples in {} bytes", body.len()));
            }
            let (m, rest) = body.split_at(n.div_ceil(8));
            Ok((Some(m.to_vec()), rest))
        }
        RUNS => {
            let (m, used) = from_runs(body, n, width.max(1))?;
            Ok((Some(m), &body[used..]))
        }
        f => Err(format!("void flag {f}")),
    }
}

/// The runs of `bitmap`'s row-XORed bits, as varints.
fn to_runs(bitmap: &[u8], n: usize, width: usize) -> Vec<u8> {
    let mut out = Vec::new();
    let mut current = false;
    let mut run = 0u64;
    for i in 0..n {
        let b = is_void(bitmap, i) ^ (i >= width && is_void(bitmap, i - width));
        if b != current {
            varint(run, &mut out);
            current = b;
            run = 0;
        }
        run += 1;
    }
    varint(run, &mut out);
    out
}

/// Appends the LEB128 varint of `v` to `out` (7 bits a byte, low first).
pub(super) fn varint(mut v: u64, out: &mut Vec<u8>) {
    loop {
        let byte = (v & 0x7f) as u8;
        v >>= 7;
        if v == 0 {
            out.push(byte);
            return;
        }
        out.push(byte | 0x80);
    }
}

/// The bitmap of `n` samples from runs at the start of `body`, and the bytes they took.
fn from_runs(body: &[u8], n: usize, width: usize) -> Result<(Vec<u8>, usize), String> {
    let bytes = n.div_ceil(8);
    // `SLACK` zero bytes past the bitmap, for the 8-byte loads and stores below; cut off at
    // the end.
    let mut m = vec![0u8; bytes + SLACK];
    let (mut at, mut i, mut ones, mut first) = (0usize, 0usize, false, true);
    while i < n || first {
        let mut run = 0u64;
        let mut shift = 0;
        loop {
            let b = *body
                .get(at)
                .ok_or_else(|| format!("void runs end after {i} of {n} samples"))?;
            at += 1;
            run |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                break;
            }
            shift += 7;
            if shift >= 35 {
                return Err("a void run's varint is longer than five bytes".into());
            }
        }
        if run == 0 && !first {
            return Err(format!("an empty void run after {i} samples"));
        }
        first = false;
        let end = usize::try_from(run)
            .ok()
            .and_then(|r| i.checked_add(r))
            .filter(|&e| e <= n)
            .ok_or_else(|| format!("void runs past the {n} samples"))?;
        if ones {
            set_bits(&mut m, i, end);
        }
        i = end;
        ones = !ones;
    }
    // Each row XORed with the row above, which is final by then, in pieces of at most 56
    // bits and at most a row (so that a piece's source lies wholly before it).
    let piece = width.min(56);
    for start in (width..n).step_by(width) {
        let end = (start + width).min(n);
        let mut off = start;
        while off < end {
            let len = (end - off).min(piece);
            let above = (word(&m, off - width) >> ((off - width) % 8)) & ((1u64 << len) - 1);
            let x = word(&m, off) ^ (above << (off % 8));
            m[off / 8..off / 8 + 8].copy_from_slice(&x.to_le_bytes());
            off += len;
        }
    }
    m.truncate(bytes);
    Ok((m, at))
}

/// Zero bytes a decoded bitmap is built with past its end ([`from_runs`]).
const SLACK: usize = 8;

/// The 8 bytes of `m` from the byte of bit `bit`, little-endian (`m` holds them: [`SLACK`]).
fn word(m: &[u8], bit: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&m[bit / 8..bit / 8 + 8]);
    u64::from_le_bytes(b)
}

/// Bits `from .. to` (`from < to`) as bytes: the first and last byte and the masks of their
/// bits in the range (one byte: both masks are its own).
fn span(from: usize, to: usize) -> (usize, usize, u8, u8) {
    let (first, last) = (from / 8, (to - 1) / 8);
    let (head, tail) = (0xffu8 << (from % 8), 0xffu8 >> (7 - (to - 1) % 8));
    match first == last {
        true => (first, last, head & tail, head & tail),
        false => (first, last, head, tail),
    }
}

/// Sets bits `from .. to` of `m`, a byte at a time.
fn set_bits(m: &mut [u8], from: usize, to: usize) {
    if from >= to {
        return;
    }
    let (first, last, head, tail) = span(from, to);
    m[first] |= head;
    if last > first {
        m[first + 1..last].fill(0xff);
        m[last] |= tail;
    }
}

/// How many of bits `from .. to` of bitmap `m` are set (voids among those samples).
pub(crate) fn count(m: &[u8], from: usize, to: usize) -> usize {
    if from >= to {
        return 0;
    }
    let (first, last, head, tail) = span(from, to);
    let mut total = (m[first] & head).count_ones();
    if last > first {
        total += m[first + 1..last].iter().map(|b| b.count_ones()).sum::<u32>();
        total += (m[last] & tail).count_ones();
    }
    total as usize
}

/// Whether sample `i` is a void in bitmap `m`.
#[inline(always)]
pub(crate) fn is_void(m: &[u8], i: usize) -> bool {
    m[i / 8] >> (i % 8) & 1 == 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn bitmap_of(bits: &[bool]) -> Vec<u8> {
        let mut m = vec![0u8; bits.len().div_ceil(8)];
        for (i, _) in bits.iter().enumerate().filter(|(_, &b)| b) {
            m[i / 8] |= 1 << (i % 8);
        }
        m
    }

    #[test]
    fn an_edge_column_costs_a_few_bytes() {
        let (w, h) = (65, 65);
        let bits: Vec<bool> = (0..w * h).map(|i| i % w < 2 || i / w == 0).collect();
        let m = bitmap_of(&bits);
        let mut out = Vec::new();
        write(&m, w * h, w, true, &mut out);
        assert_eq!(out[0], RUNS);
        assert!(out.len() < 10, "{} bytes", out.len());
        let (back, rest) = read(out[0], &out[1..], w * h, w).unwrap();
        assert_eq!(back.unwrap(), m);
        assert!(rest.is_empty());
    }

    #[test]
    fn hostile_runs_are_errors() {
        for body in [
            &[][..],
            &[5][..],
            &[0, 0][..],
            &[0x80, 0x80, 0x80, 0x80, 0x80, 1][..],
            &[3, 9][..],
        ] {
            assert!(read(RUNS, body, 8, 4).is_err(), "{body:?}");
        }
        assert!(read(7, &[0], 8, 4).is_err());
        assert!(read(RAW, &[], 9, 4).is_err());
    }

    proptest! {
        #[test]
        fn any_bitmap_round_trips(bits in proptest::collection::vec(any::<bool>(), 1..600), width in 1usize..150, runs in any::<bool>(), tail in proptest::collection::vec(any::<u8>(), 0..4)) {
            let n = bits.len();
            let m = bitmap_of(&bits);
            let mut out = Vec::new();
            write(&m, n, width, runs, &mut out);
            prop_assert!(out.len() <= 1 + m.len());
            out.extend_from_slice(&tail);
            let (back, rest) = read(out[0], &out[1..], n, width).unwrap();
            prop_assert_eq!(back.unwrap(), m);
            prop_assert_eq!(rest, &tail[..]);
        }

        /// Rows of voids cost a few bytes whatever their width (the rows' XOR, undone in
        /// pieces of up to 56 bits, is checked bit for bit against the bitmap).
        #[test]
        fn void_rows_round_trip_as_runs(width in 1usize..200, rows in 1usize..12, voided in proptest::collection::vec(any::<bool>(), 12), edge in 0usize..200) {
            let n = width * rows;
            let bits: Vec<bool> = (0..n).map(|i| voided[i / width] || i % width < edge.min(width) / 3).collect();
            let m = bitmap_of(&bits);
            let mut out = Vec::new();
            write(&m, n, width, true, &mut out);
            let (back, rest) = read(out[0], &out[1..], n, width).unwrap();
            prop_assert_eq!(back.unwrap(), m);
            prop_assert!(rest.is_empty());
        }

        /// `count` is the number of set bits in its range, and `is_void` each bit.
        #[test]
        fn counts_are_the_set_bits(bits in proptest::collection::vec(any::<bool>(), 1..300), a in any::<prop::sample::Index>(), b in any::<prop::sample::Index>()) {
            let m = bitmap_of(&bits);
            let (a, b) = (a.index(bits.len() + 1), b.index(bits.len() + 1));
            let (from, to) = (a.min(b), a.max(b));
            prop_assert_eq!(count(&m, from, to), bits[from..to].iter().filter(|&&x| x).count());
            for (i, &x) in bits.iter().enumerate() {
                prop_assert_eq!(is_void(&m, i), x);
            }
        }

        #[test]
        fn any_bytes_read_or_fail(body in proptest::collection::vec(any::<u8>(), 0..40), n in 1usize..200, width in 1usize..20) {
            if let Ok((Some(m), rest)) = read(RUNS, &body, n, width) {
                prop_assert_eq!(m.len(), n.div_ceil(8));
                prop_assert!(rest.len() <= body.len());
            }
        }
    }
}
