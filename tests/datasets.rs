//! One tile or many gives the same terrain: a field cut into tiles that share their edge
//! rows and columns, built as a dataset, extracts to exactly the field's samples, every
//! window included, and its scenes satisfy what a single file's do: a scene with a window
//! covers every cell of the window (where a tile lies) exactly once, a frustum scene covers
//! no cell twice, every view block is within tau where it is seen and every uniform block
//! within the one static bound, and blocks on a tile border know the levels across it.
//! Fixed cases: holes read as voids and stay uncovered, tiles of different sizes, opening
//! reads only the manifest and a scene opens only the tiles it meets, the seam policies, and
//! a damaged manifest or tile is reported, located.

mod common;

use glam::DVec3;
use proptest::prelude::*;

use common::fields::{self, Character, Rng};
use common::tiles::{self, camera, check_scene, cuts};
use fmrh::dataset::{Dataset, DatasetScene, SeamPolicy};
use fmrh::format::Invariant;
use fmrh::model::SampleRect;
use fmrh::scene::{Camera, Mode, SceneOptions};
use fmrh::store::CheckStatus;

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    common::first_difference(a, b).is_none()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20, ..ProptestConfig::default() })]

    #[test]
    fn one_tile_or_many_gives_the_same_samples_and_scenes(
        w in 12u32..70,
        h in 12u32..70,
        k in 1usize..=2,
        character in fields::character(),
        voids in prop_oneof![Just(0.0), Just(0.05)],
        seed in any::<u64>(),
        tau in 0.5f64..6.0,
        uniform in any::<bool>(),
    ) {
        let field = fields::make(w, h, character, voids, seed);
        let mut rng = Rng::new(seed ^ 0x5eed);
        let rects = tiles::split(&field, &cuts(u64::from(w), k, &mut rng), &cuts(u64::from(h), k, &mut rng), &[]);
        let dir = tempfile::tempdir().unwrap();
        let ds_dir = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
        let ds = Dataset::open(&ds_dir).unwrap();
        prop_assert_eq!(ds.tiles_opened(), 0);
        let all = ds.grid();
        prop_assert_eq!((all.col1 + 1, all.row1 + 1), (u64::from(w), u64::from(h)));
        let whole = ds.read_window(all).unwrap();
        prop_assert!(same_bits(whole.samples(), field.samples()), "the dataset's samples differ from the field's");
        // A random window.
        let (c0, c1) = { let a = rng.next_u64() % u64::from(w); let b = rng.next_u64() % u64::from(w); (a.min(b), a.max(b)) };
        let (r0, r1) = { let a = rng.next_u64() % u64::from(h); let b = rng.next_u64() % u64::from(h); (a.min(b), a.max(b)) };
        let win = SampleRect { col0: c0, row0: r0, col1: c1, row1: r1 };
        let part = ds.read_window(win).unwrap();
        prop_assert!(same_bits(part.samples(), tiles::crop(&field, &win).samples()));
        // Scenes: with that window and with the frustum alone.
        let mode = if uniform { Mode::Uniform } else { Mode::View };
        let cam = camera(&mut rng, f64::from(w), f64::from(h));
        let options = SceneOptions { tau, mode, window: Some(win), gap: fmrh::scene::DEFAULT_GAP };
        let scene = ds.scene(&cam, &options, None).unwrap();
        check_scene(&scene, &field, &rects, &cam, mode, tau, Some(win));
        let frustum = ds.scene(&cam, &SceneOptions { window: None, ..options }, None).unwrap();
        check_scene(&frustum, &field, &rects, &cam, mode, tau, None);
        prop_assert!(tiles::verify(&ds_dir, fmrh::store::VerifyMode::Full).valid);
    }
}

