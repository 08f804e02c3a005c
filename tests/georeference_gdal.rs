//! fmrh reads every georeferencing fixture as GDAL does, checked against GDAL itself rather
//! than against stored answers: `tests/fixtures/georef/make.sh` makes the fixtures afresh with
//! the installed GDAL and writes what `gdalinfo -json` says of each. fmrh's spacing must be
//! within 0.1 % of what that implies, its georeference must match the geotransform, and its
//! samples must equal GDAL's own decoding (`gdal_translate -of ENVI`) sample for sample, with
//! a south-up file's rows reversed.
//!
//! Part of the large-data suite (docs/testing.md): it needs gdal-bin, which `.ci/run`
//! installs. Without it the test fails and says so.

#[path = "common/georef.rs"]
mod georef;

use std::path::Path;
use std::process::Command;

fn run(cmd: &mut Command) {
    let out = cmd.output().unwrap_or_else(|e| {
        panic!("{cmd:?}: {e} (this test needs gdal-bin: apt-get install gdal-bin)")
    });
    assert!(
        out.status.success(),
        "{cmd:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn fixtures_made_now_read_as_gdal_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let make = georef::committed().join("make.sh");
    run(Command::new("bash").arg(&make).arg(dir.path()));
    let read = georef::check_fixtures(dir.path());
    for (name, hf, want) in &read {
        let raw = dir.path().join(format!("{name}.f32"));
        run(Command::new("gdal_translate")
            .args(["-q", "-of", "ENVI", "-ot", "Float32"])
            .arg(dir.path().join(name))
            .arg(&raw));
        let bytes = std::fs::read(&raw).unwrap();
        let (w, h) = (hf.width() as usize, hf.height() as usize);
        assert_eq!(bytes.len(), w * h * 4, "{name}");
        let gdal: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let nodata = nodata(dir.path(), name);
        let south_up = want["geo_transform"][5].as_f64().unwrap() > 0.0;
        for y in 0..h {
            let gy = if south_up { h - 1 - y } else { y };
            for x in 0..w {
                let g = gdal[gy * w + x];
                let g = if Some(f64::from(g)) == nodata {
                    f32::NAN
                } else {
                    g
                };
                let f = hf.samples()[y * w + x];
                assert!(
                    f.to_bits() == g.to_bits() || (f.is_nan() && g.is_nan()),
                    "{name}: sample ({x}, {y}) is {f} in fmrh, {g} in GDAL"
                );
            }
        }
    }
}

/// The band's nodata value as `gdalinfo -json` reports it.
fn nodata(dir: &Path, name: &str) -> Option<f64> {
    let out = Command::new("gdalinfo")
        .arg("-json")
        .arg(dir.join(name))
        .output()
        .expect("gdalinfo");
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).expect("gdalinfo -json");
    info["bands"][0]["noDataValue"].as_f64()
}

/// A renamed `.hgt` placed with `--tile` gets the spacing GDAL implies for the tile under its
/// own name (GDAL itself cannot place the renamed file).
#[test]
fn a_renamed_hgt_with_its_tile_name_reads_as_gdal_reads_the_original() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let original = root.join("data/srtm1-asmyasnikov/S46W066.hgt.gz");
    let out = Command::new("python3")
        .arg(georef::committed().join("gdal_expected.py"))
        .arg(format!("/vsigzip/{}", original.display()))
        .env("CPL_VSIL_GZIP_WRITE_PROPERTIES", "NO")
        .output()
        .expect("python3 and gdalinfo (apt-get install gdal-bin)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let want = v
        .as_object()
        .and_then(|o| o.values().next())
        .expect("one entry");
    let dir = tempfile::tempdir().unwrap();
    let renamed = dir.path().join("my tile.hgt.gz");
    std::fs::copy(&original, &renamed).unwrap();
    let options = fmrh::ingest::IngestOptions {
        tile: Some("S46W066".into()),
        ..Default::default()
    };
    let hf = fmrh::ingest::load(&renamed, &options).unwrap();
    let got = hf.metadata.spacing_m.expect("spacing");
    for (g, w) in got.iter().zip(want["spacing_m"].as_array().unwrap()) {
        let w = w.as_f64().unwrap();
        assert!(
            (g - w).abs() <= 1e-3 * w,
            "spacing {got:?}, gdalinfo implies {w}"
        );
    }
}

