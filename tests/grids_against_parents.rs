//! Grids coded against their parent's grid (format 5.0, container.md §6.1 and §7): a node's
//! coarse grid may store only the heights its parent's grid does not hold, so decoding it
//! needs its ancestors' grids, up to one coded alone. The properties checked here: every grid
//! decodes, through its chain, to exactly the heights it holds coded alone; a scene reads
//! every ancestor its blocks decode with and counts those bytes, each once; a commit codes
//! payloads again at most one level below a changed grid, never down the whole tree, and the
//! file still reads back and verifies; a flag on the root, a flag in a file older than 5.0,
//! and a damaged grandparent are corruption; void bitmaps on a sheet's edges cost a few bytes
//! (runs, §7), not a bitmap each.

mod common;

use std::collections::{BTreeMap, HashSet};

use common::bytes_of;
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain};
use fmrh::store::{Container, FileSource, WriteOptions};
use fmrh::CreateOptions;
use fmrh::{store::Store, store::VerifyMode, types::Invariant, Error, Heightfield};

fn alone() -> WriteOptions {
    WriteOptions {
        against_parents: false,
        ..WriteOptions::default()
    }
}

/// Smooth integer hills with a rough band: the lattice case.
fn hills(w: u32, h: u32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        let (x, y) = (x as f32 * 0.05, y as f32 * 0.07);
        (400.0 + 120.0 * x.sin() * y.cos() + 30.0 * (2.3 * x + y).sin()).round()
    })
    .unwrap()
}

/// Full-precision float hills (no lattice), as dem_hills stores them.
fn float_hills(w: u32, h: u32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32 * 0.031, y as f32 * 0.043);
        150.0 + 9.0 * fx.sin() * fy.cos() + 0.37 * (7.1 * fx + 3.3 * fy).sin()
    })
    .unwrap()
}

fn verify_full(bytes: Vec<u8>) -> fmrh::store::VerifyReport {
    fmrh::store::verify(fmrh::store::Bytes(bytes), VerifyMode::Full).unwrap()
}

#[test]
fn grids_decode_through_their_chains_to_the_heights_coded_alone() {
    for field in [hills(300, 230), float_hills(300, 230)] {
        let with = bytes_of(&field, 33, &WriteOptions::default());
        let plain = bytes_of(&field, 33, &alone());
        let a = Store::from_bytes(with.clone()).unwrap();
        let b = Store::from_bytes(plain.clone()).unwrap();
        assert_eq!(
            a.state().format_version,
            (fmrh::format::FORMAT_MAJOR, fmrh::format::FORMAT_MINOR)
        );
        let nodes = a.nodes().unwrap();
        let finest = a.domain().finest_level();
        let flagged: HashSet<u32> = (0..nodes.len() as u32)
            .filter(|&i| nodes[i as usize].grid_against_parent)
            .collect();
        assert!(!flagged.is_empty(), "no grid is coded against its parent");
        assert!(!nodes[0].grid_against_parent, "the root is coded alone");
        // Some chain is at least two grids deep.
        assert!(
            flagged.iter().any(|&i| nodes[i as usize]
                .parent
                .is_some_and(|p| flagged.contains(&p))),
            "every flagged grid's parent is coded alone"
        );
        assert!(b.nodes().unwrap().iter().all(|n| !n.grid_against_parent));
        for (i, n) in nodes.iter().enumerate().filter(|(_, n)| n.level < finest) {
            let ga = a.grid(n).unwrap();
            let gb = b.grid(&b.node(i as u32).unwrap()).unwrap();
            assert_eq!(ga.bytes(), gb.bytes(), "node {i}");
        }
        let (la, lb) = (a.layout().unwrap(), b.layout().unwrap());
        assert!(
            la.grid_bytes < lb.grid_bytes,
            "grids {} against {} coded alone",
            la.grid_bytes,
            lb.grid_bytes
        );
        assert!(verify_full(with).valid);
        assert!(verify_full(plain).valid);
    }
}

