//! The binned tANS stream: a block's residual codes (`u32`, small for small residuals) to
//! bytes and back, for format 7's encodings 9 to 15 (`format-spec/container.md` §7, "The
//! tANS stream"; the codec reaches it through `residuals`). The coder study of `benches/decode.rs` measures it
//! beside pco.
//!
//! **Why a coder of our own.** pco coded every residual stream of formats 2 to 6, and was
//! about half of every encoding's decoding time once the kernels around it were fast. Its
//! generality (chunks, modes, deltas, per-chunk tables of bins) buys nothing on a block's
//! few thousand zigzag residuals, whose length the reader already knows. This coder does
//! one thing: it bins the codes and codes the bins with tANS, one table a stream. Measured
//! on every stored stream of four DEMs (`docs/benchmarks.md`, the coder study): 0.94× pco's
//! bytes and 0.53–0.74× its decoding time.
//!
//! **Binning.** A code `v < 16` is its own symbol. Above, with `b = ⌊log₂ v⌋` and `m` the two
//! bits below the leading one, the symbol is `16 + 4(b − 4) + m` and the `b − 2` bits below
//! those follow as *extra bits*: a symbol stands for a range a quarter of its power of two
//! wide, so a residual's cost grows with its logarithm, and at most 128 symbols cover every
//! `u32`.
//!
//! **tANS** (tabled asymmetric numeral systems, as FSE and zstd use it): a table of `2^L`
//! states in which each symbol holds as many states as its weight (its share of the stream,
//! normalised to `2^L`); decoding a code is one table load, a read of its extra bits and of
//! the bits that make the next state. Four states interleave (code `i` belongs to lane
//! `i mod 4`), so that four chains of dependent loads are in flight at once.
//!
//! **The stream** is the count of its codes `n` as a LEB128 varint (7 bits a byte, low first,
//! at most 5 bytes, no byte of zeros after the first), then, for `n > 0`, one forward bit
//! stream (bit `i` is bit `i mod 8` of its byte `⌊i/8⌋`):
//!
//! | field | bits |
//! |---|---|
//! | `L − 5` (`5 ≤ L ≤ 12`) | 3 |
//! | `s − 1`, the symbols `0 .. s` | 7 |
//! | the weights of symbols `0 .. s − 1`, each as the Elias-gamma code of `w + 1` | varies |
//! | the four lanes' first states | `4 × L` |
//! | per code: its extra bits, then the bits of its lane's next state | varies |
//!
//! An Elias-gamma code of `x ≥ 1` is `⌊log₂ x⌋` zero bits, a one bit, then the `⌊log₂ x⌋`
//! bits of `x` below its leading one, low first. Symbol `s − 1`'s weight is `2^L` less the
//! others' sum and must be at least 1. The table is FSE's spread: start at position 0 and
//! step by `2^L/2 + 2^L/8 + 3` modulo `2^L`, giving each symbol in turn its `w` positions,
//! numbered `w .. 2w − 1` in the order given. Position `p` holding symbol `s` as number `k`
//! decodes to `s` and reads `bits = L − ⌊log₂ k⌋` bits, which added to `k · 2^bits − 2^L` make
//! the lane's next state.
//!
//! **A stream is exactly its bits.** The count is the one the payload's layout gives (a
//! reader knows it before it reads the stream, and checks it: a code of one symbol costs no
//! bits, so without it a stream of such codes would read as any count). After the `n` codes
//! every lane's state is 0 (a lane with no code: its first state), the bit stream is
//! `⌈bits/8⌉` bytes and the unread bits of its last byte are zero. An encoder leaves exactly
//! that; a decoder refuses anything else, so a stream cut short or run on is an error. (A bit
//! changed inside a code's extra bits changes that code and nothing else, as in any entropy
//! coder: the payload's CRC is what catches a changed byte.)
//!
//! Decoding never reads past the stream: the main loop reads four codes with 8-byte loads at
//! their bit positions, as many groups of four at once as the bytes left are sure to hold
//! for this table's largest codes, and the last bytes are copied into a zero-padded buffer
//! of the stack for the same loop to finish on. Nothing is allocated from a number in the stream: the
//! table is at most `2^12` entries whatever the header says, in a buffer the caller keeps.

