//! Terrain-RGB pyramids: `fmrh export --tiles terrain-rgb` against rio-rgbify (PyPI, GDAL's
//! bilinear warp under rasterio), on the same rasters, in one run: wall time, bytes and the
//! height error of every pixel against the source. Not a test: it prints a table
//! (docs/terrain-server.md keeps a run's).
//!
//! The DEMs: the bundled SRTM tile N43E006 (3", 1201², EPSG:4326) and Puget Sound 4k
//! (`../shared/data/puget-sound-4k-jpg`, 4096², 40 m; it has no georeference, so it is
//! placed here near where the Puget Sound DEM lies, north-west corner at 123.5° W, 48.3° N,
//! in EPSG:4326 with steps of 40 m at 47.5° N: 0.000533° east, 0.000359° south. Not in UTM:
//! rio-rgbify 1.x asks GDAL for a projected raster's geographic bounds with no densified
//! points, which GDAL 3.4 and later refuse, so it cannot tile a projected input at all).
//! Each is one float32 GeoTIFF both
//! tools read: fmrh builds its container from it (timed apart, then exports), rio-rgbify
//! tiles it directly. Both write 512-pixel Mapbox terrain-RGB PNGs (rio-rgbify's only
//! size), zooms 0 to fmrh's deepest (the first whose pixels are as fine as the samples),
//! with two workers (the machine's cores).
//!
//! Errors (`benches/py/tile_error.py`): every pixel on the data against the source at its
//! centre, interpolated bilinearly; and, free of any interpolation scheme, how far a pixel
//! lies outside the range of its cell's four samples.
//!
//! Needs `rio` (pip install rio-rgbify) and `python3` with rasterio and Pillow (rio-rgbify's
//! dependencies). Run: `cargo bench --bench terrain_rgb_export`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const FMRH: &str = env!("CARGO_BIN_EXE_fmrh");

fn run(cmd: &mut Command) -> f64 {
    let started = Instant::now();
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    started.elapsed().as_secs_f64()
}

fn bytes_under(p: &Path) -> u64 {
    if p.is_dir() {
        std::fs::read_dir(p)
            .unwrap()
            .flatten()
            .map(|e| bytes_under(&e.path()))
            .sum()
    } else {
        std::fs::metadata(p).map_or(0, |m| m.len())
    }
}

fn errors(source: &Path, tiles: &str) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/py/tile_error.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(source)
        .arg("mapbox")
        .arg(tiles)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