/// The ancestors a payload decodes with: the node it is coded against, then up the chain of
/// grids coded against their parents.
fn chain<S: fmrh::store::Source>(store: &Store<S>, block: &fmrh::scene::SceneBlock) -> Vec<u32> {
    let finest = store.domain().finest_level();
    let mut out = Vec::new();
    let mut at = if block.level == finest {
        store.stored_block(block.x, block.y).unwrap().against
    } else {
        let n = store.node(block.node.unwrap()).unwrap();
        n.grid_against_parent.then(|| n.parent.unwrap())
    };
    while let Some(i) = at {
        out.push(i);
        let n = store.node(i).unwrap();
        at = n.grid_against_parent.then(|| n.parent.unwrap());
    }
    out
}

#[test]
fn a_scene_reads_every_ancestor_it_decodes_with_and_counts_it_once() {
    let field = float_hills(513, 513);
    let with = bytes_of(&field, 17, &WriteOptions::default());
    let plain = bytes_of(&field, 17, &alone());
    let store = Store::from_bytes(with).unwrap();
    let terrain = Terrain::new(&store).unwrap();
    let cam = Camera::looking_at(
        glam::DVec3::new(-40.0, -40.0, 30.0),
        glam::DVec3::new(400.0, 420.0, 0.0),
    );
    let scene = terrain.scene(&cam, &SceneOptions::new(2.0)).unwrap();
    let levels: HashSet<u8> = scene.blocks.iter().map(|b| b.level).collect();
    assert!(levels.len() >= 2, "a scene of one level: {levels:?}");
    let mut ancestors = BTreeMap::new();
    for b in &scene.blocks {
        for i in chain(&store, b) {
            ancestors.insert(i, store.node(i).unwrap().payload.len);
        }
    }
    assert!(
        ancestors
            .keys()
            .any(|&i| store.node(i).unwrap().grid_against_parent),
        "no chain longer than one grid"
    );
    let own: u64 = scene.blocks.iter().map(|b| u64::from(b.payload.len)).sum();
    let extra: u64 = ancestors.values().map(|&l| u64::from(l)).sum();
    let before = store.read_stats();
    let loaded = load_blocks(&store, &scene.blocks, 0).unwrap();
    assert_eq!(store.read_stats().since(&before).payload_bytes, own + extra);
    assert_eq!(loaded.iter().map(|l| l.parent_bytes).sum::<u64>(), extra);
    // The same heights as the file whose payloads are all coded alone.
    let other = Store::from_bytes(plain).unwrap();
    let terrain = Terrain::new(&other).unwrap();
    let same = terrain.scene(&cam, &SceneOptions::new(2.0)).unwrap();
    let expected = load_blocks(&other, &same.blocks, 0).unwrap();
    assert_eq!(loaded.len(), expected.len());
    for (a, b) in loaded.iter().zip(&expected) {
        assert_eq!(a.heights, b.heights);
        assert_eq!(b.parent_bytes, 0);
    }
}

#[test]
fn a_commit_codes_again_at_most_one_level_below_a_changed_grid() {
    // A float field, and a separable one (f(x) + g(y), on a lattice), where the planar
    // prediction is nearly exact and wins.
    let separable = Heightfield::from_fn(257, 257, |x, y| {
        (300.0 + 40.0 * (x as f32 * 0.37).sin() + 25.0 * (y as f32 * 0.23).cos()).round()
    })
    .unwrap();
    let kept_planar: usize = [float_hills(257, 257), separable]
        .into_iter()
        .map(commits_on)
        .sum();
    assert!(
        kept_planar > 0,
        "no planar payload was kept over a parent whose heights changed"
    );
}

