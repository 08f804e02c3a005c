//! Blocks coded against their parent's grid (format 4.0, container.md §6.2 and §7): a block
//! that is a node of the tree may store only the samples its parent's grid does not hold, as
//! residuals against an interpolation of that grid. The properties checked here: every such
//! block reads back bit for bit, on any field (lattice or float, with voids, clipped at the
//! data's edge); a file is smaller for it; a transaction that rewrites a parent's grid codes
//! the kept children again, so they still decode; a reader and the validator refuse a block
//! record that names a node other than its parent, and report a damaged parent grid as
//! corruption when a child is read.

mod common;

use proptest::prelude::*;

use common::bytes_of;
use fmrh::model::SampleRect;
use fmrh::store::{Container, FileSource, WriteOptions};
use fmrh::CreateOptions;
use fmrh::{store::Store, store::VerifyMode, types::Invariant, Error, Heightfield};

/// Every block coded alone, as format 3 coded them.
fn alone_options() -> WriteOptions {
    WriteOptions {
        against_parents: false,
        ..WriteOptions::default()
    }
}

/// Blocks coded against their parent, over all blocks.
fn coded_against<S: fmrh::store::Source>(store: &Store<S>) -> (usize, usize) {
    let d = *store.domain();
    let (cols, rows) = d.nodes_across(d.finest_level());
    let against = (0..rows)
        .flat_map(|y| (0..cols).map(move |x| (x, y)))
        .filter(|&(x, y)| store.stored_block(x, y).unwrap().against.is_some())
        .count();
    (against, (cols * rows) as usize)
}

/// Smooth integer hills: the lattice case, where coding against the parent pays.
fn hills(w: u32, h: u32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        let (x, y) = (x as f32 * 0.05, y as f32 * 0.07);
        (400.0 + 120.0 * x.sin() * y.cos() + 30.0 * (2.3 * x + y).sin()).round()
    })
    .unwrap()
}

fn verify_full(bytes: Vec<u8>) -> fmrh::store::VerifyReport {
    fmrh::store::verify(fmrh::store::Bytes(bytes), VerifyMode::Full).unwrap()
}

#[test]
fn a_lattice_field_codes_blocks_against_parents_and_is_smaller() {
    let field = hills(300, 230);
    let with = bytes_of(&field, 33, &WriteOptions::default());
    let alone = bytes_of(&field, 33, &alone_options());
    let store = Store::from_bytes(with.clone()).unwrap();
    assert_eq!(
        store.state().format_version,
        (fmrh::format::FORMAT_MAJOR, fmrh::format::FORMAT_MINOR)
    );
    let (against, all) = coded_against(&store);
    assert!(against * 2 > all, "{against} of {all} blocks");
    let back = store.read_window(store.domain().data_rect()).unwrap();
    assert_eq!(back.samples(), field.samples());
    let plain = Store::from_bytes(alone.clone()).unwrap();
    assert_eq!(coded_against(&plain).0, 0);
    let payloads = |s: &Store<_>| {
        let l = s.layout().unwrap();
        l.block_bytes
    };
    assert!(
        payloads(&store) * 10 < payloads(&plain) * 9,
        "{} block bytes against {} coded alone",
        payloads(&store),
        payloads(&plain)
    );
    assert!(verify_full(with).valid);
    assert!(verify_full(alone).valid);
}

