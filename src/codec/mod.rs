//! Block codecs: a grid of `f32` heights (voids as NaN) to bytes and back, bit for bit.
//!
//! Terrain heights are smooth, and most sources store them on a lattice: SRTM in whole
//! metres, a 16-bit PNG at 0.1 m, a USGS DEM at 1 m. A general-purpose compressor (DEFLATE,
//! zstd) sees neither: on 65² blocks of real DEMs it keeps 11–62 % of the raw bytes. This
//! module tries, per block, the encodings that do see them and keeps the smallest:
//!
//! | id | encoding | when |
//! |---|---|---|
//! | 0 | raw little-endian `f32` | nothing smaller |
//! | 1 | constant: one `f32`'s bits | every sample has the same bits (sea, an all-void block) |
//! | 2 | lattice: integers `k` with `h = (k · q) as f32` exactly, predicted in 2D | every real sample lies on a lattice step `q` of [`LATTICE_STEPS`] |
//! | 3 | pco on the `f32` values | floats off any lattice |
//! | 4 | pco on 2D-predicted residuals of the `f32` bits | floats off any lattice |
//! | 5, 6 | lattice or float, against a parent grid ([`parent`]): the held samples free, the others predicted from the grid | a block (format 4) or grid (format 5) whose parent's grid holds a quarter of its samples |
//! | 7, 8 | lattice or float, the held samples free, the others 2D-predicted as in 2 and 4 | the same, where the block's own neighbours predict better |
//! | 9–14 | 2, 4, 5, 6, 7 and 8 with their residuals in the binned tANS stream ([`tans`]) rather than pco | a writer of format 7 (lattice ones: where the residuals over their common factor fit an `i32`) |
//! | 15 | lattice against a parent grid, predicted from the parent's lattice codes in integers, tANS | a writer of format 7, in place of 11 where every parent code is within ±2^22 |
//!
//! Encodings 5 to 8 code a block *against its parent's grid*: the samples the parent holds
//! cost nothing, the others are residuals against an interpolation of the parent (5, 6) or
//! against the planar predictor over the block's own samples (7, 8). [`decode`] refuses them
//! (it has no parent); [`parent::decode_against`] takes one.
//!
//! **The 2D predictor** is the planar (Lorenzo) predictor `left + up - up_left`, which is
//! exact on any plane: residuals on terrain are small and centred on zero. **pco**
//! (pcodec, a pure-Rust codec for numeric columns) then codes the residuals with binning and
//! tANS. Measured on 65² blocks (`cargo bench --bench codecs`), this keeps 29 % of Puget
//! Sound 1k's bytes where zstd keeps 57 % and plain pco 33 %, and decodes at about 1 GB/s.
//! Format 7 codes them with a binned tANS stream of our own instead ([`tans`], [`Coder`];
//! encodings 9 to 15, `format-spec/container.md` §7): the same idea without pco's generality,
//! smaller and faster to decode (`docs/format-7-plan.md` records why and how it was measured).
//!
//! **Voids** are the canonical NaN (`0x7FC00000`). The lattice encoding lists them in a
//! bitmap ([`voids`]: raw, or since format 5 as runs of the row-to-row changes) and predicts
//! through them; any other NaN bits, `-0.0`, or infinities send the block
//! to an encoding that keeps bits as they are (1, 3, 4 or 0), so every encoding round-trips
//! bit for bit.
//!
//! **Hostile bytes.** [`decode`] writes into a buffer of the declared size and never
//! allocates from a length in the input: a stream that claims more or fewer samples than the
//! block holds, trailing bytes, an unknown id or a bad lattice step is a [`DecodeError`],
//! never a panic. (The payload CRC catches corruption before decoding; this is the second
//! line.)
//!
//! **Speed.** Decoding is pco, then the kernels that turn residuals into heights: the
//! planar chain, the parent's interpolation, roundings and conversions a row at a time
//! ([`parent`]'s `rows`). Those kernels are built twice, for the baseline x86-64 and for
//! AVX2, and run as the build the CPU can (`wide`): the same bits either way.
//!
//! The module knows nothing of files: the format stores its output as payload bytes.

#[macro_use]
mod wide;
pub mod parent;
mod residuals;
pub mod tans;
pub mod voids;

pub use residuals::Coder;

#[cfg(any(test, feature = "testing"))]
pub use wide::baseline as with_baseline_kernels;

use pco::standalone::{simple_compress, DecompressorItem, FileDecompressor};
use pco::ChunkConfig;

/// The bits of a void sample.
pub const VOID_BITS: u32 = 0x7FC0_0000;

/// The lattice steps a lossless encoding tries, coarsest first: whole units and the binary
/// and decimal fractions sources quantise to.
pub const LATTICE_STEPS: [f64; 9] = [1.0, 0.5, 0.25, 0.125, 0.1, 0.05, 0.01, 0.001, 0.0001];

/// The largest lattice index `|k|` stored: beyond it the block is not a lattice.
const MAX_LATTICE_INDEX: f64 = (1u64 << 40) as f64;

