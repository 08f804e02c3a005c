//! Horizontal spacing comes out in metres whatever unit the source's CRS uses: a projected
//! GeoTIFF in feet or US survey feet (ProjLinearUnitsGeoKey) gets its pixel size converted,
//! within 0.1 % of what `gdalinfo` implies; metres stay metres; a unit fmrh does not know
//! leaves the spacing unknown instead of guessing.

#[path = "common/tiff.rs"]
mod tiff;

use fmrh::ingest::{load, IngestOptions};
use tiff::Value;

/// A 4 × 3 float32 projected GeoTIFF with 100-unit pixels in EPSG:2927 (Washington South,
/// US survey feet), with ProjLinearUnitsGeoKey `unit` when given.
fn projected(unit: Option<u16>) -> Vec<u8> {
    let samples: Vec<u8> = (0..12).flat_map(|i| (i as f32).to_le_bytes()).collect();
    let mut keys = vec![1, 1, 0, 0, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 2927];
    if let Some(u) = unit {
        keys.extend([3076, 0, 1, u]);
    }
    keys[3] = (keys.len() / 4 - 1) as u16;
    tiff::tiff(
        vec![
            (256, Value::Long(vec![4])),
            (257, Value::Long(vec![3])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![1])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (278, Value::Long(vec![3])),
            (339, Value::Short(vec![3])),
            (33550, Value::Double(vec![100.0, 100.0, 0.0])),
            (
                33922,
                Value::Double(vec![0.0, 0.0, 0.0, 1_000_000.0, 500_000.0, 0.0]),
            ),
            (34735, Value::Short(keys)),
        ],
        &[samples],
    )
}

#[test]
fn projected_spacing_is_converted_from_the_crs_unit() {
    let dir = tempfile::tempdir().unwrap();
    let us_foot = 1200.0 / 3937.0;
    for (unit, want) in [
        (Some(9003), Some(100.0 * us_foot)),
        (Some(9002), Some(30.48)),
        (Some(9001), Some(100.0)),
        (None, Some(100.0)),
        (Some(9999), None),
    ] {
        let path = dir.path().join("p.tif");
        std::fs::write(&path, projected(unit)).unwrap();
        let hf = load(&path, &IngestOptions::default()).unwrap();
        assert_eq!(hf.samples()[5], 5.0);
        match (hf.metadata.spacing_m, want) {
            (Some([dx, dy]), Some(w)) => {
                for v in [dx, dy] {
                    assert!(
                        (v - w).abs() <= 1e-3 * w,
                        "unit {unit:?}: {v} m, expected {w}"
                    );
                }
            }
            (None, None) => {}
            (got, _) => panic!("unit {unit:?}: spacing {got:?}, expected {want:?}"),
        }
        let geo = hf.metadata.georeference.expect("georeferenced");
        assert_eq!(geo.crs.as_deref(), Some("EPSG:2927"));
        // Pixel-is-area: the centre of sample (0, 0) is half a pixel in, in CRS units.
        assert_eq!(geo.origin, [1_000_050.0, 499_950.0]);
    }
}
