//! Helpers shared by the integration tests: where the real data lives, and small comparisons.

#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared/data` beside the repository: the large DEMs.
pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// `data/` in the repository: the bundled samples (see its README).
pub fn bundled_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data")
}

/// The bytes of a golden vector, by its path inside `format-spec/vectors/`.
pub fn vector(rel: &str) -> Vec<u8> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("format-spec/vectors")
        .join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A real DEM by its path inside the data set (`folder/file`): the bundled copy in `data/`
/// when there is one, else the one in `../shared/data`. Panics with a clear message when
/// neither has it: the large-data suite must not pass vacuously on a clone without
/// `../shared`.
pub fn data(rel: &str) -> PathBuf {
    let bundled = bundled_dir().join(rel);
    if bundled.exists() {
        return bundled;
    }
    let p = data_dir().join(rel);
    assert!(
        p.exists(),
        "real data {rel} is neither bundled in data/ nor in {}: the large-data suite needs \
         ../shared beside the repository (see README, Testing)",
        data_dir().display()
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

/// `v` without the timings a command reports (keys ending in `_ns`) nor the keys in `drop`,
/// at every depth: what differs between two answers about the same state.
pub fn without_keys(v: &mut serde_json::Value, drop: &[&str]) {
    match v {
        serde_json::Value::Object(m) => {
            m.retain(|k, _| !k.ends_with("_ns") && !drop.contains(&k.as_str()));
            m.values_mut().for_each(|v| without_keys(v, drop));
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(|v| without_keys(v, drop)),
        _ => {}
    }
}

/// Runs the `fmrh` binary built for these tests.
pub fn fmrh(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_fmrh"))
        .args(args)
        .output()
        .expect("the fmrh binary runs")
}

/// Runs `fmrh` and fails the test, with its stderr, unless it succeeds.
pub fn fmrh_ok(args: &[&str]) {
    let out = fmrh(args);
    assert!(
        out.status.success(),
        "fmrh {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A DEM file read as `build` reads it, with the default options.
pub fn load_dem(p: &std::path::Path) -> fmrh::Heightfield {
    fmrh::ingest::load(p, &fmrh::ingest::IngestOptions::default()).expect("the DEM loads")
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

/// A container of `field` with blocks of `block_size`, written with `options`, in memory.
pub fn bytes_of(
    field: &fmrh::Heightfield,
    block_size: u32,
    options: &fmrh::store::WriteOptions,
) -> Vec<u8> {
    let model = fmrh::model::Model::build(
        field.clone(),
        &fmrh::model::BuildOptions {
            block_size,
            ..fmrh::model::BuildOptions::default()
        },
    )
    .unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    fmrh::store::write_to(&model, &field.metadata, options, &mut out).unwrap();
    out.into_inner()
}

pub mod bundle;
pub mod cesium;
pub mod cuts;
pub mod fields;
pub mod globe;
pub mod gltf;
pub mod mercator;
pub mod oracle;
pub mod origin;
pub mod pyramids;
pub mod quantized_mesh;
pub mod serve;
pub mod servers;
pub mod tiles;
pub mod tower;
pub mod txn;
pub mod txn_driver;
pub mod views;

/// Runs the browser script `tests/js/SCRIPT` with `args` under Node.js, once `packages` are
/// installed in `tests/js` (it fails saying how to install them): its JSON report.
pub fn node_script(script: &str, packages: &[&str], args: &[&str]) -> serde_json::Value {
    let js = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/js");
    for package in packages {
        assert!(
            js.join("node_modules").join(package).is_dir(),
            "{package} is not installed: run `npm ci --prefix tests/js` (.ci/run does)"
        );
    }
    let out = std::process::Command::new("node")
        .arg(js.join(script))
        .args(args)
        .output()
        .expect("node runs (Node.js and Chromium are needed: see docs/testing.md)");
    assert!(
        out.status.success(),
        "{script} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the script's JSON report")
}
