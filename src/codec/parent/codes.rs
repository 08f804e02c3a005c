//! Encoding 15's prediction (format 7): the parent's heights as lattice codes, interpolated
//! in 32-bit integers.
//!
//! Encoding 5 interpolates the parent's heights in `f64` and rounds each prediction to the
//! lattice: four multiply-adds, a scaling and a rounding a sample, about 0.4 of its
//! decoding time once the residuals decoded fast (`docs/benchmarks.md`, "Encoding 5
//! predicted in integers"). On a lattice the parent's heights are codes already: `round(G/q)`
//! of each is exact, the cubic midpoint's weights `(−1, 9, 9, −1)/16` are whole sixteenths,
//! and a linear weight rounded to a sixteenth predicts as well as the exact one. So the
//! prediction is `(Σ_j wy_j Σ_i wx_i c(i, j) + 128) >> 8` over the codes `c`, the weights in
//! sixteenths: integer multiply-adds that vectorise eight to a register, and no rounding.
//!
//! The arithmetic is 32-bit two's complement, wrapping, and the shift arithmetic: every
//! reader computes the same prediction from any parent, so a payload cannot decode two ways.
//! A writer uses encoding 15 only where every parent code lies within ±2^22 ([`CodePredictor::fits`]):
//! the weights' magnitudes sum to at most 20 an axis, so no sum then wraps and the
//! prediction is the rounded interpolation of the codes.

use super::{cubic_pairs, parent_codes, Along, Parent};

/// The largest parent code magnitude a writer predicts from in integers: below it no sum of
/// at most `20 × 20` weighted codes reaches `2^31`.
const SMALL_CODE: u64 = 1 << 22;

/// The parent's rows a child needs, each interpolated in integers at every child column
/// (`Σ_i wx_i · c(i, j)`), once; then a child row's predictions from them.
pub(super) struct CodePredictor<'a> {
    rows: &'a [Along],
    /// `inner[(j - first) * w + c]` for parent rows `first..first + n`.
    inner: Vec<i32>,
    first: usize,
    w: usize,
    /// Whether every parent code read lies within ±2^22.
    fits: bool,
}

wide! {
    /// [`CodePredictor::new`]'s work: the needed parent rows' codes, interpolated at every
    /// child column. The codes of the parent columns no child column reads are computed
    /// only when `whole_rows` (a writer's [`CodePredictor::fits`] looks at whole rows).
    fn code_predictor<'a>(
        cols: &[Along],
        rows: &'a [Along],
        parent: &Parent<'_>,
        q: f64,
        whole_rows: bool,
    ) -> CodePredictor<'a> {
        let pw = parent.at.cols.len();
        // The parent columns the child reads: `a..b`.
        let (a, b) = if whole_rows {
            (0, pw)
        } else {
            let (mut a, mut b) = (pw, 0);
            for c in cols {
                let (terms, m) = c.sixteenths();
                for &(i, _) in &terms[..m] {
                    a = a.min(i);
                    b = b.max(i + 1);
                }
            }
            (a.min(b), b)
        };
        let (mut first, mut last) = (usize::MAX, 0);
        for r in rows {
            let (terms, n) = r.sixteenths();
            for &(j, _) in &terms[..n] {
                first = first.min(j);
                last = last.max(j);
            }
        }
        let w = cols.len();
        let n = if first <= last { last - first + 1 } else { 0 };
        let layout = ColumnLayout::of(cols);
        let (c0, i0, pairs) = layout.stretch;
        let (mut x, mut wide_codes, mut codes) = (vec![0.0f64; pw], vec![0i64; pw], vec![0i32; pw]);
        let mut inner = vec![0i32; n * w];
        let mut spread = 0u64;
        for (k, chunk) in inner.chunks_exact_mut(w.max(1)).enumerate().take(n) {
            let j = first + k;
            parent_codes(
                &parent.heights[j * pw + a..j * pw + b],
                q,
                &mut x[a..b],
                &mut wide_codes[a..b],
            );
            for (c, &k) in codes[a..b].iter_mut().zip(&wide_codes[a..b]) {
                // `k ^ (k >> 63)` is `k` or `-k - 1`: below 2^22 for all when all fit.
                spread |= (k ^ (k >> 63)) as u64;
                *c = k as i32;
            }
            if pairs > 0 {
                // Held column `i` (16 c(i)), then the cubic midpoint after it, in order.
                let terms = codes[i0 - 1..].iter().zip(&codes[i0..]).zip(&codes[i0 + 1..]).zip(&codes[i0 + 2..]);
                for (pair, (((&a, &b), &c), &d)) in chunk[c0..c0 + 2 * pairs].chunks_exact_mut(2).zip(terms) {
                    pair[0] = b.wrapping_mul(16);
                    pair[1] = b.wrapping_add(c).wrapping_mul(9).wrapping_sub(a).wrapping_sub(d);
                }
            }
            for &(c, (terms, m)) in &layout.others {
                chunk[c] = terms[..m]
                    .iter()
                    .fold(0i32, |s, &(i, wt)| s.wrapping_add(wt.wrapping_mul(codes[i])));
            }
        }
        CodePredictor {
            rows,
            inner,
            first,
            w,
            fits: spread < SMALL_CODE,
        }
    }
}

