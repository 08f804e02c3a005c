//! Lean reads: opening a container reads one small prefix (the commit slots and the
//! metadata bundle, or without a bundle the dataset header and the cluster directory: at
//! most 16 KiB on a real DEM). Without a bundle every deeper page is read and checked when a
//! lookup first reaches it, then served from the page cache, so a second scene over the same
//! region reads no metadata at all; with one, no scene reads metadata. Payload batches
//! (`Store::payloads`) return exactly what single reads return, in the order asked, with
//! payloads coalesced into fewer reads, on every kind of source; a damaged payload in a batch
//! is still a corruption error naming the file. The scheduler keeps blocks decoded: heights
//! it hands out equal the blocks' own, and a frame that sees the same blocks decodes nothing.

mod common;

use std::sync::Arc;

use glam::DVec3;
use proptest::prelude::*;

use common::views;
use fmrh::model::BuildOptions;
use fmrh::scene::{load_blocks, Camera, SceneOptions, ScheduleOptions, Scheduler, Terrain};
use fmrh::store::{Bytes, FileSource, PayloadRef};
use fmrh::{store::Store, Error};

/// Puget Sound 1k with every table in pages of its own (no metadata bundle): the layout of
/// a file whose metadata is too large to bundle, whose pages are read as lookups reach them.
fn puget() -> &'static views::Fixture {
    static F: std::sync::OnceLock<views::Fixture> = std::sync::OnceLock::new();
    F.get_or_init(|| {
        views::fixture_written(
            views::puget_1k(),
            &BuildOptions::default(),
            &fmrh::store::WriteOptions {
                bundle_limit: 0,
                ..Default::default()
            },
        )
    })
}

/// Puget Sound 1k as `fmrh build` writes it: its metadata in one bundle.
fn puget_bundled() -> &'static views::Fixture {
    static F: std::sync::OnceLock<views::Fixture> = std::sync::OnceLock::new();
    F.get_or_init(|| views::fixture(views::puget_1k(), &BuildOptions::default()))
}

fn on_disk() -> (tempfile::TempDir, std::path::PathBuf) {
    write_out(puget())
}

fn write_out(f: &views::Fixture) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.fmrh");
    std::fs::write(&path, &f.store.source().0).unwrap();
    (dir, path)
}

fn camera() -> Camera {
    Camera::looking_at(
        DVec3::new(20_000.0, 150_000.0, 5_000.0),
        DVec3::new(90_000.0, 80_000.0, 0.0),
    )
}

#[test]
fn opening_reads_a_small_prefix_and_pages_are_read_once() {
    let (_dir, path) = on_disk();
    let store = Store::open(&path).unwrap();
    let open = store.open_reads();
    assert!(open.bytes() <= 16 * 1024, "{open:?}");
    assert_eq!(open.payload_bytes, 0);
    assert_eq!(
        store.read_stats(),
        Default::default(),
        "opening counted as lookups"
    );

    let terrain = Terrain::new(&store).unwrap();
    let before = store.read_stats();
    let first = terrain.scene(&camera(), &SceneOptions::new(1.0)).unwrap();
    let after_first = store.read_stats();
    let scheduled = after_first.since(&before);
    assert!(scheduled.metadata_reads > 0);
    assert_eq!(scheduled.payload_reads, 0);
    // The same scene again: every page it needs is cached.
    let second = terrain.scene(&camera(), &SceneOptions::new(1.0)).unwrap();
    assert_eq!(first.blocks, second.blocks);
    assert_eq!(store.read_stats().since(&after_first), Default::default());
    // Each page was read once: no more reads than the pages of the file.
    assert!(scheduled.metadata_reads <= store.page_count());
    // The lean store answers as the in-memory one does.
    let mem = Terrain::new(&puget().store).unwrap();
    assert_eq!(
        mem.scene(&camera(), &SceneOptions::new(1.0))
            .unwrap()
            .blocks,
        first.blocks
    );
}