use super::voids::varint;

/// Codes below this are symbols of their own.
const DIRECT: u32 = 16;
/// The fewest and most table bits `L`.
pub const MIN_LOG: u32 = 5;
/// See [`MIN_LOG`].
pub const MAX_LOG: u32 = 12;
/// Interleaved states.
const LANES: usize = 4;
/// Symbols at most: every `u32` falls in one of them.
const SYMBOLS: usize = 128;
/// The most bits one code reads: 29 extra bits (symbol 127) and `MAX_LOG` state bits.
const MAX_CODE_BITS: usize = 29 + MAX_LOG as usize;
/// The most bytes past a group of [`LANES`] codes' first byte that their 8-byte loads reach,
/// for the largest codes any table has: the group's bits, rounded up, and a load's 8 bytes.
const REACH: usize = (LANES * MAX_CODE_BITS).div_ceil(8) + 8;

/// Why bytes are not a stream of the expected codes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum StreamError {
    /// The header's weights do not make a table.
    #[error("tANS table: {0}")]
    Table(&'static str),
    /// The codes read past the stream's end.
    #[error("tANS stream ends before its codes do")]
    Short,
    /// The stream goes on after its codes, or leaves bits or states that an encoder does not.
    #[error("tANS stream: {0}")]
    Trailing(&'static str),
    /// The stream's count is not the payload's, or not a count.
    #[error("tANS stream: {0}")]
    Count(String),
}

/// The symbol of `v`, the first code it stands for, and how many extra bits select `v`.
fn bin(v: u32) -> (usize, u32, u32) {
    if v < DIRECT {
        return (v as usize, v, 0);
    }
    let b = 31 - v.leading_zeros();
    let m = (v >> (b - 2)) & 3;
    ((DIRECT + 4 * (b - 4) + m) as usize, (4 | m) << (b - 2), b - 2)
}

/// The first code and extra bits of symbol `s < 128` (the inverse of [`bin`]).
fn symbol_range(s: usize) -> (u32, u32) {
    let s = s as u32;
    if s < DIRECT {
        return (s, 0);
    }
    let (b, m) = (4 + (s - DIRECT) / 4, (s - DIRECT) % 4);
    ((4 | m) << (b - 2), b - 2)
}

/// The step of FSE's spread over a table of `size` states.
fn spread_step(size: usize) -> usize {
    (size >> 1) + (size >> 3) + 3
}

/// Bits appended low first to a byte vector.
struct BitWriter<'a> {
    out: &'a mut Vec<u8>,
    acc: u64,
    filled: u32,
}

impl BitWriter<'_> {
    fn put(&mut self, value: u64, bits: u32) {
        debug_assert!(bits <= 32 && value >> bits == 0);
        self.acc |= value << self.filled;
        self.filled += bits;
        while self.filled >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.filled -= 8;
        }
    }

    fn gamma(&mut self, x: u32) {
        let n = 31 - x.leading_zeros();
        self.put(1 << n, n + 1);
        self.put(u64::from(x) & ((1 << n) - 1), n);
    }

    fn finish(self) {
        if self.filled > 0 {
            self.out.push(self.acc as u8);
        }
    }
}

/// Weights summing to `2^log`, each present symbol at least 1, close to `counts`' shares of
/// `n`. `2^log` must be at least the number of present symbols.
fn normalize(counts: &[u64], n: u64, log: u32) -> Vec<u32> {
    let table = 1u64 << log;
    let mut w: Vec<u32> = counts
        .iter()
        .map(|&c| match c {
            0 => 0,
            // `c ≤ n`, so the share is at most `2^log`, and `c · 2^12` cannot overflow for
            // any stream a block holds (`n < 2^40`).
            c => ((c * table + n / 2) / n).max(1) as u32,
        })
        .collect();
    let mut sum: u64 = w.iter().map(|&x| u64::from(x)).sum();
    while sum != table {
        // The largest weight changes its symbol's cost least; when taking away, one above 1
        // (there is one: the weights exceed the table, which has room for every symbol).
        let Some(i) = (0..w.len())
            .filter(|&i| w[i] > 0 && (sum < table || w[i] > 1))
            .max_by_key(|&i| w[i])
        else {
            unreachable!("a table of {table} states for the present symbols");
        };
        if sum > table {
            w[i] -= 1;
            sum -= 1;
        } else {
            w[i] += 1;
            sum += 1;
        }
    }
    w
}

