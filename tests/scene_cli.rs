//! The `scene` and `fly` commands as a user runs them: JSON with the promised fields, a
//! `--reconstruct` output (.f32 + sidecar recording the window) that is within the uniform
//! threshold of the source at every sample, the same blocks through the mapping and through
//! positioned reads, a replayed path with one report per camera, and a clear error with
//! exit status 2 for every bad camera, tolerance, window or path line (1 for a missing file).

mod common;

use std::sync::OnceLock;

use common::{fmrh, ok_json};

fn container() -> &'static std::path::Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    let dir = DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("ps1k.fmrh");
        let src = common::data("puget-sound-1k/ps_height_1k.f32");
        let o = fmrh(&[
            "build",
            src.to_str().unwrap(),
            "--spacing",
            "160",
            "-q",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        dir
    });
    Box::leak(dir.path().join("ps1k.fmrh").into_boxed_path())
}

const EYE: &str = "20000,180000,6000";
const TARGET: &str = "80000,80000,500";

/// `fmrh scene FILE` from the standard camera at tau 1, then `extra`.
fn standard_view<'a>(file: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "scene", file, "--eye", EYE, "--target", TARGET, "--tau", "1",
    ];
    args.extend_from_slice(extra);
    args
}

#[test]
fn scene_json_has_the_promised_fields() {
    let file = container().to_str().unwrap();
    let view = ok_json(&fmrh(&standard_view(file, &["--json"])));
    assert!(view["threshold"].is_null());
    let blocks = view["blocks"].as_array().unwrap();
    assert!(!blocks.is_empty());
    for b in blocks {
        for k in [
            "level",
            "col0",
            "row0",
            "col1",
            "row1",
            "error",
            "screen_error",
            "neighbours",
        ] {
            assert!(!b[k].is_null() || k == "neighbours", "{k} missing in {b}");
        }
        assert!(b["screen_error"].as_f64().unwrap() <= 1.0);
    }
    let stats = &view["stats"];
    assert_eq!(stats["blocks"].as_u64().unwrap(), blocks.len() as u64);
    assert_eq!(
        stats["triangles"].as_u64().unwrap(),
        blocks.len() as u64 * 2 * 64 * 64
    );
    for k in [
        "samples",
        "bytes",
        "index_pages",
        "ranges",
        "schedule_ns",
        "max_error",
        "max_screen_error",
    ] {
        assert!(stats[k].is_number(), "{k}");
    }
    let mapped = ok_json(&fmrh(&standard_view(file, &["--json", "--mmap"])));
    assert_eq!(mapped["blocks"], view["blocks"]);
    let uniform = ok_json(&fmrh(&[
        "scene", file, "--eye", EYE, "--target", TARGET, "--tau", "4", "--mode", "uniform",
        "--json",
    ]));
    let t = uniform["threshold"].as_f64().unwrap();
    for b in uniform["blocks"].as_array().unwrap() {
        assert!(b["error"].as_f64().unwrap() <= t);
    }
}

#[test]
fn reconstruction_is_within_the_threshold_of_the_source() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rec.f32");
    let file = container().to_str().unwrap();
    let report = ok_json(&fmrh(&[
        "scene",
        file,
        "--eye",
        "80000,80000,30000",
        "--target",
        "90000,90000,0",
        "--tau",
        "8",
        "--mode",
        "uniform",
        "--window",
        "100,200,700,650",
        "--reconstruct",
        out.to_str().unwrap(),
        "--json",
    ]));
    let threshold = report["threshold"].as_f64().unwrap();
    assert!(threshold > 0.0, "the case should exercise a lossy cluster");
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("rec.json")).unwrap()).unwrap();
    assert_eq!(sidecar["window"], serde_json::json!([100, 200, 700, 650]));
    assert_eq!(
        (sidecar["width"].as_u64(), sidecar["height"].as_u64()),
        (Some(601), Some(451))
    );
    let rec: Vec<f32> = std::fs::read(&out)
        .unwrap()
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let src: Vec<f32> = std::fs::read(common::data("puget-sound-1k/ps_height_1k.f32"))
        .unwrap()
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let mut worst = 0f64;
    for row in 200..=650usize {
        for col in 100..=700usize {
            let r = rec[(row - 200) * 601 + (col - 100)];
            let s = src[row * 1025 + col];
            worst = worst.max((f64::from(r) - f64::from(s)).abs());
        }
    }
    // The file holds binary32: allow the rounding of one value of this size (half an ulp).
    assert!(
        worst <= threshold + 4096f64 * f64::from(f32::EPSILON) / 2.0,
        "{worst} > {threshold}"
    );
    assert!(worst > 0.0);
    // The output is protected like extract's.
    let out = out.to_str().unwrap();
    let again = fmrh(&standard_view(
        file,
        &["--window", "0,0,10,10", "--reconstruct", out],
    ));
    assert_eq!(again.status.code(), Some(2));
}

#[test]
fn fly_reports_every_frame() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/paths/puget-1k-orbit.csv"
    );
    let file = container().to_str().unwrap();
    let r = ok_json(&fmrh(&[
        "fly", file, "--path", path, "--tau", "1", "--json", "--mmap",
    ]));
    let frames = r["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 720);
    assert!(frames[0]["loaded"].as_u64().unwrap() > 0);
    assert!(r["later_load_fraction"].as_f64().unwrap() < 0.25);
    let text = fmrh(&["fly", file, "--path", path, "--tau", "2"]);
    assert!(String::from_utf8_lossy(&text.stdout).contains("Table 2"));
}

#[test]
fn bad_input_is_a_clear_error() {
    let file = container().to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "scene", file, "--eye", "nan,0,0", "--target", TARGET, "--tau", "1",
            ],
            "--eye",
        ),
        (
            vec!["scene", file, "--eye", EYE, "--target", "1,2", "--tau", "1"],
            "--target",
        ),
        (
            vec!["scene", file, "--eye", EYE, "--target", EYE, "--tau", "1"],
            "differ",
        ),
        (
            vec![
                "scene", file, "--eye", EYE, "--target", TARGET, "--tau", "-1",
            ],
            "tolerance",
        ),
        (standard_view(file, &["--fov", "180"]), "field of view"),
        (standard_view(file, &["--viewport", "10x"]), "viewport"),
        (
            standard_view(file, &["--window", "0,0,2000,5"]),
            "not inside",
        ),
        (standard_view(file, &["--up", "0,0,0"]), "up vector"),
    ];
    for (all, needle) in cases {
        let o = fmrh(&all);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{all:?}: {err}");
        assert!(err.contains(needle), "{all:?}: {err}");
    }
    let bad = dir.path().join("bad.csv");
    std::fs::write(
        &bad,
        "eye_x,eye_y,eye_z,target_x,target_y,target_z\n1,2,3,4,5,6\n1,2,3\n",
    )
    .unwrap();
    let o = fmrh(&["fly", file, "--path", bad.to_str().unwrap(), "--tau", "1"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("line 3"));
    let o = fmrh(&[
        "fly",
        file,
        "--path",
        dir.path().join("none.csv").to_str().unwrap(),
        "--tau",
        "1",
    ]);
    // A missing path file is an unusable input, exit 2 (issue 40's exit table).
    assert_eq!(o.status.code(), Some(2));
}
