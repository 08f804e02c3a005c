//! The decoders' inner loops for payloads coded against a parent (encodings 5 to 8, their
//! tANS twins 11 to 14, and 15), row by row: what a scene spends most of its decoding time
//! in.
//!
//! The general decoder ([`super::decode_against`]'s other paths) asks, for every sample,
//! whether the bitmap marks it void, whether its column and row are both held, and calls
//! back for its value. A row without voids is one of two kinds, known before it starts: a
//! row the parent does not hold, where every sample is coded, and a held row, where the held
//! columns take the parent's heights and the others are coded. (A row with voids, found by a
//! count of its bits in the bitmap, goes sample by sample as the general decoder does: voids
//! lie in a few rows of a few blocks, and the rows around them keep the fast loops.) So each
//! row without voids runs as a
//! straight loop over slices: the residuals of the row taken as one slice, the planar
//! prediction carried in registers (`left + up - up_left`, the row above kept apart), the
//! interpolated predictions of a row computed for all its columns first (the same terms in
//! the same order as [`super::RowPredictor::at`], so the same bits), and the conversion of
//! codes to heights a loop of its own that the compiler vectorises.
//!
//! Every kernel produces exactly the general decoder's output for the same bytes, valid or
//! not (a property test in `parent.rs` holds them to it), and reads the residuals only
//! through checked slices: a count that does not match is an error, never a panic.

use super::super::{
    from_ordered, lattice_heights, lattice_value, to_ordered, unzigzag, voids, DecodeError,
    Wrapping, MAX_LATTICE_INDEX, VOID_BITS,
};
use super::{
    longest_pair_run, parent_codes, round_row, round_to_i64, Along, CodePredictor, Parent,
    Predictor,
};

/// What the kernels need to know of a payload's placement against its parent.
pub(super) struct Rows<'a> {
    /// Samples along a row.
    pub w: usize,
    /// Per column, the parent's column when the parent holds it.
    pub held_cols: &'a [Option<u32>],
    /// The columns the parent holds, in order, each with the parent's column: a held row's
    /// loops run over these and [`Rows::coded`] instead of asking every column.
    pub held: &'a [(usize, usize)],
    /// The columns the parent does not hold, in order.
    pub coded: &'a [usize],
    /// Per row, how the parent predicts it (held: the parent's row).
    pub rows: &'a [Along],
    /// The parent's grid.
    pub parent: Parent<'a>,
    /// The longest stretch of a held row where held and coded columns alternate.
    pub alternation: Alternation,
    /// The parent's columns from the first held to the last (`lo..=hi`), when the held
    /// columns are at least one in two of them ([`dense_span`]).
    pub span: Option<(usize, usize)>,
    /// The payload's void bitmap, when it has voids.
    pub voids: Option<&'a [u8]>,
}

/// Where a held row's columns alternate between held and coded, as they do across a child
/// lying on its parent's grid: for `k < pairs`, column `c0 + 2k` holds parent column
/// `pi0 + k` and column `c0 + 2k + 1` is coded. The kernels move that stretch's heights and
/// residuals in strided loops instead of placing each column by an index of its own
/// (measured on Puget 1k's encoding 15, the placing was a third of its row kernel's time).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Alternation {
    c0: usize,
    pi0: usize,
    pairs: usize,
    /// Of [`Rows::held`] and [`Rows::coded`], the entries before the stretch.
    held_before: usize,
    coded_before: usize,
}

impl Alternation {
    /// The longest stretch of `cols` (with `held` and `coded`, [`Rows`]'s lists of them).
    pub(super) fn of(cols: &[Along], held: &[(usize, usize)], coded: &[usize]) -> Alternation {
        let pair_at = |c: usize| match (cols.get(c), cols.get(c + 1)) {
            (Some(Along::Held(pi)), Some(Along::Mixed(..))) => Some(*pi),
            _ => None,
        };
        let (c0, pi0, pairs) = longest_pair_run(cols.len(), pair_at);
        Alternation {
            c0,
            pi0,
            pairs,
            held_before: held.partition_point(|&(c, _)| c < c0),
            coded_before: coded.partition_point(|&c| c < c0),
        }
    }
}