/// An encoding's id, the first byte of every encoded block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Encoding {
    /// Raw little-endian `f32`.
    Raw = 0,
    /// One `f32`'s bits for every sample.
    Constant = 1,
    /// Integers on a lattice step, 2D-predicted, pco-coded.
    Lattice = 2,
    /// pco on the `f32` values.
    FloatPco = 3,
    /// pco on 2D-predicted residuals of the `f32` bits.
    FloatPredicted = 4,
    /// Lattice integers of the samples the parent's grid does not hold, predicted from it
    /// ([`parent`]; decoding needs the parent's heights).
    LatticeFromParent = 5,
    /// The `f32` bits of the samples the parent's grid does not hold, predicted from it.
    FloatFromParent = 6,
    /// Lattice integers of the samples the parent's grid does not hold, 2D-predicted from
    /// the block's own samples (the held ones known from the parent first).
    LatticePlanarFromParent = 7,
    /// The `f32` bits of the samples the parent's grid does not hold, 2D-predicted from
    /// the block's own samples.
    FloatPlanarFromParent = 8,
    /// [`Encoding::Lattice`] with its residuals in a tANS stream (format 7).
    LatticeTans = 9,
    /// [`Encoding::FloatPredicted`] with its residuals in a tANS stream.
    FloatPredictedTans = 10,
    /// [`Encoding::LatticeFromParent`] with its residuals in a tANS stream.
    LatticeFromParentTans = 11,
    /// [`Encoding::FloatFromParent`] with its residuals in a tANS stream.
    FloatFromParentTans = 12,
    /// [`Encoding::LatticePlanarFromParent`] with its residuals in a tANS stream.
    LatticePlanarFromParentTans = 13,
    /// [`Encoding::FloatPlanarFromParent`] with its residuals in a tANS stream.
    FloatPlanarFromParentTans = 14,
    /// Lattice integers of the samples the parent's grid does not hold, predicted from the
    /// parent's lattice codes in integers (`parent`'s `codes`), residuals in a tANS stream
    /// (format 7).
    LatticeFromParentCodes = 15,
}

/// The pco encodings with a tANS twin, and their twins, in pairs.
const TANS_OF: [(Encoding, Encoding); 6] = [
    (Encoding::Lattice, Encoding::LatticeTans),
    (Encoding::FloatPredicted, Encoding::FloatPredictedTans),
    (Encoding::LatticeFromParent, Encoding::LatticeFromParentTans),
    (Encoding::FloatFromParent, Encoding::FloatFromParentTans),
    (Encoding::LatticePlanarFromParent, Encoding::LatticePlanarFromParentTans),
    (Encoding::FloatPlanarFromParent, Encoding::FloatPlanarFromParentTans),
];

impl Encoding {
    /// The encoding of id `byte`.
    pub fn from_id(byte: u8) -> Option<Encoding> {
        Some(match byte {
            0 => Encoding::Raw,
            1 => Encoding::Constant,
            2 => Encoding::Lattice,
            3 => Encoding::FloatPco,
            4 => Encoding::FloatPredicted,
            5 => Encoding::LatticeFromParent,
            6 => Encoding::FloatFromParent,
            7 => Encoding::LatticePlanarFromParent,
            8 => Encoding::FloatPlanarFromParent,
            9 => Encoding::LatticeTans,
            10 => Encoding::FloatPredictedTans,
            11 => Encoding::LatticeFromParentTans,
            12 => Encoding::FloatFromParentTans,
            13 => Encoding::LatticePlanarFromParentTans,
            14 => Encoding::FloatPlanarFromParentTans,
            15 => Encoding::LatticeFromParentCodes,
            _ => return None,
        })
    }

    /// The pco encoding of the same shape (itself for one that is not a tANS one): its
    /// header, prediction and layout, which the decoders dispatch on.
    pub fn shape(self) -> Encoding {
        TANS_OF
            .iter()
            .find(|&&(_, t)| t == self)
            .map_or(self, |&(p, _)| p)
    }

    /// The coder of this encoding's residuals: tANS from id 9 on (format 7).
    pub fn coder(self) -> Coder {
        if (self as u8) < 9 {
            Coder::Pco
        } else {
            Coder::Tans
        }
    }

    /// This shape (a pco encoding) with its residuals coded by `coder`.
    fn coded_by(self, coder: Coder) -> Encoding {
        match coder {
            Coder::Pco => self.shape(),
            Coder::Tans => TANS_OF
                .iter()
                .find(|&&(p, _)| p == self)
                .map_or(self, |&(_, t)| t),
        }
    }

    /// The encoding `bytes` (an encoded block) uses.
    pub fn of(bytes: &[u8]) -> Option<Encoding> {
        bytes.first().and_then(|&b| Encoding::from_id(b))
    }
}

/// Why bytes do not decode to a block.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// Empty input, or an id no encoding has.
    #[error("unknown block encoding {0:?}")]
    UnknownEncoding(Option<u8>),
    /// The bytes end before the encoding's fixed part does, or go on after it.
    #[error("{encoding:?} block of {len} bytes: {detail}")]
    Length {
        /// The encoding.
        encoding: Encoding,
        /// The input's length.
        len: usize,
        /// What is wrong.
        detail: String,
    },
    /// A lattice step that is not finite and positive.
    #[error("lattice step {0} is not finite and positive")]
    Step(f64),
    /// The pco stream is damaged or holds the wrong count.
    #[error("pco stream: {0}")]
    Pco(String),
    /// The tANS stream is damaged or holds the wrong count.
    #[error("{0}")]
    Tans(tans::StreamError),
    /// A lattice tANS stream's common factor is not a LEB128 varint in `1..2^32`.
    #[error("the residuals' common factor is not a varint in 1..2^32")]
    Factor,
}