struct Dem {
    name: &'static str,
    tif: PathBuf,
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    // The GeoTIFFs both tools read.
    let n43 = dir.join("n43e006.tif");
    let n43_fmrh = dir.join("n43-from-hgt.fmrh");
    let hgt = root.join("data/srtm3-pyhgtmap/N43E006.hgt.gz");
    run(Command::new(FMRH)
        .args(["build", "-q"])
        .arg(&hgt)
        .arg("-o")
        .arg(&n43_fmrh));
    run(Command::new(FMRH)
        .args(["extract", "-q"])
        .arg(&n43_fmrh)
        .arg("-o")
        .arg(&n43));
    let puget = dir.join("puget4k.tif");
    let f32 = root.join("../shared/data/puget-sound-4k-jpg/ps_height_4k_jpg.f32");
    assert!(
        f32.exists(),
        "{} is missing (../shared/data)",
        f32.display()
    );
    run(Command::new("python3")
        .arg(root.join("benches/py/georeference.py"))
        .arg(&f32)
        .args([
            "4096", "4096", "4326", "-123.5", "48.3", "0.000533", "0.000359",
        ])
        .arg(&puget));
    let dems = [
        Dem {
            name: "SRTM N43E006 (3\", 1201²)",
            tif: n43,
        },
        Dem {
            name: "Puget Sound 4k (40 m, 4096²)",
            tif: puget,
        },
    ];
    println!("| DEM | tool | zooms | tiles | time (s) | bytes | max \\|Δ\\| vs bilinear, per zoom (m) | max outside its cell's samples, per zoom (m) |");
    println!("|---|---|---|---|---|---|---|---|");
    for dem in &dems {
        let container = dir.join("dem.fmrh");
        let build = run(Command::new(FMRH)
            .args(["build", "-q", "--force"])
            .arg(&dem.tif)
            .arg("-o")
            .arg(&container));
        let tj = Command::new(FMRH)
            .args([
                "export",
                "-q",
                "--tiles",
                "terrain-rgb",
                "--size",
                "512",
                "--zoom",
                "0",
            ])
            .arg(&container)
            .arg("-o")
            .arg(dir.join("probe"))
            .output()
            .unwrap();
        assert!(
            tj.status.success(),
            "{}",
            String::from_utf8_lossy(&tj.stderr)
        );
        let probe: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("probe/tilejson.json")).unwrap())
                .unwrap();
        std::fs::remove_dir_all(dir.join("probe")).unwrap();
        let maxzoom = probe["maxzoom"].as_u64().unwrap();
        // Twice each, alternating, to see the noise; the table gives the faster run.
        let (mut fmrh_dir, mut fmrh_pm, mut rio) = (f64::MAX, f64::MAX, f64::MAX);
        let out_dir = dir.join("fmrh-tiles");
        let out_pm = dir.join("fmrh.pmtiles");
        let out_rio = dir.join("rio.mbtiles");
        let export = |out: &Path| {
            run(Command::new(FMRH)
                .args([
                    "export",
                    "-q",
                    "--force",
                    "--tiles",
                    "terrain-rgb",
                    "--size",
                    "512",
                ])
                .arg(&container)
                .arg("-o")
                .arg(out))
        };
        for _ in 0..2 {
            fmrh_dir = fmrh_dir.min(export(&out_dir));
            fmrh_pm = fmrh_pm.min(export(&out_pm));
            let _ = std::fs::remove_file(&out_rio);
            rio = rio.min(run(Command::new("rio")
                .args(["rgbify", "-b", "-10000", "-i", "0.1", "--min-z", "0"])
                .args([
                    "--max-z",
                    &maxzoom.to_string(),
                    "-j",
                    "2",
                    "--format",
                    "png",
                ])
                .arg(&dem.tif)
                .arg(&out_rio)));
        }
        let fmrh_err = errors(&dem.tif, &format!("dir:{}", out_dir.display()));
        let rio_err = errors(&dem.tif, &format!("mbtiles:{}", out_rio.display()));
        let per_zoom = |e: &serde_json::Value, key: &str| {
            let mut zs: Vec<(u64, f64)> = e
                .as_object()
                .unwrap()
                .iter()
                .map(|(z, v)| (z.parse().unwrap(), v[key].as_f64().unwrap()))
                .collect();
            zs.sort_by_key(|&(z, _)| z);
            zs.iter()
                .map(|(z, v)| format!("{z}:{v:.1}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let tiles = |e: &serde_json::Value| -> u64 {
            e.as_object()
                .unwrap()
                .values()
                .map(|v| v["tiles"].as_u64().unwrap())
                .sum()
        };
        println!(
            "| {} | fmrh export (directory) | 0–{maxzoom} | {} | {fmrh_dir:.2} (+ build {build:.2}) | {} | {} | {} |",
            dem.name,
            tiles(&fmrh_err),
            bytes_under(&out_dir),
            per_zoom(&fmrh_err, "max"),
            per_zoom(&fmrh_err, "outside_max")
        );
        println!(
            "| | fmrh export (PMTiles) | 0–{maxzoom} | {} | {fmrh_pm:.2} | {} | same tiles | |",
            tiles(&fmrh_err),
            bytes_under(&out_pm)
        );
        println!(
            "| | rio rgbify (MBTiles) | 0–{maxzoom} | {} | {rio:.2} | {} | {} | {} |",
            tiles(&rio_err),
            bytes_under(&out_rio),
            per_zoom(&rio_err, "max"),
            per_zoom(&rio_err, "outside_max")
        );
    }
}
