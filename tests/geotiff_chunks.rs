//! GeoTIFFs are decoded one strip or tile at a time into the grid of heights (issue 39,
//! point 2), so the property checked here is that the chunked decode is exact: a real DEM
//! (with voids) turned by GDAL into tiled and striped files whose tiles and strips do not
//! divide the image (partial tiles at the right and bottom edges, a short last strip), in
//! every sample type fmrh reads and with and without compression, loads back sample for
//! sample; and a file whose tiles cannot cover its declared size is refused as bad input
//! rather than read short.
//!
//! Part of the large-data suite's tools: it needs gdal-bin, which `.ci/run` installs.
//! Without it the test fails and says so.

mod common;
#[path = "common/tiff.rs"]
mod tiff;

use std::process::Command;

use common::data;
use fmrh::ingest::{load, IngestOptions};
use tiff::Value;

fn gdal_translate(args: &[&str]) {
    let out = Command::new("gdal_translate")
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("gdal_translate: {e} (this test needs gdal-bin)"));
    assert!(
        out.status.success(),
        "gdal_translate {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn tiled_and_striped_geotiffs_of_every_type_read_back_exactly() {
    let dem = load(
        &data("gdal-rs-dem-hills/dem-hills.tiff"),
        &IngestOptions::default(),
    )
    .unwrap();
    assert!(dem.void_count() > 0, "the fixture should carry voids");
    // Integer heights so that every sample type holds them exactly; voids stay voids through
    // GDAL_NODATA.
    let rounded: Vec<f32> = dem
        .samples()
        .iter()
        .map(|v| if v.is_nan() { *v } else { v.round() })
        .collect();
    let (w, h) = (dem.width(), dem.height());
    let nodata = -9999.0f32;
    let raw: Vec<u8> = rounded
        .iter()
        .flat_map(|v| if v.is_nan() { nodata } else { *v }.to_le_bytes())
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("source.tif");
    std::fs::write(
        &source,
        tiff::tiff(
            vec![
                (256, Value::Long(vec![w])),
                (257, Value::Long(vec![h])),
                (258, Value::Short(vec![32])),
                (259, Value::Short(vec![1])),
                (262, Value::Short(vec![1])),
                (277, Value::Short(vec![1])),
                (278, Value::Long(vec![h])),
                (339, Value::Short(vec![3])),
                (42113, Value::Ascii(format!("{nodata}"))),
            ],
            &[raw],
        ),
    )
    .unwrap();
    assert_eq!(
        common::first_difference(
            load(&source, &IngestOptions::default()).unwrap().samples(),
            &rounded
        ),
        None
    );
    // Tiles of 48 x 32 and strips of 7 rows divide none of the fixture's sides.
    assert!(w % 48 != 0 && h % 32 != 0 && h % 7 != 0, "{w} x {h}");
    let layouts: [&[&str]; 3] = [
        &[
            "-co",
            "TILED=YES",
            "-co",
            "BLOCKXSIZE=48",
            "-co",
            "BLOCKYSIZE=32",
        ],
        &["-co", "BLOCKYSIZE=7"],
        &[
            "-co",
            "TILED=YES",
            "-co",
            "BLOCKXSIZE=16",
            "-co",
            "BLOCKYSIZE=16",
        ],
    ];
    for ty in ["Int16", "UInt16", "Int32", "Float32", "Float64"] {
        for (l, layout) in layouts.iter().enumerate() {
            for compress in ["NONE", "DEFLATE"] {
                let out = dir.path().join(format!("{ty}-{l}-{compress}.tif"));
                let compress_opt = format!("COMPRESS={compress}");
                let mut args = vec!["-q", "-ot", ty, "-co", &compress_opt];
                args.extend_from_slice(layout);
                let (src, dst) = (source.to_str().unwrap(), out.to_str().unwrap());
                args.extend_from_slice(&[src, dst]);
                gdal_translate(&args);
                let back = load(&out, &IngestOptions::default())
                    .unwrap_or_else(|e| panic!("{ty}, layout {l}, {compress}: {e}"));
                assert_eq!((back.width(), back.height()), (w, h));
                assert_eq!(
                    common::first_difference(back.samples(), &rounded),
                    None,
                    "{ty}, layout {l}, {compress}"
                );
                assert_eq!(back.void_count(), dem.void_count());
            }
        }
    }
}

#[test]
fn tiles_that_cannot_cover_the_image_are_refused() {
    // A 100 x 100 image in 64 x 64 tiles needs four; the file declares one (whose data is
    // there, so only the count is wrong). The `tiff` crate finds it first ("inconsistent
    // sizes"); `geotiff::read_chunks` checks the count again before it decodes a chunk.
    let tile: Vec<u8> = (0..64 * 64u32)
        .flat_map(|i| (i as f32).to_le_bytes())
        .collect();
    let bytes = tiff::tiff_raw(
        vec![
            (256, Value::Long(vec![100])),
            (257, Value::Long(vec![100])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![1])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (322, Value::Long(vec![64])),
            (323, Value::Long(vec![64])),
            (324, Value::Long(vec![8])),
            (325, Value::Long(vec![tile.len() as u32])),
            (339, Value::Short(vec![3])),
        ],
        &tile,
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("short.tif");
    std::fs::write(&path, bytes).unwrap();
    let err = load(&path, &IngestOptions::default()).unwrap_err();
    assert!(
        matches!(err, fmrh::Error::Input { .. }),
        "not refused as bad input: {err:?}"
    );
}
