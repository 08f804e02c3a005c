//! The gate of `docs/format-7-plan.md`'s step 1 (`FMRH_PREDICT_STUDY=1 cargo bench --bench
//! decode`, issue 44): would predicting encoding 5's samples from the parent's lattice codes
//! in `i32` (weights in sixteenths, one shift) instead of from its heights in `f64` (format 6,
//! `container.md` §7) take enough off the kernel to bring encoding 5 under 4 ns a sample?
//!
//! Both kernels here do the same work on the same grids: a `w × h` block whose parent holds
//! every other sample (rows and columns `0, 2, 4, …` and the last), the parent's rows
//! interpolated at every child column once, then each child row predicted from one, two or
//! four of those rows, rounded to a lattice index, its residual added, and converted to a
//! height; the held samples copied from the parent. Residuals are each kernel's own (the true
//! index less its prediction), so both rebuild the block's samples exactly, and the study
//! checks that before it times anything. Neither is the codec's kernel (`src/codec/parent/
//! rows.rs` also plans the placement, reads the residuals and handles any parent); the
//! question is only what the arithmetic costs, one against the other, built for AVX2.

/// A coordinate's terms along one axis: `(parent index, weight)`, 1, 2 or 4 of them.
#[derive(Clone)]
pub struct Terms {
    idx: [usize; 4],
    /// Weights as `f64` (format 6's rule) and in sixteenths (the integer candidate's).
    wf: [f64; 4],
    wi: [i32; 4],
    n: usize,
}

/// The parent's coordinates along an axis of `n` samples: every other one and the last.
fn parent_axis(n: usize) -> Vec<usize> {
    let mut a: Vec<usize> = (0..n).step_by(2).collect();
    if (n - 1) % 2 == 1 {
        a.push(n - 1);
    }
    a
}

/// Each child coordinate's terms: held (weight 1), a cubic midpoint `(−1, 9, 9, −1)/16`
/// where both outer steps equal the inner one, else linear.
fn axis_terms(n: usize) -> (Vec<usize>, Vec<Terms>) {
    let xs = parent_axis(n);
    let terms = (0..n)
        .map(|x| {
            let mut t = Terms {
                idx: [0; 4],
                wf: [0.0; 4],
                wi: [0; 4],
                n: 0,
            };
            if let Ok(k) = xs.binary_search(&x) {
                (t.idx[0], t.wf[0], t.wi[0], t.n) = (k, 1.0, 16, 1);
                return t;
            }
            let k = xs.partition_point(|&c| c < x); // xs[k-1] < x < xs[k]
            let (a, b) = (xs[k - 1], xs[k]);
            if 2 * (x - a) == b - a
                && k >= 2
                && k + 1 < xs.len()
                && a - xs[k - 2] == b - a
                && xs[k + 1] - b == b - a
            {
                t.idx = [k - 2, k - 1, k, k + 1];
                t.wf = [-1.0 / 16.0, 9.0 / 16.0, 9.0 / 16.0, -1.0 / 16.0];
                t.wi = [-1, 9, 9, -1];
                t.n = 4;
            } else {
                let f = (x - a) as f64 / (b - a) as f64;
                let i = (16.0 * f).round() as i32;
                t.idx[..2].copy_from_slice(&[k - 1, k]);
                t.wf[..2].copy_from_slice(&[1.0 - f, f]);
                t.wi[..2].copy_from_slice(&[16 - i, i]);
                t.n = 2;
            }
            t
        })
        .collect();
    (xs, terms)
}

/// One block of the study: its samples' lattice, the parent's, and each kernel's residuals.
pub struct Block {
    w: usize,
    q: f64,
    cols: Vec<Terms>,
    rows: Vec<Terms>,
    /// The parent's heights (`pw × ph`) and lattice codes (for the residuals; the kernel
    /// makes its own).
    heights: Vec<f32>,
    codes: Vec<i32>,
    pw: usize,
    /// Per child row: the parent's row when it holds it.
    held_row: Vec<Option<usize>>,
    /// The child columns the parent holds, with the parent's column.
    held_cols: Vec<(usize, usize)>,
    /// Each kernel's residuals, a full row each (0 at held samples).
    rf: Vec<i32>,
    ri: Vec<i32>,
    /// The block's samples, for the check.
    samples: Vec<f32>,
}

