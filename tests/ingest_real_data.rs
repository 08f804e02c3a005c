//! Every real DEM of `../shared/data` loads from its original format, and that reading equals
//! the normalised `.f32` copy sample for sample: the same bits, and voids (`NaN`) in the same
//! places. Metadata the sidecar records (size, void count, spacing) is checked too.

mod common;

use common::{data, first_difference};
use fmrh::ingest::{load, ColorEncoding, IngestOptions};
use fmrh::Heightfield;

fn f32_pair(rel: &str) -> Heightfield {
    load(&data(rel), &IngestOptions::default()).expect("the .f32 + .json pair loads")
}

fn assert_same(original: &Heightfield, normalised: &Heightfield, what: &str) {
    assert_eq!(
        (original.width(), original.height()),
        (normalised.width(), normalised.height()),
        "{what}: size"
    );
    if let Some((i, a, b)) = first_difference(original.samples(), normalised.samples()) {
        let w = original.width() as usize;
        panic!(
            "{what}: sample at column {}, row {}: original {a}, .f32 {b}",
            i % w,
            i / w
        );
    }
}

fn check(original: &str, normalised: &str, options: IngestOptions) {
    let a = load(&data(original), &options).unwrap_or_else(|e| panic!("{original}: {e}"));
    let b = f32_pair(normalised);
    assert_same(&a, &b, original);
}

fn scaled(z_scale: f64) -> IngestOptions {
    IngestOptions {
        z_scale,
        ..IngestOptions::default()
    }
}

#[test]
fn srtm3_tiles() {
    for name in ["N19W155", "N22W160", "N44W072", "S16E166"] {
        check(
            &format!("srtm3-srtmpy/{name}.hgt"),
            &format!("srtm3-srtmpy/{name}.f32"),
            IngestOptions::default(),
        );
    }
    for name in ["N43E006", "N43E007"] {
        check(
            &format!("srtm3-pyhgtmap/{name}.hgt"),
            &format!("srtm3-pyhgtmap/{name}.json"),
            IngestOptions::default(),
        );
    }
}

#[test]
fn srtm_voids_are_nan_and_counted() {
    let hf = load(&data("srtm3-srtmpy/S16E166.hgt"), &IngestOptions::default()).unwrap();
    assert_eq!(hf.void_count(), 6229);
    let hf = load(&data("srtm3-srtmpy/N22W160.hgt"), &IngestOptions::default()).unwrap();
    assert_eq!(hf.void_count(), 4279);
    let geo = hf
        .metadata
        .georeference
        .expect("georeference from the file name");
    assert_eq!(geo.origin, [-160.0, 23.0]);
    // 3" of arc on the WGS 84 ellipsoid at 22.5° N: 92.281 m north-south, 85.747 m east-west.
    let spacing = hf.metadata.spacing_m.unwrap();
    assert!((spacing[1] - 92.281).abs() < 0.01, "{spacing:?}");
    assert!((spacing[0] - 85.747).abs() < 0.01, "{spacing:?}");
}

#[test]
fn srtm1_gzip_tile() {
    check(
        "srtm1-asmyasnikov/S46W066.hgt.gz",
        "srtm1-asmyasnikov/S46W066.f32",
        IngestOptions::default(),
    );
}

#[test]
fn geotiffs() {
    check(
        "topotoolbox-bigtujunga/bigtujunga.tif",
        "topotoolbox-bigtujunga/bigtujunga.f32",
        IngestOptions::default(),
    );
    check(
        "pysheds-dem/dem.tif",
        "pysheds-dem/pysheds_dem.f32",
        IngestOptions::default(),
    );
    check(
        "gdal-rs-dem-hills/dem-hills.tiff",
        "gdal-rs-dem-hills/dem_hills.f32",
        IngestOptions::default(),
    );
    check(
        "srtm3-pyhgtmap/N43E006.tiff",
        "srtm3-pyhgtmap/N43E006.f32",
        IngestOptions::default(),
    );
}

#[test]
fn geotiff_nodata_and_georeference() {
    let hf = load(
        &data("gdal-rs-dem-hills/dem-hills.tiff"),
        &IngestOptions::default(),
    )
    .unwrap();
    assert_eq!(hf.void_count(), 949);
    let geo = hf.metadata.georeference.unwrap();
    // Pixel-is-area tie point at the corner: the first sample's centre is half a pixel in.
    assert!((geo.origin[0] - (-87.50925926 + 0.5 * 9.259259459457456e-05)).abs() < 1e-12);
    let hf = load(
        &data("topotoolbox-bigtujunga/bigtujunga.tif"),
        &IngestOptions::default(),
    )
    .unwrap();
    assert_eq!(hf.metadata.spacing_m, Some([30.0, 30.0]));
}

#[test]
fn png_16_bit_grey_with_vertical_scale() {
    check(
        "puget-sound-1k/ps_height_1k.png",
        "puget-sound-1k/ps_height_1k.json",
        scaled(0.1),
    );
}

#[test]
fn png_grey_palette() {
    check(
        "puget-sound-east-512/ps-e.lg.png",
        "puget-sound-east-512/ps-e_lg.f32",
        IngestOptions::default(),
    );
}

#[test]
fn png_terrain_rgb() {
    check(
        "fuji-terrain-rgb/fuji.png",
        "fuji-terrain-rgb/fuji.f32",
        IngestOptions {
            color_encoding: Some(ColorEncoding::TerrainRgb),
            ..IngestOptions::default()
        },
    );
}

#[test]
fn usgs_ascii_dem() {
    check(
        "mount-st-helens-usgs/SainteHelens.dem",
        "mount-st-helens-usgs/SainteHelens.f32",
        IngestOptions::default(),
    );
}

#[test]
fn jpeg_with_vertical_scale() {
    check(
        "puget-sound-4k-jpg/ps_height_4k.jpg",
        "puget-sound-4k-jpg/ps_height_4k_jpg.f32",
        scaled(25.6),
    );
}
