//! fmrh's PMTiles archives read by a reader fmrh did not write: protomaps' `pmtiles`
//! Python package (PyPI), through `tests/py/pmtiles_read.py`. The server suite
//! (`.ci/run` installs the package; without it this test fails, naming it).
//!
//! * A terrain-RGB archive of the bundled SRTM tile N43E006: the package finds exactly the
//!   tiles of the directory export, byte for byte, both by walking the directories and by
//!   looking each address up; its header says PNG, uncompressed tiles, gzip directories,
//!   clustered, the zooms and the bounds; its metadata is the TileJSON.
//! * A quantized-mesh archive of the same tile at every level (11,414 tiles, so the
//!   directories need leaves): the package reads the same tiles as fmrh's own reader,
//!   each a gzipped quantized-mesh tile, at zoom = Cesium's level + 1.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::pyramids::{export, n43e006 as n43, tiles_in, Tiles};
use fmrh::export::pmtiles::Archive;

/// What the package read: the header and metadata, and every tile from `out`.
fn read_with_package(archive: &Path, out: &Path) -> (serde_json::Value, Tiles) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/py/pmtiles_read.py");
    let run = std::process::Command::new("python3")
        .arg(&script)
        .arg(archive)
        .arg(out)
        .output()
        .expect("python3 runs");
    assert!(
        run.status.success(),
        "the pmtiles package could not read {} (is it installed? `python3 -m pip install pmtiles`): {}",
        archive.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let tiles = tiles_in(out, "bin");
    assert_eq!(summary["tiles"].as_u64(), Some(tiles.len() as u64));
    (summary, tiles)
}

#[test]
fn the_pmtiles_package_reads_terrain_rgb_archives() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let archive = dir.path().join("rgb.pmtiles");
    let tiles_dir = dir.path().join("rgb");
    export(&file, &["--tiles", "terrain-rgb"], &[&archive, &tiles_dir]);
    let (summary, read) = read_with_package(&archive, &dir.path().join("py"));
    let h = &summary["header"];
    assert_eq!(h["version"], 3);
    assert_eq!(h["tile_type"], 2, "PNG");
    assert_eq!(h["tile_compression"], 1, "none");
    assert_eq!(h["internal_compression"], 2, "gzip");
    assert_eq!(h["clustered"], true);
    assert_eq!(
        (h["min_zoom"].as_u64(), h["max_zoom"].as_u64()),
        (Some(0), Some(11))
    );
    assert_eq!(
        [
            &h["min_lon_e7"],
            &h["min_lat_e7"],
            &h["max_lon_e7"],
            &h["max_lat_e7"]
        ],
        [60_000_000, 430_000_000, 70_000_000, 440_000_000]
    );
    assert_eq!(summary["metadata"]["encoding"], "mapbox");
    assert_eq!(summary["metadata"]["tileSize"], 256);
    let mut n = 0;
    for (&(z, x, y), bytes) in &read {
        let png = std::fs::read(tiles_dir.join(format!("{z}/{x}/{y}.png")))
            .unwrap_or_else(|e| panic!("{z}/{x}/{y} is in the archive, not in the directory: {e}"));
        assert!(png == *bytes, "{z}/{x}/{y}: the package reads other bytes");
        n += 1;
    }
    let in_dir = tiles_in(&tiles_dir, "png").len();
    assert_eq!(
        n, in_dir,
        "the package finds every tile the directory holds"
    );
}

#[test]
fn the_pmtiles_package_reads_quantized_mesh_archives_with_leaves() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let archive = dir.path().join("qm.pmtiles");
    export(&file, &["--tiles", "quantized-mesh"], &[&archive]);
    let (summary, read) = read_with_package(&archive, &dir.path().join("py"));
    let h = &summary["header"];
    assert_eq!(h["tile_type"], 0);
    assert_eq!(h["tile_compression"], 2, "gzip");
    assert!(h["leaf_directory_length"].as_u64().unwrap() > 0, "{h}");
    assert_eq!(summary["metadata"]["format"], "quantized-mesh-1.0");
    let bytes = std::fs::read(&archive).unwrap();
    let ours: BTreeMap<(u8, u32, u32), Vec<u8>> = Archive::new(&bytes, &archive)
        .unwrap()
        .tiles()
        .unwrap()
        .into_iter()
        .map(|(t, b)| (t, b.to_vec()))
        .collect();
    assert!(ours.len() > 10_000, "{}", ours.len());
    assert!(ours == read, "the package and fmrh read different tiles");
    for (&(z, x, y), zipped) in &read {
        use std::io::Read;
        let mut plain = Vec::new();
        flate2::read::GzDecoder::new(zipped.as_slice())
            .read_to_end(&mut plain)
            .unwrap();
        // A quantized-mesh header is 88 bytes; level z - 1's rows are the zoom's first half.
        assert!(plain.len() > 88, "{z}/{x}/{y}");
        assert!(z >= 1 && y < 1 << (z - 1), "{z}/{x}/{y}");
    }
}
