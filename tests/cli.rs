//! The `fmrh` command line, run as a user would run it. `build --dry-run --json` on a real DEM
//! prints the documented fields, and they agree with the library. `--thresholds` and
//! `--block-size` are honoured, and `--help` explains each command. Bad input of every kind
//! gets a clear message and a non-zero exit: 2 for unusable input or arguments, 1 for a system
//! error.

mod common;

use common::{data, fmrh, ok_json};

#[test]
fn build_dry_run_json_on_a_real_dem() {
    let input = data("srtm3-srtmpy/N44W072.hgt");
    let report = ok_json(&fmrh(&[
        "build",
        input.to_str().unwrap(),
        "--dry-run",
        "--json",
    ]));
    assert_eq!(report["width"], 1201);
    assert_eq!(report["height"], 1201);
    assert_eq!(report["block_size"], 65);
    assert_eq!(report["levels"], 6);
    assert_eq!(report["format"], "srtm-hgt");
    assert!(report["nodes"].as_u64().unwrap() > 361);
    assert!(report["max_error"].as_f64().unwrap() > 0.0);
    assert!(report["build_time_ms"].as_f64().unwrap() > 0.0);
    let clusters = report["clusters"].as_array().unwrap();
    assert!(clusters.len() > 2);
    assert_eq!(clusters[0]["threshold"], 0.0);
    assert_eq!(
        clusters[0]["nodes"],
        19 * 19,
        "the lossless cluster is the blocks"
    );
    assert_eq!(
        clusters.last().unwrap()["nodes"],
        1,
        "the top cluster is the root"
    );
    assert_eq!(clusters.last().unwrap()["threshold"], report["max_error"]);

    // The same numbers as the library.
    let hf = fmrh::ingest::load(&input, &Default::default()).unwrap();
    let model = fmrh::model::Model::build(hf, &Default::default()).unwrap();
    assert_eq!(report["nodes"], model.tree().nodes().len());
    assert_eq!(report["max_error"].as_f64().unwrap(), model.max_error());
    for (c, m) in clusters.iter().zip(model.clusters()) {
        assert_eq!(c["threshold"].as_f64().unwrap(), m.threshold);
        assert_eq!(c["nodes"], m.nodes.len());
    }
}

#[test]
fn thresholds_and_block_size_are_honoured() {
    let input = data("puget-sound-1k/ps_height_1k.png");
    let out = fmrh(&[
        "build",
        input.to_str().unwrap(),
        "--z-scale",
        "0.1",
        "--dry-run",
        "--json",
        "--block-size",
        "33",
        "--thresholds",
        "100,0,10",
    ]);
    let report = ok_json(&out);
    assert_eq!(report["block_size"], 33);
    let t: Vec<f64> = report["clusters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["threshold"].as_f64().unwrap())
        .collect();
    assert_eq!(t, vec![0.0, 10.0, 100.0]);
    // Decimetres scaled to metres: the same model as the .f32 copy (stored in metres).
    let f32_copy = data("puget-sound-1k/ps_height_1k.json");
    let other = ok_json(&fmrh(&[
        "build",
        f32_copy.to_str().unwrap(),
        "--dry-run",
        "--json",
        "--block-size",
        "33",
        "--thresholds",
        "100,0,10",
    ]));
    assert_eq!(report["max_error"], other["max_error"]);
    assert_eq!(report["nodes"], other["nodes"]);
}

#[test]
fn human_readable_report() {
    let input = data("pysheds-dem/dem.tif");
    let out = fmrh(&["build", input.to_str().unwrap(), "--dry-run"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["grid", "367 x 359", "clusters", "threshold", "max error"] {
        assert!(text.contains(word), "missing {word:?} in:\n{text}");
    }
}

#[test]
fn help_explains_each_command() {
    let out = fmrh(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("build") && text.contains("Exit status"));
    let out = fmrh(&["build", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for flag in [
        "--dry-run",
        "--block-size",
        "--thresholds",
        "--json",
        "--z-scale",
        "--color-encoding",
    ] {
        assert!(text.contains(flag), "build --help lacks {flag}");
    }
}

fn fails_with(args: &[&str], code: i32, needle: &str) {
    let out = fmrh(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{args:?}: stderr {err}");
    assert!(
        err.contains(needle),
        "{args:?}: stderr lacks {needle:?}: {err}"
    );
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
}

#[test]
fn bad_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"\x89PNG\r\n\x1a\nnot really").unwrap();
    let junk = junk.to_str().unwrap();
    let hgt = data("srtm3-srtmpy/N44W072.hgt");
    let hgt = hgt.to_str().unwrap();
    let fuji = data("fuji-terrain-rgb/fuji.png");

    // A missing input is the caller's to fix: exit 2 (issue 40's exit table).
    fails_with(
        &["build", "/nonexistent/dem.hgt", "--dry-run"],
        2,
        "No such file",
    );
    fails_with(&["build", junk, "--dry-run"], 2, "junk.png");
    fails_with(
        &["build", hgt, "--dry-run", "--block-size", "64"],
        2,
        "block size 64",
    );
    fails_with(
        &["build", hgt, "--dry-run", "--thresholds", "-1"],
        2,
        "threshold -1",
    );
    fails_with(&["build", hgt, "--dry-run", "--z-scale", "0"], 2, "z-scale");
    fails_with(&["build", hgt], 2, "--output");
    fails_with(
        &["build", fuji.to_str().unwrap(), "--dry-run"],
        2,
        "--color-encoding",
    );
    fails_with(
        &["build", hgt, "--dry-run", "--thresholds", "abc"],
        2,
        "invalid value",
    );
}
