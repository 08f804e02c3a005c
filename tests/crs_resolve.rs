//! A CRS given as WKT without its EPSG code (an ESRI `.prj`, WKT2 without its `ID`) is
//! resolved to the EPSG code whose datum, projection and parameters it has, and one that no
//! code has stays WKT and is said to be so. The WKT below is what GDAL 3.6.2 writes
//! (`gdalsrsinfo --single-line -o wkt_esri EPSG:N`); the large-data suite generates it
//! afresh for 37 codes (`tests/crs_gdal.rs`). Through the CLI: an ESRI ASCII grid with its
//! `.prj` gets EPSG:32611 and longitude/latitude bounds, as GDAL reads it; `build --crs`
//! overrides a CRS and refuses what it cannot use; `info` says what an unresolved WKT is.

mod common;

use fmrh::crs::Crs;

const UTM_11N: &str = r#"PROJCS["WGS_1984_UTM_Zone_11N",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984",SPHEROID["WGS_1984",6378137.0,298.257223563]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],PARAMETER["False_Easting",500000.0],PARAMETER["False_Northing",0.0],PARAMETER["Central_Meridian",-117.0],PARAMETER["Scale_Factor",0.9996],PARAMETER["Latitude_Of_Origin",0.0],UNIT["Meter",1.0]]"#;

/// A Lambert conic on a made-up sphere: no EPSG code has it.
const MADE_UP: &str = r#"PROJCS["made up",GEOGCS["sphere",DATUM["s",SPHEROID["s",6370000,0]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],PARAMETER["standard_parallel_1",33],PARAMETER["standard_parallel_2",45],PARAMETER["latitude_of_origin",39],PARAMETER["central_meridian",-96],PARAMETER["false_easting",0],PARAMETER["false_northing",0],UNIT["metre",1]]"#;

#[test]
fn esri_wkt_resolves_to_its_epsg_code() {
    for (code, wkt) in [
        (32611, UTM_11N),
        (
            4269,
            r#"GEOGCS["GCS_North_American_1983",DATUM["D_North_American_1983",SPHEROID["GRS_1980",6378137.0,298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]]"#,
        ),
        (
            3857,
            r#"PROJCS["WGS_1984_Web_Mercator_Auxiliary_Sphere",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984",SPHEROID["WGS_1984",6378137.0,298.257223563]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Mercator_Auxiliary_Sphere"],PARAMETER["False_Easting",0.0],PARAMETER["False_Northing",0.0],PARAMETER["Central_Meridian",0.0],PARAMETER["Standard_Parallel_1",0.0],PARAMETER["Auxiliary_Sphere_Type",0.0],UNIT["Meter",1.0]]"#,
        ),
        (
            2927,
            r#"PROJCS["NAD_1983_HARN_StatePlane_Washington_South_FIPS_4602_Feet",GEOGCS["GCS_North_American_1983_HARN",DATUM["D_North_American_1983_HARN",SPHEROID["GRS_1980",6378137.0,298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic"],PARAMETER["False_Easting",1640416.667],PARAMETER["False_Northing",0.0],PARAMETER["Central_Meridian",-120.5],PARAMETER["Standard_Parallel_1",47.3333333333333],PARAMETER["Standard_Parallel_2",45.8333333333333],PARAMETER["Latitude_Of_Origin",45.3333333333333],UNIT["US survey foot",0.304800609601219]]"#,
        ),
        (
            3035,
            r#"PROJCS["ETRS_1989_LAEA",GEOGCS["GCS_ETRS_1989",DATUM["D_ETRS_1989",SPHEROID["GRS_1980",6378137.0,298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Lambert_Azimuthal_Equal_Area"],PARAMETER["False_Easting",4321000.0],PARAMETER["False_Northing",3210000.0],PARAMETER["Central_Meridian",10.0],PARAMETER["Latitude_Of_Origin",52.0],UNIT["Meter",1.0]]"#,
        ),
        (
            26910,
            r#"PROJCRS["NAD83 / UTM zone 10N",BASEGEOGCRS["NAD83",DATUM["North American Datum 1983",ELLIPSOID["GRS 1980",6378137,298.257222101,LENGTHUNIT["metre",1]]],PRIMEM["Greenwich",0,ANGLEUNIT["degree",0.0174532925199433]]],CONVERSION["UTM zone 10N",METHOD["Transverse Mercator",ID["EPSG",9807]],PARAMETER["Latitude of natural origin",0,ANGLEUNIT["degree",0.0174532925199433],ID["EPSG",8801]],PARAMETER["Longitude of natural origin",-123,ANGLEUNIT["degree",0.0174532925199433],ID["EPSG",8802]],PARAMETER["Scale factor at natural origin",0.9996,SCALEUNIT["unity",1],ID["EPSG",8805]],PARAMETER["False easting",500000,LENGTHUNIT["metre",1],ID["EPSG",8806]],PARAMETER["False northing",0,LENGTHUNIT["metre",1],ID["EPSG",8807]]],CS[Cartesian,2],AXIS["(E)",east,ORDER[1],LENGTHUNIT["metre",1]],AXIS["(N)",north,ORDER[2],LENGTHUNIT["metre",1]]]"#,
        ),
    ] {
        let crs = Crs::from_wkt(wkt).unwrap();
        assert_eq!(crs.epsg, Some(code), "{wkt}");
        // Resolved means placed: the registry's projection inverts it.
        if code != 4269 {
            assert!(
                crs.to_lon_lat(500_000.0, 5_000_000.0).is_some(),
                "EPSG:{code}"
            );
        }
    }
    // Any parameter changed is another CRS.
    let moved = UTM_11N.replace("-117.0", "-116.5");
    assert_eq!(Crs::from_wkt(&moved).unwrap().epsg, None);
    let other_datum = UTM_11N.replace("D_WGS_1984", "D_North_American_1983");
    assert_ne!(Crs::from_wkt(&other_datum).unwrap().epsg, Some(32611));
    assert_eq!(Crs::from_wkt(MADE_UP).unwrap().epsg, None);
}

