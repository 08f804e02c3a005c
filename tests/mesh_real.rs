//! The meshes `fmrh mesh` writes from every DEM of `../shared/data`, and from a dataset of
//! the two neighbouring SRTM3 tiles, are valid glTF 2.0 to the Khronos glTF validator (npm
//! `gltf-validator`, installed by `.ci/run` into `tests/js`): no error and no warning, both
//! stitched and with skirts. Each mesh is of an oblique view over the whole DEM, so blocks of
//! several levels meet; one more, of the bundled Puget Sound 1k seen from close above, is
//! refined past the data by fractal nodes. Large-data suite: it needs `../shared/data`, Node.js and the
//! validator, and fails (never skips) without them.

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
    // A dataset of the two neighbouring SRTM3 tiles, placed by their names (they disagree
    // on their shared meridian: the first keeps its samples).
    let tiles = common::data_dir().join("srtm3-pyhgtmap");
    let ds = dir.path().join("ds");
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
    let out = dir.path().join("dataset.glb");
    let json = serde_json::json!({
        "width": 2401, "height": 1201, "spacing_m": [67.291, 92.767], "min": -16.0, "max": 2060.0
    });
    let mut args = vec!["mesh".into(), ds.display().to_string()];
    args.extend(view(&json));
    args.extend(["-o".into(), out.display().to_string()]);
    stitched.push(("N43E006+N43E007".into(), fmrh_ok(&args)));
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
