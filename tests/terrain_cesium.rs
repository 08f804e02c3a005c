//! CesiumJS itself (`@cesium/engine` on Node.js, `tests/js/cesium-sample.mjs`) reads the
//! terrain `fmrh serve` cuts live: `CesiumTerrainProvider.fromUrl` opens the served layer
//! with normals and metadata, and `sampleTerrainMostDetailed` at 240 random valid samples of
//! each source gives heights from the deepest level there (the layer's `maxzoom`), each
//! within that tile's declared (measured) error of the source sample lifted onto the
//! ellipsoid by the EGM96 geoid (SRTM heights are above the geoid; Cesium's, above the
//! ellipsoid: `h = H + N`, `layer.json` saying so). Run on the SRTM tiles
//! N43E006 (3") and S46W066 (1"), and on the N43E006 + N43E007 dataset. Large-data suite
//! (needs `../shared` and `npm ci --prefix tests/js`).

mod common;

use std::path::{Path, PathBuf};

use common::quantized_mesh::Source;
use common::serve::Served;

#[test]
fn cesium_reads_the_served_terrain_within_its_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = common::data_dir();
    let mut cases: Vec<(PathBuf, Source)> = Vec::new();
    for rel in [
        "srtm3-pyhgtmap/N43E006.hgt",
        "srtm1-asmyasnikov/S46W066.hgt.gz",
    ] {
        let dem = common::data(rel);
        let out = dir.path().join(rel.replace(['/', '.'], "_") + ".fmrh");
        common::fmrh_ok(&[
            "build",
            "-q",
            dem.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        cases.push((out, Source::of(&common::load_dem(&dem))));
    }
    let tiles = data.join("srtm3-pyhgtmap");
    let ds = dir.path().join("ds");
    common::fmrh_ok(&[
        "dataset",
        "build",
        "-q",
        "--seam",
        "first",
        tiles.join("N43E006.hgt").to_str().unwrap(),
        tiles.join("N43E007.hgt").to_str().unwrap(),
        "-o",
        ds.to_str().unwrap(),
    ]);
    cases.push((
        ds,
        Source::beside(
            &common::load_dem(&tiles.join("N43E006.hgt")),
            &common::load_dem(&tiles.join("N43E007.hgt")),
        ),
    ));
    let paths: Vec<&Path> = cases.iter().map(|(p, _)| p.as_path()).collect();
    let served = Served::start(&paths);
    for (path, source) in &cases {
        let name = path.file_name().unwrap().to_str().unwrap();
        let layer = served.get(&format!("/{name}/layer.json")).json();
        let maxzoom = layer["maxzoom"].as_u64().unwrap() as u32;
        assert_eq!(layer["fmrh"]["vertical_datum"], "egm96");
        let (points, want) = common::cesium::random_points(source, 240, 0xce51 ^ name.len() as u64);
        let url = format!("{}/{name}/", served.base());
        let (heights, levels) = common::cesium::samples(&url, dir.path(), &points);
        let worst = common::cesium::check_samples(
            &served,
            name,
            maxzoom,
            &points,
            &want,
            (&heights, &levels),
        );
        eprintln!(
            "{name}: maxzoom {maxzoom}, largest |Cesium - source| at 240 samples: {worst:.2} m"
        );
    }
}
