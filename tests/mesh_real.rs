//! The meshes `fmrh mesh` writes from every DEM of `../shared/data`, and from a dataset of
//! the two neighbouring SRTM3 tiles, are valid glTF 2.0 to the Khronos glTF validator (npm
//! `gltf-validator`, installed by `.ci/run` into `tests/js`): no error and no warning, both
//! stitched and with skirts. Each mesh is of an oblique view over the whole DEM, so blocks of
//! several levels meet; one more, of the bundled Puget Sound 1k seen from close above, is
//! refined past the data by fractal nodes; two more are of the dataset on the globe
//! (`--eye-geo`, vertices in a local east-north-up frame). And CesiumJS itself (npm `@cesium/engine`) reads
//! the geodetic quantized-mesh tilesets of every georeferenced DEM and of the dataset, within
//! each tile's declared error of the source. Large-data suite: it needs `../shared/data`,
//! Node.js, the validator and CesiumJS, and fails (never skips) without them.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The DEM sidecars of `../shared/data`.
fn shared_dems() -> Vec<PathBuf> {
    let mut out = Vec::new();
    for dir in std::fs::read_dir(common::data_dir()).expect("../shared/data is there") {
        let dir = dir.unwrap().path();
        if !dir.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&dir).unwrap() {
            let f = f.unwrap().path();
            if f.extension().is_some_and(|e| e == "json") {
                out.push(f);
            }
        }
    }
    out.sort();
    out
}

/// `--eye`, `--target` and `--spacing` for an oblique view over a `width × height` grid
/// from beyond its south-west corner.
fn view(json: &serde_json::Value) -> Vec<String> {
    let (w, h) = (
        json["width"].as_f64().unwrap(),
        json["height"].as_f64().unwrap(),
    );
    // Unitless or unknown spacing: 30 m, so that heights and distances are comparable.
    let s = json["spacing_m"].as_array().map_or([30.0, 30.0], |a| {
        [a[0].as_f64().unwrap(), a[1].as_f64().unwrap()]
    });
    let (lo, hi) = (json["min"].as_f64().unwrap(), json["max"].as_f64().unwrap());
    let (x, y) = ((w - 1.0) * s[0], (h - 1.0) * s[1]);
    vec![
        "--eye".into(),
        format!("{},{},{}", -0.25 * x, 1.25 * y, hi + 0.3 * x.max(y)),
        "--target".into(),
        format!("{},{},{}", 0.5 * x, 0.5 * y, lo),
        "--spacing".into(),
        format!("{},{}", s[0], s[1]),
        "--tau".into(),
        "2".into(),
    ]
}

/// Runs `fmrh` and returns its standard error, failing the test when it fails.
fn fmrh_ok(args: &[String]) -> String {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = common::fmrh(&refs);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "fmrh {}: {err}", args.join(" "));
    err
}

