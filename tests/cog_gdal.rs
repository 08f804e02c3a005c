//! Every `fmrh extract -o X.tif` of the real DEMs in `../shared/data` is a valid
//! Cloud-Optimized GeoTIFF to GDAL itself, and the same raster as its source: GDAL's own
//! validator (`validate_cloud_optimized_geotiff.py --full-check=yes`, from python3-gdal)
//! passes it, `gdalinfo` reports `LAYOUT=COG` and overviews down to one tile, and
//! `gdalinfo -json` gives the size, geotransform and CRS that the source's `.json` (or GDAL
//! reading the source) gives, with every sample equal to `fmrh extract -o X.f32`'s as GDAL
//! decodes it, in DEFLATE and in ZSTD. A grid with a spacing but no CRS (Puget Sound 4k,
//! 40 m) has its spacing as the geotransform; a CRS that is not an EPSG code reaches GDAL
//! through the `.aux.xml` beside the file.
//!
//! Part of the large-data suite (docs/testing.md): it needs ../shared, gdal-bin and
//! python3-gdal, which `.ci/run` installs. Without them it fails and says so.

mod common;

use std::path::Path;
use std::process::Command;

/// GDAL's COG validator, as Debian's python3-gdal installs it.
const VALIDATOR: &str =
    "/usr/lib/python3/dist-packages/osgeo_utils/samples/validate_cloud_optimized_geotiff.py";