/// Encodes a `width`-wide row-major block, picking the smallest encoding.
///
/// # Panics
/// If `samples.len()` is not a multiple of a non-zero `width` (a caller's bug).
#[cfg(any(test, feature = "testing"))]
pub fn encode(samples: &[f32], width: usize) -> Vec<u8> {
    encode_on(samples, width, None, Coder::default())
}

/// As [`encode`], also trying the lattice step `step` (a file's storage precision, which
/// need not be one of [`LATTICE_STEPS`]), with residuals coded by `coder`. The coarsest step
/// every sample lies on wins.
///
/// # Panics
/// As [`encode`].
pub fn encode_on(samples: &[f32], width: usize, step: Option<f64>, coder: Coder) -> Vec<u8> {
    assert!(
        width > 0 && samples.len().is_multiple_of(width),
        "encode: {} samples in rows of {width}",
        samples.len()
    );
    let Some(&first) = samples.first() else {
        return vec![Encoding::Raw as u8];
    };
    if samples.iter().all(|v| v.to_bits() == first.to_bits()) {
        let mut out = vec![Encoding::Constant as u8];
        out.extend_from_slice(&first.to_bits().to_le_bytes());
        return out;
    }
    let mut best = raw(samples);
    let mut keep = |candidate: Option<Vec<u8>>| {
        if let Some(c) = candidate {
            if c.len() < best.len() {
                best = c;
            }
        }
    };
    let mut steps = LATTICE_STEPS.to_vec();
    if let Some(q) = step.filter(|q| q.is_finite() && *q > 0.0) {
        steps.push(q);
        steps.sort_by(|a, b| b.total_cmp(a));
    }
    match steps.iter().find(|&&q| on_lattice(samples, q)) {
        // On a lattice the float encodings cannot win by much; skip their cost.
        Some(&q) => keep(lattice(samples, width, q, coder)),
        None => {
            keep(float_pco(samples));
            keep(float_predicted(samples, width, coder));
        }
    }
    best
}

/// The raw encoding of `samples` (encoding 0): what a writer stores when told not to
/// compress (the format's payload `Coding`).
pub fn encode_raw(samples: &[f32]) -> Vec<u8> {
    raw(samples)
}

/// Decodes `bytes` into `out`, a `width`-wide block of `out.len()` samples.
pub fn decode(bytes: &[u8], width: usize, out: &mut [f32]) -> Result<(), DecodeError> {
    let encoding =
        Encoding::of(bytes).ok_or(DecodeError::UnknownEncoding(bytes.first().copied()))?;
    let body = &bytes[1..];
    let length = |detail: String| DecodeError::Length {
        encoding,
        len: bytes.len(),
        detail,
    };
    if width == 0 || !out.len().is_multiple_of(width) {
        return Err(length(format!(
            "{} samples do not make rows of {width}",
            out.len()
        )));
    }
    let coder = encoding.coder();
    match encoding.shape() {
        Encoding::Raw => {
            if body.len() != 4 * out.len() {
                return Err(length(format!(
                    "{} samples need {} bytes",
                    out.len(),
                    4 * out.len()
                )));
            }
            for (o, b) in out.iter_mut().zip(body.chunks_exact(4)) {
                *o = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            }
        }
        Encoding::Constant => {
            let bits: [u8; 4] = body
                .try_into()
                .map_err(|_| length("a constant is 4 bytes".into()))?;
            out.fill(f32::from_bits(u32::from_le_bytes(bits)));
        }
        Encoding::Lattice => {
            let n = out.len();
            if body.len() < 9 {
                return Err(length("shorter than its step and flags".into()));
            }
            let q = f64::from_le_bytes(body[..8].try_into().unwrap_or([0; 8]));
            if !(q.is_finite() && q > 0.0) {
                return Err(DecodeError::Step(q));
            }
            let (voids, rest) = voids::read(body[8], &body[9..], n, width).map_err(length)?;
            let voids = voids.as_deref();
            with_scratch(n, |k: &mut [i64]| {
                residuals::read_lattice(coder, rest, k)?;
                if lattice_from_residuals(k, voids, width, q, out) {
                    let (i, ki) = k
                        .iter()
                        .enumerate()
                        .find(|(_, ki)| ki.unsigned_abs() > MAX_LATTICE_INDEX as u64)
                        .map_or((0, 0), |(i, &ki)| (i, ki));
                    return Err(DecodeError::Pco(format!(
                        "lattice index {ki} at sample {i} is out of range"
                    )));
                }
                Ok(())
            })?;
            if let Some(m) = voids {
                for (i, o) in out.iter_mut().enumerate() {
                    if voids::is_void(m, i) {
                        *o = f32::from_bits(VOID_BITS);
                    }
                }
            }
        }
        Encoding::FloatPco => pco_decode(body, out)?,
        Encoding::FloatPredicted => with_scratch(out.len(), |u: &mut [u32]| {
            residuals::read_float(coder, body, u)?;
            float_from_residuals(u, width, out);
            Ok::<(), DecodeError>(())
        })?,
        _ => {
            return Err(length(
                "coded against a parent grid: decode with codec::parent".into(),
            ));
        }
    }
    Ok(())
}