/// Three 3 x 3 commits on `field`, each checked; the payloads kept planar over a parent
/// whose heights changed.
fn commits_on(field: Heightfield) -> usize {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hills.fmrh");
    fmrh::create(
        &path,
        field.clone(),
        &CreateOptions {
            block_size: 17,
            ..CreateOptions::default()
        },
    )
    .unwrap();
    let (levels, grids_total) = {
        let s = Store::open(&path).unwrap();
        let finest = s.domain().finest_level();
        let nodes = s.nodes().unwrap();
        assert!(nodes.iter().any(|n| n.grid_against_parent));
        (
            u64::from(finest),
            nodes.iter().filter(|n| n.level < finest).count() as u64,
        )
    };
    let mut expected = field.clone();
    // Kept payloads whose parent's heights changed: each must be a planar coding (7, 8),
    // which reads the parent only at its own samples.
    let mut kept_planar = 0;
    for (k, (col, row)) in [(100u64, 37u64), (3, 250), (128, 128)]
        .into_iter()
        .enumerate()
    {
        let before = payloads_of(&Store::open(&path).unwrap());
        let patch = common::txn::patch(3, 3, 40.0 + k as f32);
        let c = Container::open(&path).unwrap();
        let mut txn = c.begin_write().unwrap();
        txn.replace_region(col, row, &patch).unwrap();
        let summary = txn.commit().unwrap();
        drop(c);
        expected = common::txn::paste(&expected, col, row, &patch);
        // Per level above the finest: the changed grids (two at most, for a patch on a
        // shared edge, four at a corner) and the siblings coded against them.
        assert!(
            summary.grids <= 4 * 4 * levels,
            "{} of {grids_total} grids rewritten for one 3 x 3 patch",
            summary.grids
        );
        assert!(summary.grids < grids_total / 2, "{summary:?}");
        let store = Store::open(&path).unwrap();
        let back = store.read_window(store.domain().data_rect()).unwrap();
        assert_eq!(
            common::txn::digest_samples(back.samples()),
            common::txn::digest_samples(expected.samples())
        );
        // Every grid decodes to the heights a fresh build of the same samples holds at
        // that node: whatever the commit kept, coded anew or shared.
        let fresh_path = dir.path().join(format!("fresh-{k}.fmrh"));
        fmrh::create(
            &fresh_path,
            expected.clone(),
            &CreateOptions {
                block_size: 17,
                ..CreateOptions::default()
            },
        )
        .unwrap();
        let fresh = Store::open(&fresh_path).unwrap();
        let fresh_at: BTreeMap<(u8, u32, u32), usize> = fresh
            .nodes()
            .unwrap()
            .iter()
            .enumerate()
            .map(|(i, n)| ((n.level, n.x, n.y), i))
            .collect();
        let finest = store.domain().finest_level();
        for n in store.nodes().unwrap().iter().filter(|n| n.level < finest) {
            let i = fresh_at[&(n.level, n.x, n.y)];
            let want = fresh.grid(&fresh.node(i as u32).unwrap()).unwrap();
            assert_eq!(
                store.grid(n).unwrap().bytes(),
                want.bytes(),
                "grid ({}, {}, {})",
                n.level,
                n.x,
                n.y
            );
        }
        // A payload kept over a parent whose payload was written again: when the patch
        // lies in the parent's footprint (its heights changed), only a planar coding may
        // stay; otherwise the parent was only coded anew, and any coding stays. A small
        // payload (at most 256 bytes) may also be the same reference because the commit
        // coded it anew to the same bytes and shared the stored copy (container.md §11.2):
        // the comparison with the fresh build above shows it right.
        let d = *store.domain();
        let patch_rect = fmrh::model::SampleRect {
            col0: col,
            row0: row,
            col1: col + 2,
            row1: row + 2,
        };
        for now in payloads_of(&store) {
            let Some(old) = before.iter().find(|b| b.at == now.at) else {
                continue;
            };
            if old.payload == now.payload && now.against.is_some() && old.against != now.against {
                let (level, x, y) = now.at;
                let parent_rect = d.footprint(level - 1, x / 2, y / 2);
                if parent_rect.intersect(&patch_rect).is_some() {
                    let encoding = store.payload(now.payload).unwrap()[4];
                    // The planar codings: 7 and 8, their tANS twins 13 and 14 (format 7).
                    let planar = matches!(encoding, 7 | 8 | 13 | 14);
                    if !planar && now.payload.len <= 256 {
                        continue;
                    }
                    assert!(
                        planar,
                        "{:?} kept with encoding {encoding} over changed heights",
                        now.at
                    );
                    kept_planar += 1;
                }
            }
        }
        drop(store);
        let report =
            fmrh::store::verify(FileSource::open(&path).unwrap(), VerifyMode::Full).unwrap();
        assert!(report.valid, "{report:#?}");
    }
    kept_planar
}

