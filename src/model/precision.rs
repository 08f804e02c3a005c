//! Error-bounded storage: heights kept to a step `Q`, and the storage error that adds to
//! every node's error.
//!
//! A DEM measured to a decimetre gains nothing from the other twenty bits of an `f32`, but
//! a lossless codec must keep them, and they are noise that costs most of the bytes. With a
//! storage precision `Q` (`fmrh build --precision Q`) every real height `h` with
//! `|h| <= 2^20 · Q` is stored as the lattice height nearest to it, `q(h) = (k · Q) as f32`
//! with `k = round(h / Q)`: the formula of the lattice codec
//! ([`crate::codec::lattice_value`]), so every stored block is on the lattice and codes as
//! small integers. Larger heights (beyond 104 km for `Q = 0.1`) are stored as they are.
//!
//! **The bound is `Q/2 + Q/16`, not `Q/2`.** `k · Q` is within `Q/2` of `h`, but it is
//! rounded to an `f32`, which adds up to half an `f32` ulp. Near a half step that pushes the
//! stored height past `Q/2`, and no lattice value of either neighbour is closer: for
//! `h = 2167.95` and `Q = 0.1` both `2167.9` and `2168.0` are 0.05005 away as `f32`s. Storing
//! such heights as they are would knock whole blocks off the lattice codec (at 1,000 m and
//! `Q = 0.1`, about one sample in 800, so most 65² blocks). Below `2^20 · Q` half an ulp is
//! at most `Q/16`, so
//!
//! ```text
//!   |stored(x, y) - source(x, y)| <= 9Q/16        for every valid sample
//! ```
//!
//! and in practice the measured largest change is `Q/2` and a few ulps (the build reports
//! it).
//!
//! **The storage error enters the node errors.** A node's static error is measured against
//! the *stored* samples (the only ones a later transaction can see), and the bound is added
//! to it (model §4: every band with a valid sample). By the triangle inequality the result
//! bounds the distance from the node's surface to the *source*, which is what a scene's
//! error bound promises. Finest nodes, whose grid is the stored data, get exactly the bound;
//! so no cluster threshold below it can be met, and the default ladder starts there instead
//! of at 0.
//!
//! Bounding rather than measuring the source's error keeps a file editable: a transaction
//! measures against what is stored, since the source is gone, and a fresh build and an edit
//! give the same errors. The price is at most the bound of slack on coarse nodes.

use crate::codec;
use crate::error::{Error, Result};
use crate::heightfield::Heightfield;

/// A storage precision: the lattice step heights are kept to (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Precision {
    step: f64,
}

impl Precision {
    /// The smallest step accepted: below it an `f32` height near 1 has no more to give.
    pub const MIN_STEP: f64 = 1e-6;
    /// The largest step accepted.
    pub const MAX_STEP: f64 = 1e6;

    /// The precision of lattice step `step`: finite, within
    /// [`MIN_STEP`](Self::MIN_STEP)`..=`[`MAX_STEP`](Self::MAX_STEP).
    pub fn new(step: f64) -> Result<Precision> {
        if !(step.is_finite() && (Self::MIN_STEP..=Self::MAX_STEP).contains(&step)) {
            return Err(Error::InvalidArgument(format!(
                "precision {step}: a storage step must be a number from {} to {}",
                Self::MIN_STEP,
                Self::MAX_STEP
            )));
        }
        Ok(Precision { step })
    }

    /// The lattice step `Q`.
    pub fn step(self) -> f64 {
        self.step
    }

    /// The storage error bound, `9Q/16` (see the module docs): no stored height is further
    /// from its source.
    pub fn bound(self) -> f64 {
        self.step * 0.5625
    }

    /// The largest `|h|` quantised: `2^20 · Q`, below which an `f32` ulp is at most `Q/8`.
    pub fn cap(self) -> f64 {
        self.step * f64::from(1u32 << 20)
    }

    /// The stored height of source height `v` (see the module docs). NaN (a void) stays
    /// as it is.
    pub fn quantise(self, v: f32) -> f32 {
        if !v.is_finite() || f64::from(v).abs() > self.cap() {
            return v;
        }
        match codec::lattice_index(v, self.step) {
            Some(k) => {
                let q = codec::lattice_value(k, self.step);
                // Both are f32 values, so their difference is exact in f64. Below the cap
                // both checks hold (|k| <= 2^20, so `q` is its own lattice value); they
                // stay as a guard, so that quantising is idempotent and bounded whatever
                // the arithmetic.
                if codec::is_lattice_value(q, self.step)
                    && (f64::from(q) - f64::from(v)).abs() <= self.bound()
                {
                    q
                } else {
                    v
                }
            }
            None => v,
        }
    }