wide! {
    /// Encoding 2's residuals `k` (decoded from their stream) to heights in `out`, the voids of the
    /// bitmap `voids` left for the caller; says whether an index was out of range.
    fn lattice_from_residuals(
        k: &mut [i64],
        voids: Option<&[u8]>,
        width: usize,
        q: f64,
        out: &mut [f32],
    ) -> bool {
        // In place: each residual becomes its index once the cells it is predicted from
        // (left, up, up-left: all earlier) are indexes. A void's residual is ignored
        // (written 0).
        if let Some(m) = voids {
            for (i, r) in k.iter_mut().enumerate() {
                if voids::is_void(m, i) {
                    *r = 0;
                }
            }
        }
        unpredict(k, width);
        lattice_heights(k, out, q, None)
    }
}

wide! {
    /// Encoding 4's zigzag residuals `u` (decoded from their stream) to heights in `out`.
    fn float_from_residuals(u: &mut [u32], width: usize, out: &mut [f32]) {
        for r in u.iter_mut() {
            *r = unzigzag(*r);
        }
        unpredict(u, width);
        for (o, &ui) in out.iter_mut().zip(u.iter()) {
            *o = from_ordered(ui);
        }
    }
}

/// The height of lattice index `k` (an integer-valued `f64`) on step `q`: `(k · q) as f32`,
/// the one formula the lattice encoding decodes with, so a height made by it is on the
/// lattice (for `|k| <= 2^40`). `k = -0` gives `+0.0`.
pub fn lattice_value(k: f64, q: f64) -> f32 {
    ((k + 0.0) * q) as f32
}

/// The heights of lattice indexes `codes` on step `q` into `out` ([`lattice_value`]), and
/// whether an index not in a held column (`held`: those the parent holds, whose heights the
/// caller then takes from the parent) is out of range. A row whose indexes all fit in an
/// `i32` (almost every row: ±2^31 steps) converts through `i32`, which the compiler
/// vectorises; `k as f64` is the same number either way.
#[inline(always)]
pub(crate) fn lattice_heights(
    codes: &[i64],
    out: &mut [f32],
    q: f64,
    held: Option<&[Option<u32>]>,
) -> bool {
    // `k ^ (k >> 63)` is `k` or `-k - 1`: below 2^31 for all exactly when all fit.
    let spread = codes.iter().fold(0u64, |a, &k| a | (k ^ (k >> 63)) as u64);
    if spread < 1 << 31 {
        for (o, &k) in out.iter_mut().zip(codes) {
            *o = lattice_value(f64::from(k as i32), q);
        }
        return false;
    }
    let mut bad = false;
    for (i, (o, &k)) in out.iter_mut().zip(codes).enumerate() {
        *o = lattice_value(k as f64, q);
        let coded = held.is_none_or(|h| h.get(i).is_none_or(Option::is_none));
        bad |= coded && k.unsigned_abs() > MAX_LATTICE_INDEX as u64;
    }
    bad
}

/// The lattice index nearest to `v` on step `q`, when it is within the lattice's range.
pub fn lattice_index(v: f32, q: f64) -> Option<f64> {
    let k = (f64::from(v) / q).round();
    (k.abs() <= MAX_LATTICE_INDEX).then_some(k)
}

/// Whether every real sample of `samples` is exactly `(k · q) as f32` for an integer `k`
/// within range, and every void the canonical NaN; `-0.0` is not on a lattice (it would
/// come back as `+0.0`), nor any other NaN or an infinity.
fn on_lattice(samples: &[f32], q: f64) -> bool {
    samples.iter().all(|&v| {
        if v.is_nan() {
            return v.to_bits() == VOID_BITS;
        }
        is_lattice_value(v, q) && v.is_finite()
    })
}

/// Whether `v` is exactly the lattice value of its own nearest index on step `q` (so the
/// lattice encoding gives back its bits): false for `-0.0` and beyond the index range.
pub fn is_lattice_value(v: f32, q: f64) -> bool {
    lattice_index(v, q).is_some_and(|k| lattice_value(k, q).to_bits() == v.to_bits())
}