impl Block {
    /// The study's block for `samples` (`w` wide, every sample on lattice step `q`); `None`
    /// when it is too small to hold a cubic midpoint or an index passes `i32`.
    pub fn new(samples: &[f32], w: usize, q: f64) -> Option<Block> {
        let h = samples.len() / w;
        if w < 7 || h < 7 || samples.iter().any(|v| v.is_nan()) {
            return None;
        }
        let (xs, cols) = axis_terms(w);
        let (ys, rows) = axis_terms(h);
        let k_of = |v: f32| (f64::from(v) / q).round();
        let k: Vec<f64> = samples.iter().map(|&v| k_of(v)).collect();
        if k.iter().any(|k| k.abs() >= (1u64 << 22) as f64) {
            return None;
        }
        let heights: Vec<f32> = ys
            .iter()
            .flat_map(|&y| xs.iter().map(move |&x| samples[y * w + x]))
            .collect();
        let codes: Vec<i32> = heights.iter().map(|&v| k_of(v) as i32).collect();
        let mut b = Block {
            w,
            q,
            held_row: (0..h).map(|y| ys.binary_search(&y).ok()).collect(),
            held_cols: (0..w)
                .filter_map(|x| xs.binary_search(&x).ok().map(|pi| (x, pi)))
                .collect(),
            cols,
            rows,
            heights,
            codes,
            pw: xs.len(),
            rf: Vec::new(),
            ri: Vec::new(),
            samples: samples.to_vec(),
        };
        let (pf, pi) = (b.predict_f(), b.predict_i());
        let held = |i: usize| b.held_row[i / w].is_some() && xs.binary_search(&(i % w)).is_ok();
        b.rf = (0..k.len())
            .map(|i| if held(i) { 0 } else { k[i] as i32 - pf[i] })
            .collect();
        b.ri = (0..k.len())
            .map(|i| if held(i) { 0 } else { k[i] as i32 - pi[i] })
            .collect();
        Some(b)
    }

    /// Every sample's `f64` prediction's index (the reference the kernel must match).
    fn predict_f(&self) -> Vec<i32> {
        let mut out = Vec::new();
        for ry in &self.rows {
            for cx in &self.cols {
                let mut p = 0.0f64;
                for j in 0..ry.n {
                    let mut s = 0.0f64;
                    for i in 0..cx.n {
                        s += cx.wf[i] * f64::from(self.heights[ry.idx[j] * self.pw + cx.idx[i]]);
                    }
                    p += ry.wf[j] * s;
                }
                out.push((p * (1.0 / self.q)).round() as i32);
            }
        }
        out
    }

    /// Every sample's integer prediction.
    fn predict_i(&self) -> Vec<i32> {
        let mut out = Vec::new();
        for ry in &self.rows {
            for cx in &self.cols {
                let mut p = 0i32;
                for j in 0..ry.n {
                    let mut s = 0i32;
                    for i in 0..cx.n {
                        s += cx.wi[i] * self.codes[ry.idx[j] * self.pw + cx.idx[i]];
                    }
                    p += ry.wi[j] * s;
                }
                out.push((p + 128) >> 8);
            }
        }
        out
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }
}

/// Scratch rows the kernels reuse.
#[derive(Default)]
pub struct Scratch {
    codes: Vec<i32>,
    inner_f: Vec<f64>,
    inner_i: Vec<i32>,
    p: Vec<f64>,
    k: Vec<i32>,
}

/// `x` rounded half away from zero, as the codec's `round_row` does for small values.
#[inline(always)]
fn round(x: f64) -> i32 {
    let t = x as i32;
    let frac = x - f64::from(t);
    t + i32::from(frac >= 0.5) - i32::from(frac <= -0.5)
}

#[inline(always)]
fn held(b: &Block, pj: Option<usize>, orow: &mut [f32]) {
    if let Some(pj) = pj {
        for &(c, pi) in &b.held_cols {
            orow[c] = b.heights[pj * b.pw + pi];
        }
    }
}

/// Format 6's way: `f64` interpolation of the parent's heights, scaled by `1/q`, rounded.
#[inline(always)]
fn kernel_f(b: &Block, s: &mut Scratch, out: &mut [f32]) {
    let (w, pw) = (b.w, b.pw);
    let ph = b.heights.len() / pw;
    s.inner_f.resize(ph * w, 0.0);
    for pj in 0..ph {
        let row = &b.heights[pj * pw..(pj + 1) * pw];
        for (x, cx) in s.inner_f[pj * w..(pj + 1) * w].iter_mut().zip(&b.cols) {
            let mut v = 0.0;
            for i in 0..cx.n {
                v += cx.wf[i] * f64::from(row[cx.idx[i]]);
            }
            *x = v;
        }
    }
    let inv_q = 1.0 / b.q;
    s.p.resize(w, 0.0);
    s.k.resize(w, 0);
    for (j, (ry, orow)) in b.rows.iter().zip(out.chunks_exact_mut(w)).enumerate() {
        let r = |t: usize| &s.inner_f[ry.idx[t] * w..(ry.idx[t] + 1) * w];
        match ry.n {
            1 => {
                for (p, &a) in s.p.iter_mut().zip(r(0)) {
                    *p = a * inv_q;
                }
            }
            2 => {
                let (b0, b1) = (ry.wf[0], ry.wf[1]);
                for ((p, &a), &c) in s.p.iter_mut().zip(r(0)).zip(r(1)) {
                    *p = (0.0 + b0 * a + b1 * c) * inv_q;
                }
            }
            _ => {
                let (b0, b1, b2, b3) = (ry.wf[0], ry.wf[1], ry.wf[2], ry.wf[3]);
                let rows = r(0).iter().zip(r(1)).zip(r(2)).zip(r(3));
                for (p, (((&a, &c), &d), &e)) in s.p.iter_mut().zip(rows) {
                    *p = (0.0 + b0 * a + b1 * c + b2 * d + b3 * e) * inv_q;
                }
            }
        }
        for ((k, &p), &d) in s.k.iter_mut().zip(&s.p).zip(&b.rf[j * w..(j + 1) * w]) {
            *k = round(p) + d;
        }
        for (o, &k) in orow.iter_mut().zip(&s.k) {
            *o = (f64::from(k) * b.q) as f32;
        }
        held(b, b.held_row[j], orow);
    }
}

