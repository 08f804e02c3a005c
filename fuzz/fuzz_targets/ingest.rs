//! Fuzz target: arbitrary bytes under every input format's name must load or fail with an
//! error, never panic, hang or allocate without bound. The first byte picks the format.
//!
//! Run it under a memory limit, so that a decompression bomb the ingest limits miss is a
//! finding (`src/ingest/limits.rs`): an input of at most 4 KiB may declare at most 2^24
//! samples past the proportion check (256 a byte), about 100 MB to decode, so anything near
//! 512 MB is a bomb:
//!
//! cargo fuzz run --sanitizer none ingest corpus/ingest -- -rss_limit_mb=512 -malloc_limit_mb=512

#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

/// One scratch directory for the whole run, in memory where the machine has `/dev/shm`:
/// a fresh temporary directory per input cost more than the decoding (about 2,800 inputs a
/// second, against several times that with the directory reused).
fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    let (_, path) = DIR.get_or_init(|| {
        let shm = std::path::Path::new("/dev/shm");
        let dir = if shm.is_dir() {
            tempfile::tempdir_in(shm)
        } else {
            tempfile::tempdir()
        }
        .expect("temp dir");
        let path = dir.path().to_path_buf();
        (dir, path)
    });
    path
}

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
    let path = scratch().join(NAMES[usize::from(pick) % NAMES.len()]);
    std::fs::write(&path, body).expect("write");
    let options = fmrh::ingest::IngestOptions {
        color_encoding: Some(fmrh::ingest::ColorEncoding::TerrainRgb),
        ..Default::default()
    };
    let _ = fmrh::ingest::load(&path, &options);
    // Only this input's file may be in the directory when the next one loads (a reader that
    // looks for a sidecar must not find the last input's), so a crash replays from one input.
    std::fs::remove_file(&path).expect("remove");
});
