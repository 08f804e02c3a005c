//! A CRS given as WKT without its EPSG code resolves to the code GDAL gives it: for every
//! code below, GDAL's own ESRI WKT1 (`gdalsrsinfo -o wkt1_esri EPSG:N`, `wkt_esri` before
//! GDAL 3.7; no authority codes
//! at all) and its WKT2 with the root's `ID` taken off (`-o wkt2`) are generated now, and
//! `fmrh::crs::Crs::from_wkt` must find `N` by comparing datum, projection and parameters;
//! a CRS no code has (a made-up Lambert conic on a sphere) must stay unresolved. And the
//! CRS of every GeoTIFF in `../shared/data` is what `gdalsrsinfo -e` says it is.
//!
//! Part of the large-data suite (docs/testing.md): it needs gdal-bin and ../shared.

mod common;

use std::process::Command;

use fmrh::crs::Crs;

/// Geographic CRSs on the common datums, UTM north and south on them, Web and World
/// Mercator, and national grids: transverse Mercator, Lambert conics (1SP and 2SP, metres
/// and US survey feet), Albers, Lambert azimuthal, oblique and polar stereographic.
const CODES: &[u32] = &[
    4326, 4269, 4258, 4283, 7844, 4267, 4230, 4277, 4674, 4612, // geographic
    32611, 32633, 32610, 32755, 32737, 26910, 26711, 25832, 25833, 28355, 7855, 31983, // UTM
    3857, 3395, // Mercator
    27700, 2193, 31467, 3006, 2154, 3035, 3577, 5070, 2927, 2285, 28992, 3031, 3413, // grids
];

/// GDAL's ESRI WKT of `epsg`: `-o wkt1_esri` in GDAL ≥ 3.7, `-o wkt_esri` before.
fn esri_wkt(epsg: &str) -> String {
    for flavour in ["wkt1_esri", "wkt_esri"] {
        let out = Command::new("gdalsrsinfo")
            .args(["-o", flavour, epsg])
            .output()
            .expect("gdalsrsinfo (apt-get install gdal-bin)");
        let text = String::from_utf8_lossy(&out.stdout).trim().to_string();
        if out.status.success() && !text.is_empty() {
            return text;
        }
    }
    panic!("gdalsrsinfo gives no ESRI WKT of {epsg}");
}

fn gdalsrsinfo(args: &[&str]) -> String {
    let out = Command::new("gdalsrsinfo")
        .args(args)
        .output()
        .expect("gdalsrsinfo (apt-get install gdal-bin)");
    assert!(
        out.status.success(),
        "gdalsrsinfo {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

/// WKT2 with the root's trailing `ID["EPSG",n]` (and any `USAGE` blocks) removed.
fn without_root_id(wkt2: &str) -> String {
    let one_line: String = wkt2.lines().map(str::trim).collect::<Vec<_>>().join("");
    let id = one_line.rfind(",ID[").expect("a root ID");
    let mut s = one_line[..id].to_string();
    s.push(']');
    // USAGE[...] blocks name the CRS's area and scope; they are not what it is, but they
    // may hold IDs of their own: drop them too.
    while let Some(at) = s.find(",USAGE[") {
        let mut depth = 0;
        let mut end = at + 1;
        for (i, c) in s[at + 1..].char_indices() {
            match c {
                '[' => depth += 1,
                ']' => {
                    depth -= 1;
                    if depth == 0 {
                        end = at + 1 + i + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        s.replace_range(at..end, "");
    }
    s
}

#[test]
fn wkt_without_codes_resolves_to_the_code_gdal_gives() {
    let mut failed = Vec::new();
    let mut twins = Vec::new();
    for &code in CODES {
        let epsg = format!("EPSG:{code}");
        let esri = esri_wkt(&epsg);
        assert!(!esri.contains("AUTHORITY"), "{esri}");
        let wkt2 = without_root_id(&gdalsrsinfo(&["-o", "wkt2", &epsg]));
        for (flavour, text) in [("ESRI WKT1", &esri), ("WKT2 without its ID", &wkt2)] {
            match Crs::from_wkt(text) {
                Ok(crs) if crs.epsg == Some(code) => {}
                // ESRI WKT cannot say a grid's axis order: the code of the same CRS with
                // easting first is as right (DHDN zone 3: 31467 is northing first, 5677
                // easting first; the PROJ strings, which have no axis order, are equal).
                Ok(Crs {
                    epsg: Some(other), ..
                }) if flavour == "ESRI WKT1"
                    && gdalsrsinfo(&["-o", "proj4", &format!("EPSG:{other}")])
                        == gdalsrsinfo(&["-o", "proj4", &epsg]) =>
                {
                    twins.push(format!("{epsg} as {other}"));
                }
                Ok(crs) => failed.push(format!("{epsg} as {flavour}: {:?}\n  {text}", crs.epsg)),
                Err(e) => failed.push(format!("{epsg} as {flavour}: {e}\n  {text}")),
            }
        }
    }
    assert!(
        failed.is_empty(),
        "{} of {}:\n{}",
        failed.len(),
        2 * CODES.len(),
        failed.join("\n")
    );
    // A CRS no EPSG code has stays unresolved.
    let made_up = r#"PROJCS["made up",GEOGCS["sphere",DATUM["s",SPHEROID["s",6370000,0]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],PARAMETER["standard_parallel_1",33],PARAMETER["standard_parallel_2",45],PARAMETER["latitude_of_origin",39],PARAMETER["central_meridian",-96],PARAMETER["false_easting",0],PARAMETER["false_northing",0],UNIT["metre",1]]"#;
    assert_eq!(Crs::from_wkt(made_up).unwrap().epsg, None);
}

#[test]
fn the_geotiffs_of_the_shared_data_have_the_crs_gdal_gives() {
    let mut checked = 0;
    for rel in [
        "srtm3-pyhgtmap/N43E006.tiff",
        "pysheds-dem/dem.tif",
        "gdal-rs-dem-hills/dem-hills.tiff",
    ] {
        let path = common::data(rel);
        let gdal = gdalsrsinfo(&["-e", "-o", "epsg", path.to_str().unwrap()]);
        let code: Option<u32> = gdal
            .lines()
            .find_map(|l| l.trim().strip_prefix("EPSG:"))
            .and_then(|c| c.trim().parse().ok());
        let hf = fmrh::ingest::load(&path, &fmrh::ingest::IngestOptions::default()).unwrap();
        let ours = hf
            .metadata
            .georeference
            .as_ref()
            .and_then(|g| g.crs.as_deref())
            .and_then(Crs::parse)
            .and_then(|c| c.epsg);
        assert_eq!(ours, code, "{rel}: gdalsrsinfo says {gdal:?}");
        checked += 1;
    }
    assert_eq!(checked, 3);
}
