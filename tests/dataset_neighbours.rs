//! The real neighbours: SRTM3 tiles N43E006 and N43E007 (bundled in `data/`) share their
//! meridian column, on which they disagree in 202 of 1,201 samples. A strict build refuses
//! them, naming both tiles and the first differing sample; with `--seam first` the dataset
//! builds, verifies in full, extracts across the border to exactly the two sources (the
//! shared column from the first tile), and a scene across the border is one cover of its
//! window, within tau, whose border blocks know the levels across.

mod common;

use std::path::PathBuf;

use common::{fmrh, ok_json};

fn tiles() -> [PathBuf; 2] {
    [
        common::data("srtm3-pyhgtmap/N43E006.hgt.gz"),
        common::data("srtm3-pyhgtmap/N43E007.hgt.gz"),
    ]
}

fn load(p: &std::path::Path) -> fmrh::Heightfield {
    fmrh::ingest::load(p, &Default::default()).unwrap()
}

fn read_f32(p: &std::path::Path) -> Vec<f32> {
    std::fs::read(p)
        .unwrap()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn a_strict_build_of_the_real_neighbours_names_the_first_difference() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let [a, b] = tiles();
    let r = fmrh(&[
        "dataset",
        "build",
        "-q",
        "-o",
        out.to_str().unwrap(),
        a.to_str().unwrap(),
        b.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("N43E006") && err.contains("N43E007"), "{err}");
    assert!(err.contains("dataset column 1200, row 0"), "{err}");
    assert!(err.contains("--seam"), "{err}");
    assert!(!out.exists());
}

#[test]
fn the_real_neighbours_build_extract_and_scene_across_their_border() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let ds = out.to_str().unwrap();
    let [a, b] = tiles();
    let built = ok_json(&fmrh(&[
        "dataset",
        "build",
        "--json",
        "--seam",
        "first",
        "-o",
        ds,
        a.to_str().unwrap(),
        b.to_str().unwrap(),
    ]));
    assert_eq!(built["columns"], 2401);
    assert_eq!(built["rows"], 1201);
    assert_eq!(built["shared_edges"], 1);
    assert_eq!(built["tiles"][1]["seam_samples_changed"], 202);
    let verified = ok_json(&fmrh(&["verify", "--full", "--json", ds]));
    assert_eq!(verified["valid"], true);
    let info = ok_json(&fmrh(&["info", "--json", ds]));
    assert_eq!(info["tile_count"], 2);
    assert_eq!(info["georeference"]["origin"][0], 6.0);
    // A window across the border, as the two sources give it.
    let (fa, fb) = (load(&a), load(&b));
    let f32_out = dir.path().join("w.f32");
    let r = fmrh(&[
        "extract",
        ds,
        "--window",
        "1000,300,1500,700",
        "-o",
        f32_out.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let got = read_f32(&f32_out);
    assert_eq!(got.len(), 501 * 401);
    for row in 300..=700usize {
        for col in 1000..=1500usize {
            let want = if col <= 1200 {
                fa.samples()[row * 1201 + col]
            } else {
                fb.samples()[row * 1201 + col - 1200]
            };
            let v = got[(row - 300) * 501 + col - 1000];
            assert!(
                v.to_bits() == want.to_bits() || v.is_nan() && want.is_nan(),
                "({col}, {row}): {v} vs {want}"
            );
        }
    }
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("w.json")).unwrap()).unwrap();
    assert!(
        (sidecar["georeference"]["origin"][0].as_f64().unwrap() - (6.0 + 1000.0 / 1200.0)).abs()
            < 1e-9
    );
    // A scene across the border: the eye south-west of it, looking north-east.
    let scene = ok_json(&fmrh(&[
        "scene",
        ds,
        "--eye",
        "60000,140000,6000",
        "--target",
        "90000,60000,500",
        "--tau",
        "2",
        "--window",
        "900,200,1500,1000",
        "--json",
        "--load",
    ]));
    let blocks = scene["blocks"].as_array().unwrap();
    let tiles_used: std::collections::BTreeSet<u64> =
        blocks.iter().map(|b| b["tile"].as_u64().unwrap()).collect();
    assert_eq!(tiles_used.len(), 2, "the scene spans both tiles");
    assert!(scene["stats"]["max_screen_error"].as_f64().unwrap() <= 2.0);
    // One cover of the window: every cell once.
    let (c0, r0, c1, r1) = (900u64, 200u64, 1500u64, 1000u64);
    let w = c1 - c0;
    let mut cells = vec![0u8; (w * (r1 - r0)) as usize];
    for bl in blocks {
        let g = |k: &str| bl[k].as_u64().unwrap();
        for row in g("row0").max(r0)..g("row1").min(r1) {
            for col in g("col0").max(c0)..g("col1").min(c1) {
                cells[((row - r0) * w + col - c0) as usize] += 1;
            }
        }
    }
    assert!(
        cells.iter().all(|&c| c == 1),
        "the window is not covered exactly once"
    );
    // Blocks of the west tile on the border know the levels east of it.
    let west_border: Vec<_> = blocks
        .iter()
        .filter(|bl| bl["col1"] == 1200 && bl["col0"].as_u64().unwrap() < 1200)
        .collect();
    assert!(!west_border.is_empty());
    assert!(
        west_border.iter().all(|bl| !bl["neighbours"][1].is_null()),
        "a border block lacks its east neighbour"
    );
    assert_eq!(scene["reads"]["tiles_opened"], 2);
    assert!(scene["reads"]["load"]["payload_bytes"].as_u64().unwrap() > 0);
}

