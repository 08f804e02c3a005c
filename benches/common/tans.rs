//! A candidate coder for the residual streams of `format-spec/container.md` §7, studied
//! against pco on the streams real containers store (`FMRH_CODER_STUDY=1 cargo bench --bench
//! decode`, issue 44). It is a measurement, not a format: nothing in `src/` reads it.
//!
//! The question it answers: pco is about half of each encoding's decoding time, and the
//! goal is ≤ 4 ns a sample. Can a coder built for these streams alone (small non-negative
//! codes, one table a block, lengths known to the reader) decode much faster than pco at
//! about its size? If it cannot, no change of format is worth making for speed.
//!
//! The coder: each code `v` (a zigzag residual) is a symbol and, above 15, extra bits:
//! `v < 16` is its own symbol; otherwise with `b = ⌊log₂ v⌋` and `m` the two bits below the
//! leading one, the symbol is `16 + 4(b − 4) + m` and the `b − 2` bits below those are
//! extra, so a symbol stands for a range a quarter of its power of two wide (at most 128
//! symbols). The symbols are coded by tANS (as in FSE/zstd) with four interleaved states,
//! one table of `2^L` states (`L` in 5..=11, chosen per block for the fewest bits). The
//! stream, one forward little-endian bit stream read from bit 0 of byte 0 upward:
//!
//! - `L − 5` (3 bits), the number of symbols `s` minus 1 (7 bits), then the weights of
//!   symbols `0..s−1` as Elias-gamma codes of `w + 1` (the last symbol's weight is
//!   `2^L` minus their sum);
//! - the four lanes' first states (`L` bits each);
//! - for each code in order (lane `i mod 4`): its extra bits, then its lane's next state's
//!   bits (the number FSE's decoding table gives).
//!
//! A reader reads 8 bytes at any bit position, so the decoder works on a copy padded with 8
//! zero bytes (a real format would let it read to the end of the payload instead).
//!
//! [`Decoder::decode_planar`] asks a second question: does decoding each residual where the
//! planar rebuild consumes it (one loop, no buffer between) beat running the two one after
//! the other ([`Decoder::decode`], then [`planar`])? Measured: no.

/// Symbols coded as themselves.
const DIRECT: u32 = 16;
const MIN_LOG: u32 = 5;
const MAX_LOG: u32 = 11;
const LANES: usize = 4;

/// The symbol of `v`, the first code it stands for, and how many extra bits select `v`.
fn bin(v: u32) -> (usize, u32, u32) {
    if v < DIRECT {
        return (v as usize, v, 0);
    }
    let b = 31 - v.leading_zeros();
    let m = (v >> (b - 2)) & 3;
    (
        (DIRECT + 4 * (b - 4) + m) as usize,
        (4 | m) << (b - 2),
        b - 2,
    )
}

/// The first code and extra bits of symbol `s` (the inverse of [`bin`]).
fn symbol_range(s: usize) -> (u32, u32) {
    let s = s as u32;
    if s < DIRECT {
        return (s, 0);
    }
    let (b, m) = (4 + (s - DIRECT) / 4, (s - DIRECT) % 4);
    ((4 | m) << (b - 2), b - 2)
}

/// A lattice residual's code: zigzag, small for small residuals either way.
pub fn zigzag(x: i64) -> u64 {
    ((x << 1) ^ (x >> 63)) as u64
}

/// The residual of a code below 2^32 ([`zigzag`]'s inverse).
#[inline(always)]
pub fn residual(z: u32) -> i64 {
    i64::from((z >> 1) as i32 ^ -((z & 1) as i32))
}

/// Codes and decodes the edge cases (one code, one symbol, the largest codes, every symbol,
/// odd lengths), panicking on any code lost.
pub fn check_edges() {
    let mut x = 0x9E37_79B9u32;
    let mut random = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    let edges: Vec<Vec<u32>> = vec![
        vec![0],
        vec![u32::MAX],
        vec![7; 4099],
        (0..5000).map(|_| random()).collect(),
        (0..4097).map(|_| random() >> (random() % 32)).collect(),
        (0..33).map(|i| u32::MAX - i).collect(),
    ];
    for codes in edges {
        let coded = encode(&codes).expect("codes");
        let mut back = vec![0u32; codes.len()];
        Decoder::default().decode(&coded, &mut back, |v| v);
        assert_eq!(
            back, codes,
            "the candidate coder lost a code of an edge case"
        );
    }
}

struct BitWriter {
    bytes: Vec<u8>,
    acc: u64,
    filled: u32,
}

