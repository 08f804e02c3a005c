//! Helpers for the transaction tests: building a container in memory, describing the model a
//! container holds in comparable form, digesting its samples, and applying a patch to a
//! reference heightfield the way `replace_region` should.

#![allow(dead_code)]

use std::io::Cursor;

use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::store::{write_to, Source, WriteOptions};
use fmrh::{Heightfield, Store};

/// The bytes of a fresh container of `hf`.
pub fn build_bytes(hf: &Heightfield, block: u32, thresholds: &Thresholds) -> Vec<u8> {
    let model = Model::build(
        hf.clone(),
        &BuildOptions {
            block_size: block,
            thresholds: thresholds.clone(),
        },
    )
    .unwrap();
    let mut out = Cursor::new(Vec::new());
    write_to(&model, &hf.metadata, &WriteOptions::default(), &mut out).unwrap();
    out.into_inner()
}

/// The stored cluster thresholds.
pub fn thresholds<S: Source>(s: &Store<S>) -> Vec<f64> {
    s.clusters().iter().map(|c| c.threshold).collect()
}

/// The model a container describes, in comparable form: every node record without its
/// payload location, and every cut as (key, level) lists.
pub type Described = (Vec<String>, Vec<Vec<(u64, u8)>>);

pub fn described<S: Source>(s: &Store<S>) -> Described {
    let nodes = s
        .nodes()
        .unwrap()
        .iter()
        .map(|n| {
            format!(
                "{} {} {} {} {} {} {} {} {} {} {} {}",
                n.key.get(),
                n.level,
                n.child_mask,
                n.x.get(),
                n.y.get(),
                n.parent.get(),
                n.subtree_len.get(),
                n.static_error.get().to_bits(),
                n.monotone_error.get().to_bits(),
                n.min_height.get().to_bits(),
                n.max_height.get().to_bits(),
                n.valid_samples.get(),
            )
        })
        .collect();
    let cuts = (0..s.clusters().len())
        .map(|c| {
            s.scan_codes(c, 0..s.clusters()[c].nodes())
                .unwrap()
                .map(|e| {
                    let e = e.unwrap();
                    (e.key.0, e.level)
                })
                .collect()
        })
        .collect();
    (nodes, cuts)
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