/// The LEB128 varint at the start of `bytes` (at most five bytes, no byte of zeros after the
/// first) and the bytes it took; `None` for anything else.
pub(super) fn read_varint(bytes: &[u8]) -> Option<(u64, usize)> {
    let mut v = 0u64;
    for (i, &b) in bytes.iter().take(5).enumerate() {
        v |= u64::from(b & 0x7f) << (7 * i);
        if b & 0x80 == 0 {
            return (b != 0 || i == 0).then_some((v, i + 1));
        }
    }
    None
}

/// The count at the start of `stream` and the bytes it took.
fn read_count(stream: &[u8]) -> Result<(u64, usize), StreamError> {
    read_varint(stream).ok_or_else(|| {
        StreamError::Count("no count of at most five bytes, none of zeros last".into())
    })
}

/// Appends the stream of `codes` to `out`.
///
/// # Panics
/// If there are `2^32` codes or more (a block holds at most `2^32` samples, I-3).
pub fn encode(codes: &[u32], out: &mut Vec<u8>) {
    let Ok(count) = u32::try_from(codes.len()) else {
        panic!("a stream of {} codes", codes.len());
    };
    varint(u64::from(count), out);
    if codes.is_empty() {
        return;
    }
    let mut counts = [0u64; SYMBOLS];
    for &v in codes {
        counts[bin(v).0] += 1;
    }
    let symbols = counts.iter().rposition(|&c| c > 0).map_or(1, |s| s + 1);
    let counts = &counts[..symbols];
    let n = codes.len() as u64;
    let present = counts.iter().filter(|&&c| c > 0).count() as u32;
    // The table size with the fewest bits, header included, from the smallest that holds
    // every present symbol to a quarter of the stream's length (a larger table costs more
    // to build than its precision saves: measured, a cap one lower was as small, two lower
    // made some streams twice as large).
    let lowest = MIN_LOG.max(32 - (present.max(2) - 1).leading_zeros());
    let cap = MAX_LOG.min((63 - n.leading_zeros()).saturating_sub(2)).max(lowest);
    let mut best: Option<(f64, u32, Vec<u32>)> = None;
    for log in lowest..=cap {
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
        if best.as_ref().is_none_or(|b| header + body < b.0) {
            best = Some((header + body, log, w));
        }
    }
    let Some((_, log, weights)) = best else {
        unreachable!("lowest ≤ cap, so one table size is tried");
    };
    let size = 1u32 << log;
    // Each symbol's states in the order of the spread, which is the order the decoder
    // numbers them (`k = w .. 2w − 1`).
    let mut states: Vec<Vec<u32>> = vec![Vec::new(); symbols];
    let (step, mask) = (spread_step(size as usize) as u32, size - 1);
    let mut pos = 0u32;
    for (s, &w) in weights.iter().enumerate() {
        for _ in 0..w {
            states[s].push(pos);
            pos = (pos + step) & mask;
        }
    }
    // Encoded backwards: the pieces each code adds, in reverse of the order they are read.
    let mut pieces: Vec<(u64, u32)> = Vec::with_capacity(2 * codes.len());
    let mut x = [size; LANES];
    for (i, &v) in codes.iter().enumerate().rev() {
        let lane = i % LANES;
        let (s, base, extra) = bin(v);
        let w = weights[s];
        let mut nb = log - (31 - w.leading_zeros());
        if (x[lane] >> nb) < w {
            nb -= 1;
        }
        pieces.push((u64::from(x[lane] & ((1 << nb) - 1)), nb));
        let k = x[lane] >> nb;
        x[lane] = states[s][(k - w) as usize] + size;
        pieces.push((u64::from(v - base), extra));
    }
    let mut bits = BitWriter {
        out,
        acc: 0,
        filled: 0,
    };
    bits.put(u64::from(log - MIN_LOG), 3);
    bits.put(symbols as u64 - 1, 7);
    for &w in &weights[..symbols - 1] {
        bits.gamma(w + 1);
    }
    for &state in &x {
        bits.put(u64::from(state - size), log);
    }
    for &(v, n) in pieces.iter().rev() {
        bits.put(v, n);
    }
    bits.finish();
}

