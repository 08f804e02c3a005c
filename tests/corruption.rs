//! Damage is detected: flipping any single bit of any page of a small container makes `verify`
//! report it invalid (or refuse it as unusable), and so does truncating it at any page
//! boundary. On a real DEM's container, a random sample of bit flips is detected too.
//! Nothing panics, and opening a damaged file either fails with an error or (for damage
//! outside what opening reads) succeeds without panicking.

mod common;

use std::io::Cursor;

use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::store::Store;
use fmrh::store::{verify, write_to, Bytes, WriteOptions};

fn small_container() -> Vec<u8> {
    // Voids, padding on both axes, three levels, 1024-byte pages: every kind of page.
    let field = common::fields::make(37, 29, common::fields::Character::Hills, 0.05, 5);
    let model = Model::build(
        field.clone(),
        &BuildOptions {
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap();
    let mut out = Cursor::new(Vec::new());
    let options = WriteOptions {
        page_size: 1024,
        ..WriteOptions::default()
    };
    write_to(&model, &field.metadata, &options, &mut out).unwrap();
    out.into_inner()
}

/// Whether `verify` (fast or full) rejects `bytes`.
fn rejected(bytes: &[u8], full: bool) -> bool {
    let mode = if full {
        fmrh::store::VerifyMode::Full
    } else {
        fmrh::store::VerifyMode::Fast
    };
    match verify(Bytes(bytes), mode) {
        Ok(report) => !report.valid,
        Err(_) => true,
    }
}

#[test]
fn the_small_container_is_valid() {
    let bytes = small_container();
    assert!(!rejected(&bytes, true));
    assert!(
        bytes.len() >= 8 * 1024,
        "the test container should span several pages"
    );
}

#[test]
fn every_single_bit_flip_is_detected() {
    let clean = small_container();
    let mut missed = Vec::new();
    let mut bytes = clean.clone();
    for i in 0..bytes.len() {
        for bit in 0..8 {
            bytes[i] ^= 1 << bit;
            if !rejected(&bytes, false) {
                missed.push((i, bit));
            }
            // Opening must never panic, whatever it decides.
            let _ = Store::from_bytes(&bytes[..]);
            bytes[i] ^= 1 << bit;
        }
    }
    assert_eq!(bytes, clean);
    assert!(
        missed.is_empty(),
        "{} of {} bit flips went undetected; first: {:?}",
        missed.len(),
        bytes.len() * 8,
        &missed[..missed.len().min(10)]
    );
}

#[test]
fn truncation_at_every_page_boundary_is_detected() {
    let bytes = small_container();
    for pages in 0..bytes.len() / 1024 {
        let cut = &bytes[..pages * 1024];
        assert!(rejected(cut, false), "truncated to {pages} pages");
        assert!(
            Store::from_bytes(cut).is_err(),
            "opened a file truncated to {pages} pages"
        );
    }
    // And at a few points inside pages.
    for cut in [1, 255, 256, 1023, 1025, bytes.len() - 1] {
        assert!(rejected(&bytes[..cut], false), "truncated to {cut} bytes");
    }
}

#[test]
fn bytes_that_are_not_a_container_are_unusable() {
    for bytes in [&b""[..], b"hello", &[0u8; 5000], &[0xffu8; 4096]] {
        assert!(verify(Bytes(bytes), fmrh::store::VerifyMode::Full).is_err());
        assert!(Store::from_bytes(bytes).is_err());
    }
}

#[test]
fn random_bit_flips_in_a_real_container_are_detected() {
    let path = common::data("gdal-rs-dem-hills/dem_hills.f32");
    let field = fmrh::ingest::load(&path, &Default::default()).unwrap();
    let model = Model::build(field.clone(), &BuildOptions::default()).unwrap();
    let mut out = Cursor::new(Vec::new());
    write_to(&model, &field.metadata, &WriteOptions::default(), &mut out).unwrap();
    let mut bytes = out.into_inner();
    let mut rng = common::fields::Rng::new(2026);
    for _ in 0..200 {
        let i = (rng.next_u64() % bytes.len() as u64) as usize;
        let bit = rng.next_u64() % 8;
        bytes[i] ^= 1 << bit;
        assert!(
            rejected(&bytes, false),
            "flip of bit {bit} of byte {i} went undetected"
        );
        bytes[i] ^= 1 << bit;
    }
    assert!(!rejected(&bytes, false));
}