impl<'a> Rows<'a> {
    /// The void bitmap, when row `j` has a void: its samples then go one by one.
    #[inline(always)]
    fn row_voids(&self, j: usize) -> Option<&'a [u8]> {
        self.voids
            .filter(|m| voids::count(m, j * self.w, (j + 1) * self.w) > 0)
    }

    /// The parent's heights along row `ry` when the parent holds it.
    #[inline(always)]
    fn held_row(&self, ry: &Along) -> Option<&[f32]> {
        match *ry {
            Along::Held(pj) => Some(self.parent_row(pj)),
            Along::Mixed(..) => None,
        }
    }

    /// Row `j` (`ry`, into `orow`) of an interpolated encoding, with voids among it (`m`, the
    /// bitmap), sample by sample as the general loop decodes it: a void takes the void's
    /// bits, a sample of a held row and column the parent's height, any other `coded(i, d)`
    /// of the next residual `d` of `r`.
    fn voided_row<T: Copy>(
        &self,
        (m, j, ry): (&[u8], usize, &Along),
        r: &[T],
        next: &mut usize,
        orow: &mut [f32],
        mut coded: impl FnMut(usize, T) -> f32,
    ) -> Result<(), DecodeError> {
        let heights = self.held_row(ry);
        let row = j * self.w;
        for (i, o) in orow.iter_mut().enumerate() {
            *o = if voids::is_void(m, row + i) {
                f32::from_bits(VOID_BITS)
            } else if let (Some(h), Some(pi)) = (heights, self.held_cols[i]) {
                h[pi as usize]
            } else {
                let d = *r.get(*next).ok_or_else(short)?;
                *next += 1;
                coded(i, d)
            };
        }
        Ok(())
    }

    /// The parent's heights along its row `pj`.
    #[inline(always)]
    fn parent_row(&self, pj: usize) -> &[f32] {
        let pw = self.parent.at.cols.len();
        &self.parent.heights[pj * pw..(pj + 1) * pw]
    }

    /// Gives the held samples of `orow`, a row the parent holds as its row `pj`, the
    /// parent's heights.
    #[inline(always)]
    fn held_heights(&self, pj: usize, orow: &mut [f32]) {
        self.place_held(self.parent_row(pj), 0, orow, |h| h);
    }

    /// Writes `f(src[pi - lo])` at every held column `c` of `row` (`pi` its parent column,
    /// `lo` at most the least of them, `src` reaching past the greatest), the alternating
    /// stretch in a strided loop.
    #[inline(always)]
    fn place_held<S: Copy, T>(&self, src: &[S], lo: usize, row: &mut [T], f: impl Fn(S) -> T) {
        let a = &self.alternation;
        let (before, rest) = self.held.split_at(a.held_before.min(self.held.len()));
        for &(c, pi) in before.iter().chain(rest.get(a.pairs..).unwrap_or_default()) {
            row[c] = f(src[pi - lo]);
        }
        if a.pairs > 0 {
            let stretch = &src[a.pi0 - lo..a.pi0 - lo + a.pairs];
            for (o, &h) in row[a.c0..].iter_mut().step_by(2).zip(stretch) {
                *o = f(h);
            }
        }
    }

    /// The coded samples of a held row `cur` (its held ones' codes in place, `up` the row
    /// above), in order, each from the sample to its left (held or coded) and the two above
    /// it plus its residual (`rr`, one a coded column). Along the alternating stretch the
    /// sample to the left is a held one, so its coded samples depend on nothing decoded in
    /// this row: a loop over pairs, without a column index each.
    #[inline(always)]
    fn planar_coded<T: Wrapping>(&self, rr: &[T], up: &[T], cur: &mut [T]) {
        let one = |c: usize, d: T, cur: &mut [T]| {
            let (left, up_left) = match c.checked_sub(1) {
                Some(b) => (cur[b], up[b]),
                None => (T::default(), T::default()),
            };
            cur[c] = left.plus(up[c].minus(up_left).plus(d));
        };
        let ((before, r0), r1, (after, r2)) = self.coded_parts(rr);
        for (&c, &d) in before.iter().zip(r0) {
            one(c, d, cur);
        }
        let a = &self.alternation;
        if a.pairs > 0 {
            let pairs = cur[a.c0..].chunks_exact_mut(2).zip(up[a.c0..].chunks_exact(2));
            for ((c, u), &d) in pairs.zip(r1) {
                c[1] = c[0].plus(u[1].minus(u[0]).plus(d));
            }
        }
        for (&c, &d) in after.iter().zip(r2) {
            one(c, d, cur);
        }
    }

    /// A held row's residuals `rr` (one a coded column, in order) split as the alternating
    /// stretch splits the coded columns: those before it with their columns, the
    /// stretch's (column `c0 + 2k + 1` each), those after it with their columns.
    #[inline(always)]
    fn coded_parts<'r, T>(
        &self,
        rr: &'r [T],
    ) -> (Coded<'_, 'r, T>, &'r [T], Coded<'_, 'r, T>) {
        let a = &self.alternation;
        let (r0, rest) = rr.split_at(a.coded_before.min(rr.len()));
        let (r1, r2) = rest.split_at(a.pairs.min(rest.len()));
        let after = self.coded.get(a.coded_before + a.pairs..).unwrap_or_default();
        ((&self.coded[..a.coded_before], r0), r1, (after, r2))
    }

    /// Writes the residuals `rr` of a held row (one a coded column, in order) at their
    /// columns of `row`, leaving the held columns as they are.
    #[inline(always)]
    fn spread_coded<T: Copy>(&self, rr: &[T], row: &mut [T]) {
        let ((before, r0), r1, (after, r2)) = self.coded_parts(rr);
        for (&c, &d) in before.iter().chain(after).zip(r0.iter().chain(r2)) {
            row[c] = d;
        }
        let a = &self.alternation;
        if a.pairs > 0 {
            for (x, &d) in row[a.c0 + 1..].iter_mut().step_by(2).zip(r1) {
                *x = d;
            }
        }
    }
}

