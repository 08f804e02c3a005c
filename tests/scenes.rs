//! Scenes are right: on a real DEM (Puget Sound 1k at 160 m), for random cameras and
//! tolerances, the view-dependent scene is exactly the ideal cut that a brute-force oracle
//! computes over every node (so loaded samples / oracle samples = 1), every block meets the
//! tolerance in pixels, and every visible point of the terrain lies in exactly one block. A
//! uniform scene covers its window once and its reconstruction is within the chosen static
//! threshold at every valid sample; a view scene's reconstruction is within each owning
//! block's error. Cameras at the edges of the domain (on the ground, inside the terrain, very
//! far, fields of view near 0° and 180°, straight down and up, non-finite input) are fixed
//! cases. A scheduler's selection (`Terrain::scene_blocks`, a coarser region) is the scene's
//! blocks to the bit, and the store's memo of decoded nodes answers as the node table does.

mod common;

use std::sync::OnceLock;

use glam::DVec3;
use proptest::prelude::*;

use common::fields::Rng;
use common::views::{self, Fixture};
use fmrh::model::{BuildOptions, SampleRect, Thresholds};
use fmrh::scene::{ranges, reconstruct, Camera, Mode, Scene, SceneOptions, Terrain};

fn puget() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| views::fixture(views::puget_1k(), &BuildOptions::default()))
}

/// Every terrain sample on a coarse lattice that the frustum sees must lie in a block.
fn assert_visible_points_covered(
    f: &Fixture,
    terrain: &Terrain<'_, impl fmrh::store::Source>,
    cam: &Camera,
    scene: &Scene,
) {
    let view = cam.view().unwrap();
    let d = f.model.domain();
    let keys: Vec<_> = scene.blocks.iter().map(|b| b.keys(d)).collect();
    for pair in keys.windows(2) {
        assert!(pair[0].hi < pair[1].lo, "blocks overlap: {pair:?}");
    }
    let frame = terrain.frame();
    let step = 7;
    for row in (0..u64::from(d.height())).step_by(step) {
        for col in (0..u64::from(d.width())).step_by(step) {
            let z = f64::from(f.model.raster().value(col, row));
            let p = frame.point(col as f64, row as f64, z);
            if view
                .planes
                .iter()
                .any(|pl| pl.normal.dot(p) + pl.offset < 0.0)
            {
                continue;
            }
            let (bx, by) = ranges::owner_block(d, col, row);
            let k = ranges::block_key(d, bx, by);
            let i = keys.partition_point(|r| r.lo <= k);
            assert!(
                i > 0 && keys[i - 1].hi >= k,
                "visible sample ({col}, {row}) is in no block; camera {cam:?}"
            );
        }
    }
}

