//! Containers and a dataset read from real servers give exactly the local results: nginx
//! serving a directory over HTTP (byte ranges, multi-range answers, ETags), and moto as an
//! S3 server (`s3://` URLs, SigV4-presigned requests, one range a request). For each,
//! `info`, `verify --full`, `extract` and `scene --load` print what they print for the local
//! files, and a scene's request plan stays within four rounds after opening. A container
//! changed on the origin by `fmrh replace` while a reader holds it open is reported as
//! changed underneath, and a fresh open reads the new state.
//!
//! Part of the server suite: `.ci/run` installs nginx and moto and runs it by name
//! (`cargo test --release --test remote_servers`); without them it fails saying what to
//! install.

#![cfg(feature = "remote")]

mod common;

use std::path::Path;
use std::process::{Command, Output};

use common::servers::{Moto, Nginx};
use fmrh::model::{BuildOptions, Model};
use fmrh::store::WriteOptions;
use serde_json::Value;

/// Runs the CLI with `env` set.
fn fmrh_env(args: &[&str], env: &[(&str, String)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fmrh"))
        .args(args)
        .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
        .output()
        .expect("the fmrh binary runs")
}

fn json(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "fmrh failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

/// Drops the fields that name where things are, or that only a local file has.
fn strip(v: &mut Value) {
    match v {
        Value::Object(m) => {
            for k in [
                "file",
                "path",
                "dir",
                "file_bytes",
                "total_bytes",
                "registered",
                "requests",
                "reads",
            ] {
                m.remove(k);
            }
            m.values_mut().for_each(strip);
        }
        Value::Array(a) => a.iter_mut().for_each(strip),
        _ => {}
    }
}

/// The served root: three containers (Puget Sound 1k with its metadata bundled and paged,
/// the SRTM tile S46W066) and the dataset of the two real neighbours N43E006 and N43E007.
fn root() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    let hf = common::views::puget_1k();
    let model = Model::build(hf.clone(), &BuildOptions::default()).expect("model");
    for (name, bundle_limit) in [
        ("ps1k.fmrh", WriteOptions::default().bundle_limit),
        ("ps1k-paged.fmrh", 0),
    ] {
        let options = WriteOptions {
            bundle_limit,
            ..WriteOptions::default()
        };
        fmrh::store::write_file(&model, &hf.metadata, &dir.path().join(name), &options, true)
            .expect("written");
    }
    let out = dir.path().join("S46W066.fmrh");
    let s46 = common::data("srtm1-asmyasnikov/S46W066.hgt.gz");
    let r = common::fmrh(&[
        "build",
        "-q",
        s46.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let a = common::data("srtm3-pyhgtmap/N43E006.hgt.gz");
    let b = common::data("srtm3-pyhgtmap/N43E007.hgt.gz");
    let ds = dir.path().join("ds");
    let r = common::fmrh(&[
        "dataset",
        "build",
        "-q",
        "--seam",
        "first",
        "-o",
        ds.to_str().unwrap(),
        a.to_str().unwrap(),
        b.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    dir
}

/// What each command prints for `local` and `remote` (a container or a dataset) agrees.
fn same_as_local(local: &Path, remote: &str, env: &[(&str, String)], dataset: bool) {
    let local = local.to_str().unwrap();
    let what = format!("{remote} against {local}");
    let mut l = json(&fmrh_env(&["info", "--json", local], env));
    let mut r = json(&fmrh_env(&["info", "--json", remote], env));
    if dataset {
        // Tile sizes are the file system's: unknown remotely without a request each.
        assert!(l["total_bytes"].as_u64().is_some() && r["total_bytes"].is_null());
    }
    strip(&mut l);
    strip(&mut r);
    assert_eq!(l, r, "info: {what}");
    let mut l = json(&fmrh_env(&["verify", "--full", "--json", local], env));
    let mut r = json(&fmrh_env(&["verify", "--full", "--json", remote], env));
    assert_eq!(r["valid"], true, "{what}");
    strip(&mut l);
    strip(&mut r);
    assert_eq!(l, r, "verify --full: {what}");
    let out = tempfile::tempdir().unwrap();
    let (a, b) = (out.path().join("l.f32"), out.path().join("r.f32"));
    for (src, dst) in [(local, &a), (remote, &b)] {
        let r = fmrh_env(
            &[
                "extract",
                src,
                "--window",
                "100,150,700,650",
                "-q",
                "-o",
                dst.to_str().unwrap(),
            ],
            env,
        );
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "extract: {what}"
    );
    let scene = [
        "scene",
        "--json",
        "--load",
        "--eye",
        "20000,60000,6000",
        "--target",
        "60000,20000,500",
        "--tau",
        "1",
    ];
    let l = json(&fmrh_env(&[&scene[..], &[local]].concat(), env));
    let r = json(&fmrh_env(&[&scene[..], &[remote]].concat(), env));
    assert_eq!(l["blocks"], r["blocks"], "scene: {what}");
    assert_eq!(
        l["stats"]["max_screen_error"],
        r["stats"]["max_screen_error"]
    );
    let plan = &r["requests"];
    let rounds = plan["scene"]["rounds"].as_u64().expect("a request plan");
    // A dataset also opens its tiles (one round, two for a paged one) in parallel.
    let limit = if dataset { 6 } else { 4 };
    assert!(rounds <= limit, "{what}: {plan}");
}

#[test]
fn containers_and_a_dataset_served_by_nginx_read_exactly_as_the_local_ones() {
    let root = root();
    let nginx = Nginx::start(root.path());
    for name in ["ps1k.fmrh", "ps1k-paged.fmrh", "S46W066.fmrh"] {
        same_as_local(&root.path().join(name), &nginx.url(name), &[], false);
    }
    same_as_local(&root.path().join("ds"), &nginx.url("ds/"), &[], true);
    // nginx answered multi-range requests: some request asked for several ranges.
    assert!(
        nginx.log().iter().any(|l| l.contains(',')),
        "no multi-range request in the log"
    );
}

#[test]
fn containers_and_a_dataset_in_an_s3_bucket_read_exactly_as_the_local_ones() {
    let root = root();
    let moto = Moto::start();
    moto.create_bucket("terrain");
    for name in ["ps1k.fmrh", "ps1k-paged.fmrh", "S46W066.fmrh"] {
        moto.put("terrain", name, &root.path().join(name));
    }
    for entry in std::fs::read_dir(root.path().join("ds")).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name().into_string().unwrap();
        moto.put("terrain", &format!("ds/{name}"), &entry.path());
    }
    let env = moto.env();
    for name in ["ps1k.fmrh", "ps1k-paged.fmrh", "S46W066.fmrh"] {
        let url = format!("s3://terrain/{name}");
        same_as_local(&root.path().join(name), &url, &env, false);
    }
    same_as_local(&root.path().join("ds"), "s3://terrain/ds/", &env, true);
    // A reader holding an object that is uploaded again sees it changed underneath, never
    // a mix: the S3 server answers If-Match with 412, and the ETag is checked besides.
    for (k, v) in &env {
        // Only this test reads these variables (through the library's S3 client).
        std::env::set_var(k, v);
    }
    let before = fmrh::store::Store::open_url("s3://terrain/ps1k-paged.fmrh").expect("opens");
    moto.put("terrain", "ps1k-paged.fmrh", &root.path().join("ps1k.fmrh"));
    let err = before
        .read_window(before.domain().data_rect())
        .unwrap_err()
        .to_string();
    assert!(err.contains("changed underneath"), "{err}");
    let after = fmrh::store::Store::open_url("s3://terrain/ps1k-paged.fmrh").expect("opens again");
    assert_eq!(
        after.pin(),
        fmrh::store::Store::open(&root.path().join("ps1k.fmrh"))
            .unwrap()
            .pin()
    );
    // A missing key is a clear error, not corruption.
    let r = fmrh_env(&["info", "s3://terrain/nothing.fmrh"], &env);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("404"), "{err}");
}

#[test]
fn a_replace_on_the_origin_is_changed_underneath_for_an_open_reader() {
    let root = root();
    let nginx = Nginx::start(root.path());
    let file = root.path().join("ps1k-paged.fmrh");
    let url = nginx.url("ps1k-paged.fmrh");
    let before = fmrh::store::Store::open_url(&url).expect("opens");
    let old = fmrh::store::Store::open(&file).unwrap().pin();
    // The origin commits a change to the file nginx serves: a 40 x 30 patch.
    let patch = fmrh::Heightfield::from_fn(40, 30, |x, y| 100.0 + (x * y) as f32).unwrap();
    let patch_path = common::tiles::write_f32(root.path(), "patch", &patch, 160.0);
    let r = common::fmrh(&[
        "replace",
        file.to_str().unwrap(),
        "--at",
        "200,300",
        patch_path.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let err = before
        .read_window(before.domain().data_rect())
        .unwrap_err()
        .to_string();
    assert!(err.contains("changed underneath"), "{err}");
    // A fresh open reads the new state, and its samples are the patch's.
    let after = fmrh::store::Store::open_url(&url).expect("opens again");
    assert_ne!(after.pin(), old);
    let window = fmrh::model::SampleRect {
        col0: 200,
        row0: 300,
        col1: 239,
        row1: 329,
    };
    let got = after.read_window(window).unwrap();
    assert!(common::first_difference(got.samples(), patch.samples()).is_none());
}
