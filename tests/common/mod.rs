//! Helpers shared by the integration tests: where the real data lives, and small comparisons.

#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared/data` beside the repository.
pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// A file of the shared data set, by path inside `../shared/data`. Panics with a clear message
/// when the data set is missing: the real-data tests must not pass vacuously.
pub fn data(rel: &str) -> PathBuf {
    let p = data_dir().join(rel);
    assert!(
        p.exists(),
        "real data {} is missing: clone the project with ../shared beside it",
        p.display()
    );
    p
}

/// The index and values of the first sample where two grids differ (NaN equals NaN).
pub fn first_difference(a: &[f32], b: &[f32]) -> Option<(usize, f32, f32)> {
    assert_eq!(a.len(), b.len(), "grids differ in size");
    a.iter()
        .zip(b)
        .enumerate()
        .find(|(_, (x, y))| !(x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan())))
        .map(|(i, (x, y))| (i, *x, *y))
}

/// Runs the `fmrh` binary built for these tests.
pub fn fmrh(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_fmrh"))
        .args(args)
        .output()
        .expect("the fmrh binary runs")
}

/// The JSON a successful `fmrh` run printed; fails the test with its stderr otherwise.
pub fn ok_json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

pub mod fields;
pub mod oracle;
pub mod txn;
pub mod txn_driver;
pub mod views;
