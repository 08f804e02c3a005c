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