impl BitWriter {
    fn new() -> Self {
        BitWriter {
            bytes: Vec::new(),
            acc: 0,
            filled: 0,
        }
    }
    fn put(&mut self, value: u64, bits: u32) {
        debug_assert!(bits <= 32 && (bits == 64 || value >> bits == 0));
        self.acc |= value << self.filled;
        self.filled += bits;
        while self.filled >= 8 {
            self.bytes.push(self.acc as u8);
            self.acc >>= 8;
            self.filled -= 8;
        }
    }
    fn gamma(&mut self, x: u32) {
        let n = 31 - x.leading_zeros();
        self.put(1 << n, n + 1); // n zeros, then a one
        self.put(u64::from(x) & ((1 << n) - 1), n);
    }
    fn finish(mut self) -> Vec<u8> {
        if self.filled > 0 {
            self.bytes.push(self.acc as u8);
        }
        self.bytes
    }
}

/// Weights summing to `2^log`, each present symbol at least 1, close to `counts`' shares.
fn normalize(counts: &[u64], n: u64, log: u32) -> Vec<u32> {
    let table = 1u64 << log;
    let mut w: Vec<u32> = counts
        .iter()
        .map(|&c| {
            if c == 0 {
                0
            } else {
                ((c * table + n / 2) / n).max(1) as u32
            }
        })
        .collect();
    let mut sum: i64 = w.iter().map(|&x| i64::from(x)).sum();
    while sum != table as i64 {
        // Adjust the symbol whose cost changes least: the largest weight.
        let (i, _) = w
            .iter()
            .enumerate()
            .filter(|(_, &x)| sum < table as i64 || x > 1)
            .max_by_key(|(_, &x)| x)
            .expect("a symbol to adjust");
        if sum > table as i64 {
            w[i] -= 1;
            sum -= 1;
        } else {
            w[i] += 1;
            sum += 1;
        }
    }
    w
}

/// Codes `values`; `None` when there are none.
pub fn encode(values: &[u32]) -> Option<Vec<u8>> {
    if values.is_empty() {
        return None;
    }
    let mut counts = vec![0u64; 128];
    for &v in values {
        counts[bin(v).0] += 1;
    }
    let symbols = counts.iter().rposition(|&c| c > 0).expect("a symbol") + 1;
    let counts = &counts[..symbols];
    let n = values.len() as u64;
    // The table size with the fewest bits, header included.
    let present = counts.iter().filter(|&&c| c > 0).count() as u32;
    let mut best: Option<(f64, u32, Vec<u32>)> = None;
    // A table larger than the stream costs more to build than its precision saves.
    // Capped at a quarter of the stream's length (2 below log₂ n): a cap 1 below measured the
    // same, 3 below made some streams twice as large.
    let cap = MAX_LOG.min((63 - n.leading_zeros()).saturating_sub(2).max(MIN_LOG));
    let lowest = MIN_LOG.max(32 - (present.max(2) - 1).leading_zeros());
    for log in lowest..=cap.max(lowest) {
        let w = normalize(counts, n, log);
        let header: f64 = w[..symbols - 1]
            .iter()
            .map(|&x| f64::from(2 * (31 - (x + 1).leading_zeros()) + 1))
            .sum::<f64>()
            + f64::from(10 + LANES as u32 * log);
        let body: f64 = counts
            .iter()
            .zip(&w)
            .filter(|(&c, _)| c > 0)
            .map(|(&c, &x)| c as f64 * (f64::from(log) - f64::from(x).log2()))
            .sum();
        let bits = header + body;
        if best.as_ref().is_none_or(|b| bits < b.0) {
            best = Some((bits, log, w));
        }
    }
    let (_, log, weights) = best.expect("a table size");
    let size = 1u32 << log;
    // For each symbol, its states in the order of FSE's spread, which is the order the
    // decoder numbers them (k = w .. 2w − 1).
    let mut states: Vec<Vec<u32>> = vec![Vec::new(); symbols];
    let (step, mask) = ((size >> 1) + (size >> 3) + 3, size - 1);
    let mut pos = 0u32;
    for (s, &w) in weights.iter().enumerate() {
        for _ in 0..w {
            states[s].push(pos);
            pos = (pos + step) & mask;
        }
    }
    // Encoded backwards: the pieces each code adds, in reverse of the order they are read.
    let mut pieces: Vec<(u64, u32)> = Vec::with_capacity(2 * values.len());
    let mut x = [size; LANES];
    for i in (0..values.len()).rev() {
        let lane = i % LANES;
        let (s, base, e) = bin(values[i]);
        let w = weights[s];
        let mut nb = log - (31 - w.leading_zeros());
        if (x[lane] >> nb) < w {
            nb -= 1;
        }
        pieces.push((u64::from(x[lane] & ((1 << nb) - 1)), nb));
        let k = x[lane] >> nb;
        x[lane] = states[s][(k - w) as usize] + size;
        pieces.push((u64::from(values[i] - base), e));
    }
    let mut out = BitWriter::new();
    out.put(u64::from(log - MIN_LOG), 3);
    out.put(symbols as u64 - 1, 7);
    for &w in &weights[..symbols - 1] {
        out.gamma(w + 1);
    }
    for &xl in &x {
        out.put(u64::from(xl - size), log);
    }
    for &(v, bits) in pieces.iter().rev() {
        out.put(v, bits);
    }
    Some(out.finish())
}