fn run(cmd: &mut Command) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{cmd:?}: {e} (this test needs gdal-bin and python3-gdal)"));
    assert!(
        out.status.success(),
        "{cmd:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fmrh(args: &[&str]) {
    let out = common::fmrh(args);
    assert!(
        out.status.success(),
        "fmrh {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn gdalinfo(path: &Path) -> serde_json::Value {
    // GDAL would leave a `.properties` file beside a gzipped source it reads (in data/).
    serde_json::from_str(&run(Command::new("gdalinfo")
        .env("CPL_VSIL_GZIP_WRITE_PROPERTIES", "NO")
        .arg("-json")
        .arg(path)))
    .expect("gdalinfo -json")
}

/// GDAL's validation of `tif`, and what `gdalinfo` says of its structure.
fn assert_valid_cog(tif: &Path) -> serde_json::Value {
    assert!(
        Path::new(VALIDATOR).exists(),
        "GDAL's COG validator is missing at {VALIDATOR}: apt-get install python3-gdal (.ci/run does)"
    );
    let said = run(Command::new("/usr/bin/python3")
        .arg(VALIDATOR)
        .arg("--full-check=yes")
        .arg(tif));
    assert!(
        said.contains("is a valid cloud optimized GeoTIFF"),
        "{said}"
    );
    let info = gdalinfo(tif);
    assert_eq!(
        info["metadata"]["IMAGE_STRUCTURE"]["LAYOUT"], "COG",
        "{}",
        info["metadata"]
    );
    assert_eq!(info["metadata"]["IMAGE_STRUCTURE"]["PREDICTOR"], "3");
    // Overviews halve down to the first that fits in one tile.
    let band = &info["bands"][0];
    let block = band["block"][0].as_u64().unwrap();
    let mut size = (
        info["size"][0].as_u64().unwrap(),
        info["size"][1].as_u64().unwrap(),
    );
    let overviews = band["overviews"].as_array().cloned().unwrap_or_default();
    for o in &overviews {
        size = (size.0.div_ceil(2), size.1.div_ceil(2));
        assert_eq!(
            (
                o["size"][0].as_u64().unwrap(),
                o["size"][1].as_u64().unwrap()
            ),
            size
        );
    }
    assert!(
        size.0 <= block && size.1 <= block,
        "the last overview is one tile: {size:?}"
    );
    info
}

/// GDAL's decoding of `path` as f32.
fn gdal_samples(path: &Path, dir: &Path) -> Vec<f32> {
    let raw = dir.join("decoded.f32");
    run(Command::new("gdal_translate")
        .args(["-q", "-of", "ENVI", "-ot", "Float32"])
        .arg(path)
        .arg(&raw));
    bytes_f32(&std::fs::read(&raw).unwrap())
}

fn bytes_f32(b: &[u8]) -> Vec<f32> {
    b.chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

#[test]
fn extracts_of_the_real_dems_are_valid_cogs_of_the_same_raster() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Each DEM, the arguments of its build, and whether GDAL reads its georeference (the
    // gzipped tile through /vsigzip/; a JPEG has none).
    for (rel, extra, gdal_reads) in [
        ("srtm3-pyhgtmap/N43E006.hgt", &[][..], true),
        ("srtm1-asmyasnikov/S46W066.hgt.gz", &[][..], true),
        ("mount-st-helens-usgs/SainteHelens.dem", &[][..], true),
        ("pysheds-dem/dem.tif", &[][..], true),
        (
            "puget-sound-4k-jpg/ps_height_4k.jpg",
            &["--spacing", "40", "--z-scale", "0.1"][..],
            false,
        ),
    ] {
        let src = common::data(rel);
        let source_info = gdal_reads.then(|| {
            let p = src.to_str().unwrap();
            gdalinfo(Path::new(&if p.ends_with(".gz") {
                format!("/vsigzip/{p}")
            } else {
                p.to_string()
            }))
        });
        let name = src.file_stem().unwrap().to_string_lossy().replace('.', "_");
        let container = d.join(format!("{name}.fmrh"));
        let mut args = vec![
            "build",
            src.to_str().unwrap(),
            "-o",
            container.to_str().unwrap(),
        ];
        args.extend(extra);
        fmrh(&args);
        let raw = d.join(format!("{name}.f32"));
        fmrh(&[
            "extract",
            container.to_str().unwrap(),
            "-o",
            raw.to_str().unwrap(),
        ]);
        let sidecar: serde_json::Value =
            serde_json::from_slice(&std::fs::read(raw.with_extension("json")).unwrap()).unwrap();
        let samples = bytes_f32(&std::fs::read(&raw).unwrap());
        for compress in ["deflate", "zstd"] {
            let tif = d.join(format!("{name}-{compress}.tif"));
            fmrh(&[
                "extract",
                container.to_str().unwrap(),
                "-o",
                tif.to_str().unwrap(),
                "--compress",
                compress,
            ]);
            let info = assert_valid_cog(&tif);
            assert_eq!(info["size"][0], sidecar["width"], "{rel}");
            assert_eq!(info["size"][1], sidecar["height"], "{rel}");
            let gt: Vec<f64> = info["geoTransform"]
                .as_array()
                .unwrap_or_else(|| panic!("{rel}: no geotransform: {info}"))
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            // The geotransform: the centre of sample (0, 0) is the sidecar's origin.
            let (origin, step) = match sidecar["georeference"].as_object() {
                Some(g) => (
                    [
                        g["origin"][0].as_f64().unwrap(),
                        g["origin"][1].as_f64().unwrap(),
                    ],
                    [
                        g["step"][0].as_f64().unwrap(),
                        g["step"][1].as_f64().unwrap(),
                    ],
                ),
                None => {
                    let s = &sidecar["spacing_m"];
                    let (dx, dy) = (s[0].as_f64().unwrap(), s[1].as_f64().unwrap());
                    ([0.0, 0.0], [dx, -dy])
                }
            };
            let want = [
                origin[0] - step[0] / 2.0,
                step[0],
                0.0,
                origin[1] - step[1] / 2.0,
                0.0,
                step[1],
            ];
            for (i, (a, b)) in want.iter().zip(&gt).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-9 * a.abs().max(1.0),
                    "{rel}: geotransform[{i}] {a} {b}"
                );
            }
            // The CRS: the EPSG code the source has, or none.
            let crs = sidecar["georeference"]["crs"].as_str();
            let epsg = crs.and_then(|c| c.strip_prefix("EPSG:")).map(|c| {
                c.chars()
                    .take_while(char::is_ascii_digit)
                    .collect::<String>()
                    .parse::<u64>()
                    .unwrap()
            });
            assert_eq!(
                info["stac"]["proj:epsg"].as_u64(),
                epsg,
                "{rel}: CRS {crs:?}"
            );
            if crs.is_none() {
                assert!(
                    info["coordinateSystem"]["wkt"]
                        .as_str()
                        .unwrap_or("")
                        .is_empty(),
                    "{rel}"
                );
            }
            let got = gdal_samples(&tif, d);
            assert_eq!(got.len(), samples.len());
            for (i, (a, b)) in samples.iter().zip(&got).enumerate() {
                assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "{rel} {compress}: sample {i}: {a} against GDAL's {b}"
                );
            }
            // And as GDAL reads the source itself: the same size, geotransform and CRS. For
            // the USGS DEM GDAL's frame is the header's quadrangle, fmrh's the profiles'
            // bounding box (the data set's sidecar says 327 x 466 too): GDAL has whole rows
            // more, on the same grid.
            if let Some(a) = &source_info {
                let ga: Vec<f64> = a["geoTransform"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect();
                let extra_rows = a["size"][1].as_i64().unwrap() - info["size"][1].as_i64().unwrap();
                let rows_north = (ga[3] - gt[3]) / gt[5].abs();
                if rel.ends_with(".dem") {
                    assert!(
                        rows_north == rows_north.round()
                            && (0.0..=extra_rows as f64).contains(&rows_north),
                        "{rel}: {rows_north} rows north, {extra_rows} rows more in GDAL's frame"
                    );
                } else {
                    assert_eq!(a["size"], info["size"], "{rel}: size against the source");
                    assert_eq!(rows_north, 0.0, "{rel}");
                }
                assert_eq!(
                    a["size"][0], info["size"][0],
                    "{rel}: columns against the source"
                );
                for i in [0, 1, 2, 4, 5] {
                    let (x, y) = (ga[i], gt[i]);
                    assert!(
                        (x - y).abs() <= 1e-9 * x.abs().max(1.0),
                        "{rel}: geotransform[{i}] {x} from the source, {y} from the extract"
                    );
                }
                if let Some(code) = a["stac"]["proj:epsg"].as_u64() {
                    assert_eq!(info["stac"]["proj:epsg"].as_u64(), Some(code), "{rel}");
                }
            }
            let voids = samples.iter().any(|v| v.is_nan());
            assert_eq!(
                info["bands"][0]["noDataValue"] == "NaN",
                voids,
                "{rel}: nodata"
            );
        }
    }
}