/// A patch inside one block rewrites its parent's grid: the three siblings coded against
/// that grid are coded again (against the new grid, or alone), so they still decode. The
/// patch lies next to the siblings (not on their shared edge), where their predictions
/// reach the grid samples it changes: kept as they were, they would decode wrong.
#[test]
fn a_commit_codes_again_the_siblings_of_a_rewritten_grid() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hills.fmrh");
    let field = hills(129, 129);
    fmrh::create(
        &path,
        field.clone(),
        &CreateOptions {
            block_size: 33,
            ..CreateOptions::default()
        },
    )
    .unwrap();
    let before = Store::open(&path).unwrap();
    let siblings: Vec<(u32, u32)> = [(0, 0), (1, 0), (0, 1), (1, 1)]
        .into_iter()
        .filter(|&(x, y)| before.stored_block(x, y).unwrap().against.is_some())
        .collect();
    assert!(siblings.len() >= 3, "{siblings:?}");
    drop(before);
    let patch = Heightfield::from_fn(3, 3, |x, y| 900.0 + (x * y) as f32).unwrap();
    let c = Container::open(&path).unwrap();
    let mut txn = c.begin_write().unwrap();
    txn.replace_region(29, 29, &patch).unwrap();
    let summary = txn.commit().unwrap();
    drop(c);
    let store = Store::open(&path).unwrap();
    let expected = common::txn::paste(&field, 29, 29, &patch);
    let back = store.read_window(store.domain().data_rect()).unwrap();
    assert_eq!(back.samples(), expected.samples());
    for y in 0..2 {
        for x in 0..2 {
            let b = store.block(x, y).unwrap();
            let r = b.rect;
            let view = b.view();
            for row in r.row0..=r.row1 {
                for col in r.col0..=r.col1 {
                    let i = ((row - r.row0) * u64::from(view.width) + col - r.col0) as usize;
                    let want = expected.samples()[row as usize * 129 + col as usize];
                    assert_eq!(view.samples()[i].get().to_bits(), want.to_bits());
                }
            }
        }
    }
    drop(store);
    let report = fmrh::store::verify(FileSource::open(&path).unwrap(), VerifyMode::Full).unwrap();
    assert!(report.valid, "{report:#?}");
    // Block (0, 0) holds the patch; each sibling that was coded against the old grid is
    // written again.
    assert!(
        summary.blocks >= siblings.len() as u64,
        "{} blocks rewritten",
        summary.blocks
    );
}

/// Sets block `ordinal`'s `against` field (record offset 28) to `value` in the single block
/// table page of a bundled file.
fn set_against(bytes: &mut Vec<u8>, ordinal: usize, value: u32) {
    let p = common::bundle::page_size(bytes);
    common::bundle::rewrite(bytes, |pages| {
        let page = pages
            .chunks_mut(p)
            .find(|pg| &pg[0..4] == b"FMBT")
            .expect("a block table page");
        let at = 24 + 32 * ordinal + 28;
        page[at..at + 4].copy_from_slice(&value.to_le_bytes());
        common::bundle::reseal_page(page);
    });
}

#[test]
fn a_block_naming_another_node_is_corrupt() {
    let field = hills(129, 129);
    let bytes = bytes_of(&field, 33, &WriteOptions::default());
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let (cols, _) = store.domain().nodes_across(store.domain().finest_level());
    // Block (0, 0) names the root (node 0) instead of its parent.
    assert!(store.stored_block(0, 0).unwrap().against.is_some());
    drop(store);
    let mut bad = bytes.clone();
    set_against(&mut bad, 0, 1);
    let store = Store::from_bytes(bad.clone()).unwrap();
    match store.block(0, 0) {
        Err(e @ Error::Corrupt { .. }) => assert!(e.to_string().contains("not its parent"), "{e}"),
        other => panic!("{other:?}"),
    }
    let report = verify_full(bad);
    assert!(!report.valid);
    assert!(
        report.checks.iter().any(|c| c.id == Invariant::BlockTable
            && c.failures.iter().any(|f| f.contains("not its parent"))),
        "{report:#?}"
    );
    // A block coded alone whose record names its parent does not decode against it.
    let alone = bytes_of(&field, 33, &alone_options());
    let store = Store::from_bytes(alone.clone()).unwrap();
    let parent = store
        .nodes()
        .unwrap()
        .iter()
        .position(|n| (n.level, n.x, n.y) == (store.domain().finest_level() - 1, 0, 0))
        .unwrap() as u32;
    drop(store);
    let mut bad = alone;
    set_against(&mut bad, (cols + 1) as usize, parent + 1);
    let store = Store::from_bytes(bad).unwrap();
    assert!(matches!(store.block(1, 1), Err(Error::Corrupt { .. })));
}

