//! Horizontal spacing comes out in metres whatever unit the source's CRS uses: a projected
//! GeoTIFF in feet or US survey feet (ProjLinearUnitsGeoKey, or the EPSG code's own unit)
//! gets its pixel size converted, within 0.1 % of what `gdalinfo` implies; metres stay
//! metres; a unit fmrh does not know leaves the spacing unknown instead of guessing. The
//! fixtures GDAL made (`tests/fixtures/georef`, see its `make.sh`) cover feet, US survey
//! feet, UTM, geographic, south-up (flipped to north-up), rotated (refused), no CRS
//! (unknown), `.asc` with a `.prj`, and DTED, each against the spacing `gdalinfo` implies;
//! renamed `.hgt` files are placed by a tile name anywhere in the name or by `--tile`.

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
        // No key: EPSG:2927's own unit, from the EPSG registry (US survey feet).
        (None, Some(100.0 * us_foot)),
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

#[path = "common/georef.rs"]
mod georef;

/// Every fixture GDAL made: spacing within 0.1 % of what `gdalinfo` implied when it was made,
/// and the georeference of the north-west sample.
#[test]
fn gdal_fixtures_read_as_gdalinfo_says() {
    let read = georef::check_fixtures(&georef::committed());
    let get = |name: &str| {
        &read
            .iter()
            .find(|(n, _, _)| n == name)
            .unwrap_or_else(|| panic!("{name} missing"))
            .1
    };
    // The grid's values say where they are: 100 × (row from the top of the source) + column.
    // A north-up file keeps them; the south-up file's first row is the source's top row but
    // lies at the southern edge, so fmrh's row 0 (north) is the source's last row.
    assert_eq!(get("us_feet.tif").get(0, 0), Some(0.0));
    assert_eq!(get("us_feet.tif").get(5, 3), Some(305.0));
    assert_eq!(get("south_up.tif").get(0, 0), Some(300.0));
    assert_eq!(get("south_up.tif").get(5, 3), Some(5.0));
    assert_eq!(get("feet.asc").get(2, 1), Some(102.0));
    // No CRS: the unit of the geotransform is unknown, and so is the spacing.
    assert_eq!(get("no_crs.tif").metadata.spacing_m, None);
    // The DTED tile holds the bundled SRTM3 tile's terrain (Alpes-Maritimes: sea to 2,900 m).
    let dted = get("n43e007.dt0");
    let heights: Vec<f32> = dted
        .samples()
        .iter()
        .copied()
        .filter(|h| !h.is_nan())
        .collect();
    let max = heights.iter().copied().fold(f32::MIN, f32::max);
    assert!((1500.0..3200.0).contains(&max), "highest {max}");
    assert_eq!(
        dted.metadata
            .georeference
            .as_ref()
            .and_then(|g| g.crs.as_deref()),
        Some("EPSG:4326")
    );
}

/// A rotated grid is refused with a message that says so, not read as north-up.
#[test]
fn rotated_grids_are_refused() {
    let err = load(
        &georef::committed().join("rotated.tif"),
        &IngestOptions::default(),
    )
    .expect_err("rotated");
    assert!(
        matches!(err, fmrh::Error::Unsupported { .. }) && err.to_string().contains("rotated"),
        "{err}"
    );
}

/// A DTED file whose record checksum or length is wrong is an input error, never a panic.
#[test]
fn damaged_dted_is_refused() {
    let good = std::fs::read(georef::committed().join("n43e007.dt0")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.dt0");
    let mut flipped = good.clone();
    flipped[3428 + 100] ^= 0x01; // a height byte in the first record
    let mut truncated = good.clone();
    truncated.truncate(good.len() - 10);
    let mut no_sentinel = good.clone();
    no_sentinel[3428] = 0;
    for (what, bytes) in [
        ("flipped bit", flipped),
        ("truncated", truncated),
        ("no sentinel", no_sentinel),
        ("header only", good[..80].to_vec()),
    ] {
        std::fs::write(&path, bytes).unwrap();
        let err = load(&path, &IngestOptions::default()).expect_err(what);
        assert!(matches!(err, fmrh::Error::Input { .. }), "{what}: {err}");
    }
}

/// An `.hgt` is placed by a tile name anywhere in its file name, or by `--tile`; renamed
/// beyond that, it has no georeference and no spacing rather than a wrong one.
#[test]
fn renamed_hgt_tiles() {
    let src = georef::committed().join("../../../data/srtm1-asmyasnikov/S46W066.hgt.gz");
    let original = load(&src, &IngestOptions::default()).unwrap();
    let want = original.metadata.clone();
    assert!(want.spacing_m.is_some());
    let dir = tempfile::tempdir().unwrap();
    let renamed = dir.path().join("my tile.hgt.gz");
    std::fs::copy(&src, &renamed).unwrap();
    let bare = load(&renamed, &IngestOptions::default()).unwrap();
    assert_eq!(bare.metadata.spacing_m, None);
    assert_eq!(bare.metadata.georeference, None);
    let named = IngestOptions {
        tile: Some("S46W066".into()),
        ..IngestOptions::default()
    };
    let placed = load(&renamed, &named).unwrap();
    assert_eq!(placed.metadata.spacing_m, want.spacing_m);
    assert_eq!(placed.metadata.georeference, want.georeference);
    let inside = dir.path().join("srtm_S46W066_copy.hgt.gz");
    std::fs::copy(&src, &inside).unwrap();
    let found = load(&inside, &IngestOptions::default()).unwrap();
    assert_eq!(found.metadata.georeference, want.georeference);
    for bad in ["S46W066x", "X46W066", "N95E000", ""] {
        let opts = IngestOptions {
            tile: Some(bad.into()),
            ..IngestOptions::default()
        };
        assert!(load(&renamed, &opts).is_err(), "{bad:?}");
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// A DTED file with any byte changed, or cut anywhere, loads or fails with an input
    /// error; it never panics.
    #[test]
    fn mutated_dted_never_panics(at in 0usize..40_000, value in proptest::prelude::any::<u8>(), cut in 0usize..40_000) {
        let mut bytes = std::fs::read(georef::committed().join("n43e007.dt0")).unwrap();
        let at = at % bytes.len();
        bytes[at] = value;
        bytes.truncate(cut.max(1));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.dt0");
        std::fs::write(&path, &bytes).unwrap();
        if let Err(e) = load(&path, &IngestOptions::default()) {
            proptest::prop_assert!(matches!(e, fmrh::Error::Input { .. } | fmrh::Error::TooLarge { .. }), "{e}");
        }
    }
}