#[test]
fn blocks_on_a_tile_border_know_the_levels_across_it() {
    let field = fields::make(65, 33, Character::Hills, 0.0, 7);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[32], &[], &[]);
    let ds = Dataset::open(&tiles::build(
        dir.path(),
        &field,
        &rects,
        &tiles::options(None),
    ))
    .unwrap();
    let cam = Camera::looking_at(
        DVec3::new(320.0, -200.0, 300.0),
        DVec3::new(320.0, 160.0, 0.0),
    );
    let window = SampleRect {
        col0: 0,
        row0: 0,
        col1: 64,
        row1: 32,
    };
    let options = SceneOptions {
        tau: 1.0,
        mode: Mode::View,
        window: Some(window),
        gap: 4,
    };
    let scene = ds.scene(&cam, &options, None).unwrap();
    let west: Vec<_> = scene
        .blocks
        .iter()
        .filter(|b| b.tile == rects_index(&ds, 0) && b.block.col1 == 32)
        .collect();
    let east: Vec<_> = scene
        .blocks
        .iter()
        .filter(|b| b.tile != rects_index(&ds, 0) && b.block.col0 == 32)
        .collect();
    assert!(!west.is_empty() && !east.is_empty());
    for b in &west {
        let n = b.block.neighbours[1].expect("a block on the shared edge has an east neighbour");
        // The levels across are those of the east tile's blocks that touch it.
        let touching: Vec<u8> = east
            .iter()
            .filter(|e| e.block.row0.max(b.block.row0) < e.block.row1.min(b.block.row1))
            .map(|e| e.block.level)
            .collect();
        assert_eq!(n.coarsest, *touching.iter().min().unwrap());
        assert_eq!(n.finest, *touching.iter().max().unwrap());
    }
    for b in &east {
        assert!(
            b.block.neighbours[3].is_some(),
            "{:?} has no west neighbour",
            b.block.rect()
        );
    }
}

/// The manifest index of the tile whose first column is `col0` and first row 0.
fn rects_index(ds: &Dataset, col0: u64) -> u64 {
    ds.tiles()
        .unwrap()
        .iter()
        .find(|t| t.rect().col0 == col0 && t.rect().row0 == 0)
        .unwrap()
        .index
}

#[test]
fn holes_read_as_voids_and_stay_uncovered() {
    let field = fields::make(41, 41, Character::Hills, 0.0, 3);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[20], &[20], &[3]);
    let ds_dir = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let ds = Dataset::open(&ds_dir).unwrap();
    assert_eq!(ds.tile_count(), 3);
    let all = ds.read_window(ds.grid()).unwrap();
    for row in 0..41u64 {
        for col in 0..41u64 {
            let v = all.samples()[(row * 41 + col) as usize];
            let held = rects.iter().any(|r| r.contains(col, row));
            let f = field.samples()[(row * 41 + col) as usize];
            assert!(
                if held {
                    v.to_bits() == f.to_bits()
                } else {
                    v.is_nan()
                },
                "({col}, {row}): {v} vs {f}"
            );
        }
    }
    let cam = Camera::looking_at(
        DVec3::new(200.0, -300.0, 500.0),
        DVec3::new(200.0, 200.0, 0.0),
    );
    let window = ds.grid();
    let scene = ds
        .scene(
            &cam,
            &SceneOptions {
                tau: 2.0,
                mode: Mode::View,
                window: Some(window),
                gap: 4,
            },
            None,
        )
        .unwrap();
    check_scene(&scene, &field, &rects, &cam, Mode::View, 2.0, Some(window));
    assert!(tiles::verify(&ds_dir, fmrh::store::VerifyMode::Fast).valid);
}

#[test]
fn tiles_may_differ_in_size() {
    let field = fields::make(90, 50, Character::Noise, 0.02, 11);
    let dir = tempfile::tempdir().unwrap();
    // Three tiles across of widths 61, 21 and 10, and two rows of heights 30 and 21.
    let rects = tiles::split(&field, &[60, 80], &[29], &[]);
    let ds_dir = tiles::build(
        dir.path(),
        &field,
        &rects,
        &tiles::options(Some(vec![0.0, 5.0, 40.0])),
    );
    let ds = Dataset::open(&ds_dir).unwrap();
    assert!(same_bits(
        ds.read_window(ds.grid()).unwrap().samples(),
        field.samples()
    ));
    let cam = Camera::looking_at(
        DVec3::new(450.0, 700.0, 400.0),
        DVec3::new(450.0, 100.0, 0.0),
    );
    for mode in [Mode::View, Mode::Uniform] {
        let scene = ds
            .scene(
                &cam,
                &SceneOptions {
                    tau: 1.0,
                    mode,
                    window: Some(ds.grid()),
                    gap: 4,
                },
                None,
            )
            .unwrap();
        check_scene(&scene, &field, &rects, &cam, mode, 1.0, Some(ds.grid()));
    }
}

