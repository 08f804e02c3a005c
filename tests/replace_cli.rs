//! `fmrh replace` as a user runs it on a real DEM: the patch's samples are stored exactly
//! (`extract` returns them, everything outside the patch is unchanged), the file passes
//! `verify --full`, the model equals a fresh build of the new samples with the stored
//! thresholds (`info` agrees on nodes and cluster sizes), and the report counts what changed.
//! Bad input (a patch that does not fit, a malformed `--at`, a non-container, a patch in
//! other units) exits 2 and leaves the file byte for byte as it was. `fmrh recover` repairs
//! what a crash leaves, and a second writer is locked out.

mod common;

use std::path::{Path, PathBuf};

use common::{data, first_difference, fmrh, ok_json};

fn write_f32(path: &Path, w: u32, h: u32, samples: &[f32], units: Option<&str>) {
    let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, bytes).unwrap();
    let json = serde_json::json!({ "width": w, "height": h, "units": units });
    std::fs::write(path.with_extension("json"), json.to_string()).unwrap();
}

/// A container of Puget Sound east in a fresh temporary directory: (dir, source, container).
fn built() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let src = data("puget-sound-east-512/ps-e_lg.f32");
    let file = dir.path().join("ps.fmrh");
    let file_s = file.to_str().unwrap();
    ok_json(&fmrh(&[
        "build",
        src.to_str().unwrap(),
        "-o",
        file_s,
        "--json",
    ]));
    (dir, src, file)
}