/// How a child's columns are interpolated along a parent row, found once per child. A child
/// lying on its parent's grid alternates a held parent column and the cubic midpoint after
/// it: that stretch is filled in order, two columns a parent column (placing each column by
/// an index of its own was half of the predictor's setup, measured on Puget 1k's encoding
/// 15); the columns outside it (the parent's edges, uneven spacing) term by term.
struct ColumnLayout {
    /// `(c0, i0, pairs)`: for `k < pairs`, child column `c0 + 2k` holds parent column
    /// `i0 + k` and column `c0 + 2k + 1` is the cubic midpoint of `i0 + k` and `i0 + k + 1`
    /// (so `i0 ≥ 1` and parent column `i0 + pairs + 1` exists when `pairs > 0`).
    stretch: (usize, usize, usize),
    /// Every other column, with its terms.
    others: Vec<(usize, Sixteenths)>,
}

/// A column's terms (parent column, weight in sixteenths) and their count.
type Sixteenths = ([(usize, i32); 4], usize);

impl ColumnLayout {
    fn of(cols: &[Along]) -> ColumnLayout {
        let stretch = cubic_pairs(cols);
        let (c0, _, pairs) = stretch;
        let others = (0..cols.len())
            .filter(|c| !(c0..c0 + 2 * pairs).contains(c))
            .map(|c| (c, cols[c].sixteenths()))
            .collect();
        ColumnLayout { stretch, others }
    }
}

impl<'a> CodePredictor<'a> {
    /// The predictor of a child at `cols` × `rows` from `parent`'s heights on step `q`, as a
    /// writer needs it: [`CodePredictor::fits`] looks at every code of the rows read.
    pub(super) fn new(cols: &[Along], rows: &'a [Along], parent: &Parent<'_>, q: f64) -> Self {
        code_predictor(cols, rows, parent, q, true)
    }

    /// The same predictions for a reader, which needs no [`CodePredictor::fits`]: only the
    /// parent columns the child reads are turned into codes, about half of a parent's row
    /// (measured on Puget 1k's encoding 15: 0.87× the decoding time in the kernels'
    /// baseline build, whose rounding check calls libm; the AVX2 build's time unchanged).
    pub(super) fn for_reading(
        cols: &[Along],
        rows: &'a [Along],
        parent: &Parent<'_>,
        q: f64,
    ) -> Self {
        code_predictor(cols, rows, parent, q, false)
    }

    /// Whether every parent code of the rows read lies within ±2^22: a writer's condition
    /// for encoding 15 (meaningful for a predictor made by [`CodePredictor::new`]).
    pub(super) fn fits(&self) -> bool {
        self.fits
    }

    /// Child row `j`'s predictions at every column, into `p` (of the child's width).
    #[inline(always)]
    pub(super) fn row(&self, j: usize, p: &mut [i32]) {
        let (terms, n) = self.rows[j].sixteenths();
        let w = self.w;
        let row = |i: usize| &self.inner[(i - self.first) * w..(i - self.first + 1) * w];
        match terms[..n] {
            [(i0, w0)] => {
                for (x, &a) in p.iter_mut().zip(row(i0)) {
                    *x = w0.wrapping_mul(a).wrapping_add(128) >> 8;
                }
            }
            [(i0, w0), (i1, w1)] => {
                for ((x, &a), &b) in p.iter_mut().zip(row(i0)).zip(row(i1)) {
                    *x = w0.wrapping_mul(a).wrapping_add(w1.wrapping_mul(b)).wrapping_add(128) >> 8;
                }
            }
            [(i0, w0), (i1, w1), (i2, w2), (i3, w3)] => {
                let rows = row(i0).iter().zip(row(i1)).zip(row(i2)).zip(row(i3));
                for (x, (((&a, &b), &c), &d)) in p.iter_mut().zip(rows) {
                    *x = w0
                        .wrapping_mul(a)
                        .wrapping_add(w1.wrapping_mul(b))
                        .wrapping_add(w2.wrapping_mul(c))
                        .wrapping_add(w3.wrapping_mul(d))
                        .wrapping_add(128)
                        >> 8;
                }
            }
            ref terms => {
                p.fill(0);
                for &(i, wt) in terms {
                    for (x, &a) in p.iter_mut().zip(row(i)) {
                        *x = x.wrapping_add(wt.wrapping_mul(a));
                    }
                }
                for x in p.iter_mut() {
                    *x = x.wrapping_add(128) >> 8;
                }
            }
        }
    }
}