/// Coded columns of a held row and their residuals ([`Rows::coded_parts`]).
type Coded<'c, 'r, T> = (&'c [usize], &'r [T]);

/// The parent's columns from the first held (`held`: [`Rows::held`]) to the last, when the
/// held ones are at least one in two of them: a child on its parent's grid holds every
/// one, and converting the span as one row costs less than converting each held column
/// alone ([`Rows::span`]).
pub(super) fn dense_span(held: &[(usize, usize)]) -> Option<(usize, usize)> {
    let (lo, hi) = held
        .iter()
        .fold((usize::MAX, 0), |(lo, hi), &(_, pi)| (lo.min(pi), hi.max(pi)));
    (lo <= hi && hi - lo < 2 * held.len()).then_some((lo, hi))
}

fn short() -> DecodeError {
    DecodeError::Pco("fewer residuals than the payload codes".into())
}

fn out_of_range() -> DecodeError {
    DecodeError::Pco("a lattice index is out of range".into())
}

/// The next `m` residuals of `r` from `*next`, or an error when there are fewer.
#[inline(always)]
fn take<'r, T>(r: &'r [T], next: &mut usize, m: usize) -> Result<&'r [T], DecodeError> {
    let s = r.get(*next..*next + m).ok_or_else(short)?;
    *next += m;
    Ok(s)
}