#[test]
fn opening_reads_the_manifest_and_a_scene_opens_only_the_tiles_it_meets() {
    let field = fields::make(100, 100, Character::Hills, 0.0, 5);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[33, 66], &[33, 66], &[]);
    let ds = Dataset::open(&tiles::build(
        dir.path(),
        &field,
        &rects,
        &tiles::options(None),
    ))
    .unwrap();
    assert_eq!(ds.tile_count(), 9);
    assert_eq!(ds.tiles_opened(), 0);
    // The two slots and the head (256 bytes + 64 per tile page).
    assert_eq!(ds.open_reads().metadata_bytes, 2 * 256 + 256 + 64);
    let cam = Camera::looking_at(
        DVec3::new(100.0, 100.0, 300.0),
        DVec3::new(150.0, 150.0, 0.0),
    );
    let window = SampleRect {
        col0: 2,
        row0: 2,
        col1: 30,
        row1: 30,
    };
    let scene = window_scene(&ds, &cam, window);
    assert_eq!(scene.tiles.len(), 1);
    assert_eq!(ds.tiles_opened(), 1);
    // Across the corner of four tiles.
    let window = SampleRect {
        col0: 20,
        row0: 20,
        col1: 40,
        row1: 40,
    };
    let scene = window_scene(&ds, &cam, window);
    assert_eq!(scene.tiles.len(), 4);
    assert_eq!(ds.tiles_opened(), 4);
    check_scene(&scene, &field, &rects, &cam, Mode::View, 1.0, Some(window));
}

/// The view scene at tau 1 of `window`.
fn window_scene(ds: &Dataset, cam: &Camera, window: SampleRect) -> DatasetScene {
    let options = SceneOptions {
        tau: 1.0,
        mode: Mode::View,
        window: Some(window),
        gap: 4,
    };
    ds.scene(cam, &options, None).unwrap()
}

/// Two tiles whose shared column disagrees at row 5 (and is void at row 9 in the second).
fn disagreeing(dir: &std::path::Path) -> Vec<fmrh::dataset::TileInput> {
    let a = fields::make(17, 17, Character::Hills, 0.0, 1);
    let mut right: Vec<f32> = (0..17 * 17)
        .map(|i| a.samples()[(i / 17) * 17 + 16] + (i % 17) as f32)
        .collect();
    // Column 0 of the right tile is the left tile's column 16, but for two samples.
    for y in 0..17 {
        right[y * 17] = a.samples()[y * 17 + 16];
    }
    right[5 * 17] += 3.0;
    right[9 * 17] = f32::NAN;
    let b = fmrh::Heightfield::new(17, 17, right).unwrap();
    vec![
        fmrh::dataset::TileInput {
            path: tiles::write_f32(dir, "a", &a, 10.0),
            at: Some((0, 0)),
        },
        fmrh::dataset::TileInput {
            path: tiles::write_f32(dir, "b", &b, 10.0),
            at: Some((16, 0)),
        },
    ]
}

#[test]
fn a_strict_build_names_both_tiles_and_the_first_difference_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = disagreeing(dir.path());
    let out = dir.path().join("ds");
    let err = fmrh::dataset::build(
        &inputs,
        &out,
        &tiles::options(None),
        &fmrh::progress::Silent,
        &mut |_, _, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("a.f32") && err.contains("b.f32"), "{err}");
    assert!(err.contains("column 16, row 5"), "{err}");
    assert!(!out.exists());
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".fmrh"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn seam_policies_settle_the_shared_edge_in_both_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = disagreeing(dir.path());
    let a = fmrh::ingest::load(&inputs[0].path, &Default::default()).unwrap();
    let b = fmrh::ingest::load(&inputs[1].path, &Default::default()).unwrap();
    for policy in [SeamPolicy::First, SeamPolicy::Mean] {
        let out = dir.path().join(format!("ds-{policy:?}"));
        let options = fmrh::dataset::DatasetOptions {
            seam: policy,
            ..tiles::options(None)
        };
        fmrh::dataset::build(
            &inputs,
            &out,
            &options,
            &fmrh::progress::Silent,
            &mut |_, _, _, _| {},
        )
        .unwrap();
        let ds = Dataset::open(&out).unwrap();
        for t in ds.tiles().unwrap() {
            let store = ds.open_tile(&t).unwrap();
            let col = if t.rect().col0 == 0 { 16 } else { 0 };
            let edge = store
                .read_window(SampleRect {
                    col0: col,
                    row0: 0,
                    col1: col,
                    row1: 16,
                })
                .unwrap();
            for y in 0..17usize {
                let (va, vb) = (a.samples()[y * 17 + 16], b.samples()[y * 17]);
                let expect = match policy {
                    SeamPolicy::First => va,
                    _ if va.is_nan() || vb.is_nan() => f32::NAN,
                    _ => ((f64::from(va) + f64::from(vb)) / 2.0) as f32,
                };
                let got = edge.samples()[y];
                assert!(
                    got.to_bits() == expect.to_bits() || got.is_nan() && expect.is_nan(),
                    "{policy:?} row {y}: {got} vs {expect}"
                );
            }
        }
        assert!(tiles::verify(&out, fmrh::store::VerifyMode::Full).valid);
    }
}

