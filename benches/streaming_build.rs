//! Peak memory against input size when a raster larger than the memory budget is built
//! (issue 39, point 2): Puget Sound 4k (`../shared/data`, or `FMRH_BENCH_DEM=PATH.f32` with
//! its sidecar) upsampled by GDAL (bilinear) to sides of 4,096 to 32,768 samples (1.07 G
//! samples, 4.3 GB of `f32`), each written as one tiled, deflate-compressed BigTIFF. Each is
//! built by `fmrh dataset build --max-memory M` (256 MiB unless `FMRH_BENCH_MEMORY` says,
//! e.g. `1G`), which reads the raster in windows that fit the budget; the smaller ones are
//! also built whole by `fmrh build` (no budget) beside it. Prints, per size: samples, input
//! bytes, tiles, peak RSS (the process's `VmHWM`, which `--json` reports), time, and output
//! bytes.
//!
//! `FMRH_BENCH_SIDES=4096,8192` chooses the sides; `FMRH_BENCH_DIR` keeps the generated
//! GeoTIFFs between runs (default: `target/bench-streaming`; they take about 2 GB at
//! 32,768²). Needs `gdal_translate` (gdal-bin): GDAL makes the inputs, fmrh never links it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Sides built whole beside the windowed build (a whole build of the larger ones needs
/// 6 bytes a sample: 6.4 GB at 32,768²).
const WHOLE_UP_TO: u64 = 16_384;

fn fmrh() -> &'static str {
    env!("CARGO_BIN_EXE_fmrh")
}

/// The `.f32` source and its side.
fn source() -> (PathBuf, u64) {
    let path = std::env::var_os("FMRH_BENCH_DEM").map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../shared/data/puget-sound-4k-jpg/ps_height_4k_jpg.f32")
        },
        PathBuf::from,
    );
    let sidecar: serde_json::Value = serde_json::from_slice(
        &std::fs::read(path.with_extension("json"))
            .unwrap_or_else(|e| panic!("{}: {e}", path.with_extension("json").display())),
    )
    .expect("sidecar");
    let (w, h) = (
        sidecar["width"].as_u64().expect("width"),
        sidecar["height"].as_u64().expect("height"),
    );
    (path, w.min(h))
}

/// The tiled deflate BigTIFF of the source upsampled to `side²`, made once.
fn input(dir: &Path, src: &Path, src_side: u64, side: u64) -> PathBuf {
    let out = dir.join(format!("up-{side}.tif"));
    if out.exists() {
        return out;
    }
    let vrt = dir.join("source.vrt");
    std::fs::write(
        &vrt,
        format!(
            "<VRTDataset rasterXSize=\"{src_side}\" rasterYSize=\"{src_side}\">\
             <VRTRasterBand dataType=\"Float32\" band=\"1\" subClass=\"VRTRawRasterBand\">\
             <SourceFilename relativetoVRT=\"0\">{}</SourceFilename><ImageOffset>0</ImageOffset>\
             <PixelOffset>4</PixelOffset><LineOffset>{}</LineOffset><ByteOrder>LSB</ByteOrder>\
             </VRTRasterBand></VRTDataset>",
            src.display(),
            src_side * 4
        ),
    )
    .unwrap();
    let tmp = dir.join(format!("up-{side}.tif.part"));
    let size = side.to_string();
    // 40 m at 4,096 samples, finer as the side grows; UTM 10N so the tiles are placed.
    let step = 40.0 * src_side as f64 / side as f64;
    let (x0, y0) = (500_000.0, 5_300_000.0);
    let ullr = [
        x0.to_string(),
        y0.to_string(),
        (x0 + step * side as f64).to_string(),
        (y0 - step * side as f64).to_string(),
    ];
    let status = Command::new("gdal_translate")
        .args([
            "-q", "-of", "GTiff", "-r", "bilinear", "-outsize", &size, &size,
        ])
        .args(["-a_srs", "EPSG:32610", "-a_ullr"])
        .args(&ullr)
        .args([
            "-co",
            "TILED=YES",
            "-co",
            "COMPRESS=DEFLATE",
            "-co",
            "BIGTIFF=YES",
        ])
        .arg(&vrt)
        .arg(&tmp)
        .status()
        .expect("gdal_translate (gdal-bin) is needed to make the inputs");
    assert!(status.success(), "gdal_translate failed");
    std::fs::rename(&tmp, &out).unwrap();
    out
}

/// Runs `fmrh ARGS --json`; returns its report and wall time.
fn run(args: &[&str]) -> (serde_json::Value, f64) {
    let t0 = std::time::Instant::now();
    let out = Command::new(fmrh())
        .args(args)
        .arg("--json")
        .output()
        .unwrap();
    let secs = t0.elapsed().as_secs_f64();
    assert!(
        out.status.success(),
        "fmrh {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (serde_json::from_slice(&out.stdout).unwrap(), secs)
}

fn mib(v: &serde_json::Value) -> String {
    v.as_u64().map_or("?".into(), |b| {
        format!("{:.0}", b as f64 / (1 << 20) as f64)
    })
}

fn main() {
    let sides: Vec<u64> = std::env::var("FMRH_BENCH_SIDES")
        .unwrap_or_else(|_| "4096,8192,16384,32768".into())
        .split(',')
        .map(|s| {
            s.trim()
                .parse()
                .expect("FMRH_BENCH_SIDES: sides in samples")
        })
        .collect();
    let memory = std::env::var("FMRH_BENCH_MEMORY").unwrap_or_else(|_| "256M".into());
    let dir = std::env::var_os("FMRH_BENCH_DIR").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("target/bench-streaming"),
        PathBuf::from,
    );
    std::fs::create_dir_all(&dir).unwrap();
    let (src, src_side) = source();
    let out = tempfile::tempdir_in(&dir).unwrap();
    println!("windowed builds with --max-memory {memory}; whole builds with no budget\n");
    println!(
        "| side | samples | input MB | tiles | windowed peak MiB | s | output MB | whole peak MiB | s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for side in sides {
        let tif = input(&dir, &src, src_side, side);
        let input_mb = std::fs::metadata(&tif).unwrap().len() as f64 / 1e6;
        let ds = out.path().join(format!("ds-{side}"));
        let (report, secs) = run(&[
            "dataset",
            "build",
            "-o",
            ds.to_str().unwrap(),
            tif.to_str().unwrap(),
            "--max-memory",
            &memory,
        ]);
        let tiles = report["tiles"].as_array().map_or(0, Vec::len);
        let output_mb = report["total_bytes"].as_u64().unwrap_or(0) as f64 / 1e6;
        std::fs::remove_dir_all(&ds).unwrap();
        let whole = if side <= WHOLE_UP_TO {
            let file = out.path().join(format!("whole-{side}.fmrh"));
            let (r, s) = run(&[
                "build",
                tif.to_str().unwrap(),
                "-o",
                file.to_str().unwrap(),
                "--max-memory",
                "1T",
            ]);
            std::fs::remove_file(&file).unwrap();
            format!("{} | {s:.1}", mib(&r["peak_memory_bytes"]))
        } else {
            "- | -".into()
        };
        println!(
            "| {side} | {} | {input_mb:.0} | {tiles} | {} | {secs:.1} | {output_mb:.1} | {whole} |",
            side * side,
            mib(&report["peak_memory_bytes"]),
        );
    }
}