/// With the metadata in a bundle, opening is the slots and one read of the bundle, and no
/// scene reads a metadata page: the same scenes as the paged file, from fewer reads.
#[test]
fn a_bundled_file_opens_in_three_reads_and_schedules_from_memory() {
    let (_dir, path) = write_out(puget_bundled());
    let store = Store::open(&path).unwrap();
    let layout = store.layout().unwrap();
    assert!(layout.bundle_bytes > 0 && layout.node_table_pages == 0);
    let open = store.open_reads();
    assert!(open.bytes() <= 16 * 1024, "{open:?}");
    assert!(
        open.bytes() < layout.bundle_bytes + 4096,
        "slots and bundle only: {open:?}"
    );
    let terrain = Terrain::new(&store).unwrap();
    let before = store.read_stats();
    let scene = terrain.scene(&camera(), &SceneOptions::new(1.0)).unwrap();
    assert_eq!(store.read_stats().since(&before), Default::default());
    let paged = Terrain::new(&puget().store).unwrap();
    assert_eq!(
        paged
            .scene(&camera(), &SceneOptions::new(1.0))
            .unwrap()
            .blocks,
        scene.blocks
    );
    // The paged file reads pages for the same scene; the bundled file is the smaller.
    assert!(layout.file_length < puget().store.layout().unwrap().file_length);
}

fn n_len(b: &serde_json::Value) -> u64 {
    b["payload"]["len"].as_u64().unwrap()
}

/// The payload bytes loading `blocks` (each `(level, x, y, payload bytes)`) must read: their
/// own, and once each the grid of every parent a physical block is coded against (format 4).
/// The payload bytes of `blocks` (level, x, y, own payload length) and of every ancestor
/// their payloads decode with, each once: the grid a physical block is coded against (format
/// 4), and up the chain of grids coded against their parents (format 5).
fn payload_bytes_with_parents<S: fmrh::store::Source>(
    store: &Store<S>,
    blocks: impl IntoIterator<Item = (u8, u32, u32, u64)>,
) -> u64 {
    let finest = store.domain().finest_level();
    let nodes = store.nodes().unwrap();
    let at: std::collections::HashMap<(u8, u32, u32), u32> = nodes
        .iter()
        .enumerate()
        .map(|(i, n)| ((n.level, n.x, n.y), i as u32))
        .collect();
    let up = |i: u32| {
        let n = &nodes[i as usize];
        n.grid_against_parent.then(|| n.parent.unwrap())
    };
    let mut ancestors = std::collections::BTreeSet::new();
    let mut total = 0;
    for (level, x, y, len) in blocks {
        total += len;
        let mut next = if level == finest {
            store.stored_block(x, y).unwrap().against
        } else {
            up(at[&(level, x, y)])
        };
        while let Some(i) = next {
            ancestors.insert(i);
            next = up(i);
        }
    }
    total
        + ancestors
            .into_iter()
            .map(|n| u64::from(nodes[n as usize].payload.len))
            .sum::<u64>()
}

fn scene_payload_bytes<S: fmrh::store::Source>(
    store: &Store<S>,
    blocks: &[fmrh::scene::SceneBlock],
) -> u64 {
    payload_bytes_with_parents(
        store,
        blocks
            .iter()
            .map(|b| (b.level, b.x, b.y, u64::from(b.payload.len))),
    )
}