fn failed(report: &fmrh::dataset::DatasetReport) -> Vec<Invariant> {
    report
        .checks
        .iter()
        .filter(|c| c.status == CheckStatus::Failed)
        .map(|c| c.id)
        .collect()
}

/// Issue 39: a head without the georeference flag but with an origin of (NaN, 1e300) and a
/// step of (inf, 0), CRCs fixed, passed `verify --full`; `dataset.md` §3.1 requires zeros
/// there. It is a D-2 failure, and opening the dataset refuses it as corrupt.
#[test]
fn a_head_without_georeference_must_hold_zeros_where_it_would_be() {
    let field = fields::make(33, 33, Character::Hills, 0.0, 9);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[16], &[], &[]);
    let ds_dir = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let manifest = ds_dir.join("MANIFEST");
    let original = std::fs::read(&manifest).unwrap();
    let state =
        fmrh::dataset::manifest::ManifestState::read(&fmrh::store::Bytes(&original[..])).unwrap();
    let head = state.record.head_offset.get() as usize;
    let head_len = state.record.head_len.get() as usize;
    assert_eq!(
        u32::from_le_bytes(original[head + 16..head + 20].try_into().unwrap()),
        0
    );
    assert!(original[head + 24..head + 56].iter().all(|&b| b == 0));
    let slot = usize::from(state.slot) * fmrh::format::manifest::MANIFEST_PAGE as usize;
    let with = |values: [f64; 4]| {
        let mut bytes = original.clone();
        for (i, v) in values.iter().enumerate() {
            bytes[head + 24 + 8 * i..head + 32 + 8 * i].copy_from_slice(&v.to_le_bytes());
        }
        // The head's CRC in the record (offset 44), then the record's own (offset 252).
        let crc = fmrh::format::crc32(&bytes[head..head + head_len]);
        bytes[slot + 44..slot + 48].copy_from_slice(&crc.to_le_bytes());
        let crc = fmrh::format::crc32(&bytes[slot..slot + 252]);
        bytes[slot + 252..slot + 256].copy_from_slice(&crc.to_le_bytes());
        bytes
    };
    // The CRCs are placed right: the same zeros, resealed, are still valid.
    std::fs::write(&manifest, with([0.0; 4])).unwrap();
    assert!(tiles::verify(&ds_dir, fmrh::store::VerifyMode::Full).valid);
    for values in [
        [f64::NAN, 1e300, f64::INFINITY, 0.0],
        [0.0, 0.0, 0.0, -0.0],
        [1.0, 0.0, 0.0, 0.0],
    ] {
        std::fs::write(&manifest, with(values)).unwrap();
        let r = tiles::verify(&ds_dir, fmrh::store::VerifyMode::Full);
        assert_eq!(failed(&r), vec![Invariant::ManifestPages], "{values:?}");
        assert!(
            matches!(Dataset::open(&ds_dir), Err(fmrh::Error::Corrupt { .. })),
            "{values:?}"
        );
    }
}