    /// Quantises every sample of `heightfield` in place. Returns it with the largest
    /// `|stored - source|` over its real heights, or `None` when no sample changed a bit
    /// (integer data and a step of 1, say: the precision changes nothing).
    pub fn quantise_heightfield(self, heightfield: Heightfield) -> (Heightfield, Option<f64>) {
        let (w, h) = (heightfield.width(), heightfield.height());
        let metadata = heightfield.metadata.clone();
        let mut samples = heightfield.into_samples();
        let mut worst = 0.0f64;
        let mut changed = false;
        for v in &mut samples {
            let q = self.quantise(*v);
            if q.to_bits() != v.to_bits() {
                changed = true;
                worst = worst.max((f64::from(q) - f64::from(*v)).abs());
            }
            *v = q;
        }
        let mut out = Heightfield::new(w, h, samples)
            .unwrap_or_else(|_| unreachable!("quantising keeps the shape and finiteness"));
        out.metadata = metadata;
        (out, changed.then_some(worst))
    }
}

/// Whether quantising to `precision` would change a bit of `samples`. A caller may then
/// drop a precision that changes nothing (`fmrh build` does: the file is lossless, and its
/// errors carry no storage bound).
pub fn changes_any(precision: Precision, samples: &[f32]) -> bool {
    samples
        .iter()
        .any(|&v| precision.quantise(v).to_bits() != v.to_bits())
}

/// Checks cluster thresholds (sorted) against `precision`: none may be below its storage
/// error, which every node with real heights carries.
pub fn check_thresholds(thresholds: Vec<f64>, precision: Option<Precision>) -> Result<Vec<f64>> {
    if let (Some(p), Some(&lowest)) = (precision, thresholds.first()) {
        if lowest < p.bound() {
            return Err(Error::InvalidArgument(format!(
                "threshold {lowest} is below the storage error {} of precision {}: no node \
                 of such a file meets it (use thresholds of at least {})",
                p.bound(),
                p.step(),
                p.bound()
            )));
        }
    }
    Ok(thresholds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn steps_outside_the_range_are_refused() {
        for bad in [0.0, -0.1, f64::NAN, f64::INFINITY, 1e-9, 1e7] {
            assert!(Precision::new(bad).is_err(), "{bad}");
        }
        assert!(Precision::new(0.1).is_ok());
    }

    #[test]
    fn negative_zero_and_tiny_values_become_plus_zero() {
        let p = Precision::new(0.1).unwrap();
        for v in [-0.0f32, 1e-40, -1e-40, 0.04, -0.04] {
            let q = p.quantise(v);
            assert_eq!(q.to_bits(), 0.0f32.to_bits(), "{v}");
        }
    }

    #[test]
    fn a_half_step_past_q_over_2_is_still_quantised() {
        let p = Precision::new(0.1).unwrap();
        let v = 2167.95f32;
        let q = p.quantise(v);
        assert!(q == 2168.0 || q == 2167.9, "{q}");
        let off = (f64::from(q) - f64::from(v)).abs();
        assert!(off > 0.05 && off <= p.bound(), "{off}");
    }

    #[test]
    fn huge_values_are_kept() {
        let p = Precision::new(0.1).unwrap();
        for v in [f32::MAX, f32::MIN, 3.0e38, -3.0e38] {
            assert_eq!(p.quantise(v).to_bits(), v.to_bits());
        }
        assert!(p.quantise(f32::NAN).is_nan());
    }

    proptest! {
        /// The bound holds for every finite f32, and quantising twice changes nothing (a
        /// transaction reads stored heights back and may quantise them again).
        #[test]
        fn within_the_bound_and_idempotent(
            bits in any::<u32>(),
            step in prop::sample::select(vec![1e-6, 0.001, 0.1, 0.25, 0.3, 1.0, 7.0, 1e6]),
        ) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            let p = Precision::new(step).unwrap();
            let q = p.quantise(v);
            prop_assert!((f64::from(q) - f64::from(v)).abs() <= step * 0.5625);
            prop_assert_eq!(p.quantise(q).to_bits(), q.to_bits());
            // Below the cap every height lands on the lattice.
            if f64::from(v).abs() <= p.cap() {
                let k = codec::lattice_index(q, step).unwrap();
                prop_assert_eq!(codec::lattice_value(k, step).to_bits(), q.to_bits());
            }
        }

        /// Ordinary heights land on the lattice, so the lattice codec takes them, the half
        /// steps where f32 rounding goes past Q/2 included.
        #[test]
        fn ordinary_heights_are_on_the_lattice(v in -12000.0f32..9000.0) {
            let p = Precision::new(0.1).unwrap();
            let q = p.quantise(v);
            let k = codec::lattice_index(q, 0.1).unwrap();
            prop_assert_eq!(codec::lattice_value(k, 0.1).to_bits(), q.to_bits());
        }
    }
}