/// `gdalinfo -json` of `path`.
fn gdalinfo(path: &Path) -> serde_json::Value {
    let out = Command::new("gdalinfo")
        .arg("-json")
        .arg(path)
        .output()
        .expect("gdalinfo (apt-get install gdal-bin)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("gdalinfo -json")
}

/// GDAL's decoding of `path` as f32 (`gdal_translate -of ENVI -ot Float32`).
fn gdal_samples(path: &Path, dir: &Path) -> Vec<f32> {
    let raw = dir.join("decoded.f32");
    run(Command::new("gdal_translate")
        .args(["-q", "-of", "ENVI", "-ot", "Float32"])
        .arg(path)
        .arg(&raw));
    std::fs::read(&raw)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// The EPSG code GDAL gives a file's CRS (its STAC summary), if any.
fn gdal_epsg(info: &serde_json::Value) -> Option<u64> {
    info["stac"]["proj:epsg"].as_u64()
}

/// Every GeoTIFF fixture made now by GDAL, built into a container and extracted with
/// `fmrh extract -o X.tif`, is the same raster to GDAL: size, geotransform, CRS and
/// samples (the fixture's integers as f32). fmrh keeps voids, not a source's nodata
/// sentinel: a file without voids says no nodata, and a grid with voids says NaN, which
/// GDAL reads back as nodata at exactly the void samples.
#[test]
fn extracts_as_geotiff_are_what_gdal_says_of_their_sources() {
    let dir = tempfile::tempdir().unwrap();
    run(Command::new("bash")
        .arg(georef::committed().join("make.sh"))
        .arg(dir.path()));
    let fmrh_bin = env!("CARGO_BIN_EXE_fmrh");
    for name in georef::GEOTIFFS {
        let src = dir.path().join(name);
        let container = dir.path().join(format!("{name}.fmrh"));
        let tif = dir.path().join(format!("{name}.out.tif"));
        run(Command::new(fmrh_bin)
            .args(["build", "--block-size", "9", "-o"])
            .arg(&container)
            .arg(&src));
        run(Command::new(fmrh_bin)
            .arg("extract")
            .arg(&container)
            .arg("-o")
            .arg(&tif));
        let (a, b) = (gdalinfo(&src), gdalinfo(&tif));
        assert_eq!(a["size"], b["size"], "{name}: size");
        let (ga, gb) = (
            a["geoTransform"].as_array().unwrap(),
            b["geoTransform"].as_array().unwrap(),
        );
        let south_up = ga[5].as_f64().unwrap() > 0.0;
        let w = a["size"][0].as_u64().unwrap() as usize;
        let h = a["size"][1].as_u64().unwrap() as usize;
        // fmrh turns a south-up grid north-up: the same ground, its last row first.
        let want_gt: Vec<f64> = if south_up {
            let g: Vec<f64> = ga.iter().map(|v| v.as_f64().unwrap()).collect();
            vec![g[0], g[1], g[2], g[3] + g[5] * h as f64, g[4], -g[5]]
        } else {
            ga.iter().map(|v| v.as_f64().unwrap()).collect()
        };
        for (i, (x, y)) in want_gt.iter().zip(gb).enumerate() {
            let y = y.as_f64().unwrap();
            assert!(
                (x - y).abs() <= 1e-9 * x.abs().max(1.0),
                "{name}: geotransform[{i}] {x} against {y}"
            );
        }
        assert_eq!(gdal_epsg(&a), gdal_epsg(&b), "{name}: CRS");
        assert_eq!(
            a["coordinateSystem"].is_null(),
            b["coordinateSystem"].is_null(),
            "{name}"
        );
        assert!(
            b["bands"][0]["noDataValue"].is_null(),
            "{name}: no voids, no nodata"
        );
        assert_eq!(b["bands"][0]["type"], "Float32");
        let (sa, sb) = (
            gdal_samples(&src, dir.path()),
            gdal_samples(&tif, dir.path()),
        );
        for y in 0..h {
            let ya = if south_up { h - 1 - y } else { y };
            for x in 0..w {
                assert_eq!(
                    sa[ya * w + x].to_bits(),
                    sb[y * w + x].to_bits(),
                    "{name}: ({x}, {y})"
                );
            }
        }
    }
    // Voids: a grid with NaN samples, through a container, is NaN nodata to GDAL.
    let (w, h) = (40u32, 30u32);
    let samples: Vec<f32> = (0..w * h)
        .map(|i| {
            if i % 7 == 3 {
                f32::NAN
            } else {
                (i % 97) as f32 * 1.5
            }
        })
        .collect();
    let raw: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.path().join("voids.f32"), raw).unwrap();
    std::fs::write(
        dir.path().join("voids.json"),
        format!(
            r#"{{"width": {w}, "height": {h}, "georeference": {{"crs": "EPSG:32610", "origin": [500010.0, 4100010.0], "step": [20.0, -20.0]}}}}"#
        ),
    )
    .unwrap();
    let container = dir.path().join("voids.fmrh");
    let tif = dir.path().join("voids.tif");
    run(Command::new(fmrh_bin)
        .args(["build", "--block-size", "9", "-o"])
        .arg(&container)
        .arg(dir.path().join("voids.f32")));
    run(Command::new(fmrh_bin)
        .arg("extract")
        .arg(&container)
        .arg("-o")
        .arg(&tif));
    let info = gdalinfo(&tif);
    assert_eq!(info["bands"][0]["noDataValue"], "NaN", "{info}");
    assert_eq!(gdal_epsg(&info), Some(32610));
    let gt: Vec<f64> = info["geoTransform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(gt, vec![500000.0, 20.0, 0.0, 4100020.0, 0.0, -20.0]);
    let got = gdal_samples(&tif, dir.path());
    for (i, (a, b)) in samples.iter().zip(&got).enumerate() {
        assert!(
            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
            "sample {i}: {a} against {b}"
        );
    }
}
