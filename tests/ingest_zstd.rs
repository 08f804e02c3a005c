//! ZSTD-compressed GeoTIFFs (the common Cloud-Optimized GeoTIFF codec, GDAL's COMPRESS=ZSTD,
//! TIFF compression 50000) load exactly: a real DEM written as a tiled-by-strips ZSTD GeoTIFF
//! (float32, its nodata as GDAL_NODATA) reads back sample for sample, voids included, and a
//! ZSTD strip that claims more than its codec could make is refused before allocation.

mod common;

use common::data;
use fmrh::ingest::{load, IngestOptions};

/// A little-endian float32 GeoTIFF of `w × h` whose rows are cut into strips of
/// `rows_per_strip`, each compressed with ZSTD; NaN samples are written as `nodata`, and
/// GDAL_NODATA says so.
fn zstd_tiff(w: u32, h: u32, samples: &[f32], rows_per_strip: u32, nodata: f32) -> Vec<u8> {
    let mut strips = Vec::new();
    for rows in samples.chunks((w * rows_per_strip) as usize) {
        let raw: Vec<u8> = rows
            .iter()
            .flat_map(|v| if v.is_nan() { nodata } else { *v }.to_le_bytes())
            .collect();
        strips.push(zstd::encode_all(&raw[..], 3).unwrap());
    }
    let nodata_text = format!("{nodata}\0");
    // Layout: header, strips, then the arrays the IFD points to, then the IFD.
    let mut t = b"II*\0\0\0\0\0".to_vec();
    let mut offsets = Vec::new();
    for s in &strips {
        offsets.push(t.len() as u32);
        t.extend_from_slice(s);
    }
    let at_offsets = t.len() as u32;
    offsets.iter().for_each(|o| t.extend(o.to_le_bytes()));
    let at_counts = t.len() as u32;
    strips
        .iter()
        .for_each(|s| t.extend((s.len() as u32).to_le_bytes()));
    let at_nodata = t.len() as u32;
    t.extend_from_slice(nodata_text.as_bytes());
    if t.len() % 2 == 1 {
        t.push(0);
    }
    let n = strips.len() as u32;
    // (tag, type, count, value or offset): 3 SHORT, 4 LONG, 2 ASCII.
    let entries: [(u16, u16, u32, u32); 11] = [
        (256, 4, 1, w),
        (257, 4, 1, h),
        (258, 3, 1, 32),
        (259, 3, 1, 50000),
        (262, 3, 1, 1),
        (273, 4, n, if n == 1 { offsets[0] } else { at_offsets }),
        (277, 3, 1, 1),
        (278, 4, 1, rows_per_strip),
        (
            279,
            4,
            n,
            if n == 1 {
                strips[0].len() as u32
            } else {
                at_counts
            },
        ),
        (339, 3, 1, 3),
        (42113, 2, nodata_text.len() as u32, at_nodata),
    ];
    let ifd = t.len() as u32;
    t[4..8].copy_from_slice(&ifd.to_le_bytes());
    t.extend((entries.len() as u16).to_le_bytes());
    for (tag, kind, count, value) in entries {
        t.extend(tag.to_le_bytes());
        t.extend(kind.to_le_bytes());
        t.extend(count.to_le_bytes());
        if kind == 3 && count == 1 {
            t.extend((value as u16).to_le_bytes());
            t.extend([0, 0]);
        } else {
            t.extend(value.to_le_bytes());
        }
    }
    t.extend(0u32.to_le_bytes());
    t
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
    // 100 bytes of ZSTD cannot make a 60,000² float image (14 GB).
    let one_row = vec![1.0f32; 60_000];
    let mut tif = zstd_tiff(60_000, 1, &one_row, 1, -9999.0);
    // Claim 60,000 rows (tag 257, the IFD's second entry) in one strip of the same bytes.
    let ifd = u32::from_le_bytes(tif[4..8].try_into().unwrap()) as usize;
    let height_entry = ifd + 2 + 12;
    assert_eq!(
        u16::from_le_bytes([tif[height_entry], tif[height_entry + 1]]),
        257
    );
    tif[height_entry + 8..height_entry + 12].copy_from_slice(&60_000u32.to_le_bytes());
    let rps_entry = ifd + 2 + 7 * 12;
    tif[rps_entry + 8..rps_entry + 12].copy_from_slice(&60_000u32.to_le_bytes());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("claims.tif");
    std::fs::write(&path, &tif).unwrap();
    let err = load(&path, &IngestOptions::default()).unwrap_err();
    assert!(err.to_string().contains("ZSTD"), "{err}");
}