fn opts(tau: f64, mode: Mode, window: Option<SampleRect>) -> SceneOptions {
    SceneOptions {
        tau,
        mode,
        window,
        gap: fmrh::scene::DEFAULT_GAP,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn view_scenes_are_the_ideal_cut(seed in any::<u64>(), tau in 0.25f64..8.0) {
        let f = puget();
        let terrain = Terrain::new(&f.store).unwrap();
        let cam = views::random_camera(&f.model, terrain.frame(), &mut Rng::new(seed));
        let scene = terrain.scene(&cam, &opts(tau, Mode::View, None)).unwrap();
        let oracle = views::ideal_cut(&f.model, terrain.frame(), &cam.view().unwrap(), tau);
        prop_assert_eq!(views::node_indexes(&scene.blocks), oracle);
        // The top-down walk without clusters finds the same cut.
        let walked = fmrh::scene::baseline::traversal(&terrain, &cam, tau, None).unwrap();
        prop_assert_eq!(&walked, &scene.blocks);
        // Every scene block lies over physical blocks of the region.
        let finest = fmrh::scene::baseline::all_finest(&terrain, &cam, None).unwrap();
        let d = f.model.domain();
        for b in &scene.blocks {
            let r = b.keys(d);
            prop_assert!(finest.iter().any(|p| r.lo <= p.key && p.key <= r.hi), "{:?}", b);
        }
        for b in &scene.blocks {
            prop_assert!(b.screen_error <= tau, "{:?} misses tau {}", b, tau);
        }
        assert_visible_points_covered(f, &terrain, &cam, &scene);
    }

    /// The store's memo of decoded nodes answers as the node table does, whatever the order
    /// of reads: every node read twice is the node read once, and a node past the table is
    /// an error every time.
    #[test]
    fn nodes_read_again_are_the_nodes_of_the_table(
        reads in proptest::collection::vec(any::<u32>(), 1..400),
    ) {
        let f = puget();
        let all = f.store.nodes().unwrap();
        let count = u32::try_from(all.len()).unwrap();
        for r in reads {
            let i = r % (count + 8);
            match all.get(i as usize) {
                Some(n) => prop_assert_eq!(&f.store.node(i).unwrap(), n),
                None => prop_assert!(f.store.node(i).is_err()),
            }
        }
    }

    /// What a scheduler selects ([`Terrain::scene_blocks`]: a coarser frustum region, nodes
    /// outside the frustum dropped as they are met) is the scene's blocks to the bit, in
    /// both modes, from tolerances where pruned leaves give way to physical blocks to coarse
    /// ones.
    #[test]
    fn a_schedulers_selection_is_the_scene(
        seed in any::<u64>(),
        tau in prop_oneof![0.02f64..0.5, 0.5f64..16.0],
        uniform in any::<bool>(),
    ) {
        let f = puget();
        let terrain = Terrain::new(&f.store).unwrap();
        let cam = views::random_camera(&f.model, terrain.frame(), &mut Rng::new(seed));
        let mode = if uniform { Mode::Uniform } else { Mode::View };
        let scene = terrain.scene(&cam, &opts(tau, mode, None)).unwrap();
        let selected = terrain.scene_blocks(&cam, &opts(tau, mode, None)).unwrap();
        prop_assert_eq!(&selected.blocks, &scene.blocks);
        prop_assert_eq!(selected.stats.max_screen_error, scene.stats.max_screen_error);
        prop_assert_eq!(selected.stats.samples, scene.stats.samples);
    }

    #[test]
    fn uniform_scenes_reconstruct_within_the_threshold(
        seed in any::<u64>(),
        tau in 0.25f64..8.0,
        corner in (0u64..1025, 0u64..1025),
        size in (1u64..400, 1u64..400),
    ) {
        let f = puget();
        let terrain = Terrain::new(&f.store).unwrap();
        let cam = views::random_camera(&f.model, terrain.frame(), &mut Rng::new(seed));
        let window = SampleRect {
            col0: corner.0,
            row0: corner.1,
            col1: (corner.0 + size.0).min(1024),
            row1: (corner.1 + size.1).min(1024),
        };
        let scene = terrain.scene(&cam, &opts(tau, Mode::Uniform, Some(window))).unwrap();
        views::assert_window_cover(&f.model, &scene.blocks, &window);
        let threshold = scene.stats.threshold.unwrap();
        prop_assert!(threshold <= scene.stats.allowed_error.unwrap());
        prop_assert!(scene.stats.max_error <= threshold);
        let rec = reconstruct(&f.store, &scene, window).unwrap();
        prop_assert_eq!(rec.uncovered, 0);
        let w = (window.col1 - window.col0 + 1) as usize;
        for (i, v) in rec.values.iter().enumerate() {
            let (col, row) = (window.col0 + (i % w) as u64, window.row0 + (i / w) as u64);
            if let Some(h) = f.model.raster().original(col, row) {
                let err = (f64::from(h) - v).abs();
                prop_assert!(err <= threshold, "sample ({}, {}) off by {} > {}", col, row, err, threshold);
            }
        }
    }

    #[test]
    fn view_scenes_reconstruct_within_block_errors(seed in any::<u64>(), tau in 0.5f64..4.0) {
        let f = puget();
        let terrain = Terrain::new(&f.store).unwrap();
        let cam = views::random_camera(&f.model, terrain.frame(), &mut Rng::new(seed));
        let scene = terrain.scene(&cam, &opts(tau, Mode::View, None)).unwrap();
        let Some(window) = scene.window else {
            prop_assert!(scene.blocks.is_empty());
            return Ok(());
        };
        let rec = reconstruct(&f.store, &scene, window).unwrap();
        let w = (window.col1 - window.col0 + 1) as usize;
        for (i, (v, bound)) in rec.values.iter().zip(&rec.bound).enumerate() {
            let (col, row) = (window.col0 + (i % w) as u64, window.row0 + (i / w) as u64);
            if let (Some(h), false) = (f.model.raster().original(col, row), v.is_nan()) {
                let err = (f64::from(h) - v).abs();
                prop_assert!(err <= *bound, "sample ({}, {}) off by {} > {}", col, row, err, bound);
            }
        }
    }
}

#[test]
fn window_scenes_cover_their_window_in_both_modes() {
    let f = puget();
    let terrain = Terrain::new(&f.store).unwrap();
    let mut rng = Rng::new(7);
    for _ in 0..40 {
        let cam = views::random_camera(&f.model, terrain.frame(), &mut rng);
        let c0 = (rng.unit() * 1000.0) as u64;
        let r0 = (rng.unit() * 1000.0) as u64;
        let window = SampleRect {
            col0: c0,
            row0: r0,
            col1: (c0 + (rng.unit() * 600.0) as u64).min(1024),
            row1: (r0 + (rng.unit() * 600.0) as u64).min(1024),
        };
        for mode in [Mode::Uniform, Mode::View] {
            for gap in [0, 4, 1 << 20] {
                let mut o = opts(1.0, mode, Some(window));
                o.gap = gap;
                let scene = terrain.scene(&cam, &o).unwrap();
                views::assert_window_cover(&f.model, &scene.blocks, &window);
                if gap == 0 {
                    // Gap merging changes cost, never the answer.
                    let mut o2 = o;
                    o2.gap = 1 << 20;
                    let other = terrain.scene(&cam, &o2).unwrap();
                    assert_eq!(other.blocks, scene.blocks);
                    assert!(other.stats.ranges <= scene.stats.ranges);
                }
            }
        }
    }
}

/// Neighbour levels agree with a brute-force look at which blocks share an edge.
#[test]
fn neighbour_levels_match_adjacent_blocks() {
    let f = puget();
    let terrain = Terrain::new(&f.store).unwrap();
    let mut rng = Rng::new(11);
    for _ in 0..10 {
        let cam = views::random_camera(&f.model, terrain.frame(), &mut rng);
        let scene = terrain.scene(&cam, &opts(1.0, Mode::View, None)).unwrap();
        for b in &scene.blocks {
            let r = b.rect();
            for (e, got) in b.neighbours.iter().enumerate() {
                let mut levels: Vec<u8> = scene
                    .blocks
                    .iter()
                    .filter(|o| {
                        let q = o.rect();
                        let rows = q.row0 < r.row1 && q.row1 > r.row0;
                        let cols = q.col0 < r.col1 && q.col1 > r.col0;
                        match e {
                            0 => q.row1 == r.row0 && cols,
                            1 => q.col0 == r.col1 && rows,
                            2 => q.row0 == r.row1 && cols,
                            _ => q.col1 == r.col0 && rows,
                        }
                    })
                    .map(|o| o.level)
                    .collect();
                levels.sort_unstable();
                let want = levels.first().map(|&c| (c, *levels.last().unwrap()));
                assert_eq!(
                    got.map(|n| (n.coarsest, n.finest)),
                    want,
                    "block {b:?} edge {e}"
                );
            }
        }
    }
}

/// With thresholds that leave no lossless cluster, a close view needs blocks below the
/// tree's leaves: physical blocks, exact, still a cover.
#[test]
fn leaves_above_the_finest_level_fall_back_to_physical_blocks() {
    let options = BuildOptions {
        thresholds: Thresholds::Explicit(vec![150.0, 600.0]),
        ..BuildOptions::default()
    };
    let f = views::fixture(views::puget_1k(), &options);
    let terrain = Terrain::new(&f.store).unwrap();
    let z = f64::from(f.model.raster().value(500, 500));
    let cam = Camera::looking_at(
        DVec3::new(500.0 * 160.0, 500.0 * 160.0, z + 50.0),
        DVec3::new(600.0 * 160.0, 520.0 * 160.0, z),
    );
    let window = SampleRect {
        col0: 300,
        row0: 300,
        col1: 700,
        row1: 700,
    };
    for mode in [Mode::View, Mode::Uniform] {
        let scene = terrain.scene(&cam, &opts(1.0, mode, Some(window))).unwrap();
        assert!(
            scene.blocks.iter().any(|b| b.node.is_none()),
            "{mode:?}: no physical block"
        );
        views::assert_window_cover(&f.model, &scene.blocks, &window);
        assert!(scene
            .blocks
            .iter()
            .all(|b| b.screen_error <= 1.0 || mode == Mode::Uniform));
        let rec = reconstruct(&f.store, &scene, window).unwrap();
        let w = (window.col1 - window.col0 + 1) as usize;
        for (i, (v, bound)) in rec.values.iter().zip(&rec.bound).enumerate() {
            let (col, row) = (window.col0 + (i % w) as u64, window.row0 + (i / w) as u64);
            let h = f.model.raster().original(col, row).unwrap();
            assert!((f64::from(h) - v).abs() <= *bound);
        }
    }
    // Uniform at a bound below every threshold: all physical, error 0.
    let scene = terrain
        .scene(&cam, &opts(1.0, Mode::Uniform, Some(window)))
        .unwrap();
    assert_eq!(scene.stats.cluster, None);
    assert_eq!(scene.stats.threshold, Some(0.0));
    assert!(scene
        .blocks
        .iter()
        .all(|b| b.node.is_none() && b.error == 0.0));
}

fn view_scene(cam: &Camera, tau: f64) -> Scene {
    let f = puget();
    let terrain = Terrain::new(&f.store).unwrap();
    let scene = terrain.scene(cam, &opts(tau, Mode::View, None)).unwrap();
    let oracle = views::ideal_cut(&f.model, terrain.frame(), &cam.view().unwrap(), tau);
    assert_eq!(views::node_indexes(&scene.blocks), oracle, "camera {cam:?}");
    assert_visible_points_covered(f, &terrain, cam, &scene);
    scene
}

fn ground(col: u64, row: u64) -> DVec3 {
    let z = f64::from(puget().model.raster().value(col, row));
    DVec3::new(col as f64 * 160.0, row as f64 * 160.0, z)
}

#[test]
fn eye_on_the_ground_needs_full_resolution_at_the_eye() {
    let eye = ground(512, 512);
    let cam = Camera::looking_at(eye, ground(700, 600));
    let scene = view_scene(&cam, 1.0);
    let finest = puget().model.domain().finest_level();
    let (bx, by) = ranges::owner_block(puget().model.domain(), 512, 512);
    // The block under the eye (if visible) is physical: P_min = 0 allows no error.
    for b in scene.blocks.iter().filter(|b| b.distance == 0.0) {
        assert_eq!(b.error, 0.0, "{b:?}");
    }
    assert!(scene
        .blocks
        .iter()
        .any(|b| b.level == finest && (b.x, b.y) == (bx, by)));
    let terrain = Terrain::new(&puget().store).unwrap();
    let u = terrain
        .scene(&cam, &opts(1.0, Mode::Uniform, None))
        .unwrap();
    assert_eq!(u.stats.p_min, Some(0.0));
    assert_eq!(u.stats.threshold, Some(0.0));
}

#[test]
fn eye_inside_the_terrain() {
    let mut eye = ground(300, 800);
    eye.z -= 200.0;
    let cam = Camera::looking_at(eye, ground(400, 800));
    let scene = view_scene(&cam, 1.0);
    assert!(!scene.blocks.is_empty());
}

#[test]
fn eye_very_far_sees_one_block() {
    let c = ground(512, 512);
    let cam = Camera::looking_at(c + DVec3::new(0.0, 0.0, 1e9), c);
    let scene = view_scene(&cam, 1.0);
    assert_eq!(scene.blocks.len(), 1);
    assert_eq!(scene.blocks[0].level, 0);
}

#[test]
fn extreme_fields_of_view() {
    for fov in [1e-4, 0.5, 179.0, 179.999] {
        let mut cam = Camera::looking_at(
            ground(100, 100) + DVec3::new(0.0, 0.0, 2000.0),
            ground(600, 700),
        );
        cam.fov_y_deg = fov;
        let scene = view_scene(&cam, 1.0);
        assert!(!scene.blocks.is_empty(), "fov {fov}");
    }
}

#[test]
fn straight_down_over_a_block_corner() {
    // Sample (512, 512) is a corner of four physical blocks (64 cells each).
    let mut eye = ground(512, 512);
    eye.z += 3000.0;
    let target = DVec3::new(eye.x, eye.y, 0.0);
    let scene = view_scene(&Camera::looking_at(eye, target), 1.0);
    let d = puget().model.domain();
    let corner_blocks: Vec<_> = scene
        .blocks
        .iter()
        .filter(|b| b.col0 <= 512 && b.col1 >= 512 && b.row0 <= 512 && b.row1 >= 512)
        .collect();
    assert!(!corner_blocks.is_empty());
    assert!(d.finest_level() > 0);
}

#[test]
fn straight_up() {
    // From above the highest point looking up: nothing to see.
    let mut eye = ground(512, 512);
    eye.z = 10_000.0;
    let scene = view_scene(&Camera::looking_at(eye, eye + DVec3::Z), 1.0);
    assert!(scene.blocks.is_empty());
    assert_eq!(scene.window, None);
    // From below the lowest point: the terrain above.
    eye.z = -500.0;
    let scene = view_scene(&Camera::looking_at(eye, eye + DVec3::Z), 1.0);
    assert!(!scene.blocks.is_empty());
}

#[test]
fn non_finite_cameras_and_tolerances_are_errors() {
    let f = puget();
    let terrain = Terrain::new(&f.store).unwrap();
    let good = Camera::looking_at(ground(1, 1) + DVec3::Z * 100.0, ground(500, 500));
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut c = good;
        c.eye.y = bad;
        let err = terrain.scene(&c, &opts(1.0, Mode::View, None)).unwrap_err();
        assert!(err.to_string().contains("not finite"), "{err}");
        for tau in [bad, -1.0] {
            assert!(terrain
                .scene(&good, &opts(tau, Mode::Uniform, None))
                .is_err());
        }
    }
    let outside = SampleRect {
        col0: 0,
        row0: 0,
        col1: 1025,
        row1: 10,
    };
    assert!(terrain
        .scene(&good, &opts(1.0, Mode::View, Some(outside)))
        .is_err());
}
