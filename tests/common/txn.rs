//! Helpers for the transaction tests: building a container in memory, describing the model a
//! container holds in comparable form, digesting its samples, and applying a patch to a
//! reference heightfield the way `replace_region` should.

#![allow(dead_code, unused_imports)]

use fmrh::store::Source;
use fmrh::{store::Store, Heightfield};

pub use super::txn_driver::{build_bytes, build_bytes_paged, described, Described};

/// The stored cluster thresholds.
pub fn thresholds<S: Source>(s: &Store<S>) -> Vec<f64> {
    s.clusters().iter().map(|c| c.threshold).collect()
}

/// A digest of every sample (bits; every void as one value).
pub fn digest_samples(samples: &[f32]) -> u64 {
    samples.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
        let bits = if v.is_nan() { 0x7FC0_0000 } else { v.to_bits() };
        (h ^ u64::from(bits)).wrapping_mul(0x100_0000_01b3)
    })
}

/// A digest of every sample a state holds.
pub fn samples_digest<S: Source>(s: &Store<S>) -> u64 {
    let hf = s.read_window(s.domain().data_rect()).unwrap();
    digest_samples(hf.samples())
}

/// `hf` with `patch` pasted at `(col0, row0)`.
pub fn paste(hf: &Heightfield, col0: u64, row0: u64, patch: &Heightfield) -> Heightfield {
    let w = u64::from(hf.width());
    let mut samples = hf.samples().to_vec();
    for j in 0..u64::from(patch.height()) {
        for k in 0..u64::from(patch.width()) {
            samples[((row0 + j) * w + col0 + k) as usize] =
                patch.samples()[(j * u64::from(patch.width()) + k) as usize];
        }
    }
    let mut out = Heightfield::new(hf.width(), hf.height(), samples).unwrap();
    out.metadata = hf.metadata.clone();
    out
}

/// A smooth patch, different for every seed.
pub fn patch(w: u32, h: u32, seed: f32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        (seed * 10.0 + (x as f32 * 0.9 + seed).sin() * 45.0 + y as f32 * 2.0).round()
    })
    .unwrap()
}