#[test]
fn a_damaged_parent_grid_is_corruption_when_a_child_is_read() {
    let field = hills(129, 129);
    let mut bytes = bytes_of(&field, 33, &WriteOptions::default());
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let parent = store.stored_block(0, 0).unwrap().against.unwrap();
    let grid = store.node(parent).unwrap().payload;
    drop(store);
    bytes[grid.offset as usize + grid.len as usize / 2] ^= 0x40;
    let store = Store::from_bytes(bytes).unwrap();
    assert!(matches!(store.block(0, 0), Err(Error::Corrupt { .. })));
    assert!(matches!(
        store.read_window(SampleRect {
            col0: 0,
            row0: 0,
            col1: 10,
            row1: 10
        }),
        Err(Error::Corrupt { .. })
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Any field (lattice or float, voids, any size, clipped at the edge), any block size:
    /// the file reads back bit for bit and verifies in full, whichever blocks are coded
    /// against their parents.
    #[test]
    fn any_field_round_trips(
        field in common::fields::any_field(160),
        k in 3u32..6,
    ) {
        let bytes = bytes_of(&field, (1 << k) + 1, &WriteOptions::default());
        let store = Store::from_bytes(bytes.clone()).unwrap();
        let back = store.read_window(store.domain().data_rect()).unwrap();
        for (a, b) in back.samples().iter().zip(field.samples()) {
            prop_assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
        }
        prop_assert!(verify_full(bytes).valid);
    }
}

/// `fmrh build` on a small real DEM (St Helens, bundled): 1 KiB pages unless told
/// otherwise (its data is at most 1024² samples), blocks coded against their parents unless
/// `--payloads-alone` (or its 4.0 name `--blocks-alone`); every variant reads back the same
/// samples and verifies in full.
#[test]
fn the_cli_picks_small_pages_and_codes_against_parents_unless_told() {
    let dir = tempfile::tempdir().unwrap();
    let input = common::data("mount-st-helens-usgs/SainteHelens.dem");
    let build = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec![
            "build",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-q",
        ];
        args.extend_from_slice(extra);
        let run = common::fmrh(&args);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        out
    };
    let default = build("default.fmrh", &[]);
    let paged = build("paged.fmrh", &["--page-size", "4096"]);
    let alone = build("alone.fmrh", &["--payloads-alone"]);
    // The flag's 4.0 name still works.
    let old_name = build("old-name.fmrh", &["--blocks-alone"]);
    assert_eq!(
        std::fs::read(&alone).unwrap(),
        std::fs::read(&old_name).unwrap()
    );
    let open = |p: &std::path::Path| Store::open(p).unwrap();
    let (d, p, a) = (open(&default), open(&paged), open(&alone));
    assert_eq!(d.page_size(), 1024);
    assert_eq!(p.page_size(), 4096);
    assert!(coded_against(&d).0 > 0);
    assert!(d.nodes().unwrap().iter().any(|n| n.grid_against_parent));
    assert_eq!(coded_against(&a).0, 0);
    assert!(a.nodes().unwrap().iter().all(|n| !n.grid_against_parent));
    let size = |p: &std::path::Path| std::fs::metadata(p).unwrap().len();
    assert!(size(&default) < size(&paged), "1 KiB pages cost less");
    assert!(
        size(&default) < size(&alone),
        "coding against parents costs less"
    );
    let bits = |s: &Store<FileSource>| -> Vec<u32> {
        let w = s.read_window(s.domain().data_rect()).unwrap();
        w.samples().iter().map(|v| v.to_bits()).collect()
    };
    assert!(
        bits(&d) == bits(&p) && bits(&d) == bits(&a),
        "the variants read the same"
    );
    for path in [&default, &paged, &alone] {
        let report =
            fmrh::store::verify(FileSource::open(path).unwrap(), VerifyMode::Full).unwrap();
        assert!(report.valid, "{}: {report:#?}", path.display());
    }
    let bad = common::fmrh(&[
        "build",
        input.to_str().unwrap(),
        "-o",
        dir.path().join("bad.fmrh").to_str().unwrap(),
        "--page-size",
        "3000",
    ]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("page size"));
    assert!(!dir.path().join("bad.fmrh").exists());
}

/// A loader that already holds a parent's decoded grid (a renderer drew the parent in an
/// earlier frame) need not read it again: `load_blocks_reusing` decodes the same heights
/// from the held grid and reads only the blocks' own payloads; the store keeps the grids a
/// load decoded for the next one; a held grid of the wrong size is not used (the grid is
/// read instead).
#[test]
fn a_held_parent_grid_is_not_read_again() {
    use fmrh::scene::{load_blocks, load_blocks_reusing, Camera, SceneOptions, Terrain};
    use std::collections::HashMap;
    use std::sync::Arc;

    let field = hills(129, 129);
    let bytes = bytes_of(&field, 33, &WriteOptions::default());
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let terrain = Terrain::new(&store).unwrap();
    let cam = Camera::looking_at(
        glam::DVec3::new(64.0, 64.0, 900.0),
        glam::DVec3::new(64.0, 65.0, 0.0),
    );
    let scene = terrain.scene(&cam, &SceneOptions::new(0.01)).unwrap();
    let finest = store.domain().finest_level();
    let parents: Vec<u32> = scene
        .blocks
        .iter()
        .filter(|b| b.level == finest)
        .filter_map(|b| store.stored_block(b.x, b.y).unwrap().against)
        .collect();
    assert!(
        !parents.is_empty(),
        "the scene has blocks coded against parents"
    );
    // The grids a renderer would hold, decoded by another store (this one caches nothing yet).
    let other = Store::from_bytes(bytes.clone()).unwrap();
    let grids: HashMap<u32, Arc<[f32]>> = parents
        .iter()
        .map(|&n| {
            let node = other.node(n).unwrap();
            (n, Arc::from(other.grid(&node).unwrap().view().expanded()))
        })
        .collect();
    let own: u64 = scene.blocks.iter().map(|b| u64::from(b.payload.len)).sum();

    let before = store.read_stats();
    let plain = load_blocks(&store, &scene.blocks, 0).unwrap();
    let read_plain = store.read_stats().since(&before).payload_bytes;
    assert!(read_plain > own, "the parents' grids were read");

    let before = store.read_stats();
    let held = |n: u32, _: &fmrh::format::StoredNode| grids.get(&n).cloned();
    let reused = load_blocks_reusing(&store, &scene.blocks, 0, &held).unwrap();
    assert_eq!(store.read_stats().since(&before).payload_bytes, own);
    for (a, b) in plain.iter().zip(&reused) {
        assert_eq!(a.heights, b.heights);
        assert_eq!(b.parent_bytes, 0);
    }

    // The store keeps the grids it decoded for the next load (Store::parent_grid).
    let before = store.read_stats();
    let again = load_blocks(&store, &scene.blocks, 0).unwrap();
    assert_eq!(store.read_stats().since(&before).payload_bytes, own);
    for (a, b) in plain.iter().zip(&again) {
        assert_eq!(a.heights, b.heights);
    }

    // Held grids that do not fit are not used: a fresh store (nothing cached) reads them.
    let fresh = Store::from_bytes(bytes.clone()).unwrap();
    let wrong = |_: u32, _: &fmrh::format::StoredNode| Some(Arc::from(vec![0.0f32; 7]));
    let before = fresh.read_stats();
    let fallback = load_blocks_reusing(&fresh, &scene.blocks, 0, &wrong).unwrap();
    assert_eq!(fresh.read_stats().since(&before).payload_bytes, read_plain);
    for (a, b) in plain.iter().zip(&fallback) {
        assert_eq!(a.heights, b.heights);
    }
}