/// The validator's report of each file, one JSON object a file.
fn validate(files: &[PathBuf]) -> Vec<serde_json::Value> {
    let js = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/js");
    assert!(
        js.join("node_modules/gltf-validator").is_dir(),
        "the glTF validator is not installed: run `npm ci --prefix tests/js` (.ci/run does)"
    );
    let out = Command::new("node")
        .arg(js.join("validate-gltf.mjs"))
        .args(files)
        .output()
        .expect("node runs (Node.js is needed for the glTF validator)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reports: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(reports.len(), files.len());
    reports
}

/// A dataset of the two neighbouring SRTM3 tiles N43E006 and N43E007 under `dir`, placed
/// by their names (they disagree on their shared meridian: the first keeps its samples).
fn srtm_dataset(dir: &Path) -> PathBuf {
    let tiles = common::data_dir().join("srtm3-pyhgtmap");
    let ds = dir.join("ds");
    fmrh_ok(&[
        "dataset".into(),
        "build".into(),
        "-q".into(),
        "--seam".into(),
        "first".into(),
        tiles.join("N43E006.hgt").display().to_string(),
        tiles.join("N43E007.hgt").display().to_string(),
        "-o".into(),
        ds.display().to_string(),
    ]);
    ds
}

#[test]
fn meshes_of_every_shared_dem_and_a_dataset_are_valid_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    let mut stitched = Vec::new();
    for json_path in shared_dems() {
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&json_path).unwrap()).unwrap();
        let name = json_path
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let container = dir.path().join(format!("{name}.fmrh"));
        fmrh_ok(&[
            "build".into(),
            json_path.display().to_string(),
            "-o".into(),
            container.display().to_string(),
        ]);
        for cracks in ["stitch", "skirts"] {
            let out = dir.path().join(format!("{name}-{cracks}.glb"));
            let mut args = vec!["mesh".into(), container.display().to_string()];
            args.extend(view(&json));
            args.extend([
                "--cracks".into(),
                cracks.into(),
                "-o".into(),
                out.display().to_string(),
            ]);
            let said = fmrh_ok(&args);
            if cracks == "stitch" {
                stitched.push((name.clone(), said));
            }
            files.push(out);
        }
    }
    assert!(files.len() >= 2 * 15, "{} meshes", files.len());
    let ds = srtm_dataset(dir.path());
    let out = dir.path().join("dataset.glb");
    let json = serde_json::json!({
        "width": 2401, "height": 1201, "spacing_m": [67.291, 92.767], "min": -16.0, "max": 2060.0
    });
    let mut args = vec!["mesh".into(), ds.display().to_string()];
    args.extend(view(&json));
    args.extend(["-o".into(), out.display().to_string()]);
    stitched.push(("N43E006+N43E007".into(), fmrh_ok(&args)));
    files.push(out);
    // The same as JSON glTF with its buffer beside it (`-o X.gltf` writes X.bin too).
    let out = dir.path().join("dataset.gltf");
    let mut args = vec!["mesh".into(), ds.display().to_string()];
    args.extend(view(&json));
    args.extend(["-o".into(), out.display().to_string()]);
    fmrh_ok(&args);
    assert!(dir.path().join("dataset.bin").is_file());
    files.push(out);

    // Detail past the data: Puget Sound 1k (bundled) seen from 800 m, refined by fractal
    // nodes and stitched to its stored blocks.
    let ps = dir.path().join("ps1k.fmrh");
    let png = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/puget-sound-1k/ps_height_1k.png");
    fmrh_ok(&[
        "build".into(),
        png.display().to_string(),
        "--z-scale".into(),
        "0.1".into(),
        "--spacing".into(),
        "160".into(),
        "-o".into(),
        ps.display().to_string(),
    ]);
    let out = dir.path().join("ps1k-fractal.glb");
    let said = fmrh_ok(&[
        "mesh".into(),
        ps.display().to_string(),
        "--eye".into(),
        "80000,92000,800".into(),
        "--target".into(),
        "80000,88000,0".into(),
        "--tau".into(),
        "1".into(),
        "--refine".into(),
        "fractal".into(),
        "-o".into(),
        out.display().to_string(),
    ]);
    assert!(!said.contains(" 0 synthetic"), "{said}");
    assert!(said.contains(" synthetic"), "{said}");
    stitched.push(("ps1k fractal".into(), said));
    files.push(out);

    // On the globe: the dataset of the two SRTM3 tiles from 30 km, looking across their
    // border, and from orbit.
    for (name, eye, look) in [
        ("globe-near", "43.4,6.9,30000", "45,-35"),
        ("globe-orbit", "43.5,7.0,5000000", "0,-90"),
    ] {
        let out = dir.path().join(format!("{name}.glb"));
        let said = fmrh_ok(&[
            "mesh".into(),
            ds.display().to_string(),
            "--eye-geo".into(),
            eye.into(),
            "--look".into(),
            look.into(),
            "--tau".into(),
            "1".into(),
            "-o".into(),
            out.display().to_string(),
        ]);
        stitched.push((format!("N43E006+N43E007 {name}"), said));
        files.push(out);
    }

    for (name, said) in &stitched {
        println!("{name}: {}", said.trim());
    }
    // Blocks of different levels met, and were stitched, somewhere.
    assert!(
        stitched
            .iter()
            .filter(|(_, s)| !s.contains("(0 stitched"))
            .count()
            >= 10,
        "{stitched:?}"
    );
    for report in validate(&files) {
        println!("{report}");
        assert_eq!(report["errors"], 0, "{report}");
        assert_eq!(report["warnings"], 0, "{report}");
        assert!(report["triangles"].as_u64().unwrap() > 0);
    }
}