/// What encodings 7 and 8 differ in: the space their codes live in and how heights map to
/// it. A trait with methods inlined, not closures, so that the kernels' AVX2 build holds
/// their loops too (a closure is a function of its own, built as the baseline).
trait CodeSpace {
    type Code: Wrapping;
    /// The held samples' codes, from the heights of the parent's row `pj`: written at the
    /// held columns ([`Rows::held`]) and nowhere else.
    fn codes_of(&mut self, g: &Rows<'_>, pj: usize, codes: &mut [Self::Code]);
    /// A row of codes to heights (given the held columns in a held row, whose heights are
    /// then the parent's and whose codes it must not judge); whether any coded one was out
    /// of range.
    fn emit(&self, codes: &[Self::Code], out: &mut [f32], held: Option<&[Option<u32>]>) -> bool;
    /// One held sample's code (in a row with voids).
    fn code_of(&self, height: f32) -> Self::Code;
    /// One coded sample's height, and whether its code is out of range (in a row with
    /// voids).
    fn value_of(&self, code: Self::Code) -> (f32, bool);
}

/// Encoding 7's codes: lattice indexes on step `q` (`x`, `k`: scratch of a row).
struct LatticeCodes {
    q: f64,
    x: Vec<f64>,
    k: Vec<i64>,
}

impl CodeSpace for LatticeCodes {
    type Code = i64;
    #[inline(always)]
    fn codes_of(&mut self, g: &Rows<'_>, pj: usize, codes: &mut [i64]) {
        let heights = g.parent_row(pj);
        // The parent's columns of the held ones converted as one row, in loops the compiler
        // vectorises, then placed: one by one, the conversion was a fifth of the kernel's
        // time (Puget Sound 4k's encoding 13).
        let span = g.span.and_then(|(lo, hi)| Some((lo, heights.get(lo..=hi)?)));
        if let Some((lo, span)) = span {
            let n = span.len();
            parent_codes(span, self.q, &mut self.x[..n], &mut self.k[..n]);
            g.place_held(&self.k[..n], lo, codes, |k| k);
        } else {
            for &(c, pi) in g.held {
                codes[c] = round_to_i64(f64::from(heights[pi]) / self.q);
            }
        }
    }
    #[inline(always)]
    fn emit(&self, codes: &[i64], out: &mut [f32], held: Option<&[Option<u32>]>) -> bool {
        lattice_heights(codes, out, self.q, held)
    }
    #[inline(always)]
    fn code_of(&self, height: f32) -> i64 {
        round_to_i64(f64::from(height) / self.q)
    }
    #[inline(always)]
    fn value_of(&self, k: i64) -> (f32, bool) {
        lattice_sample(k, self.q)
    }
}

/// A coded sample's height from its lattice index `k` on step `q`, and whether `k` is out of
/// range (as the general loop judges a coded sample: in a row with voids).
#[inline(always)]
fn lattice_sample(k: i64, q: f64) -> (f32, bool) {
    (lattice_value(k as f64, q), k.unsigned_abs() > MAX_LATTICE_INDEX as u64)
}

/// Encoding 8's codes: order-preserving bits.
struct FloatCodes;

impl CodeSpace for FloatCodes {
    type Code = u32;
    #[inline(always)]
    fn codes_of(&mut self, g: &Rows<'_>, pj: usize, codes: &mut [u32]) {
        g.place_held(g.parent_row(pj), 0, codes, to_ordered);
    }
    #[inline(always)]
    fn emit(&self, codes: &[u32], out: &mut [f32], _: Option<&[Option<u32>]>) -> bool {
        for (o, &u) in out.iter_mut().zip(codes) {
            *o = from_ordered(u);
        }
        false
    }
    #[inline(always)]
    fn code_of(&self, height: f32) -> u32 {
        to_ordered(height)
    }
    #[inline(always)]
    fn value_of(&self, u: u32) -> (f32, bool) {
        (from_ordered(u), false)
    }
}

/// Encodings 7 and 8: codes in `space`, the planar predictor over them; whether any coded
/// sample's code was out of range.
#[inline(always)]
fn planar<S: CodeSpace>(
    g: &Rows<'_>,
    r: &[S::Code],
    out: &mut [f32],
    space: &mut S,
) -> Result<bool, DecodeError> {
    let w = g.w;
    // The row above (zeros above the first: `left + 0 - 0` is the first row's predictor,
    // `0 + up - 0` the first column's) and the row being decoded.
    let mut up = vec![S::Code::default(); w];
    let mut cur = vec![S::Code::default(); w];
    let mut next = 0usize;
    let mut bad = false;
    // The chain from sample to sample is one addition: `left + ((up - up_left) + r)`, the
    // same wrapping sum as `left + up - up_left + r` in another order.
    for (j, (ry, orow)) in g.rows.iter().zip(out.chunks_exact_mut(w.max(1))).enumerate() {
        let (mut left, mut up_left) = (S::Code::default(), S::Code::default());
        if let Some(m) = g.row_voids(j) {
            // Sample by sample: a void's code is its prediction, a held sample's its
            // height's, a coded sample's the prediction plus the next residual.
            let heights = g.held_row(ry);
            let samples = cur.iter_mut().zip(&up).zip(orow.iter_mut()).enumerate();
            for (i, ((c, &u), o)) in samples {
                let p = left.plus(u).minus(up_left);
                *c = if voids::is_void(m, j * w + i) {
                    *o = f32::from_bits(VOID_BITS);
                    p
                } else if let (Some(h), Some(pi)) = (heights, g.held_cols[i]) {
                    *o = h[pi as usize];
                    space.code_of(*o)
                } else {
                    let d = *r.get(next).ok_or_else(short)?;
                    next += 1;
                    let code = p.plus(d);
                    let (value, far) = space.value_of(code);
                    bad |= far;
                    *o = value;
                    code
                };
                (left, up_left) = (*c, u);
            }
            std::mem::swap(&mut up, &mut cur);
            continue;
        }
        let held = match *ry {
            Along::Mixed(..) => {
                let rr = take(r, &mut next, w)?;
                for ((c, &u), &d) in cur.iter_mut().zip(&up).zip(rr) {
                    left = left.plus(u.minus(up_left).plus(d));
                    up_left = u;
                    *c = left;
                }
                None
            }
            Along::Held(pj) => {
                // The held samples' codes first, off the chain; then each coded sample from
                // the sample to its left (held or coded) and the two above.
                space.codes_of(g, pj, &mut cur);
                g.planar_coded(take(r, &mut next, g.coded.len())?, &up, &mut cur);
                Some(pj)
            }
        };
        // One call of `emit` a row (inlined once).
        bad |= space.emit(&cur, orow, held.map(|_| g.held_cols));
        if let Some(pj) = held {
            g.held_heights(pj, orow);
        }
        std::mem::swap(&mut up, &mut cur);
    }
    Ok(bad)
}

wide! {
    /// Encoding 7: lattice indexes on step `q`.
    pub(super) fn planar_lattice(
        g: &Rows<'_>,
        q: f64,
        r: &[i64],
        out: &mut [f32],
    ) -> Result<(), DecodeError> {
        let n = g.span.map_or(0, |(lo, hi)| hi - lo + 1);
        let mut space = LatticeCodes {
            q,
            x: vec![0.0f64; n],
            k: vec![0i64; n],
        };
        if planar(g, r, out, &mut space)? {
            return Err(out_of_range());
        }
        Ok(())
    }
}

wide! {
    /// Encoding 8: order-preserving bits, zigzag residuals.
    pub(super) fn planar_float(
        g: &Rows<'_>,
        r: &mut [u32],
        out: &mut [f32],
    ) -> Result<(), DecodeError> {
        // The residuals are zigzag codes: undone first, in place, a loop of its own.
        for z in r.iter_mut() {
            *z = unzigzag(*z);
        }
        planar(g, r, out, &mut FloatCodes).map(|_| ())
    }
}

/// The interpolated predictions of row `j` at every column, into `p`, each passed through
/// `finish`: `Σ_j wy_j · inner(j, c)` from `0.0`, term by term, as
/// [`super::RowPredictor::at`] sums them. The usual counts of terms (one, two, four) are
/// summed in one pass over the row, the others a pass a term.
#[inline(always)]
pub(super) fn predictions(
    predictor: &Predictor<'_>,
    j: usize,
    p: &mut [f64],
    finish: impl Fn(f64) -> f64,
) {
    let along = predictor.row(j);
    let w = p.len();
    let row = |start: usize| &along.inner[start..start + w];
    match along.terms[..along.n] {
        [(s0, b0)] => {
            for (x, &i0) in p.iter_mut().zip(row(s0)) {
                *x = finish(0.0 + b0 * i0);
            }
        }
        [(s0, b0), (s1, b1)] => {
            for ((x, &i0), &i1) in p.iter_mut().zip(row(s0)).zip(row(s1)) {
                *x = finish(0.0 + b0 * i0 + b1 * i1);
            }
        }
        [(s0, b0), (s1, b1), (s2, b2), (s3, b3)] => {
            let rows = row(s0).iter().zip(row(s1)).zip(row(s2)).zip(row(s3));
            for (x, (((&i0, &i1), &i2), &i3)) in p.iter_mut().zip(rows) {
                *x = finish(0.0 + b0 * i0 + b1 * i1 + b2 * i2 + b3 * i3);
            }
        }
        ref terms => {
            p.fill(0.0);
            for &(start, b) in terms {
                for (x, &i) in p.iter_mut().zip(row(start)) {
                    *x += b * i;
                }
            }
            for x in p.iter_mut() {
                *x = finish(*x);
            }
        }
    }
}

wide! {
    /// Encoding 5: per row, the predictions' indexes `round(p · (1/q))` a row at
    /// a time, the residuals added, the indexes converted a row at a time.
    pub(super) fn interpolated_lattice(
        g: &Rows<'_>,
        predictor: &Predictor<'_>,
        q: f64,
        r: &[i64],
        out: &mut [f32],
    ) -> Result<(), DecodeError> {
        // The prediction's index: `p · (1/q)`, one division a block (container.md §7).
        let inv_q = 1.0 / q;
        let w = g.w;
        let mut p = vec![0.0f64; w];
        let mut k = vec![0i64; w];
        // A held row's residuals at their columns; the held columns stay 0.
        let mut d = vec![0i64; w];
        let mut next = 0usize;
        let mut bad = false;
        for (j, (ry, orow)) in g.rows.iter().zip(out.chunks_exact_mut(w.max(1))).enumerate() {
            predictions(predictor, j, &mut p, |x| x * inv_q);
            round_row(&p, &mut k);
            if let Some(m) = g.row_voids(j) {
                g.voided_row((m, j, ry), r, &mut next, orow, |i, d| {
                    let (value, far) = lattice_sample(k[i].wrapping_add(d), q);
                    bad |= far;
                    value
                })?;
                continue;
            }
            match *ry {
                Along::Mixed(..) => {
                    for (k, &d) in k.iter_mut().zip(take(r, &mut next, w)?) {
                        *k = k.wrapping_add(d);
                    }
                    bad |= lattice_heights(&k, orow, q, None);
                }
                Along::Held(pj) => {
                    g.spread_coded(take(r, &mut next, g.coded.len())?, &mut d);
                    for (k, &d) in k.iter_mut().zip(&d) {
                        *k = k.wrapping_add(d);
                    }
                    bad |= lattice_heights(&k, orow, q, Some(g.held_cols));
                    g.held_heights(pj, orow);
                }
            }
        }
        if bad {
            return Err(out_of_range());
        }
        Ok(())
    }
}

wide! {
    /// Encoding 15: per row, the predictions from the parent's codes in
    /// integers a row at a time, the residuals added, the indexes converted a row at a time.
    pub(super) fn interpolated_codes(
        g: &Rows<'_>,
        predictor: &CodePredictor<'_>,
        q: f64,
        r: &[i64],
        out: &mut [f32],
    ) -> Result<(), DecodeError> {
        let w = g.w;
        let mut p = vec![0i32; w];
        let mut k = vec![0i64; w];
        // A held row's residuals at their columns; the held columns stay 0.
        let mut d = vec![0i64; w];
        let mut next = 0usize;
        let mut bad = false;
        for (j, (ry, orow)) in g.rows.iter().zip(out.chunks_exact_mut(w.max(1))).enumerate() {
            predictor.row(j, &mut p);
            if let Some(m) = g.row_voids(j) {
                g.voided_row((m, j, ry), r, &mut next, orow, |i, d| {
                    let (value, far) = lattice_sample(i64::from(p[i]).wrapping_add(d), q);
                    bad |= far;
                    value
                })?;
                continue;
            }
            match *ry {
                Along::Mixed(..) => {
                    for ((k, &p), &d) in k.iter_mut().zip(&p).zip(take(r, &mut next, w)?) {
                        *k = i64::from(p).wrapping_add(d);
                    }
                    bad |= lattice_heights(&k, orow, q, None);
                }
                Along::Held(pj) => {
                    g.spread_coded(take(r, &mut next, g.coded.len())?, &mut d);
                    for ((k, &p), &d) in k.iter_mut().zip(&p).zip(&d) {
                        *k = i64::from(p).wrapping_add(d);
                    }
                    bad |= lattice_heights(&k, orow, q, Some(g.held_cols));
                    g.held_heights(pj, orow);
                }
            }
        }
        if bad {
            return Err(out_of_range());
        }
        Ok(())
    }
}

wide! {
    /// Encoding 6: a coded sample's height is its interpolated prediction's
    /// order-preserving bits plus its residual, a held one the parent's.
    pub(super) fn interpolated_float(
        g: &Rows<'_>,
        predictor: &Predictor<'_>,
        r: &[u32],
        out: &mut [f32],
    ) -> Result<(), DecodeError> {
        let w = g.w;
        let mut p = vec![0.0f64; w];
        // A held row's residuals at their columns; the held columns stay 0.
        let mut d = vec![0u32; w];
        let mut next = 0usize;
        #[inline(always)]
        fn value(p: f64, z: u32) -> f32 {
            from_ordered(to_ordered(p as f32).wrapping_add(unzigzag(z)))
        }
        for (j, (ry, orow)) in g.rows.iter().zip(out.chunks_exact_mut(w.max(1))).enumerate() {
            predictions(predictor, j, &mut p, |x| x);
            if let Some(m) = g.row_voids(j) {
                g.voided_row((m, j, ry), r, &mut next, orow, |i, z| value(p[i], z))?;
                continue;
            }
            match *ry {
                Along::Mixed(..) => {
                    for ((o, &x), &z) in orow.iter_mut().zip(&p).zip(take(r, &mut next, w)?) {
                        *o = value(x, z);
                    }
                }
                Along::Held(pj) => {
                    g.spread_coded(take(r, &mut next, g.coded.len())?, &mut d);
                    for ((o, &x), &z) in orow.iter_mut().zip(&p).zip(&d) {
                        *o = value(x, z);
                    }
                    g.held_heights(pj, orow);
                }
            }
        }
        Ok(())
    }
}