#[test]
fn damage_to_the_manifest_or_a_tile_is_reported_located() {
    let field = fields::make(33, 33, Character::Hills, 0.0, 9);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[16], &[], &[]);
    let ds_dir = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let verify = || tiles::verify(&ds_dir, fmrh::store::VerifyMode::Fast);
    assert!(verify().valid);
    let manifest = ds_dir.join("MANIFEST");
    let original = std::fs::read(&manifest).unwrap();
    // A flipped bit in the tile page (page 2) and in the head (after the adjacency area).
    let state =
        fmrh::dataset::manifest::ManifestState::read(&fmrh::store::Bytes(&original[..])).unwrap();
    let head = state.record.head_offset.get() as usize;
    assert!(
        state.record.adjacency_len.get() > 0,
        "the two tiles' border has tables"
    );
    for (at, expect) in [
        (2 * 4096 + 20, Invariant::ManifestPages),
        (head + 300, Invariant::ManifestPages),
    ] {
        let mut bytes = original.clone();
        bytes[at] ^= 0x10;
        std::fs::write(&manifest, &bytes).unwrap();
        assert_eq!(failed(&verify()), vec![expect], "flip at {at}");
    }
    std::fs::write(&manifest, &original).unwrap();
    // A tile's payload damaged, then its file replaced by another state.
    let ds = Dataset::open(&ds_dir).unwrap();
    let tile = &ds.tiles().unwrap()[1];
    let path = ds.tile_path(tile);
    let good = std::fs::read(&path).unwrap();
    let mut bad = good.clone();
    let n = bad.len();
    bad[n - 100] ^= 0xff;
    std::fs::write(&path, &bad).unwrap();
    let r = verify();
    assert_eq!(failed(&r), vec![Invariant::TilePins]);
    assert!(!r.tile_reports[1].valid && r.tile_reports[0].valid);
    std::fs::remove_file(&path).unwrap();
    let r = verify();
    assert_eq!(failed(&r), vec![Invariant::TilePins]);
    // A different file under the tile's name: not the pinned state.
    let other = fields::make(17, 33, Character::Noise, 0.0, 1);
    let bytes = common::bytes_of(
        &other,
        9,
        &fmrh::store::WriteOptions {
            page_size: 1024,
            ..Default::default()
        },
    );
    std::fs::write(&path, bytes).unwrap();
    let r = verify();
    assert_eq!(failed(&r), vec![Invariant::TilePins]);
    assert!(matches!(
        ds.open_tile_uncached(tile),
        Err(fmrh::Error::Corrupt {
            invariant: Invariant::TilePins,
            ..
        })
    ));
    std::fs::write(&path, &good).unwrap();
    assert!(verify().valid);
}

#[test]
fn a_directory_without_a_manifest_is_not_a_dataset() {
    let dir = tempfile::tempdir().unwrap();
    assert!(!fmrh::dataset::is_dataset(dir.path()));
    let err = Dataset::open(dir.path())
        .err()
        .expect("no manifest, no dataset")
        .to_string();
    assert!(err.contains("MANIFEST"), "{err}");
    std::fs::write(dir.path().join("MANIFEST"), b"hello").unwrap();
    let err = Dataset::open(dir.path())
        .err()
        .expect("not a manifest")
        .to_string();
    assert!(err.contains("not an fmrh dataset manifest"), "{err}");
}

#[test]
fn frames_across_tiles_load_what_each_scene_needs_and_keep_the_rest() {
    let field = fields::make(100, 100, Character::Hills, 0.0, 21);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[33, 66], &[33, 66], &[]);
    let ds = Dataset::open(&tiles::build(
        dir.path(),
        &field,
        &rects,
        &tiles::options(None),
    ))
    .unwrap();
    let mut s =
        fmrh::dataset::DatasetScheduler::new(&ds, fmrh::scene::ScheduleOptions::new(1.0)).unwrap();
    let mut previous: Option<std::collections::HashSet<(u64, u8, u32, u32)>> = None;
    let mut dropped = 0;
    for i in 0..40 {
        let t = f64::from(i) / 39.0;
        let eye = DVec3::new(50.0 + 900.0 * t, 80.0 + 300.0 * t, 120.0);
        let cam = Camera::looking_at(eye, eye + DVec3::new(200.0, 150.0, -100.0));
        let f = s.frame(&cam).unwrap();
        let scene = ds.scene(&cam, &SceneOptions::new(1.0), None).unwrap();
        let now: std::collections::HashSet<_> = scene
            .blocks
            .iter()
            .map(|b| (b.tile, b.block.level, b.block.x, b.block.y))
            .collect();
        assert_eq!(f.stats.visible, now.len() as u64, "frame {i}");
        assert_eq!(
            f.stats.resident,
            now.len() as u64,
            "frame {i}: no memory radius, nothing else stays"
        );
        let new = previous
            .as_ref()
            .map_or(now.len(), |p| now.difference(p).count());
        assert_eq!(
            f.stats.loaded, new as u64,
            "frame {i}: loaded what the last frame did not hold"
        );
        dropped += f.tiles_dropped;
        previous = Some(now);
    }
    assert!(dropped > 0, "the path leaves some tile behind");
}

