//! Fuzz target: arbitrary bytes under every input format's name must load or fail with an
//! error, never panic, hang or allocate without bound. The first byte picks the format.
//!
//! cargo install cargo-fuzz
//! cargo fuzz run --sanitizer none ingest      (stable toolchain)

#![no_main]

use libfuzzer_sys::fuzz_target;

const NAMES: [&str; 9] = [
    "N10E010.hgt",
    "N10E010.hgt.gz",
    "x.tif",
    "x.png",
    "x.jpg",
    "x.asc",
    "x.dem",
    "x.json",
    "x.dt1",
];

fuzz_target!(|data: &[u8]| {
    let Some((&pick, body)) = data.split_first() else {
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(NAMES[usize::from(pick) % NAMES.len()]);
    std::fs::write(&path, body).expect("write");
    let options = fmrh::ingest::IngestOptions {
        color_encoding: Some(fmrh::ingest::ColorEncoding::TerrainRgb),
        ..Default::default()
    };
    let _ = fmrh::ingest::load(&path, &options);
});