/// One state of the decoding table.
#[derive(Clone, Copy, Default)]
struct Entry {
    /// The symbol's first code.
    base: u32,
    /// `2^extra − 1`: masks, not variable shifts, select a code's bits.
    extra_mask: u32,
    /// `2^bits − 1`.
    bits_mask: u32,
    /// The next state, before its bits are added.
    next: u16,
    /// Extra bits of the code.
    extra: u8,
    /// Bits the code reads in all: its extra bits and its next state's (one addition a code
    /// moves the bit position by).
    len: u8,
}

/// A decoder's table, kept by the caller from stream to stream so that decoding allocates
/// nothing once warm.
#[derive(Default)]
pub struct Decoder {
    table: Vec<Entry>,
}

/// 8 bytes of `buf` from bit `pos`, past its end read as zeros.
#[inline(always)]
fn peek_checked(buf: &[u8], pos: usize) -> u64 {
    if (pos >> 3) + 8 <= buf.len() {
        // The header of every stream but the shortest: as fast as the codes' loads (a
        // copy of a length known only at run time is a call, a fifth of a short stream's
        // decoding when the header took it for every weight, as measured).
        return peek(buf, pos);
    }
    let mut word = [0u8; 8];
    let start = (pos >> 3).min(buf.len());
    let have = (buf.len() - start).min(8);
    word[..have].copy_from_slice(&buf[start..start + have]);
    u64::from_le_bytes(word) >> (pos & 7)
}

/// 8 bytes of `buf` from bit `pos`; the caller has checked that they are in it.
#[inline(always)]
fn peek(buf: &[u8], pos: usize) -> u64 {
    let at = pos >> 3;
    let mut word = [0u8; 8];
    word.copy_from_slice(&buf[at..at + 8]);
    u64::from_le_bytes(word) >> (pos & 7)
}

/// Decodes one code at bit `pos` of `buf` in the lane whose state is `state`, and moves both
/// on. The caller has checked that 8 bytes from `pos` are in `buf`.
#[inline(always)]
fn step(table: &[Entry], buf: &[u8], pos: &mut usize, state: &mut usize) -> u32 {
    let e = table[*state];
    let word = peek(buf, *pos);
    *state = usize::from(e.next) + ((word >> e.extra) as u32 & e.bits_mask) as usize;
    *pos += usize::from(e.len);
    e.base + (word as u32 & e.extra_mask)
}

/// [`step`] without its two bounds checks, for the main loop of [`groups`], where they were
/// a fifth of a code's instructions (the loop is bound by how many it issues, not by its
/// chains of loads: measured in `docs/benchmarks.md`).
///
/// # Safety
/// `*state < table.len()`, `table` is a table [`Decoder::start`] built (every entry's next
/// state is below its length, so the lane's state stays so), and the 8 bytes from bit `pos`
/// lie in `buf`.
#[inline(always)]
unsafe fn step_unchecked(table: &[Entry], buf: &[u8], pos: &mut usize, state: &mut usize) -> u32 {
    debug_assert!(*state < table.len() && (*pos >> 3) + 8 <= buf.len());
    // SAFETY: the caller's contract: the state indexes the table.
    let e = unsafe { *table.get_unchecked(*state) };
    // SAFETY: the caller's contract: bytes `pos/8 .. pos/8 + 8` are in `buf`; an unaligned
    // read of them as a `u64` (any bits are a `u64`).
    let word = unsafe { buf.as_ptr().add(*pos >> 3).cast::<u64>().read_unaligned() };
    let word = u64::from_le(word) >> (*pos & 7);
    *state = usize::from(e.next) + ((word >> e.extra) as u32 & e.bits_mask) as usize;
    *pos += usize::from(e.len);
    e.base + (word as u32 & e.extra_mask)
}