/// Geodetic quantized-mesh tilesets of every georeferenced shared DEM (the SRTM tiles by
/// their HGT names, whose sidecars carry no machine-readable georeference) and of the
/// N43E006 + N43E007 dataset (gzipped), opened by CesiumJS itself: at random valid samples, the
/// height Cesium draws comes from the deepest tile on disk there, equals the reference
/// decoder's reading of that tile (to a millimetre), and is within the tile's declared
/// error of the source sample.
#[test]
fn cesium_reads_the_geodetic_tilesets_within_their_errors() {
    use common::quantized_mesh::{read_tiles, Source};
    let dir = tempfile::tempdir().unwrap();
    let srtm = |rel: &str| common::data_dir().join(rel);
    let load = |p: &Path| {
        fmrh::ingest::load(p, &fmrh::ingest::IngestOptions::default()).expect("the DEM loads")
    };
    // (name, input, source)
    let mut cases: Vec<(String, PathBuf, Source)> = Vec::new();
    for rel in [
        "srtm1-asmyasnikov/S46W066.hgt.gz",
        "srtm3-pyhgtmap/N43E006.hgt",
        "srtm3-pyhgtmap/N43E006.tiff",
        "srtm3-srtmpy/N19W155.hgt",
        "srtm3-srtmpy/N22W160.hgt",
        "srtm3-srtmpy/N44W072.hgt",
        "srtm3-srtmpy/S16E166.hgt",
        "mount-st-helens-usgs/SainteHelens.dem",
    ] {
        let dem = common::data(rel);
        let name = rel.replace(['/', '.'], "_");
        let container = dir.path().join(format!("{name}.fmrh"));
        fmrh_ok(&[
            "build".into(),
            "-q".into(),
            dem.display().to_string(),
            "-o".into(),
            container.display().to_string(),
        ]);
        let field = load(&dem);
        assert!(
            field.metadata.georeference.is_some(),
            "{rel} is georeferenced"
        );
        cases.push((name, container, Source::of(&field)));
    }
    let ds = srtm_dataset(dir.path());
    cases.push((
        "dataset".into(),
        ds,
        Source::beside(
            &load(&srtm("srtm3-pyhgtmap/N43E006.hgt")),
            &load(&srtm("srtm3-pyhgtmap/N43E007.hgt")),
        ),
    ));
    for (name, input, source) in &cases {
        let out = dir.path().join(format!("{name}-tiles"));
        // The oblique view over the whole data from beyond its south-west corner.
        let info: serde_json::Value = {
            let o = common::fmrh(&["info", input.to_str().unwrap(), "--json"]);
            serde_json::from_slice(&o.stdout).unwrap()
        };
        let width = info["width"].as_f64().or(info["columns"].as_f64()).unwrap();
        let height = info["height"].as_f64().or(info["rows"].as_f64()).unwrap();
        let s = &info["spacing_m"];
        let (sx, sy) = (s[0].as_f64().unwrap(), s[1].as_f64().unwrap());
        let (x, y) = ((width - 1.0) * sx, (height - 1.0) * sy);
        // The dataset's tiles gzipped, as Cesium's tiles are served.
        let gzip = if name == "dataset" {
            "--gzip"
        } else {
            "--force"
        };
        let said = fmrh_ok(&[
            "mesh".into(),
            gzip.into(),
            input.display().to_string(),
            "--eye".into(),
            format!("{},{},{}", -0.25 * x, 1.25 * y, 0.3 * x.max(y)),
            "--target".into(),
            format!("{},{},0", 0.5 * x, 0.5 * y),
            "--tau".into(),
            "2".into(),
            "--format".into(),
            "quantized-mesh".into(),
            "-o".into(),
            out.display().to_string(),
        ]);
        eprintln!("{name}: {}", said.trim());
        let tiles = read_tiles(&out);
        // 300 valid samples, drawn evenly at random.
        let mut rng = common::fields::Rng::new(0x5eed ^ name.len() as u64);
        let mut points = Vec::new();
        let mut want = Vec::new();
        while points.len() < 300 {
            let k = (rng.next_u64() % source.samples.len() as u64) as usize;
            if !source.samples[k].is_nan() {
                points.push(source.lon_lat[k]);
                want.push(f64::from(source.samples[k]));
            }
        }
        let (heights, levels) = common::cesium::samples(out.to_str().unwrap(), &out, &points);
        for (i, &[lon, lat]) in points.iter().enumerate() {
            let holding: Vec<&common::quantized_mesh::Tile> = tiles
                .values()
                .filter(|t| {
                    let [w, s, e, n] = t.bounds();
                    lon >= w && lon <= e && lat >= s && lat <= n
                })
                .collect();
            let deepest = holding.iter().map(|t| t.z).max().unwrap();
            assert_eq!(levels[i], deepest, "{name}: Cesium's level at {lon},{lat}");
            let ok = holding.iter().filter(|t| t.z == deepest).any(|t| {
                let ours = t.height_at(lon, lat);
                let error = t.meta()["error"].as_f64().unwrap();
                (heights[i] - ours).abs() <= 1e-3 && (heights[i] - want[i]).abs() <= error + 1e-3
            });
            assert!(
                ok,
                "{name}: at {lon},{lat} Cesium draws {} where the source has {} (level {deepest})",
                heights[i], want[i]
            );
        }
    }
}
