//! MapLibre GL JS in a real browser over fmrh's terrain-RGB: headless Chromium (SwiftShader,
//! driven by playwright-core from `tests/js/maplibre-terrain.mjs`) draws a map whose
//! `raster-dem` source is the bundled SRTM tile N43E006 as terrain and hillshade, once from
//! `fmrh serve`'s TileJSON and once from the PMTiles archive `fmrh export` writes (read
//! through the `pmtiles` protocol, over HTTP range requests). Checked, for each:
//!
//! * the map loads with no page error, console error, failed request or 4xx/5xx, and the
//!   screenshot shows relief;
//! * `map.queryTerrainElevation` at 120 points of the view is, within 1 cm, the bilinear
//!   interpolation of fmrh's own zoom-11 pixels around the point (MapLibre places a DEM
//!   pixel at its centre), read here from the exported tiles: the browser reads what fmrh
//!   wrote;
//! * and each is within the tile pixel's declared error of fmrh's samples: its tile's bound
//!   (0 at the deepest zoom, whose tiles are cut from the exact blocks) plus half the
//!   encoding's step, plus what bilinear interpolation between the four pixel
//!   centres itself departs from the source's surface at the point (computed here from the
//!   samples), so the check is exact and fails if any pixel around a point is wrong;
//! * the archive and the server give the same heights.
//!
//! Browser suite, run by name (`.ci/run` installs Chromium and `tests/js`):
//! `cargo test --release --test maplibre_terrain`; `FMRH_MAPLIBRE_SCREENSHOT=PATH` keeps the
//! archive's screenshot (docs/maplibre-n43e006.png is one).

mod common;

use std::collections::HashMap;
use std::path::Path;

use common::mercator::{decode, n43e006_at, rgba, world};
use common::serve::Served;

const CENTRE: [f64; 2] = [6.5, 43.5];

/// Runs `tests/js/maplibre-terrain.mjs` on `source`: its JSON report.
fn map(source: &str, points: &[[f64; 2]], shot: &Path, scratch: &Path) -> serde_json::Value {
    let file = scratch.join("points.json");
    std::fs::write(&file, serde_json::to_vec(points).unwrap()).unwrap();
    let report = common::node_script(
        "maplibre-terrain.mjs",
        &["maplibre-gl", "pmtiles", "playwright-core"],
        &[
            source,
            "mapbox",
            "256",
            file.to_str().unwrap(),
            &format!("{},{}", CENTRE[0], CENTRE[1]),
            shot.to_str().unwrap(),
        ],
    );
    assert_eq!(
        report["problems"],
        serde_json::json!([]),
        "{source}: {report}"
    );
    report
}