fn all_refs() -> Vec<PayloadRef> {
    let s = &puget().store;
    let mut refs: Vec<PayloadRef> = s.nodes().unwrap().iter().map(|n| n.payload).collect();
    let (cols, rows) = s.domain().nodes_across(s.domain().finest_level());
    for y in 0..rows {
        for x in 0..cols {
            refs.push(s.stored_block(x, y).unwrap().payload);
        }
    }
    refs
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Any selection of payloads, in any order and with repeats, at any gap: the batch
    /// returns what single reads return, and never more reads than payloads.
    #[test]
    fn batches_equal_single_reads(
        picks in prop::collection::vec(any::<prop::sample::Index>(), 0..60),
        gap in prop::sample::select(vec![0u64, 100, 4096, 1 << 20]),
    ) {
        let refs = all_refs();
        let chosen: Vec<PayloadRef> = picks.iter().map(|i| refs[i.index(refs.len())]).collect();
        let (_dir, path) = on_disk();
        let file = Store::open(&path).unwrap();
        let mem = &puget().store;
        let before = file.read_stats();
        let batch = file.payloads(&chosen, gap).unwrap();
        let used = file.read_stats().since(&before);
        prop_assert!(used.payload_reads <= chosen.len() as u64);
        prop_assert_eq!(batch.len(), chosen.len());
        let in_memory = mem.payloads(&chosen, gap).unwrap();
        for ((r, a), b) in chosen.iter().zip(&batch).zip(&in_memory) {
            let single = mem.payload(*r).unwrap();
            prop_assert_eq!(&**a, &*single);
            prop_assert_eq!(&**b, &*single);
        }
    }
}

#[test]
fn touching_payloads_share_a_read() {
    let (_dir, path) = on_disk();
    let store = Store::open(&path).unwrap();
    let terrain = Terrain::new(&store).unwrap();
    let scene = terrain.scene(&camera(), &SceneOptions::new(0.5)).unwrap();
    let before = store.read_stats();
    let loaded = load_blocks(&store, &scene.blocks, 0).unwrap();
    let used = store.read_stats().since(&before);
    assert_eq!(loaded.len(), scene.blocks.len());
    assert!(
        used.payload_reads * 2 < scene.blocks.len() as u64,
        "{} reads for {} blocks",
        used.payload_reads,
        scene.blocks.len()
    );
    let stored = scene_payload_bytes(&store, &scene.blocks);
    assert_eq!(
        used.payload_bytes, stored,
        "gap 0 reads no byte between payloads, and every grid a block is coded against"
    );
    // Each loaded block draws what the store's own decoding gives.
    for (b, l) in scene.blocks.iter().zip(&loaded) {
        let want = match b.node.filter(|_| b.level < store.domain().finest_level()) {
            Some(i) => store
                .grid(&store.node(i).unwrap())
                .unwrap()
                .view()
                .expanded(),
            None => store.block(b.x, b.y).unwrap().view().mended(),
        };
        assert_eq!(&*l.heights, &want[..]);
    }
}

#[test]
fn a_damaged_payload_in_a_batch_is_corruption_named() {
    let mut bytes = puget().store.source().0.clone();
    let refs = all_refs();
    let victim = refs[refs.len() / 2];
    bytes[victim.offset as usize + 1] ^= 0x40;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.fmrh");
    std::fs::write(&path, &bytes).unwrap();
    let store = Store::from_source(FileSource::open(&path).unwrap()).unwrap();
    let err = store.payloads(&refs, 4096).unwrap_err();
    assert!(
        matches!(err, Error::Corrupt { .. }) && err.to_string().contains("damaged.fmrh"),
        "{err}"
    );
    let mem = Store::from_bytes(bytes).unwrap();
    assert!(matches!(mem.payloads(&refs, 0), Err(Error::Corrupt { .. })));
}

#[test]
fn the_scheduler_decodes_each_block_once() {
    let store = Arc::new(Store::from_source(Bytes(puget().store.source().0.clone())).unwrap());
    let mut s = Scheduler::new(Arc::clone(&store), ScheduleOptions::new(1.0)).unwrap();
    let first = s.frame(&camera()).unwrap();
    assert!(!first.load.is_empty());
    for id in &first.load {
        let l = s.block(id).unwrap();
        let b = s
            .resident()
            .find(|b| (b.level, b.x, b.y) == (id.level, id.x, id.y))
            .unwrap();
        assert_eq!(l.stored.len() as u32, b.payload.len);
        assert_eq!(s.payload(id).unwrap(), &*l.stored);
    }
    let heights = Arc::clone(&s.block(&first.load[0]).unwrap().heights);
    let again = s.frame(&camera()).unwrap();
    assert!(again.load.is_empty());
    assert_eq!(again.stats.loaded_bytes, 0);
    // The very same decoded heights, not a second decoding.
    assert!(Arc::ptr_eq(
        &heights,
        &s.block(&first.load[0]).unwrap().heights
    ));
}

