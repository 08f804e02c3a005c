//! CesiumJS in a real browser over the terrain `fmrh serve` cuts live: headless Chromium
//! (SwiftShader, driven by playwright-core from `tests/js/cesium-globe.mjs`) loads a page
//! whose `CesiumWidget` takes its terrain from `CesiumTerrainProvider.fromUrl` on the
//! served `layer.json`, for the bundled SRTM tile N43E006 and for the N43E006 + N43E007
//! dataset. Checked: the globe finishes loading with no console error, no failed request and
//! no 4xx/5xx; the screenshot shows relief (not a blank or one-colour canvas); and
//! `sampleTerrainMostDetailed` in the page, at 200 random valid samples of each source,
//! takes every height from the deepest level, equal to what the served tile draws there and
//! within its declared (measured) error of the source sample on the ellipsoid (`h = H + N`,
//! EGM96). Browser suite, run by name (`.ci/run` installs Chromium and `tests/js`):
//! `cargo test --release --test cesium_globe`; `FMRH_CESIUM_SCREENSHOT=PATH` keeps the
//! single tile's screenshot.

mod common;

use std::path::{Path, PathBuf};

use common::quantized_mesh::Source;
use common::serve::Served;

/// Runs `tests/js/cesium-globe.mjs` on the layer at `url`: its JSON report.
fn globe(
    url: &str,
    points: &[[f64; 2]],
    camera: &str,
    shot: &Path,
    scratch: &Path,
) -> serde_json::Value {
    let file = scratch.join("points.json");
    std::fs::write(&file, serde_json::to_vec(points).unwrap()).unwrap();
    common::node_script(
        "cesium-globe.mjs",
        &["@cesium/engine", "esbuild", "playwright-core"],
        &[url, file.to_str().unwrap(), camera, shot.to_str().unwrap()],
    )
}

/// The screenshot shows relief: most pixels are the globe (not Chromium's white or the
/// black of space) and they take many colours (the sun shades the slopes).
fn assert_relief(shot: &Path) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(shot).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let mut colours = std::collections::BTreeSet::new();
    let (mut globe, mut total) = (0usize, 0usize);
    for px in buf[..info.buffer_size()].chunks(channels) {
        let rgb = [px[0], px[1], px[2]];
        total += 1;
        let sum: u32 = rgb.iter().map(|&c| u32::from(c)).sum();
        if sum > 30 && sum < 750 {
            globe += 1;
            colours.insert(rgb);
        }
    }
    assert!(
        globe * 2 > total && colours.len() > 500,
        "{}: {globe} of {total} pixels drawn, {} colours",
        shot.display(),
        colours.len()
    );
}

#[test]
fn cesium_in_chromium_draws_the_served_globe_and_samples_it_within_its_errors() {
    let dir = tempfile::tempdir().unwrap();
    let srtm = common::bundled_dir().join("srtm3-pyhgtmap");
    let (west, east) = (srtm.join("N43E006.hgt.gz"), srtm.join("N43E007.hgt.gz"));
    let tile = dir.path().join("n43e006.fmrh");
    common::fmrh_ok(&[
        "build",
        "-q",
        west.to_str().unwrap(),
        "-o",
        tile.to_str().unwrap(),
    ]);
    let ds = dir.path().join("alps");
    common::fmrh_ok(&[
        "dataset",
        "build",
        "-q",
        "--seam",
        "first",
        west.to_str().unwrap(),
        east.to_str().unwrap(),
        "-o",
        ds.to_str().unwrap(),
    ]);
    let cases: Vec<(PathBuf, Source, &str)> = vec![
        (
            tile,
            Source::of(&common::load_dem(&west)),
            "6.55,43.05,14000,0,-30",
        ),
        (
            ds,
            Source::beside(&common::load_dem(&west), &common::load_dem(&east)),
            "7.0,42.95,26000,0,-25",
        ),
    ];
    let paths: Vec<&Path> = cases.iter().map(|(p, ..)| p.as_path()).collect();
    let served = Served::start(&paths);
    for (k, (path, source, camera)) in cases.iter().enumerate() {
        let name = path.file_name().unwrap().to_str().unwrap();
        let layer = served.get(&format!("/{name}/layer.json")).json();
        let maxzoom = layer["maxzoom"].as_u64().unwrap() as u32;
        let (points, want) = common::cesium::random_points(source, 200, 0x910be ^ k as u64);
        let shot = dir.path().join(format!("{name}.png"));
        let url = format!("{}/{name}/", served.base());
        let report = globe(&url, &points, camera, &shot, dir.path());
        assert_eq!(
            report["problems"],
            serde_json::json!([]),
            "{name}: {report}"
        );
        assert!(
            !report["renderer"].as_str().unwrap_or("").is_empty(),
            "{report}"
        );
        assert!(
            report["drawn"].as_u64().unwrap_or(0) > 0,
            "{name}: {report}"
        );
        assert_eq!(report["hasVertexNormals"], true);
        assert_eq!(report["hasMetadata"], true);
        let heights: Vec<f64> = report["heights"]
            .as_array()
            .unwrap()
            .iter()
            .map(|h| h.as_f64().expect("Cesium gave a height at every point"))
            .collect();
        let levels: Vec<u32> = report["levels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| l.as_u64().unwrap() as u32)
            .collect();
        let worst = common::cesium::check_samples(
            &served,
            name,
            maxzoom,
            &points,
            &want,
            (&heights, &levels),
        );
        eprintln!(
            "{name}: {} tiles drawn by {}; largest |Cesium - source| at 200 samples: {worst:.2} m",
            report["drawn"], report["renderer"]
        );
        assert_relief(&shot);
        if k == 0 {
            if let Ok(keep) = std::env::var("FMRH_CESIUM_SCREENSHOT") {
                std::fs::copy(&shot, keep).unwrap();
            }
        }
    }
}