/// A CRS fmrh cannot reduce to an EPSG code reaches GDAL through `X.tif.aux.xml`.
#[test]
fn a_wkt_crs_reaches_gdal_through_the_aux_xml() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (w, h) = (700u32, 600u32);
    let samples: Vec<f32> = (0..w * h).map(|i| (i % 1009) as f32).collect();
    std::fs::write(
        d.join("g.f32"),
        samples
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    // A Lambert conformal conic on a made-up sphere: no EPSG code has it.
    let wkt = r#"PROJCS["made up",GEOGCS["sphere",DATUM["s",SPHEROID["s",6370000,0]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],PARAMETER["standard_parallel_1",33],PARAMETER["standard_parallel_2",45],PARAMETER["latitude_of_origin",39],PARAMETER["central_meridian",-96],PARAMETER["false_easting",0],PARAMETER["false_northing",0],UNIT["metre",1]]"#;
    let json = serde_json::json!({
        "width": w, "height": h,
        "georeference": {"crs": wkt, "origin": [10_015.0, 20_015.0], "step": [30.0, -30.0]}
    });
    std::fs::write(d.join("g.json"), json.to_string()).unwrap();
    let container = d.join("g.fmrh");
    fmrh(&[
        "build",
        d.join("g.f32").to_str().unwrap(),
        "-o",
        container.to_str().unwrap(),
    ]);
    let tif = d.join("g.tif");
    fmrh(&[
        "extract",
        container.to_str().unwrap(),
        "-o",
        tif.to_str().unwrap(),
    ]);
    assert!(d.join("g.tif.aux.xml").exists());
    let info = assert_valid_cog(&tif);
    let got = info["coordinateSystem"]["wkt"].as_str().unwrap_or("");
    assert!(got.contains("made up") && got.contains("Lambert"), "{got}");
    assert_eq!(
        info["geoTransform"],
        serde_json::json!([10_000.0, 30.0, 0.0, 20_030.0, 0.0, -30.0])
    );
}