/// Regression (fuzzing, open_verify, lean open): a node record whose level lies below the
/// finest level, in a page whose checksums were made right, reached the scene's geometry
/// (a shift by a negative amount). Table pages are no longer walked at open, so every node a
/// lookup returns is checked to be a node of the domain.
#[test]
fn a_node_below_the_finest_level_is_corruption_not_a_panic() {
    let mut bytes = common::vector("hills-20x13-voids-paged.fmrh");
    let p = 1024usize;
    let root = u64::from_le_bytes(bytes[72..80].try_into().unwrap()) as usize;
    let depth = u16::from_le_bytes(bytes[88..90].try_into().unwrap());
    assert_eq!(depth, 1, "the vector's node table is one leaf");
    let page = &mut bytes[root * p..(root + 1) * p];
    assert_eq!(&page[..4], b"FMNT");
    // Record 1 starts after the 24-byte page header and one 80-byte record; its level at +8.
    page[24 + 80 + 8] = 200;
    let crc = crc32fast::hash(&page[8..]);
    page[4..8].copy_from_slice(&crc.to_le_bytes());
    let store = Store::from_bytes(&bytes[..]).unwrap();
    match store.node(1) {
        Err(Error::Corrupt { invariant, .. }) => {
            assert_eq!(invariant, fmrh::types::Invariant::NodeTable)
        }
        other => panic!("{other:?}"),
    }
    assert!(store.nodes().is_err());
    let terrain = Terrain::new(&store).unwrap();
    let cam = Camera::looking_at(DVec3::new(10.0, 40.0, 30.0), DVec3::new(10.0, 6.0, 0.0));
    assert!(terrain.scene(&cam, &SceneOptions::new(0.1)).is_err());
}

/// A reader that did not register, on a file read with `pread`, checks on the first read of
/// each page that fewer than 2^16 - 1 transactions have committed since its state's pages
/// were written (format §4): past that, a page could carry a reused 16-bit tag, so the read
/// is refused as superseded instead of trusted.
#[test]
fn an_unregistered_reader_refuses_pages_after_a_tag_wrap() {
    struct Unregistered(FileSource);
    impl fmrh::store::Source for Unregistered {
        fn len(&self) -> u64 {
            self.0.len()
        }
        fn read_at(&self, offset: u64, len: usize) -> std::io::Result<std::borrow::Cow<'_, [u8]>> {
            self.0.read_at(offset, len)
        }
        fn stable(&self) -> bool {
            false
        }
        fn name(&self) -> &std::path::Path {
            self.0.name()
        }
    }
    let (_dir, path) = on_disk();
    let store = Store::from_source(Unregistered(FileSource::open(&path).unwrap())).unwrap();
    assert!(!store.is_registered());
    let first = store.node(0).unwrap();
    // A newer record in slot 1, 70,000 transactions on (same roots, valid CRC).
    let mut bytes = std::fs::read(&path).unwrap();
    let p = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut record = bytes[..256].to_vec();
    record[16..24].copy_from_slice(&70_000u64.to_le_bytes());
    let crc = crc32fast::hash(&record[..252]);
    record[252..256].copy_from_slice(&crc.to_le_bytes());
    bytes[p..p + 256].copy_from_slice(&record);
    std::fs::write(&path, &bytes).unwrap();
    // A page already read and kept is this state's page: still served.
    assert_eq!(store.node(0).unwrap(), first);
    // A page read for the first time is refused.
    let last = u32::try_from(store.header().node_count - 1).unwrap();
    match store.node(last) {
        Err(Error::Superseded { latest, .. }) => assert_eq!(latest, 70_000),
        other => panic!("{other:?}"),
    }
}