/// Decodes groups of [`LANES`] codes from `buf` into `out` for as long as every load is sure
/// to lie in `buf`, and says how many codes it decoded: a multiple of four. A group of this
/// table's codes moves the bit position at most `group` bytes on (its first byte included),
/// and its loads reach at most `group + 8` bytes past its first: so as many groups at once
/// as the bytes left are sure to hold run in a loop that tests nothing but its count
/// (testing the bytes left every group, or bounding a group by the largest codes any table
/// has rather than this one's, cost a tenth to a third of a short stream's time, as measured).
#[inline(always)]
fn groups<T>(
    table: &[Entry],
    group: usize,
    buf: &[u8],
    pos: &mut usize,
    states: &mut [usize; LANES],
    out: &mut [T],
    map: &mut impl FnMut(u32) -> T,
) -> usize {
    let mut i = 0;
    while i + LANES <= out.len() {
        let Some(room) = buf.len().checked_sub((*pos >> 3) + group + 8) else {
            break;
        };
        let count = (room / group + 1).min((out.len() - i) / LANES);
        for four in out[i..i + count * LANES].chunks_exact_mut(LANES) {
            // The lanes' states stay in registers: an array zipped, not indexed.
            for (o, state) in four.iter_mut().zip(states.iter_mut()) {
                // SAFETY: every state is below the table's length (the first ones are
                // masked by it in `start`, every next one is by the table's making: see
                // `start`; the spread writes every entry of `table`, its step being odd and
                // the weights summing to its length), and the group's loads lie in `buf`: the group starts at
                // most `count - 1` groups of at most `group` bytes past the first, its
                // codes move at most `group` bytes on, and `room` leaves 8 more.
                *o = map(unsafe { step_unchecked(table, buf, pos, state) });
            }
        }
        i += count * LANES;
    }
    i
}

/// What a stream's header gives its decoding.
struct Start {
    /// The bit position of the first code.
    pos: usize,
    /// The lanes' first states.
    states: [usize; LANES],
    /// The most bytes a group of codes moves on ([`groups`]).
    group: usize,
    /// The table's states, `2^L`.
    size: usize,
}

