//! `fmrh::distributed` (a dataset build's phases as separate calls, for many machines) makes
//! the same dataset as `fmrh::build_dataset`, byte for byte: every tile file and the
//! manifest, over the bundled SRTM neighbours (whose shared edge disagrees, settled by each
//! builder from the scans alone) and over synthetic tiles with voids on their edges. Scans
//! and plans survive their trip as bytes and JSON exactly (voids included), and damaged ones
//! are refused. Publishing into an existing dataset commits the next manifest state: the new
//! tiles under names the old state does not use, the old names reported superseded, and
//! the dataset valid.

mod common;

use std::path::{Path, PathBuf};

use common::fields::{self, Character};
use common::tiles;
use fmrh::distributed::{self, Plan, TileScan};
use fmrh::types::{SampleRect, SeamPolicy, Silent};
use fmrh::DatasetBuildOptions;

/// Runs the phases as separate "machines" would: every value crosses as bytes or JSON.
fn build_in_phases(
    inputs: &[(PathBuf, Option<(u64, u64)>)],
    out: &Path,
    options: &DatasetBuildOptions,
) -> Plan {
    let scans: Vec<Vec<u8>> = inputs
        .iter()
        .map(|(p, _)| distributed::scan_tile(p, options).unwrap().to_bytes())
        .collect();
    // The planner needs only descriptions (no borders).
    let described: Vec<_> = inputs
        .iter()
        .zip(&scans)
        .map(|((p, at), s)| {
            let d = TileScan::from_bytes(s).unwrap().description().to_bytes();
            assert!(d.len() < 400, "{} bytes", d.len());
            (p.clone(), *at, TileScan::from_bytes(&d).unwrap())
        })
        .collect();
    let plan = distributed::plan_dataset(&described, options, &[]).unwrap();
    let json = plan.to_json();
    std::fs::create_dir(out).unwrap();
    for (i, (p, _)) in inputs.iter().enumerate() {
        let plan = Plan::from_json(&json).unwrap();
        let mut needed = vec![(i, TileScan::from_bytes(&scans[i]).unwrap())];
        for &(a, b, _) in &plan.shared {
            if a == i || b == i {
                let k = if a == i { b } else { a };
                needed.push((k, TileScan::from_bytes(&scans[k]).unwrap()));
            }
        }
        distributed::build_planned_tile(
            &plan,
            i,
            p,
            &needed,
            options,
            &out.join(&plan.files[i]),
            &Silent,
        )
        .unwrap();
    }
    distributed::publish_dataset(&plan, out, &out.join("MANIFEST"), false).unwrap();
    plan
}

fn same_dirs(a: &Path, b: &Path) {
    let names = |d: &Path| {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(a), names(b));
    for n in names(a) {
        assert!(
            std::fs::read(a.join(&n)).unwrap() == std::fs::read(b.join(&n)).unwrap(),
            "{n} differs"
        );
    }
}

#[test]
fn the_phases_make_the_dataset_build_dataset_makes_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let srtm = common::bundled_dir().join("srtm3-pyhgtmap");
    let inputs = vec![
        (srtm.join("N43E006.hgt.gz"), None),
        (srtm.join("N43E007.hgt.gz"), None),
    ];
    let options = DatasetBuildOptions {
        seam: Some(SeamPolicy::Mean),
        ..Default::default()
    };
    let whole = dir.path().join("whole");
    fmrh::build_dataset(&inputs, &whole, &options, &Silent, &mut |_, _, _, _| {}).unwrap();
    let phased = dir.path().join("phased");
    let plan = build_in_phases(&inputs, &phased, &options);
    assert_eq!(plan.shared.len(), 1);
    same_dirs(&whole, &phased);
    // Strict: the real neighbours disagree, and the builder of either tile says so.
    let strict = DatasetBuildOptions::default();
    let scans: Vec<_> = inputs
        .iter()
        .map(|(p, at)| (p.clone(), *at, distributed::scan_tile(p, &strict).unwrap()))
        .collect();
    let plan = distributed::plan_dataset(&scans, &strict, &[]).unwrap();
    let given: Vec<_> = scans
        .iter()
        .enumerate()
        .map(|(i, s)| (i, s.2.clone()))
        .collect();
    let err = distributed::build_planned_tile(
        &plan,
        1,
        &inputs[1].0,
        &given,
        &strict,
        &dir.path().join("x"),
        &Silent,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("disagree") && err.contains("N43E006"), "{err}");
    assert!(!dir.path().join("x").exists());
    // A neighbour's scan missing is an error, not a guess.
    let err = distributed::build_planned_tile(
        &plan,
        1,
        &inputs[1].0,
        &given[1..],
        &strict,
        &dir.path().join("x"),
        &Silent,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("whose scan was not given"), "{err}");
    let described: Vec<_> = given.iter().map(|(i, s)| (*i, s.description())).collect();
    let err = distributed::build_planned_tile(
        &plan,
        1,
        &inputs[1].0,
        &described,
        &strict,
        &dir.path().join("x"),
        &Silent,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("is a description"), "{err}");
}