/// `fmrh scene --load` and `fmrh fly` report what they read: opening within 16 KiB, a
/// scene's payload bytes exactly its blocks' and their parents' grids they are coded against
/// (touching payloads are read together, no byte between them), and a fly-through's metadata read once however many frames reuse it.
#[test]
fn the_cli_reports_reads() {
    let (_dir, path) = on_disk();
    let p = path.to_str().unwrap();
    let scene_json = |extra: &[&str]| {
        let mut args = vec![
            "scene",
            p,
            "--eye",
            "20000,150000,5000",
            "--target",
            "90000,80000,0",
            "--tau",
            "1",
            "--json",
        ];
        args.extend_from_slice(extra);
        common::ok_json(&common::fmrh(&args))
    };
    let scene = scene_json(&["--load"]);
    let reads = &scene["reads"];
    assert!(reads["open"]["metadata_bytes"].as_u64().unwrap() <= 16384);
    assert_eq!(reads["schedule"]["payload_bytes"], 0);
    let stored = payload_bytes_with_parents(
        &Store::open(&path).unwrap(),
        scene["blocks"].as_array().unwrap().iter().map(|b| {
            let n = |k: &str| b[k].as_u64().unwrap();
            (n("level") as u8, n("x") as u32, n("y") as u32, n_len(b))
        }),
    );
    assert!(
        stored
            > scene["blocks"]
                .as_array()
                .unwrap()
                .iter()
                .map(n_len)
                .sum::<u64>(),
        "this scene has blocks coded against their parents' grids"
    );
    assert_eq!(reads["load"]["payload_bytes"].as_u64().unwrap(), stored);
    let without = scene_json(&[]);
    assert!(without["reads"]["load"].is_null());

    let route =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/paths/puget-1k-orbit.csv");
    let fly = common::ok_json(&common::fmrh(&[
        "fly",
        p,
        "--path",
        route.to_str().unwrap(),
        "--tau",
        "1",
        "--json",
    ]));
    let frames = fly["frames"].as_array().unwrap().len() as u64;
    let metadata = fly["reads"]["path"]["metadata_reads"].as_u64().unwrap();
    let pages = std::fs::metadata(&path).unwrap().len() / 4096;
    assert!(
        frames > 100 && metadata <= pages,
        "{metadata} page reads over {frames} frames"
    );
}

/// A page is checked once, but every reference still gets the kind of page it expects: a
/// damaged (and resealed) commit record whose node table root names the block table's root
/// page is refused when a node lookup reaches that page, even after a block lookup checked
/// and cached it, on a mapping-like source and on a `pread` file alike.
#[test]
fn a_cached_page_of_another_table_is_refused() {
    let mut bytes = common::vector("hills-20x13-voids.fmrh");
    let block_root = bytes[96..104].to_vec();
    assert_eq!(
        bytes[88..90],
        bytes[112..114],
        "both trees have the same depth"
    );
    bytes[72..80].copy_from_slice(&block_root);
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("crossed.fmrh");
    std::fs::write(&path, &bytes).unwrap();
    let check = |store_node: Result<fmrh::store::StoredNode, Error>| match store_node {
        Err(Error::Corrupt {
            invariant, detail, ..
        }) => {
            assert_eq!(invariant, fmrh::types::Invariant::Page);
            assert!(detail.contains("FMBT"), "{detail}");
        }
        other => panic!("{other:?}"),
    };
    let mem = Store::from_bytes(&bytes[..]).unwrap();
    mem.stored_block(0, 0).unwrap();
    check(mem.node(0));
    let file = Store::open(&path).unwrap();
    file.stored_block(0, 0).unwrap();
    check(file.node(0));
}
