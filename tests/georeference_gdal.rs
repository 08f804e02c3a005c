//! fmrh reads every georeferencing fixture as GDAL does, checked against GDAL itself rather
//! than against stored answers: `tests/fixtures/georef/make.sh` makes the fixtures afresh with
//! the installed GDAL and writes what `gdalinfo -json` says of each. fmrh's spacing must be
//! within 0.1 % of what that implies, its georeference must match the geotransform, and its
//! samples must equal GDAL's own decoding (`gdal_translate -of ENVI`) sample for sample, with
//! a south-up file's rows reversed.
//!
//! Part of the large-data suite (README, Testing): it needs gdal-bin, which `.ci/run`
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