impl Decoder {
    /// Reads the header of `stream` and builds the table.
    fn start(&mut self, stream: &[u8]) -> Result<Start, StreamError> {
        let head = peek_checked(stream, 0);
        let log = (head & 7) as u32 + MIN_LOG;
        let symbols = ((head >> 3) & 127) as usize + 1;
        let mut pos = 10usize;
        let size = 1u32 << log;
        let mut weights = [0u32; SYMBOLS];
        let mut sum = 0u32;
        for w in weights.iter_mut().take(symbols - 1) {
            let word = peek_checked(stream, pos);
            let n = word.trailing_zeros();
            // `w + 1 ≤ 2^L + 1`, so a code has at most `L + 1` leading zeros.
            if n > log + 1 {
                return Err(StreamError::Table("a weight larger than the table"));
            }
            let x = (1u64 << n) | ((word >> (n + 1)) & ((1 << n) - 1));
            pos += 2 * n as usize + 1;
            *w = (x - 1) as u32;
            sum += *w;
            if sum >= size {
                return Err(StreamError::Table(
                    "the weights leave no state for the last symbol",
                ));
            }
        }
        weights[symbols - 1] = size - sum;
        // Every entry of the first `size` is written below (the step is odd, so the spread
        // visits each position once, and the weights sum to `size`): kept from the last
        // stream, not zeroed.
        if self.table.len() < size as usize {
            self.table.resize(size as usize, Entry::default());
        }
        let (step, mask) = (spread_step(size as usize), size as usize - 1);
        let table = &mut self.table[..size as usize];
        let mut p = 0usize;
        // The most bits a code reads: its symbol's extra bits and, at its first state
        // (`k = w`), the most state bits.
        let mut most = 0u32;
        for (s, &w) in weights[..symbols].iter().enumerate() {
            if w == 0 {
                continue;
            }
            let (base, extra) = symbol_range(s);
            // States `k = w .. 2w − 1` read `L − ⌊log₂ k⌋` bits: `L − b` up to `2^(b+1)`
            // (`b = ⌊log₂ w⌋`), one fewer from there on. So two runs of entries alike but
            // for their next state, which grows by `2^bits` a state (the table's build was
            // a tenth of a short stream's decoding when each entry worked out its bits).
            let b = 31 - w.leading_zeros();
            most = most.max(extra + log - b);
            let split = 2u32 << b;
            // (`w = 2^L`, one symbol in all, has no second run: `b = L`.)
            for (ks, bits) in [(w..split, log - b), (split..2 * w, (log - b).saturating_sub(1))] {
                if ks.is_empty() {
                    continue;
                }
                // `2^⌊log₂ k⌋ ≤ k < 2^(⌊log₂ k⌋ + 1)`, so the next states
                // `k · 2^bits − 2^L + (0 .. 2^bits)` lie in `0 .. 2^L`: every state a lane
                // reaches indexes the table ([`step_unchecked`] relies on it), and a code
                // reads at most `most` bits ([`groups`] does).
                debug_assert!(ks.end << bits <= 2 * size && extra + bits <= most);
                let entry = Entry {
                    base,
                    extra_mask: ((1u64 << extra) - 1) as u32,
                    bits_mask: (1 << bits) - 1,
                    next: 0,
                    extra: extra as u8,
                    len: (extra + bits) as u8,
                };
                let mut next = (ks.start << bits) - size;
                for _ in ks {
                    table[p] = Entry {
                        next: next as u16,
                        ..entry
                    };
                    next += 1 << bits;
                    p = (p + step) & mask;
                }
            }
        }
        let mut states = [0usize; LANES];
        for s in &mut states {
            *s = (peek_checked(stream, pos) & u64::from(size - 1)) as usize;
            pos += log as usize;
        }
        Ok(Start {
            pos,
            states,
            group: (LANES * most as usize).div_ceil(8).max(1),
            size: size as usize,
        })
    }

