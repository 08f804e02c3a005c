//! `fmrh export --tiles quantized-mesh|terrain-rgb`: a static pyramid holds, tile for tile,
//! what `fmrh serve` answers for the same state, and nothing else.
//!
//! * On the bundled SRTM tile N43E006, for both pyramids, both destinations (a directory
//!   and a PMTiles archive, read back here with fmrh's own reader, which the Python
//!   `pmtiles` package cross-checks in `tests/pmtiles_python.rs`): every tile written
//!   equals the server's answer byte for byte (quantized-mesh with both extensions; in an
//!   archive, gzipped as the server gzips it), and every tile around them that was not
//!   written gets `404` from the server. A directory and an archive hold the same tiles.
//! * The archive's header names the tile type, compression, zooms and bounds, and its
//!   metadata is the description the directory gets (`layer.json` or TileJSON).
//! * `--bbox` keeps exactly the tiles meeting the box; `--zoom` the zooms asked.
//! * Refusals: an existing output without `--force` (left as it was), bad zooms and
//!   boxes, options of the other pyramid, a box with no data, a terrain with no place on
//!   the globe; each exits non-zero with a message, and writes nothing.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::pyramids::{export, n43e006 as n43, tiles_in};
use common::serve::Served;
use fmrh::export::pmtiles::Archive;

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Read;
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(bytes)
        .read_to_end(&mut out)
        .unwrap();
    out
}

/// The tiles around `tiles` in each zoom (their extent widened by one) that are not in it.
fn around(tiles: &BTreeMap<(u8, u32, u32), Vec<u8>>) -> Vec<(u8, u32, u32)> {
    let mut extent: BTreeMap<u8, (u32, u32, u32, u32)> = BTreeMap::new();
    for &(z, x, y) in tiles.keys() {
        let e = extent.entry(z).or_insert((x, y, x, y));
        *e = (e.0.min(x), e.1.min(y), e.2.max(x), e.3.max(y));
    }
    let mut out = Vec::new();
    for (&z, &(x0, y0, x1, y1)) in &extent {
        for y in y0.saturating_sub(1)..=y1 + 1 {
            for x in x0.saturating_sub(1)..=x1 + 1 {
                if !tiles.contains_key(&(z, x, y)) {
                    out.push((z, x, y));
                }
            }
        }
    }
    out
}

#[test]
fn terrain_rgb_exports_are_what_the_server_answers() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let out_dir = dir.path().join("rgb");
    let archive = dir.path().join("rgb.pmtiles");
    export(
        &file,
        &[
            "--tiles",
            "terrain-rgb",
            "--encoding",
            "terrarium",
            "--size",
            "512",
        ],
        &[&out_dir, &archive],
    );
    let written = tiles_in(&out_dir, "png");
    // 3" at 43.5° N: zoom 10's 512 px pixels are the first finer; one tile a zoom down to 6.
    assert_eq!(written.keys().map(|t| t.0).max(), Some(10));
    assert_eq!(written.keys().filter(|t| t.0 <= 6).count(), 7);
    let tj: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("tilejson.json")).unwrap()).unwrap();
    assert_eq!(tj["encoding"], "terrarium");
    assert_eq!(tj["tileSize"], 512);
    assert_eq!(tj["tiles"][0], "{z}/{x}/{y}.png");

    let bytes = std::fs::read(&archive).unwrap();
    let a = Archive::new(&bytes, &archive).unwrap();
    assert_eq!(
        (a.tile_type, a.tile_compression),
        (2, 1),
        "PNG, uncompressed"
    );
    assert!(a.clustered);
    assert_eq!((a.min_zoom, a.max_zoom), (0, 10));
    for (got, want) in a.bounds.iter().zip([6.0, 43.0, 7.0, 44.0]) {
        assert!((got - want).abs() < 1e-6, "{:?}", a.bounds);
    }
    let meta = a.metadata().unwrap();
    assert_eq!(meta["encoding"], "terrarium");
    assert!(
        meta.get("tiles").is_none(),
        "an archive's clients make their own addresses"
    );
    let in_archive: BTreeMap<(u8, u32, u32), Vec<u8>> = a
        .tiles()
        .unwrap()
        .into_iter()
        .map(|(t, b)| (t, b.to_vec()))
        .collect();
    assert_eq!(
        in_archive, written,
        "the archive and the directory hold the same tiles"
    );
    assert_eq!(a.counts[0], written.len() as u64);

    let served = Served::start(&[&file]);
    for ((z, x, y), png) in &written {
        let path = format!("/n6.fmrh/terrain-rgb/{z}/{x}/{y}.png?encoding=terrarium&size=512");
        let answer = served.get(&path);
        assert_eq!(answer.status, 200, "{path}");
        assert!(
            answer.body == *png,
            "{path}: the export differs from the server's tile"
        );
    }
    let missing = around(&written);
    assert!(missing.len() > 20);
    for (z, x, y) in missing {
        let path = format!("/n6.fmrh/terrain-rgb/{z}/{x}/{y}.png?encoding=terrarium&size=512");
        // Past the zoom's columns or rows is a bad request; inside it, nothing there.
        let want = if x >> z != 0 || y >> z != 0 { 400 } else { 404 };
        assert_eq!(served.get(&path).status, want, "{path} was not exported");
    }
    assert_eq!(
        served
            .get("/n6.fmrh/terrain-rgb/11/1060/746.png?encoding=terrarium&size=512")
            .status,
        404,
        "past the deepest zoom"
    );
}