#[test]
fn a_patch_across_the_real_border_is_exact_in_both_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let ds = out.to_str().unwrap();
    let [a, b] = tiles();
    ok_json(&fmrh(&[
        "dataset",
        "build",
        "--json",
        "--seam",
        "first",
        "-o",
        ds,
        a.to_str().unwrap(),
        b.to_str().unwrap(),
    ]));
    // 60 x 40 samples over columns 1170..=1229 (the border is column 1200), with voids.
    let patch = fmrh::Heightfield::from_fn(60, 40, |x, y| {
        if (x + y) % 17 == 0 {
            f32::NAN
        } else {
            100.0 + (x * 7 + y * 3) as f32 * 0.25
        }
    })
    .unwrap();
    let p = common::tiles::write_f32(dir.path(), "patch", &patch, 90.0);
    let r = ok_json(&fmrh(&[
        "replace",
        ds,
        "--at",
        "1170,500",
        p.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(r["tiles"].as_array().unwrap().len(), 2, "both files change");
    assert_eq!(r["txn_id"], 2);
    assert_eq!(
        ok_json(&fmrh(&["verify", "--full", "--json", ds]))["valid"],
        true
    );
    // Each file alone holds its part of the patch, bit for bit, the shared column in both.
    let dset = fmrh::dataset::Dataset::open(&out).unwrap();
    for t in dset.tiles().unwrap() {
        let store = dset.open_tile(&t).unwrap();
        let tr = t.rect();
        let (c0, c1) = (1170u64.max(tr.col0), 1229u64.min(tr.col1));
        let got = store
            .read_window(fmrh::model::SampleRect {
                col0: c0 - tr.col0,
                row0: 500,
                col1: c1 - tr.col0,
                row1: 539,
            })
            .unwrap();
        let w = (c1 - c0 + 1) as usize;
        for y in 0..40usize {
            for x in 0..w {
                let want = patch.samples()[y * 60 + (c0 - 1170) as usize + x];
                let v = got.samples()[y * w + x];
                assert!(
                    v.to_bits() == want.to_bits() || v.is_nan() && want.is_nan(),
                    "{} ({x}, {y}): {v} vs {want}",
                    t.name()
                );
            }
        }
    }
}

#[test]
fn adding_the_western_neighbour_moves_the_grid_and_settles_the_edge() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let ds = out.to_str().unwrap();
    let [a, b] = tiles();
    ok_json(&fmrh(&[
        "dataset",
        "build",
        "--json",
        "-o",
        ds,
        b.to_str().unwrap(),
    ]));
    // Strict: the disagreement is refused, and nothing changes.
    let r = fmrh(&["dataset", "add", ds, a.to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("disagree"));
    assert_eq!(ok_json(&fmrh(&["info", "--json", ds]))["tile_count"], 1);
    let added = ok_json(&fmrh(&[
        "dataset",
        "add",
        ds,
        a.to_str().unwrap(),
        "--seam",
        "mean",
        "--json",
    ]));
    assert_eq!(added["origin_shift"][0], 1200);
    assert_eq!(
        added["tiles"].as_array().unwrap().len(),
        1,
        "the eastern tile changes too"
    );
    let info = ok_json(&fmrh(&["info", "--json", ds]));
    assert_eq!(info["columns"], 2401);
    assert_eq!(info["georeference"]["origin"][0], 6.0);
    assert_eq!(
        ok_json(&fmrh(&["verify", "--full", "--json", ds]))["valid"],
        true
    );
    let (fa, fb) = (load(&a), load(&b));
    let dset = fmrh::dataset::Dataset::open(&out).unwrap();
    let edge = dset
        .read_window(fmrh::model::SampleRect {
            col0: 1200,
            row0: 0,
            col1: 1200,
            row1: 1200,
        })
        .unwrap();
    for y in 0..1201usize {
        let (va, vb) = (fa.samples()[y * 1201 + 1200], fb.samples()[y * 1201]);
        let want = if va.is_nan() || vb.is_nan() {
            f32::NAN
        } else {
            ((f64::from(va) + f64::from(vb)) / 2.0) as f32
        };
        let v = edge.samples()[y];
        assert!(
            v.to_bits() == want.to_bits() || v.is_nan() && want.is_nan(),
            "row {y}: {v} vs {want}"
        );
    }
}

#[test]
fn bad_dataset_input_gets_a_clear_error_and_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().to_str().unwrap();
    for args in [
        vec!["info", plain],
        vec!["verify", plain],
        vec!["extract", plain, "-o", "/dev/null"],
        vec!["recover", plain],
    ] {
        let r = fmrh(&args);
        assert_eq!(r.status.code(), Some(2), "{args:?}");
        assert!(
            String::from_utf8_lossy(&r.stderr).contains("without a MANIFEST"),
            "{args:?}"
        );
    }
    // A layout line that is not path,col0,row0 is named; an existing output is refused.
    let layout = dir.path().join("layout.csv");
    std::fs::write(
        &layout,
        "# tiles\nN43E006.hgt.gz,0,0\nN43E007.hgt.gz,-1200,0\n",
    )
    .unwrap();
    let out = dir.path().join("ds");
    let r = fmrh(&[
        "dataset",
        "build",
        "-q",
        "--layout",
        layout.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&r.stderr).contains("layout line 3"),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    let r = fmrh(&[
        "dataset",
        "build",
        "-q",
        "-o",
        plain,
        tiles()[0].to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("exists"));
}
