//! What a terrain's heights are above is recorded when it is built and kept through every
//! path that carries heights (issue 41 point 3, format 6.1, `container.md` §5): an SRTM tile
//! records EGM96, a raw grid unknown, `--vertical-datum` overrides either, and `info` shows
//! it; an extracted GeoTIFF carries it as its vertical CRS and builds back to the same datum;
//! a dataset's tiles share one datum, and a patch or tile above another is refused with
//! nothing written; the terrain server lifts EGM96 heights and refuses, with the reason, to
//! place EGM2008 heights it has no grid for.

mod common;

use std::path::{Path, PathBuf};

use common::serve::Served;
use common::{data, fmrh, ok_json};

fn hgt() -> PathBuf {
    data("srtm3-pyhgtmap/N43E006.hgt.gz")
}

fn build(input: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "build",
        input.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let r = fmrh(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

fn datum_of(path: &Path) -> String {
    let info = ok_json(&fmrh(&["info", "--json", path.to_str().unwrap()]));
    info["vertical_datum"].as_str().unwrap().to_string()
}

fn txn_of(path: &Path) -> u64 {
    ok_json(&fmrh(&["info", "--json", path.to_str().unwrap()]))["txn_id"]
        .as_u64()
        .unwrap()
}

/// Runs `fmrh args`, which must succeed.
fn ok(args: &[&str]) {
    let r = fmrh(args);
    assert!(
        r.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&r.stderr)
    );
}

/// Runs `fmrh args`, which must fail (not exit 0); its standard error.
fn refused(args: &[&str]) -> String {
    let r = fmrh(args);
    assert_ne!(r.status.code(), Some(0), "{args:?}");
    String::from_utf8_lossy(&r.stderr).into_owned()
}

/// `fmrh extract FROM --output TO --format tif EXTRA...`.
fn extract_tif(from: &Path, to: &Path, extra: &[&str]) {
    let mut args = vec![
        "extract",
        from.to_str().unwrap(),
        "--output",
        to.to_str().unwrap(),
        "--format",
        "tif",
    ];
    args.extend_from_slice(extra);
    ok(&args);
}

#[test]
fn build_records_the_datum_and_info_shows_it() {
    let dir = tempfile::tempdir().unwrap();
    let srtm = dir.path().join("srtm.fmrh");
    build(&hgt(), &srtm, &[]);
    assert_eq!(datum_of(&srtm), "egm96");
    let text = fmrh(&["info", srtm.to_str().unwrap()]);
    assert!(
        String::from_utf8_lossy(&text.stdout).contains("above the EGM96 geoid"),
        "{}",
        String::from_utf8_lossy(&text.stdout)
    );
    let version = ok_json(&fmrh(&["info", "--json", srtm.to_str().unwrap()]))["format_version"]
        .as_str()
        .unwrap()
        .to_string();
    // The current version, which records the datum (6.1 and later).
    assert_eq!(
        version,
        format!(
            "{}.{}",
            fmrh::format::FORMAT_MAJOR,
            fmrh::format::FORMAT_MINOR
        )
    );

    let raw = dir.path().join("raw.fmrh");
    build(&data("gdal-rs-dem-hills/dem_hills.f32"), &raw, &[]);
    assert_eq!(datum_of(&raw), "unknown");

    for (flag, want) in [
        ("ellipsoid", "ellipsoid"),
        ("EGM2008", "egm2008"),
        ("wgs84", "ellipsoid"),
        ("unknown", "unknown"),
    ] {
        let out = dir.path().join(format!("srtm-{flag}.fmrh"));
        build(&hgt(), &out, &["--vertical-datum", flag]);
        assert_eq!(datum_of(&out), want, "--vertical-datum {flag}");
    }

    let bad = dir.path().join("bad.fmrh");
    let r = fmrh(&[
        "build",
        hgt().to_str().unwrap(),
        "--output",
        bad.to_str().unwrap(),
        "--vertical-datum",
        "navd88",
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("egm96, egm2008, ellipsoid or unknown"));
    assert!(!bad.exists());
}

/// `extract --format tif` writes VerticalCSTypeGeoKey (EPSG 5773 for EGM96), and building
/// the GeoTIFF reads it back: the datum survives a round trip through a GIS file.
#[test]
fn an_extracted_geotiff_carries_the_datum_back() {
    let dir = tempfile::tempdir().unwrap();
    for (flag, key) in [
        ("egm96", Some(5773u16)),
        ("egm2008", Some(3855)),
        ("ellipsoid", None),
    ] {
        let built = dir.path().join(format!("{flag}.fmrh"));
        build(&hgt(), &built, &["--vertical-datum", flag]);
        let tif = dir.path().join(format!("{flag}.tif"));
        extract_tif(&built, &tif, &[]);
        assert_eq!(vertical_key(&tif), key, "{flag}");
        let back = dir.path().join(format!("{flag}-back.fmrh"));
        build(&tif, &back, &[]);
        // A GeoTIFF with no vertical key is unknown, whatever it was built from.
        let want = if key.is_some() { flag } else { "unknown" };
        assert_eq!(datum_of(&back), want, "{flag}");
    }
}

/// The GeoKeyDirectory's VerticalCSTypeGeoKey (4096), read with the `tiff` crate.
fn vertical_key(tif: &Path) -> Option<u16> {
    let mut dec = tiff::decoder::Decoder::new(std::fs::File::open(tif).unwrap()).unwrap();
    let keys = dec
        .get_tag_u16_vec(tiff::tags::Tag::GeoKeyDirectoryTag)
        .unwrap();
    keys[4..]
        .chunks_exact(4)
        .find(|k| k[0] == 4096)
        .map(|k| k[3])
}

#[test]
fn a_dataset_keeps_one_datum() {
    let dir = tempfile::tempdir().unwrap();
    let (west, east) = (hgt(), data("srtm3-pyhgtmap/N43E007.hgt.gz"));
    let (west, east) = (west.to_str().unwrap(), east.to_str().unwrap());
    let mean = ["--seam", "mean"];
    let dataset_build = |out: &Path, inputs: &[&str]| {
        let mut args = vec!["dataset", "build", "--output", out.to_str().unwrap()];
        args.extend_from_slice(inputs);
        args.extend_from_slice(&mean);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    // Two SRTM tiles: EGM96 both.
    let ds = dir.path().join("ds");
    let args = dataset_build(&ds, &[west, east]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(datum_of(&ds), "egm96");

    // One said to be ellipsoidal: refused, naming both.
    let (single, tif) = (dir.path().join("e.fmrh"), dir.path().join("e.tif"));
    build(Path::new(east), &single, &["--vertical-datum", "ellipsoid"]);
    extract_tif(&single, &tif, &[]);
    let mixed = dir.path().join("mixed");
    let args = dataset_build(&mixed, &[west, tif.to_str().unwrap()]);
    let err = refused(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        err.contains("one vertical datum") && err.contains("egm96"),
        "{err}"
    );
    assert!(!mixed.join("MANIFEST").exists());

    // Adding a tile above another datum to a dataset: refused, the dataset untouched.
    let one = dir.path().join("one");
    let args = dataset_build(&one, &[west]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let before = txn_of(&one);
    let add = [
        "dataset",
        "add",
        one.to_str().unwrap(),
        east,
        "--seam",
        "mean",
    ];
    let err = refused(&[&add[..], &["--vertical-datum", "egm2008"]].concat());
    assert!(err.contains("egm2008") && err.contains("egm96"), "{err}");
    assert_eq!(txn_of(&one), before);
    ok(&add);
    assert_eq!(datum_of(&one), "egm96");
}

/// A patch whose file names another datum is refused before anything is written; a raw
/// patch, which names none, is taken as the terrain's.
#[test]
fn a_patch_above_another_datum_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("t.fmrh");
    build(&hgt(), &target, &[]);
    let other = dir.path().join("o.fmrh");
    build(&hgt(), &other, &["--vertical-datum", "ellipsoid"]);
    let patch = dir.path().join("patch.tif");
    extract_tif(&other, &patch, &["--window", "10,10,19,19"]);
    let before = txn_of(&target);
    let replace = [
        "replace",
        target.to_str().unwrap(),
        patch.to_str().unwrap(),
        "--at",
        "10,10",
    ];
    let err = refused(&[&replace[..], &["--vertical-datum", "egm2008"]].concat());
    assert!(err.contains("egm2008") && err.contains("egm96"), "{err}");
    assert_eq!(txn_of(&target), before);
    // The same GeoTIFF without a vertical key (ellipsoid writes none) is taken as the
    // terrain's: it commits.
    ok(&replace);
    assert!(txn_of(&target) > before);
    assert_eq!(datum_of(&target), "egm96");
}

/// The server places what it can: the recorded EGM96 is lifted (layer.json says so), and
/// EGM2008, which it has no grid for, gets no terrain route but a reason, until
/// `--vertical-datum` says how to place it.
#[test]
fn the_server_follows_the_recorded_datum() {
    let dir = tempfile::tempdir().unwrap();
    let srtm = dir.path().join("srtm.fmrh");
    build(&hgt(), &srtm, &[]);
    let g08 = dir.path().join("g08.fmrh");
    build(&hgt(), &g08, &["--vertical-datum", "egm2008"]);
    let served = Served::start(&[&srtm, &g08]);
    let layer = served.get("/srtm.fmrh/layer.json");
    assert_eq!(layer.status, 200);
    let json: serde_json::Value = serde_json::from_slice(&layer.body).unwrap();
    assert_eq!(json["fmrh"]["vertical_datum"], "egm96");
    let refused = served.get("/g08.fmrh/layer.json");
    assert!((400..500).contains(&refused.status), "{}", refused.status);
    let why = String::from_utf8_lossy(&refused.body);
    assert!(why.contains("EGM2008"), "{why}");
    let tile = served.get("/g08.fmrh/0/0/0.terrain");
    assert!((400..500).contains(&tile.status), "{}", tile.status);
    drop(served);

    let told = Served::start_with(&[&g08], &["--vertical-datum", "egm96"]);
    let layer = told.get("/g08.fmrh/layer.json");
    assert_eq!(layer.status, 200);
    let json: serde_json::Value = serde_json::from_slice(&layer.body).unwrap();
    assert_eq!(json["fmrh"]["vertical_datum"], "egm96");
}

/// On the globe, EGM96 terrain is placed N higher (tests/gltf.rs checks every vertex), and
/// EGM2008 terrain, which fmrh has no grid to place, is refused with the reason, nothing
/// written: for a scene and for a glTF alike.
#[test]
fn globe_outputs_refuse_a_datum_they_cannot_place() {
    let dir = tempfile::tempdir().unwrap();
    let g08 = dir.path().join("g08.fmrh");
    build(&hgt(), &g08, &["--vertical-datum", "egm2008"]);
    let glb = dir.path().join("out.glb");
    for args in [
        vec![
            "scene",
            g08.to_str().unwrap(),
            "--eye-geo",
            "43.3,6.4,30000",
            "--tau",
            "1",
        ],
        vec![
            "mesh",
            g08.to_str().unwrap(),
            "--eye-geo",
            "43.3,6.4,30000",
            "--tau",
            "1",
            "-o",
            glb.to_str().unwrap(),
        ],
    ] {
        let r = fmrh(&args);
        assert_eq!(r.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains("EGM2008"), "{err}");
    }
    assert!(!glb.exists());
    // The same file recorded as EGM96 is placed.
    let g96 = dir.path().join("g96.fmrh");
    build(&hgt(), &g96, &[]);
    let r = fmrh(&[
        "scene",
        g96.to_str().unwrap(),
        "--eye-geo",
        "43.3,6.4,30000",
        "--tau",
        "1",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}