#[test]
fn quantized_mesh_exports_are_what_the_server_answers() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let out_dir = dir.path().join("qm");
    let archive = dir.path().join("qm.pmtiles");
    export(
        &file,
        &["--tiles", "quantized-mesh", "--zoom", "2..=9"],
        &[&out_dir, &archive],
    );
    let written = tiles_in(&out_dir, "terrain");
    assert_eq!(written.keys().map(|t| t.0).min(), Some(2));
    assert_eq!(written.keys().map(|t| t.0).max(), Some(9));
    let layer: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("layer.json")).unwrap()).unwrap();
    assert_eq!(layer["format"], "quantized-mesh-1.0");
    // A part of the pyramid: its layer.json lists only what is there, and leaves the
    // tiles' own metadata (the whole pyramid's availability) unread.
    assert_eq!(layer["maxzoom"], 9);
    assert!(layer.get("metadataAvailability").is_none());
    let available = layer["available"].as_array().unwrap();
    assert_eq!(available.len(), 10);
    for (z, ranges) in available.iter().enumerate() {
        let mut listed: Vec<(u8, u32, u32)> = ranges
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| {
                let n = |k: &str| r[k].as_u64().unwrap() as u32;
                let (x0, y0, x1, y1) = (n("startX"), n("startY"), n("endX"), n("endY"));
                (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| (z as u8, x, y)))
            })
            .collect();
        listed.sort();
        let here: Vec<(u8, u32, u32)> =
            written.keys().copied().filter(|t| t.0 == z as u8).collect();
        assert_eq!(listed, here, "level {z}: available lists the tiles written");
    }
    assert_eq!(
        layer["extensions"],
        serde_json::json!(["octvertexnormals", "metadata"])
    );

    let bytes = std::fs::read(&archive).unwrap();
    let a = Archive::new(&bytes, &archive).unwrap();
    assert_eq!(
        (a.tile_type, a.tile_compression),
        (0, 2),
        "unknown type, gzip"
    );
    // Cesium's level z is the archive's zoom z + 1.
    assert_eq!((a.min_zoom, a.max_zoom), (3, 10));
    let meta = a.metadata().unwrap();
    assert_eq!(meta["format"], "quantized-mesh-1.0");
    assert!(meta["fmrh"]["pmtiles_zoom"].is_string());
    let in_archive: BTreeMap<(u8, u32, u32), Vec<u8>> = a
        .tiles()
        .unwrap()
        .into_iter()
        .map(|((z, x, y), b)| ((z - 1, x, y), b.to_vec()))
        .collect();
    assert_eq!(
        in_archive.keys().collect::<Vec<_>>(),
        written.keys().collect::<Vec<_>>()
    );

    let served = Served::start(&[&file]);
    let accept = (
        "Accept",
        "application/vnd.quantized-mesh;extensions=octvertexnormals-metadata",
    );
    for ((z, x, y), plain) in &written {
        let path = format!("/n6.fmrh/{z}/{x}/{y}.terrain");
        let answer = served.ask("GET", &path, &[accept]);
        assert_eq!(answer.status, 200, "{path}");
        assert!(
            answer.body == *plain,
            "{path}: the directory's tile differs from the server's"
        );
        let zipped = served.ask("GET", &path, &[accept, ("Accept-Encoding", "gzip")]);
        assert_eq!(zipped.header("content-encoding"), Some("gzip"));
        let stored = &in_archive[&(*z, *x, *y)];
        assert!(
            zipped.body == *stored,
            "{path}: the archive's tile differs from the server's"
        );
        assert!(gunzip(stored) == *plain);
    }
    for (z, x, y) in around(&written) {
        let path = format!("/n6.fmrh/{z}/{x}/{y}.terrain");
        let status = served.ask("GET", &path, &[accept]).status;
        assert_eq!(status, 404, "{path} was not exported");
    }
}

