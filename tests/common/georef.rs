//! Checks fmrh's reading of the georeferencing fixtures against what GDAL said of them
//! (`tests/fixtures/georef/expected.json`, written by `gdal_expected.py`): the size, the
//! ground spacing in metres within 0.1 %, and the georeference of the north-west sample after
//! fmrh turns the grid north-up.

#![allow(dead_code)]

use std::path::Path;

use fmrh::heightfield::Heightfield;
use fmrh::ingest::{load, IngestOptions};

/// The fixtures that are GeoTIFFs with a north-up or south-up geotransform (not rotated):
/// what `fmrh extract` writes back as GeoTIFFs in the tests.
pub const GEOTIFFS: [&str; 6] = [
    "geographic.tif",
    "utm.tif",
    "us_feet.tif",
    "intl_feet.tif",
    "south_up.tif",
    "no_crs.tif",
];

/// The committed fixtures.
pub fn committed() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/georef")
}

/// Reads every fixture `expected.json` in `dir` names and checks it; returns the fixtures'
/// names with fmrh's heightfields, for further checks.
pub fn check_fixtures(dir: &Path) -> Vec<(String, Heightfield, serde_json::Value)> {
    let text = std::fs::read_to_string(dir.join("expected.json")).expect("expected.json");
    let expected: serde_json::Value = serde_json::from_str(&text).expect("expected.json parses");
    let entries = expected.as_object().expect("an object");
    assert!(entries.len() >= 9, "{} fixtures", entries.len());
    let mut out = Vec::new();
    for (name, want) in entries {
        let hf = load(&dir.join(name), &IngestOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let num = |v: &serde_json::Value| v.as_f64().expect("a number");
        let size: Vec<u64> = want["size"]
            .as_array()
            .expect("size")
            .iter()
            .map(|v| v.as_u64().expect("an integer"))
            .collect();
        assert_eq!(
            [u64::from(hf.width()), u64::from(hf.height())],
            [size[0], size[1]],
            "{name}: size"
        );
        match (&hf.metadata.spacing_m, want["spacing_m"].as_array()) {
            (Some(got), Some(w)) => {
                for (g, w) in got.iter().zip(w.iter().map(num)) {
                    assert!(
                        (g - w).abs() <= 1e-3 * w,
                        "{name}: spacing {got:?} m, gdalinfo implies {w} m"
                    );
                }
            }
            (None, None) => {}
            (got, w) => panic!("{name}: spacing {got:?}, gdalinfo implies {w:?}"),
        }
        // GDAL's geotransform: corner of pixel (0, 0) and steps. fmrh's origin is the centre
        // of its north-west sample, which for a south-up grid (positive y step) is GDAL's
        // last row.
        let gt: Vec<f64> = want["geo_transform"]
            .as_array()
            .expect("geo_transform")
            .iter()
            .map(num)
            .collect();
        let g = hf
            .metadata
            .georeference
            .as_ref()
            .unwrap_or_else(|| panic!("{name}: no georeference"));
        let rows = size[1] as f64;
        let (north, step_y) = if gt[5] < 0.0 {
            (gt[3] + gt[5] / 2.0, gt[5])
        } else {
            (gt[3] + gt[5] * (rows - 0.5), -gt[5])
        };
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0);
        assert!(
            close(g.origin[0], gt[0] + gt[1] / 2.0) && close(g.origin[1], north),
            "{name}: origin {:?}, GDAL's geotransform {gt:?}",
            g.origin
        );
        assert!(
            close(g.step[0], gt[1]) && close(g.step[1], step_y),
            "{name}: step {:?}, GDAL's geotransform {gt:?}",
            g.step
        );
        out.push((name.clone(), hf, want.clone()));
    }
    out
}