/// A node's payload and, when it is coded against its parent's grid, that grid's payload.
struct Coded {
    at: (u8, u32, u32),
    payload: fmrh::format::PayloadRef,
    against: Option<fmrh::format::PayloadRef>,
}

fn payloads_of<S: fmrh::store::Source>(s: &Store<S>) -> Vec<Coded> {
    let nodes = s.nodes().unwrap();
    let finest = s.domain().finest_level();
    nodes
        .iter()
        .map(|n| {
            let against = if n.level == finest {
                s.stored_block(n.x, n.y).unwrap().against
            } else {
                n.grid_against_parent.then(|| n.parent.unwrap())
            };
            Coded {
                at: (n.level, n.x, n.y),
                payload: n.payload,
                against: against.map(|p| nodes[p as usize].payload),
            }
        })
        .collect()
}

/// Sets or clears flag bit 1 of node `ordinal` (record offset 10) in the node table pages of a
/// bundled file.
fn set_node_flag(bytes: &mut Vec<u8>, ordinal: usize, on: bool) {
    let p = common::bundle::page_size(bytes);
    common::bundle::rewrite(bytes, |pages| {
        let mut seen = 0usize;
        for page in pages.chunks_mut(p).filter(|pg| &pg[0..4] == b"FMNT") {
            // Page header (§4): level u16 at 16, record count u32 at 20.
            let level = u16::from_le_bytes([page[16], page[17]]);
            let count = u32::from_le_bytes([page[20], page[21], page[22], page[23]]) as usize;
            if level != 0 {
                continue; // a branch page
            }
            if ordinal < seen + count {
                let at = 24 + 80 * (ordinal - seen) + 10;
                let flags = u16::from_le_bytes([page[at], page[at + 1]]);
                let flags = if on { flags | 2 } else { flags & !2 };
                page[at..at + 2].copy_from_slice(&flags.to_le_bytes());
                common::bundle::reseal_page(page);
                return;
            }
            seen += count;
        }
        panic!("no node {ordinal}");
    });
}

#[test]
fn a_flag_on_the_root_or_before_format_5_is_corrupt() {
    let field = hills(129, 129);
    let bytes = bytes_of(&field, 33, &WriteOptions::default());
    let mut bad = bytes.clone();
    set_node_flag(&mut bad, 0, true);
    let store = Store::from_bytes(bad.clone()).unwrap();
    let root = store.node(0).unwrap();
    assert!(root.grid_against_parent);
    match store.grid(&root) {
        Err(e @ Error::Corrupt { .. }) => assert!(e.to_string().contains("root"), "{e}"),
        other => panic!("{other:?}"),
    }
    let report = verify_full(bad);
    assert!(!report.valid);
    assert!(
        report
            .checks
            .iter()
            .any(|c| c.id == Invariant::NodeTable && c.failures.iter().any(|f| f.contains("root"))),
        "{report:#?}"
    );
    // A grid coded against its parent whose flag is cleared does not decode alone.
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let flagged = (0..store.nodes().unwrap().len())
        .find(|&i| store.node(i as u32).unwrap().grid_against_parent)
        .expect("a flagged grid");
    drop(store);
    let mut bad = bytes;
    set_node_flag(&mut bad, flagged, false);
    let store = Store::from_bytes(bad).unwrap();
    assert!(matches!(
        store.grid(&store.node(flagged as u32).unwrap()),
        Err(Error::Corrupt { .. })
    ));
    // A 4.0 file has no such flag: bit 1 is reserved there.
    let v4 = std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("format-spec/vectors/v4.0/hills-20x13-voids.fmrh"),
    )
    .unwrap();
    assert_eq!(
        Store::from_bytes(v4.clone())
            .unwrap()
            .state()
            .format_version,
        (4, 0)
    );
    let mut bad = v4;
    set_node_flag(&mut bad, 1, true);
    let report = verify_full(bad.clone());
    assert!(
        report
            .checks
            .iter()
            .any(|c| c.id == Invariant::NodeTable && !c.failures.is_empty()),
        "{report:#?}"
    );
    let store = Store::from_bytes(bad).unwrap();
    assert!(matches!(
        store.grid(&store.node(1).unwrap()),
        Err(Error::Corrupt { .. })
    ));
}