/// The candidate: the parent's lattice codes interpolated in `i32`, weights in sixteenths.
/// The codes are made from the parent's heights here, as a decoder holding only those would
/// (`round(h · (1/q))`: exact for heights on the lattice, which a parent's held ones are).
#[inline(always)]
fn kernel_i(b: &Block, s: &mut Scratch, out: &mut [f32]) {
    let (w, pw) = (b.w, b.pw);
    let ph = b.heights.len() / pw;
    let inv_q = 1.0 / b.q;
    s.codes.resize(b.heights.len(), 0);
    for (c, &h) in s.codes.iter_mut().zip(&b.heights) {
        *c = round(f64::from(h) * inv_q);
    }
    s.inner_i.resize(ph * w, 0);
    for pj in 0..ph {
        let row = &s.codes[pj * pw..(pj + 1) * pw];
        for (x, cx) in s.inner_i[pj * w..(pj + 1) * w].iter_mut().zip(&b.cols) {
            let mut v = 0;
            for i in 0..cx.n {
                v += cx.wi[i] * row[cx.idx[i]];
            }
            *x = v;
        }
    }
    s.k.resize(w, 0);
    for (j, (ry, orow)) in b.rows.iter().zip(out.chunks_exact_mut(w)).enumerate() {
        let r = |t: usize| &s.inner_i[ry.idx[t] * w..(ry.idx[t] + 1) * w];
        let d = &b.ri[j * w..(j + 1) * w];
        match ry.n {
            1 => {
                for ((k, &a), &d) in s.k.iter_mut().zip(r(0)).zip(d) {
                    *k = ((16 * a + 128) >> 8) + d;
                }
            }
            2 => {
                let (b0, b1) = (ry.wi[0], ry.wi[1]);
                for (((k, &a), &c), &d) in s.k.iter_mut().zip(r(0)).zip(r(1)).zip(d) {
                    *k = ((b0 * a + b1 * c + 128) >> 8) + d;
                }
            }
            _ => {
                let (b0, b1, b2, b3) = (ry.wi[0], ry.wi[1], ry.wi[2], ry.wi[3]);
                let rows = r(0).iter().zip(r(1)).zip(r(2)).zip(r(3)).zip(d);
                for (k, ((((&a, &c), &e), &f), &d)) in s.k.iter_mut().zip(rows) {
                    *k = ((b0 * a + b1 * c + b2 * e + b3 * f + 128) >> 8) + d;
                }
            }
        }
        for (o, &k) in orow.iter_mut().zip(&s.k) {
            *o = (f64::from(k) * b.q) as f32;
        }
        held(b, b.held_row[j], orow);
    }
}

/// Kernel `integer` or not built for AVX2, as the codec's kernels are where the CPU has it.
///
/// # Safety
/// The CPU must have AVX2.
#[target_feature(enable = "avx2")]
unsafe fn run_avx2(integer: bool, b: &Block, s: &mut Scratch, out: &mut [f32]) {
    match integer {
        true => kernel_i(b, s, out),
        false => kernel_f(b, s, out),
    }
}

/// Runs kernel `integer` or not on `b` into `out`, the AVX2 build where the CPU has it.
pub fn run(integer: bool, b: &Block, s: &mut Scratch, out: &mut [f32]) {
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        unsafe { run_avx2(integer, b, s, out) }
    } else if integer {
        kernel_i(b, s, out)
    } else {
        kernel_f(b, s, out)
    }
}

/// Whether both kernels rebuild `b`'s samples bit for bit.
pub fn check(b: &Block) -> bool {
    let mut s = Scratch::default();
    let mut out = vec![0f32; b.len()];
    [false, true].iter().all(|&integer| {
        run(integer, b, &mut s, &mut out);
        out.iter()
            .zip(&b.samples)
            .all(|(a, c)| a.to_bits() == c.to_bits())
    })
}