/// The pairs of two edge lists that share a positive length inside `first ..= last`, by
/// brute force.
fn brute_pairs(
    a: &[(u32, u64, u64)],
    b: &[(u32, u64, u64)],
    first: u64,
    last: u64,
) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for &(na, a0, a1) in a {
        for &(nb, b0, b1) in b {
            if a0.max(b0).max(first) < a1.min(b1).min(last) {
                out.push((na, nb));
            }
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    #[test]
    fn adjacent_cluster_tables_are_every_pair_of_edge_nodes_that_meet(
        w in 20u32..80,
        h in 20u32..80,
        seed in any::<u64>(),
        character in fields::character(),
    ) {
        use fmrh::dataset::adjacency::{TileEdges, EAST};
        let field = fields::make(w, h, character, 0.02, seed);
        let mut rng = Rng::new(seed);
        let rects = tiles::split(&field, &cuts(u64::from(w), 2, &mut rng), &cuts(u64::from(h), 1, &mut rng), &[]);
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::open(&tiles::build(dir.path(), &field, &rects, &tiles::options(None))).unwrap();
        let all = ds.tiles().unwrap();
        let mut stored_borders = 0;
        for t in &all {
            let mine = TileEdges::read(&ds.open_tile(t).unwrap(), &t.record).unwrap();
            for b in ds.borders(t).unwrap() {
                stored_borders += 1;
                let r = t.rect();
                let n = all
                    .iter()
                    .find(|u| u.rect().col0 as i64 - r.col0 as i64 == b.dcol && u.rect().row0 as i64 - r.row0 as i64 == b.drow)
                    .expect("the neighbour a border names exists");
                let theirs = TileEdges::read(&ds.open_tile(n).unwrap(), &n.record).unwrap();
                let origin = if b.side == EAST { r.row0 } else { r.col0 };
                let (e_mine, e_theirs) = if b.side == EAST { (1, 3) } else { (2, 0) };
                prop_assert!(!b.tables.is_empty());
                for (ci, cj, pairs) in &b.tables {
                    let expect = brute_pairs(
                        &mine.lists[usize::from(*ci)][e_mine],
                        &theirs.lists[usize::from(*cj)][e_theirs],
                        origin + b.first,
                        origin + b.last,
                    );
                    prop_assert_eq!(pairs, &expect);
                    prop_assert!(!pairs.is_empty(), "clusters {} and {} meet nowhere along the border", ci, cj);
                }
            }
        }
        // Every shared edge of positive length is stored once.
        let tilings = fmrh::dataset::placement::check_tiling(&rects).unwrap();
        let long = tilings.iter().filter(|(_, _, o)| o.col1 - o.col0 + o.row1 - o.row0 > 0).count();
        prop_assert_eq!(stored_borders, long);
    }
}

/// A two-tile dataset (49 × 25 hills cut at column 24) that verifies, in `dir`.
fn two_tiles(dir: &std::path::Path) -> std::path::PathBuf {
    let field = fields::make(49, 25, Character::Hills, 0.0, 4);
    let rects = tiles::split(&field, &[24], &[], &[]);
    let ds_dir = tiles::build(dir, &field, &rects, &tiles::options(None));
    assert!(tiles::verify(&ds_dir, fmrh::store::VerifyMode::Fast).valid);
    ds_dir
}

/// Commits a new manifest state of the dataset in `ds_dir`: its current contents as
/// `change` leaves them (every checksum right, whatever the content).
fn rewrite_manifest(
    ds_dir: &std::path::Path,
    change: impl FnOnce(&mut fmrh::dataset::manifest::Contents),
) {
    use fmrh::dataset::manifest::{write_state, Contents, ManifestState};
    let all = Dataset::open(ds_dir).unwrap().tiles().unwrap();
    let src = fmrh::store::FileSource::open(&ds_dir.join("MANIFEST")).unwrap();
    let state = ManifestState::read(&src).unwrap();
    let adjacency = all
        .iter()
        .map(|t| {
            (
                t.name().to_string(),
                state.adjacency(&src, &t.record).unwrap(),
            )
        })
        .filter(|(_, blob)| !blob.is_empty())
        .collect();
    let mut contents = Contents {
        tiles: all.iter().map(|t| t.record).collect(),
        spacing_m: state.record.spacing_m(),
        georeference: state.georeference(),
        seam: state.record.seam,
        vertical_datum: state.vertical_datum(),
        adjacency,
    };
    change(&mut contents);
    let io = fmrh::store::io::FileIo::open(&ds_dir.join("MANIFEST")).unwrap();
    write_state(&io, Some((state.slot, &state.record)), &contents).unwrap();
}

#[test]
fn tables_that_are_not_the_merge_are_reported() {
    use fmrh::dataset::manifest::ManifestState;
    let dir = tempfile::tempdir().unwrap();
    let ds_dir = two_tiles(dir.path());
    let verify = || tiles::verify(&ds_dir, fmrh::store::VerifyMode::Fast);
    // Rewrite the manifest with one pair dropped from the west tile's tables: checksums
    // right, content wrong.
    let ds = Dataset::open(&ds_dir).unwrap();
    let all = ds.tiles().unwrap();
    let west = all.iter().find(|t| t.rect().col0 == 0).unwrap();
    let mut borders = ds.borders(west).unwrap();
    assert_eq!(borders.len(), 1);
    borders[0].tables[0].2.pop();
    let name = west.name().to_string();
    rewrite_manifest(&ds_dir, |c| {
        c.adjacency
            .insert(name, fmrh::dataset::adjacency::encode(&borders));
    });
    assert_eq!(failed(&verify()), vec![Invariant::AdjacentClusters]);
    // A flipped bit in the tables: their CRC.
    let bytes = std::fs::read(ds_dir.join("MANIFEST")).unwrap();
    let state = ManifestState::read(&fmrh::store::Bytes(&bytes[..])).unwrap();
    let area = state.record.adjacency_area();
    let mut bad = bytes.clone();
    bad[area.start as usize + 40] ^= 1;
    std::fs::write(ds_dir.join("MANIFEST"), &bad).unwrap();
    assert_eq!(failed(&verify()), vec![Invariant::AdjacentClusters]);
}

#[test]
fn a_change_to_one_tile_brings_its_western_and_northern_neighbours_tables_up_to_date() {
    // A 2 x 2 dataset; the patch lies inside the south-east tile only, changing its cuts
    // along its west and north edges, whose tables its west and north neighbours store.
    let field = fields::make(65, 65, Character::Hills, 0.0, 12);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[32], &[32], &[]);
    let ds_dir = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let patch = fields::make(20, 20, Character::Spikes, 0.0, 3);
    let r = fmrh::dataset::replace(&fmrh::dataset::Dir(ds_dir.clone()), 34, 34, &patch).unwrap();
    assert_eq!(r.tiles.len(), 1);
    let report = tiles::verify(&ds_dir, fmrh::store::VerifyMode::Fast);
    assert!(report.valid, "{:?}", failed(&report));
}