#[test]
fn a_box_and_zooms_select_the_tiles_meeting_them() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let all = dir.path().join("all");
    let part = dir.path().join("part");
    let f = file.to_str().unwrap();
    common::fmrh_ok(&[
        "export",
        "-q",
        f,
        "--tiles",
        "terrain-rgb",
        "--zoom",
        "9..",
        "-o",
        all.to_str().unwrap(),
    ]);
    let bbox = [6.1, 43.1, 6.4, 43.3];
    common::fmrh_ok(&[
        "export",
        "-q",
        f,
        "--tiles",
        "terrain-rgb",
        "--zoom",
        "9..=11",
        "--bbox",
        "6.1,43.1,6.4,43.3",
        "-o",
        part.to_str().unwrap(),
    ]);
    let tj: serde_json::Value =
        serde_json::from_slice(&std::fs::read(part.join("tilejson.json")).unwrap()).unwrap();
    assert_eq!(
        (tj["minzoom"].as_u64(), tj["maxzoom"].as_u64()),
        (Some(9), Some(11))
    );
    assert_eq!(tj["bounds"], serde_json::json!([6.1, 43.1, 6.4, 43.3]));
    let all = tiles_in(&all, "png");
    let part = tiles_in(&part, "png");
    assert_eq!(all.keys().map(|t| t.0).min(), Some(9));
    let bounds = |(z, x, y): (u8, u32, u32)| {
        let n = f64::from(1u32 << z);
        let lat = |yy: f64| {
            (std::f64::consts::PI * (1.0 - 2.0 * yy / n))
                .sinh()
                .atan()
                .to_degrees()
        };
        [
            f64::from(x) / n * 360.0 - 180.0,
            lat(f64::from(y) + 1.0),
            f64::from(x + 1) / n * 360.0 - 180.0,
            lat(f64::from(y)),
        ]
    };
    let meets = |t| {
        let [w, s, e, n] = bounds(t);
        w <= bbox[2] && e >= bbox[0] && s <= bbox[3] && n >= bbox[1]
    };
    let want: Vec<_> = all.keys().copied().filter(|&t| meets(t)).collect();
    assert_eq!(part.keys().copied().collect::<Vec<_>>(), want);
    assert!(
        part.len() < all.len() / 2,
        "{} of {}",
        part.len(),
        all.len()
    );
    for (t, png) in &part {
        assert!(all[t] == *png, "{t:?}: the same tile either way");
    }
}

#[test]
fn bad_exports_are_refused_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let f = file.to_str().unwrap();
    let existing = dir.path().join("there.pmtiles");
    std::fs::write(&existing, b"keep").unwrap();
    let refused = |args: &[&str], why: &str| {
        let out = common::fmrh(args);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(why), "{args:?}: {err}");
    };
    let e = existing.to_str().unwrap();
    refused(&["export", f, "--tiles", "terrain-rgb", "-o", e], "--force");
    assert_eq!(std::fs::read(&existing).unwrap(), b"keep");
    let o = dir.path().join("o.pmtiles");
    let o = o.to_str().unwrap();
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--zoom",
            "7..3",
            "-o",
            o,
        ],
        "--zoom",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--zoom",
            "30",
            "-o",
            o,
        ],
        "deepest",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--bbox",
            "1,2,3",
            "-o",
            o,
        ],
        "--bbox",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--bbox",
            "7,44,6,43",
            "-o",
            o,
        ],
        "bbox",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--zoom",
            "9..",
            "--bbox",
            "-10,-10,-9,-9",
            "-o",
            o,
        ],
        "no tiles",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--size",
            "300",
            "-o",
            o,
        ],
        "256 or 512",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--max-error",
            "2",
            "-o",
            o,
        ],
        "quantized-mesh",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "quantized-mesh",
            "--encoding",
            "terrarium",
            "-o",
            o,
        ],
        "terrain-rgb",
    );
    refused(
        &[
            "export",
            f,
            "--tiles",
            "terrain-rgb",
            "--base-url",
            "http://x",
            "-o",
            o,
        ],
        "directory",
    );
    // A terrain with no georeference has no place on a map.
    let plain = dir.path().join("plain.fmrh");
    let png = common::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    common::fmrh_ok(&[
        "build",
        "-q",
        png.to_str().unwrap(),
        "-o",
        plain.to_str().unwrap(),
    ]);
    refused(
        &[
            "export",
            plain.to_str().unwrap(),
            "--tiles",
            "terrain-rgb",
            "-o",
            o,
        ],
        "georeference",
    );
    assert!(!Path::new(o).exists());
    let strays: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(strays.is_empty(), "{strays:?}");
}