/// One state of the decoding table.
#[derive(Clone, Copy, Default)]
struct Entry {
    /// The symbol's first code.
    base: u32,
    /// The next state, before its bits are added.
    next: u16,
    /// Extra bits of the code.
    extra: u8,
    /// Bits of the next state.
    bits: u8,
    /// `2^extra − 1` and `2^bits − 1`, so that a code costs no variable shift to mask.
    extra_mask: u32,
    bits_mask: u32,
}

/// A decoder's reusable buffers.
#[derive(Default)]
pub struct Decoder {
    padded: Vec<u8>,
    table: Vec<Entry>,
}

#[inline(always)]
fn peek(buf: &[u8], pos: usize) -> u64 {
    let b = &buf[pos >> 3..(pos >> 3) + 8];
    u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) >> (pos & 7)
}

impl Decoder {
    /// Reads the header of `stream` into a copy padded for 8-byte reads and builds the
    /// table: the bit position of the first code and the lanes' first states.
    fn start(&mut self, stream: &[u8]) -> (usize, [usize; LANES]) {
        self.padded.clear();
        self.padded.extend_from_slice(stream);
        self.padded.extend_from_slice(&[0; 8]);
        let buf = &self.padded[..];
        let mut pos = 0usize;
        let head = peek(buf, 0);
        let log = (head & 7) as u32 + MIN_LOG;
        let symbols = ((head >> 3) & 127) as usize + 1;
        pos += 10;
        let size = 1u32 << log;
        let mut weights = [0u32; 128];
        let mut sum = 0u32;
        for w in weights.iter_mut().take(symbols - 1) {
            let word = peek(buf, pos);
            let n = word.trailing_zeros();
            let x = (1u64 << n) | ((word >> (n + 1)) & ((1 << n) - 1));
            pos += 2 * n as usize + 1;
            *w = x as u32 - 1;
            sum += *w;
        }
        weights[symbols - 1] = size - sum;
        // The decoding table: FSE's spread, each symbol's states numbered w .. 2w − 1.
        self.table.clear();
        self.table.resize(size as usize, Entry::default());
        let step = (size as usize >> 1) + (size as usize >> 3) + 3;
        let mask = size as usize - 1;
        let mut p = 0usize;
        for (s, &w) in weights[..symbols].iter().enumerate() {
            let (base, extra) = symbol_range(s);
            for k in w..2 * w {
                let bits = log - (31 - k.leading_zeros());
                self.table[p] = Entry {
                    base,
                    next: ((k << bits) - size) as u16,
                    extra: extra as u8,
                    bits: bits as u8,
                    extra_mask: ((1u64 << extra) - 1) as u32,
                    bits_mask: (1 << bits) - 1,
                };
                p = (p + step) & mask;
            }
        }
        let mut st = [0usize; LANES];
        for s in &mut st {
            *s = (peek(buf, pos) & u64::from(size - 1)) as usize;
            pos += log as usize;
        }
        (pos, st)
    }

    /// Decodes `out.len()` codes from `stream` into `out`, mapped in order by `map`. (Built
    /// with BMI2's one-instruction variable shifts it was no faster, as measured.)
    pub fn decode<T>(&mut self, stream: &[u8], out: &mut [T], mut map: impl FnMut(u32) -> T) {
        let (mut pos, mut st) = self.start(stream);
        let buf = &self.padded[..];
        let table = &self.table[..];
        let mut step_one = |s: &mut usize, pos: &mut usize| -> T {
            let e = table[*s];
            let word = peek(buf, *pos);
            let v = e.base + (word as u32 & e.extra_mask);
            *s = usize::from(e.next) + ((word >> e.extra) as u32 & e.bits_mask) as usize;
            *pos += usize::from(e.extra) + usize::from(e.bits);
            map(v)
        };
        let mut chunks = out.chunks_exact_mut(LANES);
        for c in &mut chunks {
            for (o, s) in c.iter_mut().zip(&mut st) {
                *o = step_one(s, &mut pos);
            }
        }
        for (o, s) in chunks.into_remainder().iter_mut().zip(&mut st) {
            *o = step_one(s, &mut pos);
        }
    }

    /// [`Decoder::decode`] of lattice residuals fused with [`planar`]'s rebuild: each code
    /// becomes its residual (`zigzag⁻¹ · factor`), then its sample, in one loop, so that the
    /// coder's chain (its bit position) and the planar sum's run side by side. `above` is a
    /// row of `w` zeros on entry.
    pub fn decode_planar(
        &mut self,
        stream: &[u8],
        factor: i64,
        w: usize,
        q: f64,
        above: &mut [i64],
        out: &mut [f32],
    ) {
        let (mut left, mut up_left, mut c) = (0i64, 0i64, 0usize);
        self.decode(stream, out, |z| {
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
    }
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
