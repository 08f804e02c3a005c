//! `fmrh compact` rewrites a container's current state as a fresh build of it would be: after
//! edits, the file is exactly as long as a fresh build of the same samples with the file's
//! own options, every sample reads the same bit for bit, every scene answers the same, the
//! full validator passes; a reader that had the old file open reads on, undisturbed; and a
//! file another writer holds is refused and left as it was (issue 39, point 4).
//!
//! `fmrh compact DIR` does the same for every tile of a dataset, in one manifest commit: each
//! new tile file is byte for byte what compacting that tile's container alone makes, the
//! dataset reads every sample and answers every scene as before, validates, and holds no file
//! but the manifest and the new tiles; a reader of the state before reads the same samples or
//! is told its state was superseded, never anything else; a compaction that fails part way
//! leaves the directory as it was; a dataset another writer holds is refused.

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

/// A 2 x 2 dataset of Puget Sound 1k (tiles sharing their edges), edited by 30 changes of
/// 65² patches across tile borders; returns its directory.
fn edited_dataset(dir: &std::path::Path) -> std::path::PathBuf {
    let hf = common::views::puget_1k();
    let (w, h) = (u64::from(hf.width()), u64::from(hf.height()));
    let rects = common::tiles::split(&hf, &[w / 2], &[h / 2], &[]);
    let ds = common::tiles::build(dir, &hf, &rects, &common::tiles::options(None));
    let files = fmrh::dataset::Dir(ds.clone());
    let mut rng = Rng::new(3939);
    for i in 0..30 {
        let (c, r) = (
            w / 2 - 40 + rng.next_u64() % 80,
            h / 2 - 40 + rng.next_u64() % 80,
        );
        let (c, r) = (c.min(w - 65), r.min(h - 65));
        let patch = Heightfield::from_fn(65, 65, |x, y| {
            100.0 + i as f32 + ((x * 11 + y * 5) % 31) as f32
        })
        .unwrap();
        fmrh::dataset::replace(&files, c, r, &patch).unwrap();
    }
    ds
}

fn names_in(dir: &std::path::Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn dataset_scene(ds: &str) -> serde_json::Value {
    let mut v = common::ok_json(&common::fmrh(&[
        "scene",
        ds,
        "--eye",
        "5000,13000,3000",
        "--target",
        "5000,4000,0",
        "--tau",
        "1",
        "--json",
    ]));
    common::without_keys(
        &mut v,
        &[
            "timing",
            "times",
            "elapsed_ms",
            "reads",
            "read",
            "offset",
            "length",
            "crc",
            "bytes",
            "index_pages",
            "payload",
            "tile_file",
            "file",
            "name",
        ],
    );
    v
}

#[test]
fn a_dataset_compacts_tile_by_tile_in_one_commit() {
    let dir = tempfile::tempdir().unwrap();
    let ds = edited_dataset(dir.path());
    let ds_s = ds.to_str().unwrap();
    let before = fmrh::dataset::Dataset::open(&ds).unwrap();
    let all = before.read_window(before.grid()).unwrap();
    let scene_before = dataset_scene(ds_s);
    // Each tile's container compacted alone, on a copy: what the dataset's must hold.
    let copies = dir.path().join("copies");
    std::fs::create_dir(&copies).unwrap();
    let mut expected = Vec::new();
    for name in names_in(&ds).into_iter().filter(|n| n.ends_with(".fmrh")) {
        let copy = copies.join(&name);
        std::fs::copy(ds.join(&name), &copy).unwrap();
        common::ok_json(&common::fmrh(&[
            "compact",
            copy.to_str().unwrap(),
            "--json",
        ]));
        expected.push((name, std::fs::read(&copy).unwrap()));
    }

    let report = common::ok_json(&common::fmrh(&["compact", ds_s, "--json"]));
    let (b, a) = (
        report["bytes_before"].as_u64().unwrap(),
        report["bytes_after"].as_u64().unwrap(),
    );
    eprintln!("dataset {b} bytes -> {a}");
    assert!(a < b, "{report}");
    let tiles = report["tiles"].as_array().unwrap();
    assert_eq!(tiles.len(), expected.len());
    let mut now_names = vec!["MANIFEST".to_string()];
    for t in tiles {
        let (old, new) = (
            t["name_before"].as_str().unwrap(),
            t["name_after"].as_str().unwrap(),
        );
        assert_ne!(old, new);
        let want = &expected.iter().find(|(n, _)| n == old).unwrap().1;
        let got = std::fs::read(ds.join(new)).unwrap();
        assert!(
            got == *want,
            "{new} is not what compacting {old} alone makes"
        );
        now_names.push(new.to_string());
    }
    now_names.sort();
    assert_eq!(
        names_in(&ds),
        now_names,
        "old tiles or temporaries left behind"
    );

    let after = fmrh::dataset::Dataset::open(&ds).unwrap();
    let again = after.read_window(after.grid()).unwrap();
    assert!(common::first_difference(again.samples(), all.samples()).is_none());
    assert_eq!(dataset_scene(ds_s), scene_before);
    let v = common::fmrh(&["verify", "--full", ds_s]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
    // The reader of the state before: the same samples, or told it was superseded.
    match before.read_window(before.grid()) {
        Ok(old) => assert!(common::first_difference(old.samples(), all.samples()).is_none()),
        Err(e) => assert!(matches!(e, fmrh::Error::Superseded { .. }), "{e:?}"),
    }
    // Again: the names go back, the bytes stay.
    let report = common::ok_json(&common::fmrh(&["compact", ds_s, "--json"]));
    assert_eq!(
        report["bytes_after"].as_u64(),
        report["bytes_before"].as_u64()
    );
    let mut first: Vec<String> = expected.iter().map(|(n, _)| n.clone()).collect();
    first.push("MANIFEST".into());
    first.sort();
    assert_eq!(names_in(&ds), first);
}

#[test]
fn a_dataset_compaction_that_fails_part_way_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let ds = edited_dataset(dir.path());
    let names = names_in(&ds);
    let manifest = std::fs::read(ds.join("MANIFEST")).unwrap();
    // The last tile (in record order) cannot be read: its payload pages are zeroed. The
    // tiles before it are rewritten first, then the failure must take their new files away.
    let dataset = fmrh::dataset::Dataset::open(&ds).unwrap();
    let last = dataset.tiles().unwrap().last().unwrap().name().to_string();
    drop(dataset);
    let path = ds.join(&last);
    let mut bytes = std::fs::read(&path).unwrap();
    let n = bytes.len();
    bytes[n / 2..n - 4096].fill(0);
    std::fs::write(&path, &bytes).unwrap();
    let out = common::fmrh(&["compact", ds.to_str().unwrap()]);
    assert!(!out.status.success(), "a corrupt tile was compacted");
    assert_eq!(
        names_in(&ds),
        names,
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(ds.join("MANIFEST")).unwrap(), manifest);
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
}

#[test]
fn a_dataset_another_writer_holds_is_not_compacted() {
    let dir = tempfile::tempdir().unwrap();
    let ds = edited_dataset(dir.path());
    let names = names_in(&ds);
    let manifest = std::fs::read(ds.join("MANIFEST")).unwrap();
    let holder = fmrh::store::io::FileIo::open(&ds.join("MANIFEST")).unwrap();
    let out = common::fmrh(&["compact", ds.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("locked"));
    assert_eq!(names_in(&ds), names);
    assert_eq!(std::fs::read(ds.join("MANIFEST")).unwrap(), manifest);
    drop(holder);
}
