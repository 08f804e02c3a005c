//! `fmrh compact` rewrites a container's current state as a fresh build of it would be: after
//! edits, the file is exactly as long as a fresh build of the same samples with the file's
//! own options, every sample reads the same bit for bit, every scene answers the same, the
//! full validator passes; a reader that had the old file open reads on, undisturbed; and a
//! file another writer holds is refused and left as it was (issue 39, point 4).

mod common;

use common::fields::Rng;
use fmrh::store::{Container, FileSource, Store};
use fmrh::types::Thresholds;
use fmrh::{CreateOptions, Heightfield};

/// A scene's answer (its blocks, their levels, errors, distances and neighbours): its JSON
/// without what differs run to run (timings, read reports) and without how the bytes are
/// stored (payload offsets, lengths and CRCs, bytes, index pages touched), which a rewrite
/// changes by design: a commit may code a payload alone where a fresh build codes it
/// against its parent. The samples themselves are compared bit for bit besides.
fn scene(file: &str) -> serde_json::Value {
    let mut v = common::ok_json(&common::fmrh(&[
        "scene",
        file,
        "--spacing=1",
        "--eye",
        "500,1300,600",
        "--target",
        "500,400,0",
        "--tau",
        "1",
        "--json",
    ]));
    common::without_keys(&mut v, &["reads", "payload", "bytes", "index_pages"]);
    v
}

#[test]
fn compaction_after_edits_is_a_fresh_build_of_the_same_state() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ps1k.fmrh");
    let hf = common::views::puget_1k();
    let (w, h) = (u64::from(hf.width()), u64::from(hf.height()));
    fmrh::create(&file, hf, &CreateOptions::default()).unwrap();
    let built = std::fs::metadata(&file).unwrap().len();
    // 40 replacements of 65² patches: the file grows with what they leave behind.
    let container = Container::open(&file).unwrap();
    let mut rng = Rng::new(39);
    for i in 0..40 {
        let (col0, row0) = (rng.next_u64() % (w - 65), rng.next_u64() % (h - 65));
        let patch = Heightfield::from_fn(65, 65, |x, y| {
            200.0 + i as f32 + ((x * 13 + y * 7) % 29) as f32
        })
        .unwrap();
        let mut txn = container.begin_write().unwrap();
        txn.replace_region(col0, row0, &patch).unwrap();
        txn.commit().unwrap();
    }
    container.close().unwrap();
    let edited = std::fs::metadata(&file).unwrap().len();
    assert!(
        edited > built,
        "the edits grew the file ({built} -> {edited})"
    );
    let f = file.to_str().unwrap();
    let before = Store::<FileSource>::open(&file).unwrap();
    let samples = before.read_window(before.domain().data_rect()).unwrap();
    let thresholds: Vec<f64> = before.clusters().iter().map(|c| c.threshold).collect();
    let page_size = before.page_size();
    let metadata = before.header().metadata.clone();
    let scene_before = scene(f);

    let out = common::fmrh(&["compact", f, "--json"]);
    let report = common::ok_json(&out);
    assert_eq!(report["bytes_before"], edited);
    let after_len = std::fs::metadata(&file).unwrap().len();
    assert_eq!(report["bytes_after"], after_len);
    eprintln!("built {built} bytes, edited {edited}, compacted {after_len}");
    assert!(after_len < edited);

    // What a fresh build of the same samples with the file's options makes, byte for byte.
    let fresh = dir.path().join("fresh.fmrh");
    fmrh::create(
        &fresh,
        samples.clone().with_metadata(metadata),
        &CreateOptions {
            thresholds: Thresholds::Explicit(thresholds),
            page_size: Some(page_size),
            ..CreateOptions::default()
        },
    )
    .unwrap();
    let (a, b) = (
        std::fs::read(&fresh).unwrap(),
        std::fs::read(&file).unwrap(),
    );
    assert_eq!(
        a.len(),
        b.len(),
        "a fresh build's length, and the compacted file's"
    );
    let first = a.iter().zip(&b).position(|(x, y)| x != y);
    assert!(first.is_none(), "they differ first at byte {first:?}");

    // The same samples, the same scene, valid; and the reader of the old file reads on.
    let now = Store::<FileSource>::open(&file).unwrap();
    let again = now.read_window(now.domain().data_rect()).unwrap();
    assert!(common::first_difference(again.samples(), samples.samples()).is_none());
    assert_eq!(scene(f), scene_before);
    let v = common::fmrh(&["verify", "--full", f]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
    let old = before.read_window(before.domain().data_rect()).unwrap();
    assert!(common::first_difference(old.samples(), samples.samples()).is_none());
}

#[test]
fn a_file_another_writer_holds_is_not_compacted() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("t.fmrh");
    let hf = Heightfield::from_fn(200, 150, |x, y| (x * y % 97) as f32).unwrap();
    fmrh::create(&file, hf, &CreateOptions::default()).unwrap();
    let holder = Container::open(&file).unwrap();
    let bytes = std::fs::read(&file).unwrap();
    let out = common::fmrh(&["compact", file.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("locked"));
    assert_eq!(std::fs::read(&file).unwrap(), bytes);
    let hidden: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name() != "t.fmrh")
        .collect();
    assert!(hidden.is_empty(), "a refused compaction left files behind");
    drop(holder);
}