#[test]
fn synthetic_tiles_with_voids_by_a_layout_and_a_rebuild_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let field = fields::make(70, 50, Character::Hills, 0.2, 11);
    let rects = tiles::split(&field, &[30], &[20], &[]);
    let src = dir.path().join("src");
    std::fs::create_dir(&src).unwrap();
    let inputs: Vec<(PathBuf, Option<(u64, u64)>)> = rects
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let p = tiles::write_f32(&src, &format!("t{i}"), &tiles::crop(&field, r), 10.0);
            (p, Some((r.col0, r.row0)))
        })
        .collect();
    let mut options = DatasetBuildOptions {
        seam: Some(SeamPolicy::First),
        ..Default::default()
    };
    options.create.block_size = 9;
    let whole = dir.path().join("whole");
    fmrh::build_dataset(&inputs, &whole, &options, &Silent, &mut |_, _, _, _| {}).unwrap();
    let phased = dir.path().join("phased");
    let plan = build_in_phases(&inputs, &phased, &options);
    same_dirs(&whole, &phased);
    // Scans and plans cross exactly, voids included; damage is refused.
    // (Bit for bit: NaN equals nothing, so the bytes are compared, not the values.)
    let scan = distributed::scan_tile(&inputs[0].0, &options).unwrap();
    let bytes = scan.to_bytes();
    assert!(bytes.len() > 4 * (2 * 31 + 2 * 21));
    assert_eq!(TileScan::from_bytes(&bytes).unwrap().to_bytes(), bytes);
    for cut in [0, 7, 12, bytes.len() - 1] {
        assert!(TileScan::from_bytes(&bytes[..cut]).is_err());
    }
    assert_eq!(Plan::from_json(&plan.to_json()).unwrap(), plan);
    assert!(Plan::from_json("{}").is_err());
    // Rebuild in place with a changed tile: new names, one commit, the old ones superseded.
    let mut changed = tiles::crop(&field, &rects[0]);
    let samples: Vec<f32> = changed.samples().iter().map(|v| v + 1.0).collect();
    changed = fmrh::Heightfield::new(changed.width(), changed.height(), samples).unwrap();
    let new0 = tiles::write_f32(&src, "t0b", &changed, 10.0);
    let mut inputs2 = inputs.clone();
    inputs2[0].0 = new0;
    let taken: Vec<String> = plan.files.clone();
    let scans: Vec<_> = inputs2
        .iter()
        .map(|(p, at)| (p.clone(), *at, distributed::scan_tile(p, &options).unwrap()))
        .collect();
    let plan2 = distributed::plan_dataset(&scans, &options, &taken).unwrap();
    assert!(
        plan2.files.iter().all(|f| !taken.contains(f)),
        "{:?}",
        plan2.files
    );
    let given: Vec<_> = scans
        .iter()
        .enumerate()
        .map(|(i, s)| (i, s.2.clone()))
        .collect();
    for (i, (p, _)) in inputs2.iter().enumerate() {
        distributed::build_planned_tile(
            &plan2,
            i,
            p,
            &given,
            &options,
            &phased.join(&plan2.files[i]),
            &Silent,
        )
        .unwrap();
    }
    let before = fmrh::Terrain::open(&phased).unwrap();
    let published =
        distributed::publish_dataset(&plan2, &phased, &phased.join("MANIFEST"), true).unwrap();
    assert_eq!(published.txn_id, before.info().unwrap().txn_id + 1);
    let mut sup = published.superseded.clone();
    sup.sort();
    let mut old = taken.clone();
    old.sort();
    assert_eq!(sup, old);
    let after = fmrh::Terrain::open(&phased).unwrap();
    let got = after
        .read(Some(SampleRect {
            col0: 1,
            row0: 1,
            col1: 1,
            row1: 1,
        }))
        .unwrap();
    let want = changed.samples()[changed.width() as usize + 1];
    assert!(got.samples()[0].to_bits() == want.to_bits() || want.is_nan());
    assert!(after.verify(fmrh::types::VerifyMode::Full).unwrap().valid());
    // The reader opened before the commit still reads its state.
    assert_eq!(
        before.info().unwrap().txn_id + 1,
        after.info().unwrap().txn_id
    );
}