fn raw(samples: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(1 + 4 * samples.len());
    out.push(Encoding::Raw as u8);
    for v in samples {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Integers the planar predictor works on, in wrapping arithmetic.
trait Wrapping: Copy + Default {
    fn plus(self, other: Self) -> Self;
    fn minus(self, other: Self) -> Self;
}

impl Wrapping for i64 {
    #[inline(always)]
    fn plus(self, other: i64) -> i64 {
        self.wrapping_add(other)
    }
    #[inline(always)]
    fn minus(self, other: i64) -> i64 {
        self.wrapping_sub(other)
    }
}

impl Wrapping for u32 {
    #[inline(always)]
    fn plus(self, other: u32) -> u32 {
        self.wrapping_add(other)
    }
    #[inline(always)]
    fn minus(self, other: u32) -> u32 {
        self.wrapping_sub(other)
    }
}

/// The planar prediction of cell `i` from its decoded neighbours: `left + up - up_left`,
/// the left one in the first row, the upper one in the first column, zero at the start.
fn predict<T: Wrapping>(k: &[T], i: usize, width: usize) -> T {
    match (i % width, i / width) {
        (0, 0) => T::default(),
        (_, 0) => k[i - 1],
        (0, _) => k[i - width],
        _ => k[i - 1].plus(k[i - width]).minus(k[i - width - 1]),
    }
}

/// Turns residuals into values in place, row by row: cell `i` gets [`predict`]'s value from
/// the cells before it plus its residual. The same arithmetic as `predict` in another
/// order, `left + ((up - up_left) + r)`, so the chain from cell to cell is one addition held
/// in a register (decoding spends its time here and in pco).
#[inline(always)]
fn unpredict<T: Wrapping>(k: &mut [T], width: usize) {
    let width = width.max(1);
    for row in (0..k.len()).step_by(width) {
        let (above, rest) = k.split_at_mut(row);
        let len = width.min(rest.len());
        let cur = &mut rest[..len];
        let (mut left, mut up_left) = (T::default(), T::default());
        match above.len().checked_sub(width) {
            None => {
                for c in cur.iter_mut() {
                    left = left.plus(*c);
                    *c = left;
                }
            }
            Some(start) => {
                for (c, &u) in cur.iter_mut().zip(&above[start..]) {
                    left = left.plus(u.minus(up_left).plus(*c));
                    up_left = u;
                    *c = left;
                }
            }
        }
    }
}

fn lattice(samples: &[f32], width: usize, q: f64, coder: Coder) -> Option<Vec<u8>> {
    let n = samples.len();
    let mut k = vec![0i64; n];
    let mut residuals = vec![0i64; n];
    let mut bitmap = vec![0u8; n.div_ceil(8)];
    let mut any_void = false;
    for i in 0..n {
        let p = predict(&k, i, width);
        if samples[i].is_nan() {
            // Predicted through: the void costs a zero residual and a bitmap bit.
            k[i] = p;
            bitmap[i / 8] |= 1 << (i % 8);
            any_void = true;
        } else {
            k[i] = (f64::from(samples[i]) / q).round() as i64;
            residuals[i] = k[i].wrapping_sub(p);
        }
    }
    let (coder, coded) = residuals::code_lattice(coder, &residuals)?;
    let mut out = Vec::with_capacity(10 + bitmap.len() + coded.len());
    out.push(Encoding::Lattice.coded_by(coder) as u8);
    out.extend_from_slice(&q.to_le_bytes());
    if any_void {
        voids::write(&bitmap, n, width, true, &mut out);
    } else {
        out.push(voids::NONE);
    }
    out.extend_from_slice(&coded);
    Some(out)
}

fn float_pco(samples: &[f32]) -> Option<Vec<u8>> {
    let coded = simple_compress(samples, &ChunkConfig::default()).ok()?;
    let mut out = Vec::with_capacity(1 + coded.len());
    out.push(Encoding::FloatPco as u8);
    out.extend_from_slice(&coded);
    Some(out)
}

/// `f32` bits mapped so that integer order is float order (negative floats reversed): a
/// negative float's bits inverted, a positive one's sign bit set. Without a branch (an XOR
/// with the sign spread over the word, and the sign bit), which the scalar loops of the
/// float kernels take a row's held samples through.
#[inline(always)]
fn to_ordered(v: f32) -> u32 {
    let b = v.to_bits();
    b ^ (((b as i32) >> 31) as u32 | 0x8000_0000)
}

/// The inverse of [`to_ordered`].
#[inline(always)]
fn from_ordered(u: u32) -> f32 {
    f32::from_bits(u ^ ((((!u) as i32) >> 31) as u32 | 0x8000_0000))
}

/// A wrapping `u32` difference as an unsigned code, small for small differences either way.
fn zigzag(d: u32) -> u32 {
    let d = d as i32;
    ((d << 1) ^ (d >> 31)) as u32
}

/// The inverse of [`zigzag`].
#[inline(always)]
fn unzigzag(z: u32) -> u32 {
    ((z >> 1) as i32 ^ -((z & 1) as i32)) as u32
}

fn float_predicted(samples: &[f32], width: usize, coder: Coder) -> Option<Vec<u8>> {
    let u: Vec<u32> = samples.iter().map(|&v| to_ordered(v)).collect();
    let residuals: Vec<u32> = (0..u.len())
        .map(|i| zigzag(u[i].wrapping_sub(predict(&u, i, width))))
        .collect();
    let coded = residuals::code_float(coder, &residuals)?;
    let mut out = Vec::with_capacity(1 + coded.len());
    out.push(Encoding::FloatPredicted.coded_by(coder) as u8);
    out.extend_from_slice(&coded);
    Some(out)
}

/// Numbers a decoder keeps a scratch buffer of, one per thread, reused from payload to
/// payload so that decoding allocates and zeroes nothing per block once warm.
pub(crate) trait Scratch: pco::data_types::Number + Default {
    /// Runs `f` with this thread's buffer of `Self`.
    fn with_buffer<R>(f: impl FnOnce(&mut Vec<Self>) -> R) -> R;
}

macro_rules! scratch {
    ($t:ty) => {
        impl Scratch for $t {
            fn with_buffer<R>(f: impl FnOnce(&mut Vec<Self>) -> R) -> R {
                thread_local! {
                    static BUFFER: std::cell::RefCell<Vec<$t>> = const { std::cell::RefCell::new(Vec::new()) };
                }
                BUFFER.with(|b| match b.try_borrow_mut() {
                    Ok(mut v) => f(&mut v),
                    // Re-entered (no decoder does): a buffer of its own.
                    Err(_) => f(&mut Vec::new()),
                })
            }
        }
    };
}
scratch!(i64);
scratch!(u32);

/// The largest scratch buffer a thread keeps between payloads, in numbers: a block of the
/// largest size (a larger one is decoded in a buffer of its own, then dropped).
const SCRATCH_KEPT: usize = 1 << 17;

/// Runs `f` on `n` numbers of this thread's scratch buffer (their values left over from
/// the last use: `f` overwrites them).
pub(crate) fn with_scratch<T: Scratch, R>(n: usize, f: impl FnOnce(&mut [T]) -> R) -> R {
    T::with_buffer(|v| {
        if v.len() < n {
            v.resize(n, T::default());
        }
        let result = f(&mut v[..n]);
        if v.len() > SCRATCH_KEPT {
            *v = Vec::new();
        }
        result
    })
}

/// Decodes a pco stream of exactly `out.len()` numbers into `out`: no allocation sized by
/// the stream, no bytes after its end.
fn pco_decode<T: pco::data_types::Number>(src: &[u8], out: &mut [T]) -> Result<(), DecodeError> {
    let err = |e: pco::errors::PcoError| DecodeError::Pco(e.to_string());
    let (file, mut rest) = FileDecompressor::new(src).map_err(err)?;
    let mut done = 0usize;
    loop {
        match file.chunk_decompressor::<T, &[u8]>(rest).map_err(err)? {
            DecompressorItem::Chunk(mut chunk) => {
                let n = chunk.n();
                if n > out.len() - done {
                    return Err(DecodeError::Pco(format!(
                        "a chunk of {n} numbers past the block's {}",
                        out.len()
                    )));
                }
                let progress = chunk.read(&mut out[done..done + n]).map_err(err)?;
                if progress.n_processed != n || !progress.finished {
                    return Err(DecodeError::Pco(format!(
                        "a chunk of {n} numbers decoded {}",
                        progress.n_processed
                    )));
                }
                done += n;
                rest = chunk.into_src();
            }
            DecompressorItem::EndOfData(tail) => {
                if done != out.len() {
                    return Err(DecodeError::Pco(format!(
                        "{done} numbers for a block of {}",
                        out.len()
                    )));
                }
                if !tail.is_empty() {
                    return Err(DecodeError::Pco(format!(
                        "{} bytes after the end of the stream",
                        tail.len()
                    )));
                }
                return Ok(());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(samples: &[f32], width: usize) -> Encoding {
        round_trip_by(samples, width, Coder::Tans);
        round_trip_by(samples, width, Coder::Pco)
    }

    fn round_trip_by(samples: &[f32], width: usize, coder: Coder) -> Encoding {
        let bytes = encode_on(samples, width, None, coder);
        let mut out = vec![0.0f32; samples.len()];
        decode(&bytes, width, &mut out).expect("decodes");
        for (i, (a, b)) in samples.iter().zip(&out).enumerate() {
            assert_eq!(a.to_bits(), b.to_bits(), "sample {i}: {a} became {b}");
        }
        Encoding::of(&bytes).expect("an encoding")
    }

    #[test]
    fn each_encoding_is_chosen_where_it_fits() {
        let w = 65;
        let flat = vec![12.5f32; w * w];
        assert_eq!(round_trip(&flat, w), Encoding::Constant);
        let void = vec![f32::from_bits(VOID_BITS); w * w];
        assert_eq!(round_trip(&void, w), Encoding::Constant);
        let ints: Vec<f32> = (0..w * w)
            .map(|i| ((i % w) * 3 + (i / w) * 2 + (i * 7919) % 5) as f32)
            .collect();
        assert_eq!(round_trip(&ints, w), Encoding::Lattice);
        let tenths: Vec<f32> = (0..w * w)
            .map(|i| ((i % w) as f64 * 0.1 + (i / w) as f64 * 0.3) as f32)
            .collect();
        assert_eq!(round_trip(&tenths, w), Encoding::Lattice);
        let smooth: Vec<f32> = (0..w * w)
            .map(|i| ((i % w) as f32 * 0.0173).sin() * 100.0 + (i / w) as f32 * 0.311)
            .collect();
        assert!(matches!(
            round_trip(&smooth, w),
            Encoding::FloatPco | Encoding::FloatPredicted
        ));
    }

    #[test]
    fn the_tans_encodings_are_chosen_where_they_fit() {
        let w = 65;
        let ints: Vec<f32> = (0..w * w)
            .map(|i| ((i % w) * 3 + (i / w) * 2 + (i * 7919) % 5) as f32)
            .collect();
        assert_eq!(round_trip_by(&ints, w, Coder::Tans), Encoding::LatticeTans);
        let smooth: Vec<f32> = (0..w * w)
            .map(|i| ((i % w) as f32 * 0.0173).sin() * 100.0 + (i / w) as f32 * 0.311)
            .collect();
        assert!(matches!(
            round_trip_by(&smooth, w, Coder::Tans),
            Encoding::FloatPco | Encoding::FloatPredictedTans
        ));
        // A cliff of 2^33 steps among small residuals: past an `i32`, so pco.
        let mut cliff = ints.clone();
        cliff[100] = (1u64 << 33) as f32;
        assert_eq!(round_trip_by(&cliff, w, Coder::Tans), Encoding::Lattice);
        // On 25.6 m (Puget Sound 4k's step) coded on 0.1: a factor of 256, one byte more
        // than the same block in whole steps, and smaller than pco's.
        let coarse: Vec<f32> = ints.iter().map(|&v| (f64::from(v) * 25.6) as f32).collect();
        let by_tans = encode_on(&coarse, w, None, Coder::Tans);
        assert_eq!(round_trip_by(&coarse, w, Coder::Tans), Encoding::LatticeTans);
        assert_eq!(f64::from_le_bytes(by_tans[1..9].try_into().expect("8 bytes")), 0.1);
        assert_eq!(&by_tans[10..12], &[0x80, 0x02], "f = 256");
        let whole = encode_on(&ints, w, None, Coder::Tans);
        assert_eq!(by_tans.len(), whole.len() + 1);
        assert!(by_tans.len() < encode_on(&coarse, w, None, Coder::Pco).len());
    }

    #[test]
    fn every_id_names_its_shape_and_coder() {
        for id in 0..=255u8 {
            let Some(e) = Encoding::from_id(id) else {
                assert!(id > 15, "id {id} has no encoding");
                continue;
            };
            assert_eq!(e as u8, id);
            let (shape, coder) = (e.shape(), e.coder());
            assert_eq!(coder == Coder::Tans, (9..=15).contains(&id), "id {id}");
            if e == Encoding::LatticeFromParentCodes {
                // A shape of its own, tANS only.
                assert_eq!(shape, e);
                continue;
            }
            assert_eq!(shape.coder(), Coder::Pco);
            assert_eq!(shape.coded_by(coder), e);
            assert_eq!(e.coded_by(Coder::Pco), shape);
        }
        // Raw, constant and pco on floats have no tANS twin.
        for e in [Encoding::Raw, Encoding::Constant, Encoding::FloatPco] {
            assert_eq!(e.coded_by(Coder::Tans), e);
        }
    }

    #[test]
    fn hard_values_come_back_bit_for_bit() {
        let w = 8;
        let mut v: Vec<f32> = (0..64).map(|i| i as f32).collect();
        v[3] = -0.0;
        v[9] = f32::from_bits(1); // the smallest subnormal
        v[10] = -f32::from_bits(0x007F_FFFF);
        v[17] = f32::MAX;
        v[18] = -f32::MAX;
        v[30] = f32::from_bits(VOID_BITS);
        v[31] = f32::from_bits(0x7FC0_0001); // a NaN with a payload
        v[40] = f32::from_bits(0xFFC0_0000); // a negative NaN
        assert_ne!(round_trip(&v, w), Encoding::Lattice);
        // Canonical voids alone stay on the lattice.
        let mut v: Vec<f32> = (0..64).map(|i| (i * i) as f32).collect();
        v[5] = f32::from_bits(VOID_BITS);
        v[63] = f32::from_bits(VOID_BITS);
        assert_eq!(round_trip(&v, w), Encoding::Lattice);
        // A single fractional sample in integer data moves the lattice to its step.
        let mut v: Vec<f32> = (0..64).map(|i| (i % 8 + i / 8) as f32).collect();
        v[20] += 0.5;
        round_trip(&v, w);
        // Rows of one, columns of one.
        round_trip(&[1.0, 2.0, 4.0, 8.0], 1);
        round_trip(&[1.0, 2.0, 4.0, 8.0], 4);
    }

    #[test]
    fn hostile_bytes_are_errors() {
        let w = 9;
        let v: Vec<f32> = (0..81).map(|i| (i % 9 * 2 + i / 9) as f32).collect();
        let good = encode(&v, w);
        assert_eq!(Encoding::of(&good), Some(Encoding::Lattice));
        let mut out = vec![0.0f32; 81];
        let bad = |bytes: &[u8], out: &mut [f32]| decode(bytes, w, out).is_err();
        assert!(bad(&[], &mut out));
        assert!(bad(&[16], &mut out));
        assert!(bad(&[9], &mut out));
        assert!(bad(&good[..good.len() - 1], &mut out));
        let mut longer = good.clone();
        longer.push(0);
        assert!(bad(&longer, &mut out));
        // The same stream for a block of another size.
        assert!(bad(&good, &mut vec![0.0; 72]));
        assert!(bad(&good, &mut vec![0.0; 90]));
        // A step of zero, NaN, negative.
        for q in [0.0f64, f64::NAN, -1.0] {
            let mut b = good.clone();
            b[1..9].copy_from_slice(&q.to_le_bytes());
            assert!(bad(&b, &mut out));
        }
        assert!(bad(&[1, 0, 0], &mut out));
        assert!(bad(&[0, 0, 0, 0], &mut out));
        // The same with tANS; and its common factor zero, too large, or not a varint.
        let good = encode_on(&v, w, None, Coder::Tans);
        assert_eq!(Encoding::of(&good), Some(Encoding::LatticeTans));
        assert!(decode(&good, w, &mut out).is_ok());
        assert!(bad(&good[..good.len() - 1], &mut out));
        let mut longer = good.clone();
        longer.push(0);
        assert!(bad(&longer, &mut out));
        assert!(bad(&good, &mut vec![0.0; 72]));
        let (head, factor_and_stream) = good.split_at(10);
        assert_eq!(factor_and_stream[0], 1, "a factor of one");
        for factor in [&[0u8][..], &[0x80, 0x80, 0x80, 0x80, 0x10], &[0x81, 0x00]] {
            let mut b = head.to_vec();
            b.extend_from_slice(factor);
            b.extend_from_slice(&factor_and_stream[1..]);
            assert_eq!(decode(&b, w, &mut out), Err(DecodeError::Factor));
        }
        // A parent's encodings are refused here whatever their coder.
        for id in [5u8, 8, 11, 14, 15] {
            let mut b = good.clone();
            b[0] = id;
            assert!(bad(&b, &mut out), "id {id}");
        }
    }

    proptest::proptest! {
        /// The order-preserving map is the format's (§7: a negative float's bits inverted,
        /// another's sign bit set), its inverse undoes it, and it orders as the floats do.
        #[test]
        fn ordered_bits_are_the_formats(a in proptest::prelude::any::<u32>(), b in proptest::prelude::any::<u32>()) {
            let formats = |b: u32| if b & 0x8000_0000 != 0 { !b } else { b | 0x8000_0000 };
            let (x, y) = (f32::from_bits(a), f32::from_bits(b));
            proptest::prop_assert_eq!(to_ordered(x), formats(a));
            proptest::prop_assert_eq!(from_ordered(to_ordered(x)).to_bits(), a);
            proptest::prop_assert_eq!(to_ordered(from_ordered(a)), a);
            if x.is_finite() && y.is_finite() && x < y {
                proptest::prop_assert!(to_ordered(x) < to_ordered(y));
            }
        }

        /// Any samples, any shape: encode then decode gives the same bits.
        #[test]
        fn any_block_round_trips(
            bits in proptest::collection::vec(proptest::prelude::any::<u32>(), 1..200),
            width in 1usize..20,
            lattice in proptest::bool::ANY,
        ) {
            let n = bits.len() / width * width;
            proptest::prop_assume!(n > 0);
            let samples: Vec<f32> = bits[..n]
                .iter()
                .map(|&b| if lattice { ((b % 2000) as f32 - 1000.0) * 0.25 } else { f32::from_bits(b) })
                .collect();
            // Both coders (round_trip runs each).
            round_trip(&samples, width);
        }

        /// A real encoding with any byte changed, or cut anywhere, decodes or fails.
        #[test]
        fn damaged_encodings_decode_or_fail(
            at in 0usize..4000,
            value in proptest::prelude::any::<u8>(),
            cut in 0usize..4000,
            kind in 0usize..3,
            tans in proptest::bool::ANY,
        ) {
            let w = 33;
            let samples: Vec<f32> = (0..w * w)
                .map(|i| match kind {
                    0 => ((i % w) * 3 + (i / w) * 5 % 7) as f32,
                    1 => ((i % w) as f32 * 0.0173).sin() * 100.0 + (i / w) as f32 * 0.311,
                    _ => if i % 17 == 0 { f32::from_bits(VOID_BITS) } else { (i % 97) as f32 * 0.1 },
                })
                .collect();
            let coder = if tans { Coder::Tans } else { Coder::Pco };
            let mut bytes = encode_on(&samples, w, None, coder);
            let at = at % bytes.len();
            bytes[at] = value;
            bytes.truncate(cut.max(1));
            let mut out = vec![0.0f32; w * w];
            let _ = decode(&bytes, w, &mut out);
        }

        /// The decoder's row-wise reconstruction inverts the encoder's per-cell residuals,
        /// in wrapping arithmetic, for any values and shape (overflowing ones included).
        #[test]
        fn unpredict_inverts_predict(
            values in proptest::collection::vec(proptest::prelude::any::<i64>(), 1..300),
            width in 1usize..25,
        ) {
            let n = values.len() / width * width;
            proptest::prop_assume!(n > 0);
            let k = &values[..n];
            let mut r: Vec<i64> = (0..n).map(|i| k[i].wrapping_sub(predict(k, i, width))).collect();
            unpredict(&mut r, width);
            proptest::prop_assert_eq!(&r[..], k);
            let u: Vec<u32> = k.iter().map(|&v| v as u32).collect();
            let mut ru: Vec<u32> = (0..n).map(|i| u[i].wrapping_sub(predict(&u, i, width))).collect();
            unpredict(&mut ru, width);
            proptest::prop_assert_eq!(ru, u);
        }

        /// The kernels' two builds (`wide`: AVX2 where the CPU has it, and the baseline)
        /// decode any block, voids and damage included, to the same bits or the same error.
        #[test]
        fn both_builds_of_the_kernels_decode_alike(
            bits in proptest::collection::vec(proptest::prelude::any::<u32>(), 1..400),
            width in 1usize..40,
            kind in 0usize..3,
            damage in proptest::option::of((proptest::prelude::any::<proptest::sample::Index>(), proptest::prelude::any::<u8>())),
            tans in proptest::bool::ANY,
        ) {
            let n = bits.len() / width * width;
            proptest::prop_assume!(n > 0);
            let samples: Vec<f32> = bits[..n]
                .iter()
                .map(|&b| match kind {
                    0 => ((b % 2000) as f32 - 1000.0) * 0.25,
                    1 if b % 7 == 0 => f32::from_bits(VOID_BITS),
                    1 => (b % 5000) as f32 * 0.1,
                    _ => f32::from_bits(b),
                })
                .collect();
            let coder = if tans { Coder::Tans } else { Coder::Pco };
            let mut bytes = encode_on(&samples, width, None, coder);
            if let Some((i, v)) = damage {
                let i = i.index(bytes.len());
                bytes[i] = v;
            }
            let (mut a, mut b) = (vec![0.0f32; n], vec![0.0f32; n]);
            let wide = decode(&bytes, width, &mut a);
            let narrow = wide::baseline(|| decode(&bytes, width, &mut b));
            proptest::prop_assert_eq!(&wide, &narrow);
            if wide.is_ok() {
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                proptest::prop_assert_eq!(bits(&a), bits(&b));
            }
        }

        /// Any bytes decode or fail; nothing panics.
        #[test]
        fn any_bytes_decode_or_fail(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300), width in 1usize..12, rows in 1usize..12) {
            let mut out = vec![0.0f32; width * rows];
            let _ = decode(&bytes, width, &mut out);
        }
    }
}