#[test]
fn a_damaged_grandparent_is_corruption_when_a_block_is_read() {
    let field = float_hills(257, 257);
    let mut bytes = bytes_of(&field, 17, &WriteOptions::default());
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let d = *store.domain();
    let (cols, rows) = d.nodes_across(d.finest_level());
    let (x, y, grand) = (0..rows)
        .flat_map(|y| (0..cols).map(move |x| (x, y)))
        .find_map(|(x, y)| {
            let p = store.stored_block(x, y).unwrap().against?;
            let pn = store.node(p).unwrap();
            pn.grid_against_parent.then(|| (x, y, pn.parent.unwrap()))
        })
        .expect("a block whose parent grid is coded against its own parent");
    let r = store.node(grand).unwrap().payload;
    assert!(store.block(x, y).is_ok());
    drop(store);
    bytes[r.offset as usize + r.len as usize / 2] ^= 0x10;
    let store = Store::from_bytes(bytes).unwrap();
    assert!(matches!(store.block(x, y), Err(Error::Corrupt { .. })));
}

#[test]
fn voids_on_a_sheets_edges_cost_a_few_bytes_each_block() {
    let solid = hills(257, 200);
    // The first two rows and the last column void, as a reprojected sheet's edges are.
    let edged = Heightfield::from_fn(257, 200, |x, y| {
        if y < 2 || x == 256 {
            f32::NAN
        } else {
            solid.samples()[y as usize * 257 + x as usize]
        }
    })
    .unwrap();
    let bytes = bytes_of(&edged, 65, &WriteOptions::default());
    let b = Store::from_bytes(bytes.clone()).unwrap();
    let d = *b.domain();
    let (cols, rows) = d.nodes_across(d.finest_level());
    let mut with_voids = 0;
    for y in 0..rows {
        for x in 0..cols {
            let sb = b.stored_block(x, y).unwrap();
            if sb.void_count == 0 {
                continue;
            }
            with_voids += 1;
            // The samples' code holds the bitmap behind a void flag (§7): runs of a few
            // bytes, where a raw bitmap would take up to 528.
            let bytes = b.payload(sb.payload).unwrap();
            let encoding = bytes[4];
            // The lattice codings put their step before the flag: 2, 5, 7 and (format 7)
            // their tANS twins 9, 11, 13, and 15.
            let flag_at = if matches!(encoding, 2 | 5 | 7 | 9 | 11 | 13 | 15) {
                13
            } else {
                5
            };
            assert_eq!(bytes[flag_at], fmrh::codec::voids::RUNS, "block ({x}, {y})");
            let after = &bytes[flag_at + 1..];
            let n = (sb.width * sb.height) as usize;
            let (bitmap, rest) =
                fmrh::codec::voids::read(bytes[flag_at], after, n, sb.width as usize).unwrap();
            assert!(bitmap.is_some());
            assert!(
                after.len() - rest.len() <= 12,
                "block ({x}, {y}): {} bytes of runs",
                after.len() - rest.len()
            );
        }
    }
    assert!(with_voids >= 4);
    let back = b.read_window(d.data_rect()).unwrap();
    for (p, q) in back.samples().iter().zip(edged.samples()) {
        assert!(p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan()));
    }
    assert!(verify_full(bytes).valid);
}
