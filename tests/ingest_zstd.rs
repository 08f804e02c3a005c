//! ZSTD-compressed GeoTIFFs (the common Cloud-Optimized GeoTIFF codec, GDAL's COMPRESS=ZSTD,
//! TIFF compression 50000) load exactly: a real DEM written as a tiled-by-strips ZSTD GeoTIFF
//! (float32, its nodata as GDAL_NODATA) reads back sample for sample, voids included, and a
//! ZSTD strip that claims more than its codec could make is refused before allocation.

mod common;
#[path = "common/tiff.rs"]
mod tiff;

use common::data;
use fmrh::ingest::{load, IngestOptions};
use tiff::Value;

/// A float32 GeoTIFF of `w × h` whose rows are cut into strips of `rows_per_strip`, each
/// compressed with ZSTD; NaN samples are written as `nodata`, and GDAL_NODATA says so.
fn zstd_tiff(w: u32, h: u32, samples: &[f32], rows_per_strip: u32, nodata: f32) -> Vec<u8> {
    let strips: Vec<Vec<u8>> = samples
        .chunks((w * rows_per_strip) as usize)
        .map(|rows| {
            let raw: Vec<u8> = rows
                .iter()
                .flat_map(|v| if v.is_nan() { nodata } else { *v }.to_le_bytes())
                .collect();
            zstd::encode_all(&raw[..], 3).unwrap()
        })
        .collect();
    tiff::tiff(
        vec![
            (256, Value::Long(vec![w])),
            (257, Value::Long(vec![h])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![50000])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (278, Value::Long(vec![rows_per_strip])),
            (339, Value::Short(vec![3])),
            (42113, Value::Ascii(format!("{nodata}"))),
        ],
        &strips,
    )
}

#[test]
fn a_zstd_geotiff_of_a_real_dem_reads_back_exactly() {
    let dem = load(
        &data("gdal-rs-dem-hills/dem-hills.tiff"),
        &IngestOptions::default(),
    )
    .unwrap();
    assert!(dem.void_count() > 0, "the fixture should carry voids");
    let dir = tempfile::tempdir().unwrap();
    for rows_per_strip in [1, 16, dem.height()] {
        let tif = zstd_tiff(
            dem.width(),
            dem.height(),
            dem.samples(),
            rows_per_strip,
            -9999.0,
        );
        let path = dir.path().join(format!("zstd-{rows_per_strip}.tif"));
        std::fs::write(&path, &tif).unwrap();
        let back = load(&path, &IngestOptions::default())
            .unwrap_or_else(|e| panic!("{rows_per_strip} rows a strip: {e}"));
        assert_eq!((back.width(), back.height()), (dem.width(), dem.height()));
        assert_eq!(
            common::first_difference(back.samples(), dem.samples()),
            None,
            "{rows_per_strip} rows a strip"
        );
        assert_eq!(back.void_count(), dem.void_count());
    }
}

#[test]
fn a_zstd_strip_claiming_more_than_it_can_hold_is_refused() {
    // A few hundred bytes of ZSTD cannot make a 60,000² float image (14 GB): the header
    // claims it anyway, one strip of the same bytes.
    let one_row = vec![1.0f32; 60_000];
    let strip = zstd::encode_all(
        &one_row
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>()[..],
        3,
    )
    .unwrap();
    let tif = tiff::tiff(
        vec![
            (256, Value::Long(vec![60_000])),
            (257, Value::Long(vec![60_000])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![50000])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (278, Value::Long(vec![60_000])),
            (339, Value::Short(vec![3])),
        ],
        &[strip],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("claims.tif");
    std::fs::write(&path, &tif).unwrap();
    // The memory budget and the proportion of samples to bytes (issue 39) would refuse it
    // first; lifted, the codec's own ceiling is what this checks.
    let options = IngestOptions {
        limits: fmrh::ingest::IngestLimits::none(),
        ..IngestOptions::default()
    };
    let err = load(&path, &options).unwrap_err();
    assert!(err.to_string().contains("ZSTD"), "{err}");
}