/// The screenshot shows relief: many colours, few pixels of one colour.
fn assert_relief(shot: &Path) {
    let bytes = std::fs::read(shot).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(&bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let mut counts: HashMap<[u8; 3], usize> = HashMap::new();
    let mut total = 0;
    for px in buf[..info.buffer_size()].chunks(channels) {
        *counts.entry([px[0], px[1], px[2]]).or_default() += 1;
        total += 1;
    }
    let commonest = counts.values().max().copied().unwrap_or(0);
    assert!(
        counts.len() > 2000 && commonest * 4 < total,
        "{}: {} colours, the commonest {commonest} of {total} pixels",
        shot.display(),
        counts.len()
    );
}

#[test]
fn maplibre_reads_served_and_archived_terrain_within_its_declared_error() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::bundled_dir().join("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = common::pyramids::n43e006(dir.path());
    let tiles_dir = dir.path().join("rgb");
    let archive = dir.path().join("n6.pmtiles");
    common::pyramids::export(&file, &["--tiles", "terrain-rgb"], &[&tiles_dir, &archive]);
    let samples = common::load_dem(&dem);
    let samples = samples.samples();

    // 120 points spread over the middle of the view (zoom 14 around the centre, pitch 0).
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let points: Vec<[f64; 2]> = (0..120)
        .map(|_| {
            [
                CENTRE[0] + (next() - 0.5) * 0.03,
                CENTRE[1] + (next() - 0.5) * 0.014,
            ]
        })
        .collect();

    let served = Served::start(&[&file]);
    let url = format!("http://{}/n6.fmrh/terrain-rgb.json", served.address);
    let shot_served = dir.path().join("served.png");
    let from_server = map(&url, &points, &shot_served, dir.path());
    let shot = std::env::var_os("FMRH_MAPLIBRE_SCREENSHOT")
        .map_or_else(|| dir.path().join("archive.png"), Into::into);
    let from_archive = map(archive.to_str().unwrap(), &points, &shot, dir.path());
    assert_relief(&shot_served);
    assert_relief(&shot);
    let fetched = from_server["fetched"].as_array().unwrap();
    assert!(
        fetched.iter().any(|t| t[0] == 11),
        "the view at zoom 14 reads the deepest tiles, zoom 11: {fetched:?}"
    );

    // fmrh's zoom-11 pixels, from the exported tiles.
    const Z: u32 = 11;
    let mut tiles: HashMap<(u32, u32), (Vec<u8>, u32, png::ColorType)> = HashMap::new();
    let mut pixel = |i: i64, j: i64| -> (f64, f64) {
        let (tx, ty) = ((i / 256) as u32, (j / 256) as u32);
        let (px, size, _) = tiles.entry((tx, ty)).or_insert_with(|| {
            rgba(&std::fs::read(tiles_dir.join(format!("{Z}/{tx}/{ty}.png"))).unwrap())
        });
        assert_eq!(*size, 256);
        let k = (((j % 256) * 256 + (i % 256)) * 4) as usize;
        let h = decode("mapbox", &px[k..k + 4]).unwrap();
        // The tile's bound: 0, the deepest zoom's tiles hold the data itself (elsewhere,
        // the smallest pixel on the ground).
        (h, 0.0)
    };
    let (mut worst_pixels, mut worst_source, mut worst_margin) = (0.0f64, 0.0f64, 0.0f64);
    for (k, &[lon, lat]) in points.iter().enumerate() {
        let ml = from_server["heights"][k]
            .as_f64()
            .unwrap_or_else(|| panic!("no height at {lon}, {lat}"));
        let ml_archive = from_archive["heights"][k].as_f64().unwrap();
        assert!(
            (ml - ml_archive).abs() < 1e-9,
            "{lon}, {lat}: {ml} served, {ml_archive} archived"
        );
        // MapLibre's DEM pixel `i` is centred at `(i + 0.5) / 256` of its tile.
        let [wx, wy] = world(Z, lon, lat);
        let (gx, gy) = (wx * 256.0 - 0.5, wy * 256.0 - 0.5);
        let (i0, j0) = (gx.floor() as i64, gy.floor() as i64);
        let (fx, fy) = (gx - i0 as f64, gy - j0 as f64);
        let mut ours = 0.0;
        let mut from_source = 0.0;
        let mut bound = 0.0f64;
        for (di, dj, w) in [
            (0, 0, (1.0 - fx) * (1.0 - fy)),
            (1, 0, fx * (1.0 - fy)),
            (0, 1, (1.0 - fx) * fy),
            (1, 1, fx * fy),
        ] {
            let (i, j) = (i0 + di, j0 + dj);
            let (h, b) = pixel(i, j);
            ours += w * h;
            bound = bound.max(b);
            let n = 256.0 * f64::from(1u32 << Z);
            let [clon, clat] =
                common::mercator::lon_lat(0, 0, 0, (i as f64 + 0.5) / n, (j as f64 + 0.5) / n);
            from_source += w * n43e006_at(samples, clon, clat).unwrap();
        }
        let source = n43e006_at(samples, lon, lat).unwrap();
        assert!(
            (ml - ours).abs() <= 0.01,
            "{lon}, {lat}: MapLibre reads {ml} m where fmrh's pixels give {ours} m"
        );
        let interpolation = (from_source - source).abs();
        let allowed = bound + 0.05 + interpolation + 0.01;
        let off = (ml - source).abs();
        assert!(
            off <= allowed,
            "{lon}, {lat}: MapLibre's {ml} m is {off} m from the source's {source} m; \
             allowed {allowed} m (bound {bound}, interpolation {interpolation})"
        );
        worst_pixels = worst_pixels.max((ml - ours).abs());
        worst_source = worst_source.max(off);
        worst_margin = worst_margin.max(off / allowed);
    }
    eprintln!(
        "120 points: |MapLibre - fmrh's pixels| <= {worst_pixels:.4} m; |MapLibre - source| <= \
         {worst_source:.2} m, at most {:.0} % of what the declared error allows",
        worst_margin * 100.0
    );
}