#[test]
fn a_user_crs_is_an_epsg_code_wkt_or_a_proj_string() {
    assert_eq!(Crs::from_user("EPSG:32611").unwrap().epsg, Some(32611));
    assert_eq!(Crs::from_user(UTM_11N).unwrap().epsg, Some(32611));
    assert_eq!(
        Crs::from_user("+proj=utm +zone=11 +datum=WGS84 +units=m +no_defs")
            .unwrap()
            .epsg,
        Some(32611)
    );
    assert_eq!(
        Crs::from_user("+units=m +proj=utm +datum=WGS84 +zone=11")
            .unwrap()
            .epsg,
        Some(32611),
        "in any order"
    );
    for bad in [
        "EPSG:99999999",
        "EPSG:x",
        "+proj=utm +zone=61 +datum=WGS84",
        "UTM 11",
        "",
    ] {
        assert!(Crs::from_user(bad).is_err(), "{bad:?}");
    }
}

/// An ESRI ASCII grid, its `.prj` beside it, written into `dir` as `NAME.asc`.
fn ascii_grid(dir: &std::path::Path, name: &str, prj: Option<&str>) -> std::path::PathBuf {
    let mut text = String::from(
        "ncols 40\nnrows 30\nxllcorner 440000\nyllcorner 3750000\ncellsize 30\nNODATA_value -9999\n",
    );
    for y in 0..30 {
        let row: Vec<String> = (0..40).map(|x| format!("{}", 100 + x + y)).collect();
        text.push_str(&row.join(" "));
        text.push('\n');
    }
    let asc = dir.join(format!("{name}.asc"));
    std::fs::write(&asc, text).unwrap();
    if let Some(p) = prj {
        std::fs::write(dir.join(format!("{name}.prj")), p).unwrap();
    }
    asc
}

fn info_json(path: &std::path::Path) -> serde_json::Value {
    let out = common::fmrh(&["info", path.to_str().unwrap(), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn an_ascii_grid_with_an_esri_prj_is_placed_by_its_epsg_code() {
    let dir = tempfile::tempdir().unwrap();
    let asc = ascii_grid(dir.path(), "utm", Some(UTM_11N));
    let file = dir.path().join("utm.fmrh");
    let out = common::fmrh(&["build", asc.to_str().unwrap(), "-o", file.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    let info = info_json(&file);
    let geo = &info["georeference"];
    assert_eq!(geo["crs"], "EPSG:32611", "{info}");
    // 440 km east, 3,750 km north in zone 11: about 117.6° W, 33.9° N.
    let ll = &geo["lon_lat_bounds"];
    assert!((ll[0].as_f64().unwrap() + 117.65).abs() < 0.1, "{ll}");
    assert!((ll[1].as_f64().unwrap() - 33.88).abs() < 0.1, "{ll}");
}

#[test]
fn build_crs_overrides_and_refuses_what_it_cannot_use() {
    let dir = tempfile::tempdir().unwrap();
    // A WKT no code has: kept, with a warning at build and said so by info.
    let asc = ascii_grid(dir.path(), "odd", Some(MADE_UP));
    let odd = dir.path().join("odd.fmrh");
    let out = common::fmrh(&["build", asc.to_str().unwrap(), "-o", odd.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("warning") && said.contains("place on the ground"),
        "{said}"
    );
    let out = common::fmrh(&["info", odd.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("\"made up\"") && text.contains("cannot place"),
        "{text}"
    );
    // --crs over it: the code, and the spacing from the code's unit.
    let fixed = dir.path().join("fixed.fmrh");
    let out = common::fmrh(&[
        "build",
        asc.to_str().unwrap(),
        "--crs",
        "EPSG:26911",
        "-o",
        fixed.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    let info = info_json(&fixed);
    assert_eq!(info["georeference"]["crs"], "EPSG:26911");
    assert_eq!(info["spacing_m"], serde_json::json!([30.0, 30.0]), "{info}");
    // A US-feet state plane: the same steps are 30 ft = 9.144 m.
    let feet = dir.path().join("feet.fmrh");
    let out = common::fmrh(&[
        "build",
        asc.to_str().unwrap(),
        "--crs",
        "EPSG:2927",
        "-o",
        feet.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = info_json(&feet)["spacing_m"][0].as_f64().unwrap();
    assert!((s - 30.0 * 1200.0 / 3937.0).abs() < 1e-9, "{s}");
    // Refused, exit 2, nothing written: an unknown code, text that is no CRS, and a CRS for
    // an input without a georeference.
    let png = common::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    for (input, crs) in [
        (asc.to_str().unwrap(), "EPSG:99999"),
        (asc.to_str().unwrap(), "UTM zone 11"),
        (png.to_str().unwrap(), "EPSG:32611"),
    ] {
        let never = dir.path().join("never.fmrh");
        let out = common::fmrh(&["build", input, "--crs", crs, "-o", never.to_str().unwrap()]);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{crs}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(String::from_utf8_lossy(&out.stderr).contains("--crs"));
        assert!(!never.exists());
    }
}