#[test]
fn replacing_a_whole_tile_is_one_commit_and_an_older_reader_is_told() {
    let field = fields::make(49, 25, Character::Hills, 0.0, 6);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[24], &[], &[]);
    let ds_dir = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let before = Dataset::open(&ds_dir).unwrap();
    // A new east tile: other heights, but the shared column 24 as it was.
    let east = SampleRect {
        col0: 24,
        row0: 0,
        col1: 48,
        row1: 24,
    };
    let mut new_field = field.samples().to_vec();
    for row in 0..25u64 {
        for col in 25..49u64 {
            new_field[(row * 49 + col) as usize] = (col * 3 + row) as f32;
        }
    }
    let new_field = fmrh::Heightfield::new(49, 25, new_field).unwrap();
    let path = tiles::write_f32(dir.path(), "east-v2", &tiles::crop(&new_field, &east), 10.0);
    // Not at a tile's place and size: refused.
    let err = fmrh::dataset::replace_tile(
        &ds_dir,
        &path,
        Some((23, 0)),
        &tiles::options(None),
        &fmrh::progress::Silent,
    )
    .unwrap_err();
    assert!(err.to_string().contains("no tile lies"), "{err}");
    let (commit, record, _) = fmrh::dataset::replace_tile(
        &ds_dir,
        &path,
        Some((24, 0)),
        &tiles::options(None),
        &fmrh::progress::Silent,
    )
    .unwrap();
    assert_eq!(commit.txn_id, 2);
    assert_eq!(record.name(), "east-v2.fmrh");
    let after = Dataset::open(&ds_dir).unwrap();
    assert!(same_bits(
        after.read_window(after.grid()).unwrap().samples(),
        new_field.samples()
    ));
    let report = tiles::verify(&ds_dir, fmrh::store::VerifyMode::Full);
    assert!(
        report.valid && report.stray_files.is_empty(),
        "{:?} {:?}",
        failed(&report),
        report.stray_files
    );
    // The reader of the state before: the west tile still reads, the east one is superseded.
    let old_east = before
        .tiles()
        .unwrap()
        .into_iter()
        .find(|t| t.rect().col0 == 24)
        .unwrap();
    assert!(matches!(
        before.open_tile(&old_east),
        Err(fmrh::Error::Superseded { .. })
    ));
    let old_west = before
        .tiles()
        .unwrap()
        .into_iter()
        .find(|t| t.rect().col0 == 0)
        .unwrap();
    before.open_tile(&old_west).unwrap();
}