fn read_f32(path: &Path) -> Vec<f32> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn replace_stores_the_patch_and_equals_a_rebuild() {
    let (dir, src, file) = built();
    let file_s = file.to_str().unwrap();

    // A 70 x 40 patch with a void and a cliff, straddling block edges.
    let (pw, ph, c0, r0) = (70u32, 40u32, 250u32, 120u32);
    let patch: Vec<f32> = (0..pw * ph)
        .map(|i| match (i % pw, i / pw) {
            (3, 4) => f32::NAN,
            (x, _) if x > 35 => 900.0,
            (x, y) => (x * 3 + y) as f32,
        })
        .collect();
    let patch_path = dir.path().join("patch.f32");
    write_f32(&patch_path, pw, ph, &patch, None);
    let report = ok_json(&fmrh(&[
        "replace",
        file_s,
        "--at",
        &format!("{c0},{r0}"),
        patch_path.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(report["replacements"], 1);
    assert!(report["blocks"].as_u64().unwrap() >= 1, "{report}");
    assert!(report["nodes_changed"].as_u64().unwrap() >= 1, "{report}");
    assert!(!report["clusters_changed"].as_array().unwrap().is_empty());
    assert_eq!(
        report["file_length"],
        std::fs::metadata(&file).unwrap().len()
    );

    let v = ok_json(&fmrh(&["verify", file_s, "--full", "--json"]));
    assert_eq!(v["valid"], true, "{v}");

    // The stored samples: the source with the patch pasted in.
    let mut expected = read_f32(&src);
    for y in 0..ph {
        for x in 0..pw {
            expected[((r0 + y) * 512 + c0 + x) as usize] = patch[(y * pw + x) as usize];
        }
    }
    let whole = dir.path().join("whole.f32");
    let e = fmrh(&["extract", file_s, "-o", whole.to_str().unwrap()]);
    assert!(e.status.success(), "{}", String::from_utf8_lossy(&e.stderr));
    assert_eq!(first_difference(&read_f32(&whole), &expected), None);

    // A fresh build of those samples with the stored thresholds describes the same model.
    let info = ok_json(&fmrh(&["info", file_s, "--json"]));
    // Closed cleanly; dead payload bytes may remain; the replaced payloads' pages are free.
    assert_eq!(info["recovery_needed"], false);
    assert_eq!(info["payload_slack"], true);
    assert!(
        info["sections"]["free_pages"].as_u64().unwrap() > 0,
        "{info}"
    );
    let thresholds: Vec<String> = info["clusters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["threshold"].as_f64().unwrap().to_string())
        .collect();
    let fresh = dir.path().join("fresh.fmrh");
    ok_json(&fmrh(&[
        "build",
        whole.to_str().unwrap(),
        "-o",
        fresh.to_str().unwrap(),
        "--thresholds",
        &thresholds.join(","),
        "--json",
    ]));
    let fresh_info = ok_json(&fmrh(&["info", fresh.to_str().unwrap(), "--json"]));
    assert_eq!(info["nodes"], fresh_info["nodes"]);
    assert_eq!(info["nodes_per_level"], fresh_info["nodes_per_level"]);
    assert_eq!(info["clusters"], fresh_info["clusters"]);
}

#[test]
fn bad_input_exits_2_and_leaves_the_file_alone() {
    let (dir, _, file) = built();
    let file_s = file.to_str().unwrap();
    let before = std::fs::read(&file).unwrap();
    let patch = dir.path().join("p.f32");
    write_f32(&patch, 20, 20, &[1.0; 400], None);
    let metres = dir.path().join("m.f32");
    write_f32(&metres, 20, 20, &[1.0; 400], Some("metres"));
    let patch_s = patch.to_str().unwrap();
    let cases: [(&[&str], &str); 6] = [
        (&["--at", "500,0", patch_s], "does not fit"),
        (&["--at", "0,493", patch_s], "does not fit"),
        (&["--at", "18446744073709551615,0", patch_s], "does not fit"),
        (&["--at", "1", patch_s], "COL,ROW"),
        (&["--at=-1,2", patch_s], "COL,ROW"),
        (&["--at", "0,0", metres.to_str().unwrap()], "units"),
    ];
    for (args, says) in cases {
        let mut all = vec!["replace", file_s];
        all.extend_from_slice(args);
        let out = fmrh(&all);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
        assert!(
            std::fs::read(&file).unwrap() == before,
            "{args:?} changed the file"
        );
    }
    // Not a container: exit 2, and the target is untouched.
    let out = fmrh(&["replace", patch_s, "--at", "0,0", patch_s]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not an fmrh container"));
}

/// What a crash can leave (pages past the committed length, a torn record in the unused
/// slot) fails `verify` with I-3 and I-4; `fmrh recover` repairs it without losing the
/// committed state, and a file held by another writer is refused (exit 1), untouched.
#[test]
fn recover_repairs_what_a_crash_leaves_and_writers_exclude_each_other() {
    let (dir, _, file) = built();
    let file_s = file.to_str().unwrap();
    let before = std::fs::read(&file).unwrap();
    let page = ok_json(&fmrh(&["info", file_s, "--json"]))["page_size"]
        .as_u64()
        .unwrap() as usize;
    let mut damaged = before.clone();
    damaged.extend(std::iter::repeat_n(0xA5u8, 3 * page));
    damaged[page..page + 256].fill(0x5A);
    std::fs::write(&file, &damaged).unwrap();
    let v = fmrh(&["verify", file_s, "--json"]);
    assert_eq!(v.status.code(), Some(1));
    let text = String::from_utf8_lossy(&v.stdout);
    assert!(text.contains("fmrh recover"), "{text}");

    let r = ok_json(&fmrh(&["recover", file_s, "--json"]));
    assert_eq!(r["truncated"], 3 * page as u64);
    assert_eq!(r["slot_cleared"], true);
    let v = ok_json(&fmrh(&["verify", file_s, "--full", "--json"]));
    assert_eq!(v["valid"], true, "{v}");
    assert!(std::fs::read(&file).unwrap()[2 * page..] == before[2 * page..]);
    let again = fmrh(&["recover", file_s]);
    assert!(String::from_utf8_lossy(&again.stdout).contains("nothing to recover"));

    // Another writer holds the file: refused, exit 1, nothing written.
    let holder = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&file)
        .unwrap();
    holder.try_lock().unwrap();
    let now = std::fs::read(&file).unwrap();
    let patch = dir.path().join("p.f32");
    write_f32(&patch, 4, 4, &[1.0; 16], None);
    let out = fmrh(&["replace", file_s, "--at", "0,0", patch.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("locked"));
    assert!(std::fs::read(&file).unwrap() == now);
    drop(holder);
    ok_json(&fmrh(&[
        "replace",
        file_s,
        "--at",
        "0,0",
        patch.to_str().unwrap(),
        "--json",
    ]));
}