    /// Decodes exactly `out.len()` codes from `stream` (all of it) into `out`, each mapped
    /// by `map` in order: the residual kernels take them as they need them (a lattice
    /// residual widened and scaled, a float's as it is).
    pub fn decode<T>(
        &mut self,
        stream: &[u8],
        out: &mut [T],
        mut map: impl FnMut(u32) -> T,
    ) -> Result<(), StreamError> {
        let (count, at) = read_count(stream)?;
        if count != out.len() as u64 {
            return Err(StreamError::Count(format!(
                "{count} codes where the payload has {}",
                out.len()
            )));
        }
        let stream = &stream[at..];
        if out.is_empty() {
            return match stream.is_empty() {
                true => Ok(()),
                false => Err(StreamError::Trailing("bytes for no codes")),
            };
        }
        let Start {
            mut pos,
            mut states,
            group,
            size,
        } = self.start(stream)?;
        let table = &self.table[..size];
        let n = out.len();
        let mut i = groups(table, group, stream, &mut pos, &mut states, out, &mut map);
        if i < n {
            // Fewer than four codes left, or too few bytes for a group: the rest from a
            // copy of the last bytes padded with zeros for the loads to overrun. (A stream
            // whose last codes take more bytes than the copy holds has bytes after them, which
            // the checks below refuse.)
            let from = pos >> 3;
            let Some(left) = stream.len().checked_sub(from) else {
                return Err(StreamError::Short);
            };
            let take = left.min(2 * REACH);
            let mut tail = [0u8; 3 * REACH];
            tail[..take].copy_from_slice(&stream[from..from + take]);
            let mut at = pos - 8 * from;
            i += groups(
                table,
                group,
                &tail[..take + group + 8],
                &mut at,
                &mut states,
                &mut out[i..],
                &mut map,
            );
            while i < n {
                // Past the real bytes the stream is short: stop before a load overruns.
                if (at >> 3) > take {
                    return Err(StreamError::Short);
                }
                out[i] = map(step(table, &tail, &mut at, &mut states[i % LANES]));
                i += 1;
            }
            pos = 8 * from + at;
        }
        if pos > 8 * stream.len() {
            return Err(StreamError::Short);
        }
        if pos.div_ceil(8) != stream.len() {
            return Err(StreamError::Trailing("bytes after the last code"));
        }
        if pos % 8 != 0 && stream[stream.len() - 1] >> (pos % 8) != 0 {
            return Err(StreamError::Trailing("bits set after the last code"));
        }
        if states.iter().any(|&s| s != 0) {
            return Err(StreamError::Trailing("a state an encoder does not end in"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn round_trip(codes: &[u32]) -> Vec<u8> {
        let mut stream = Vec::new();
        encode(codes, &mut stream);
        let mut back = vec![0u32; codes.len()];
        Decoder::default()
            .decode(&stream, &mut back, |v| v)
            .expect("an encoder's stream decodes");
        assert_eq!(back, codes, "a code came back changed");
        stream
    }

    fn xorshift(seed: u32) -> impl FnMut() -> u32 {
        let mut x = seed;
        move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        }
    }

    #[test]
    fn bins_cover_every_code_once() {
        // Each symbol's range starts where the one before ends, and the last ends at 2^32.
        let mut next = 0u64;
        for s in 0..SYMBOLS {
            let (base, extra) = symbol_range(s);
            assert_eq!(u64::from(base), next, "symbol {s} starts at {base}");
            assert_eq!(bin(base), (s, base, extra));
            let last = u64::from(base) + (1u64 << extra) - 1;
            assert_eq!(bin(last as u32), (s, base, extra));
            next = last + 1;
        }
        assert_eq!(next, 1u64 << 32);
    }

    #[test]
    fn edge_cases_round_trip() {
        let mut random = xorshift(0x9E37_79B9);
        let cases: Vec<Vec<u32>> = vec![
            vec![0],
            vec![u32::MAX],
            vec![5, 5, 5],
            vec![7; 4099],
            (0..5000).map(|_| random()).collect(),
            (0..4097).map(|_| random() >> (random() % 32)).collect(),
            (0..33).map(|i| u32::MAX - i).collect(),
            (0..(1 << 16)).map(|_| random() % 3).collect(),
            // Every symbol once: 128 present symbols need a table of at least 2^7.
            (0..SYMBOLS).map(|s| symbol_range(s).0).collect(),
        ];
        for codes in cases {
            round_trip(&codes);
        }
    }

    #[test]
    fn codes_of_one_symbol_cost_no_bits() {
        // Every state of a one-symbol table reads no bits, so the codes cost nothing past the
        // count (2 bytes for 1000, 1 for 100) and the header: 3 + 7 bits, symbols 0 to 2's
        // weights of 0 (a bit each) and four states of 5 bits, 33 bits in 5 bytes.
        assert_eq!(round_trip(&[3; 1000]).len(), 2 + 5);
        assert_eq!(round_trip(&[3; 100]).len(), 1 + 5);
        // The count is what tells them apart: read as another count, the stream is refused.
        let stream = round_trip(&[3; 100]);
        let mut other = vec![0u32; 99];
        let mut d = Decoder::default();
        assert!(matches!(
            d.decode(&stream, &mut other, |v| v),
            Err(StreamError::Count(_))
        ));
        // Its last byte holds 1 bit of the stream and 7 unread, which must be zeros.
        let mut set = stream.clone();
        *set.last_mut().expect("a byte") |= 0x80;
        let mut back = vec![0u32; 100];
        assert_eq!(
            d.decode(&set, &mut back, |v| v),
            Err(StreamError::Trailing("bits set after the last code"))
        );
    }

    #[test]
    fn no_codes_are_a_count_of_zero() {
        assert_eq!(round_trip(&[]), [0]);
        let mut none: [u32; 0] = [];
        let mut d = Decoder::default();
        assert_eq!(
            d.decode(&[0, 0], &mut none, |v| v),
            Err(StreamError::Trailing("bytes for no codes"))
        );
        for not_a_count in [&[][..], &[0x80, 0], &[0x80; 5], &[0x80; 6]] {
            assert!(matches!(
                d.decode(not_a_count, &mut none, |v| v),
                Err(StreamError::Count(_))
            ));
        }
    }

    #[test]
    fn counts_round_trip() {
        for v in [0, 1, 127, 128, 16_383, 16_384, u32::MAX] {
            let mut out = Vec::new();
            varint(u64::from(v), &mut out);
            assert_eq!(read_count(&out), Ok((u64::from(v), out.len())));
        }
    }

    #[test]
    fn a_stream_cut_or_extended_is_refused() {
        let mut random = xorshift(7);
        let codes: Vec<u32> = (0..700).map(|_| random() % 40).collect();
        let stream = round_trip(&codes);
        let mut back = vec![0u32; codes.len()];
        let mut d = Decoder::default();
        for cut in 0..stream.len() {
            assert!(
                d.decode(&stream[..cut], &mut back, |v| v).is_err(),
                "cut to {cut} bytes of {}",
                stream.len()
            );
        }
        let mut longer = stream.clone();
        longer.push(0);
        assert!(d.decode(&longer, &mut back, |v| v).is_err());
        // One code fewer or more than stored.
        assert!(d.decode(&stream, &mut back[1..], |v| v).is_err());
        let mut more = vec![0u32; codes.len() + 1];
        assert!(d.decode(&stream, &mut more, |v| v).is_err());
    }

    #[test]
    fn a_stream_run_on_past_its_last_codes_is_refused() {
        // Regression: with fewer codes left than lanes and many bytes after them, the tail
        // copied more bytes than its buffer held (found by the property test below).
        for n in 1..9u32 {
            let codes: Vec<u32> = (0..n).map(|i| i * 1000).collect();
            let mut stream = round_trip(&codes);
            stream.extend_from_slice(&[0; 64]);
            let mut back = vec![0u32; codes.len()];
            assert_eq!(
                Decoder::default().decode(&stream, &mut back, |v| v),
                Err(StreamError::Trailing("bytes after the last code")),
                "{n} codes"
            );
        }
    }

    #[test]
    fn a_hostile_header_is_refused() {
        let mut out = [0u32; 4];
        let mut d = Decoder::default();
        // L = 5, two symbols, the first's weight 32 (gamma of 33: five zeros, a one, then
        // 00001): nothing is left for the last symbol.
        let mut stream = vec![4];
        let mut bits = BitWriter {
            out: &mut stream,
            acc: 0,
            filled: 0,
        };
        bits.put(0, 3);
        bits.put(1, 7);
        bits.gamma(33);
        bits.put(0, 32);
        bits.finish();
        assert_eq!(
            d.decode(&stream, &mut out, |v| v),
            Err(StreamError::Table(
                "the weights leave no state for the last symbol"
            ))
        );
        // A run of zero bits as long as the stream: a weight past any table.
        assert_eq!(
            d.decode(&[4, 0xF8, 0x0F, 0, 0, 0, 0, 0, 0, 0, 0], &mut out, |v| v),
            Err(StreamError::Table("a weight larger than the table"))
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn any_codes_round_trip(
            codes in proptest::collection::vec(any::<u32>(), 0..600),
            shift in 0u32..32,
            modulus in 1u32..64,
            kind in 0usize..3,
        ) {
            let codes: Vec<u32> = match kind {
                0 => codes,
                1 => codes.iter().map(|&v| v >> shift).collect(),
                _ => codes.iter().map(|&v| v % modulus).collect(),
            };
            round_trip(&codes);
        }

        #[test]
        fn any_bytes_decode_or_fail_without_panic(
            bytes in proptest::collection::vec(any::<u8>(), 0..300),
            n in 0u32..400,
        ) {
            // (At 256 cases this found the tail's overrun, kept as a fixed case above.)
            // The right count first, so that the bytes reach the table and the codes.
            let mut stream = Vec::new();
            varint(u64::from(n), &mut stream);
            stream.extend_from_slice(&bytes);
            let mut out = vec![0u32; n as usize];
            if Decoder::default().decode(&stream, &mut out, |v| v).is_ok() {
                // What decodes is a stream an encoder could have written: its codes code
                // back to codes that decode alike.
                round_trip(&out);
            }
        }
    }
}