/// One prefetcher warms every tile the predicted camera will see, and changes where bytes
/// come from, never what a frame holds: frame for frame, the counts are those of a
/// scheduler without it. On a straight path the prediction is exact, so with a cache radius
/// that holds the whole view every load after the second frame is a prefetch hit; with a
/// radius of 800 m, a good share still is.
#[test]
fn prefetch_works_across_tiles() {
    // A 3 x 3 dataset of 2 km; the camera slides east looking north, so each frame sees new
    // blocks at its east edge, in tiles it did not see before.
    let field = fields::make(200, 200, Character::Hills, 0.0, 22);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, &[66, 133], &[66, 133], &[]);
    let built = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let ds = Dataset::open(&built).unwrap();
    // The scheduler without prefetch reads its own tiles: the decoded ancestors a store
    // keeps change which bytes a load reads, never what it holds.
    let other = Dataset::open(&built).unwrap();
    let plain = fmrh::scene::ScheduleOptions::new(1.0);
    for radius in [800.0, 1e6] {
        let options = fmrh::scene::ScheduleOptions {
            prefetch: true,
            cache_radius: radius,
            ..plain
        };
        let mut s = fmrh::dataset::DatasetScheduler::new(&ds, options).unwrap();
        let mut without = fmrh::dataset::DatasetScheduler::new(&other, plain).unwrap();
        let (mut hits, mut loaded) = (0, 0);
        for i in 0..30 {
            let eye = DVec3::new(100.0 + 60.0 * f64::from(i), -100.0, 200.0);
            let cam = Camera::looking_at(eye, eye + DVec3::new(0.0, 700.0, -200.0));
            let f = s.frame(&cam).unwrap();
            let g = without.frame(&cam).unwrap();
            let counts = |f: &fmrh::dataset::DatasetFrame| {
                let t = &f.stats;
                (t.visible, t.loaded, t.evicted, t.resident, t.resident_bytes)
            };
            assert_eq!(counts(&f), counts(&g), "frame {i}, radius {radius}");
            assert_eq!(
                f.stats.visible,
                ds.scene(&cam, &SceneOptions::new(1.0), None)
                    .unwrap()
                    .blocks
                    .len() as u64
            );
            assert!(f.stats.prefetch_hits <= f.stats.loaded);
            assert_eq!(g.stats.prefetch_hits, 0);
            if radius > 1e5 && i >= 2 {
                assert_eq!(
                    f.stats.prefetch_hits, f.stats.loaded,
                    "frame {i}: the prediction was exact and the radius holds the view"
                );
            }
            if i > 0 {
                hits += f.stats.prefetch_hits;
                loaded += f.stats.loaded;
            }
            s.wait_prefetch();
        }
        assert!(
            hits * 4 >= loaded && loaded > 0,
            "radius {radius}: the prefetcher warmed {hits} of the {loaded} blocks later frames loaded"
        );
    }
}

/// D-4 (manifest 1.1): the head records what every tile's heights are above. A head that
/// names another datum than its tiles' (rewritten here with every checksum right) fails
/// D-4 alone, and a reader takes the head's word without opening a tile.
#[test]
fn a_head_datum_that_is_not_its_tiles_is_reported() {
    use fmrh::types::VerticalDatum;
    let dir = tempfile::tempdir().unwrap();
    let ds_dir = two_tiles(dir.path());
    let ds = Dataset::open(&ds_dir).unwrap();
    assert_eq!(ds.state().vertical_datum(), Some(VerticalDatum::Unknown));
    drop(ds);
    rewrite_manifest(&ds_dir, |c| c.vertical_datum = Some(VerticalDatum::Egm96));
    let ds = Dataset::open(&ds_dir).unwrap();
    assert_eq!(ds.vertical_datum().unwrap(), VerticalDatum::Egm96);
    assert_eq!(ds.tiles_opened(), 0, "the head answered");
    assert_eq!(
        failed(&tiles::verify(&ds_dir, fmrh::store::VerifyMode::Fast)),
        vec![Invariant::TilePins]
    );
}
