//! Datasets on the globe (`Dataset::scene_on_globe`, `fmrh scene DATASET --eye-geo`): the
//! bundled SRTM3 neighbours N43E006 and N43E007 built into one dataset (placed by their
//! names, `--seam first`), seen from random ECEF cameras from 300 m to 20,000 km. Checked:
//!
//! * **the same as each tile alone**: in view-dependent mode the dataset's blocks in each
//!   tile are exactly that tile's own container's scene on the globe (`Terrain::on_globe`,
//!   its own georeference), and a tile the dataset does not open has no block in view; so the
//!   dataset scene inherits the single-file properties `tests/globe_scenes.rs` checks (one
//!   cover of what is seen, within tau at true distances, nothing below the horizon);
//! * **one cover across the border**: every grid cell of the dataset whose centre is seen (in
//!   the frustum, above the horizon) lies in exactly one block, in both modes;
//! * **within tau** in uniform mode too;
//! * the CLI's `--eye-geo` answer is the library's, and a dataset with no georeference is
//!   refused on the globe with a clear error;
//! * **frames** (`fmrh fly DATASET --geo`, `DatasetScheduler` with `globe`) from orbit to
//!   1 km show the dataset's globe scene, and a memory radius holds the tiles within it.
//!
//! Placing every tile at the dataset's origin (not at its own place) fails the first two.

mod common;

use std::collections::BTreeSet;
use std::path::PathBuf;

use fmrh::dataset::{Dataset, DatasetScene};
use fmrh::globe;
use fmrh::scene::{Aabb, Camera, Mode, SceneOptions, Terrain};
use fmrh::Heightfield;
use proptest::prelude::*;

struct Built {
    _dir: tempfile::TempDir,
    ds: PathBuf,
    fields: [Heightfield; 2],
}

fn built() -> &'static Built {
    static B: std::sync::OnceLock<Built> = std::sync::OnceLock::new();
    B.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let ds = dir.path().join("ds");
        let a = common::data("srtm3-pyhgtmap/N43E006.hgt.gz");
        let b = common::data("srtm3-pyhgtmap/N43E007.hgt.gz");
        let out = common::fmrh(&[
            "dataset",
            "build",
            "-q",
            "--seam",
            "first",
            "-o",
            ds.to_str().unwrap(),
            a.to_str().unwrap(),
            b.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let load = |p: &PathBuf| fmrh::ingest::load(p, &Default::default()).unwrap();
        Built {
            _dir: dir,
            ds,
            fields: [load(&a), load(&b)],
        }
    })
}

type Key = (u8, u32, u32);

fn keys_of_tile(scene: &DatasetScene, tile: u64) -> BTreeSet<Key> {
    scene
        .blocks
        .iter()
        .filter(|b| b.tile == tile)
        .map(|b| (b.block.level, b.block.x, b.block.y))
        .collect()
}

/// The height of dataset sample `(col, row)` (the first tile's on the shared column, as the
/// dataset reads it), NaN for a void.
fn height(fields: &[Heightfield; 2], col: u64, row: u64) -> f32 {
    let (f, c) = if col <= 1200 {
        (&fields[0], col)
    } else {
        (&fields[1], col - 1200)
    };
    f.samples()[row as usize * 1201 + c as usize]
}

/// Every dataset cell (the square between samples `(c, r)` and `(c+1, r+1)`) on a lattice
/// whose centre is seen lies in exactly one block; the number of such cells.
fn check_cover(
    ds: &Dataset,
    scene: &DatasetScene,
    camera: &Camera,
    fields: &[Heightfield; 2],
) -> Result<usize, TestCaseError> {
    let view = camera.view().unwrap();
    let g = ds.globe_frame().unwrap();
    let mut seen = 0;
    for r in (0..1200u64).step_by(7) {
        for c in (0..2400u64).step_by(7) {
            let hs = [(c, r), (c + 1, r), (c, r + 1), (c + 1, r + 1)]
                .map(|(i, j)| f64::from(height(fields, i, j)));
            if hs.iter().any(|h| h.is_nan()) {
                continue;
            }
            let (lon, lat) = g.lon_lat(c as f64 + 0.5, r as f64 + 0.5);
            let p = globe::ecef_point(lon, lat, hs.iter().sum::<f64>() / 4.0);
            if !view.intersects(&Aabb { min: p, max: p })
                || !common::globe::above_horizon(camera.eye, p)
            {
                continue;
            }
            seen += 1;
            let n = scene
                .blocks
                .iter()
                .filter(|b| {
                    let k = &b.block;
                    k.col0 <= c && c < k.col1 && k.row0 <= r && r < k.row1
                })
                .count();
            prop_assert_eq!(n, 1, "cell ({}, {}) in {} blocks", c, r, n);
        }
    }
    Ok(seen)
}

fn check(camera: &Camera, tau: f64) -> Result<usize, TestCaseError> {
    let b = built();
    let ds = Dataset::open(&b.ds).unwrap();
    let options = SceneOptions {
        mode: Mode::View,
        ..SceneOptions::new(tau)
    };
    let scene = ds.scene_on_globe(camera, &options).unwrap();
    // Tile by tile, the tile's own scene on the globe.
    for tile in ds.tiles().unwrap() {
        let store = ds.open_tile_uncached(&tile).unwrap();
        let own = Terrain::on_globe(&store)
            .unwrap()
            .scene(camera, &options)
            .unwrap();
        let own: BTreeSet<Key> = own.blocks.iter().map(|k| (k.level, k.x, k.y)).collect();
        prop_assert_eq!(
            keys_of_tile(&scene, tile.index),
            own,
            "tile {}",
            tile.name()
        );
    }
    let seen = check_cover(&ds, &scene, camera, &b.fields)?;
    // Uniform mode: one cover, within tau.
    let uniform = ds
        .scene_on_globe(
            camera,
            &SceneOptions {
                mode: Mode::Uniform,
                ..SceneOptions::new(tau)
            },
        )
        .unwrap();
    for blk in &uniform.blocks {
        prop_assert!(
            blk.block.screen_error <= tau * (1.0 + 1e-9),
            "uniform block {:?}: {} px",
            (blk.tile, blk.block.level, blk.block.x, blk.block.y),
            blk.block.screen_error
        );
    }
    check_cover(&ds, &uniform, camera, &b.fields)?;
    Ok(seen)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]
    #[test]
    fn dataset_scenes_on_the_globe_are_their_tiles_scenes(
        lat in 42.5f64..44.5, lon in 5.5f64..8.5, log_h in 2.5f64..7.3,
        heading in 0.0f64..360.0, pitch in -90.0f64..-5.0, tau in 0.5f64..4.0,
    ) {
        check(&Camera::on_globe(lat, lon, 10f64.powf(log_h), heading, pitch), tau)?;
    }
}

/// Looking across the border from the south-west and straight down on it, near and far:
/// both tiles are seen, and the checks hold.
#[test]
fn across_the_border() {
    for (h, heading, pitch) in [
        (3_000.0, 60.0, -20.0),
        (30_000.0, 45.0, -35.0),
        (300_000.0, 0.0, -90.0),
        (2.0e7, 0.0, -90.0),
    ] {
        let camera = Camera::on_globe(43.4, 6.9, h, heading, pitch);
        let seen = check(&camera, 1.0).unwrap();
        assert!(seen > 0, "the camera at {h} m sees the tiles");
        let ds = Dataset::open(&built().ds).unwrap();
        let scene = ds.scene_on_globe(&camera, &SceneOptions::new(1.0)).unwrap();
        let tiles: BTreeSet<u64> = scene.blocks.iter().map(|b| b.tile).collect();
        assert_eq!(tiles.len(), 2, "both tiles at {h} m");
    }
}

/// From the far side of the Earth nothing is opened: both tiles are below the horizon.
#[test]
fn tiles_below_the_horizon_are_not_opened() {
    let ds = Dataset::open(&built().ds).unwrap();
    let camera = Camera::on_globe(-43.5, -173.0, 1.0e6, 0.0, -90.0);
    let scene = ds.scene_on_globe(&camera, &SceneOptions::new(1.0)).unwrap();
    assert!(scene.blocks.is_empty());
    assert_eq!(ds.tiles_opened(), 0);
    // Looking at them from the same height above them, they are.
    let near = Camera::on_globe(43.5, 7.0, 1.0e6, 0.0, -90.0);
    assert!(!ds
        .scene_on_globe(&near, &SceneOptions::new(1.0))
        .unwrap()
        .blocks
        .is_empty());
}

/// `fmrh scene DATASET --eye-geo` answers as the library; `--spacing` is refused on the
/// globe, and so is a dataset with no georeference.
#[test]
fn the_cli_takes_geographic_cameras_for_datasets() {
    let b = built();
    let ds_path = b.ds.to_str().unwrap();
    let json = common::ok_json(&common::fmrh(&[
        "scene",
        ds_path,
        "--eye-geo",
        "43.4,6.9,30000",
        "--look",
        "45,-35",
        "--tau",
        "1",
        "--json",
    ]));
    let ds = Dataset::open(&b.ds).unwrap();
    let scene = ds
        .scene_on_globe(
            &Camera::on_globe(43.4, 6.9, 30_000.0, 45.0, -35.0),
            &SceneOptions::new(1.0),
        )
        .unwrap();
    let cli: BTreeSet<(u64, u64, u64, u64)> = json["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| {
            (
                v["tile"].as_u64().unwrap(),
                v["level"].as_u64().unwrap(),
                v["x"].as_u64().unwrap(),
                v["y"].as_u64().unwrap(),
            )
        })
        .collect();
    let lib: BTreeSet<(u64, u64, u64, u64)> = scene
        .blocks
        .iter()
        .map(|v| {
            (
                v.tile,
                u64::from(v.block.level),
                u64::from(v.block.x),
                u64::from(v.block.y),
            )
        })
        .collect();
    assert!(!lib.is_empty());
    assert_eq!(cli, lib);
    let out = common::fmrh(&[
        "scene",
        ds_path,
        "--eye-geo",
        "43.4,6.9,30000",
        "--spacing",
        "90",
        "--tau",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--spacing"));
    // A dataset placed by a layout has no georeference.
    let dir = tempfile::tempdir().unwrap();
    let field = common::fields::make(40, 30, common::fields::Character::Hills, 0.0, 7);
    let rects = common::tiles::split(&field, &[20], &[], &[]);
    let plain = common::tiles::build(dir.path(), &field, &rects, &common::tiles::options(None));
    let out = common::fmrh(&[
        "scene",
        plain.to_str().unwrap(),
        "--eye-geo",
        "43.4,6.9,30000",
        "--tau",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("georeference"), "{err}");
}

/// `fmrh fly DATASET --geo` and `DatasetScheduler` with `globe`: frame by frame from orbit to
/// 1 km over the border, the blocks in view are the dataset's scene on the globe, and the
/// CLI's frames are the library's; with a memory radius, the tiles within it are scheduled
/// even when out of view, and a tile beyond it is not.
#[test]
fn a_geographic_path_flies_over_the_dataset() {
    use fmrh::dataset::DatasetScheduler;
    use fmrh::scene::ScheduleOptions;
    let b = built();
    let ds = Dataset::open(&b.ds).unwrap();
    let heights = [2.0e7, 1.0e6, 1.0e5, 2.0e4, 5.0e3, 1.0e3];
    let pitch = |i: usize| -90.0 + 12.0 * i as f64;
    let globe = ScheduleOptions {
        globe: true,
        ..ScheduleOptions::new(1.0)
    };
    let mut scheduler = DatasetScheduler::new(&ds, globe).unwrap();
    let mut visible = Vec::new();
    for (i, h) in heights.iter().enumerate() {
        let camera = Camera::on_globe(43.4, 6.9, *h, 45.0, pitch(i));
        let scene = ds.scene_on_globe(&camera, &SceneOptions::new(1.0)).unwrap();
        assert!(!scene.blocks.is_empty(), "frame {i}");
        let f = scheduler.frame(&camera).unwrap();
        assert_eq!(f.stats.visible, scene.blocks.len() as u64, "frame {i}");
        assert!(f.stats.max_screen_error <= 1.0);
        visible.push(f.stats.visible);
    }
    let path = b.ds.with_file_name("geo-path.csv");
    let lines: Vec<String> = heights
        .iter()
        .enumerate()
        .map(|(i, h)| format!("43.4,6.9,{h},45,{}", pitch(i)))
        .collect();
    std::fs::write(&path, lines.join("\n")).unwrap();
    let out = common::ok_json(&common::fmrh(&[
        "fly",
        b.ds.to_str().unwrap(),
        "--path",
        path.to_str().unwrap(),
        "--geo",
        "--tau",
        "1",
        "--json",
    ]));
    let cli: Vec<u64> = out["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["visible"].as_u64().unwrap())
        .collect();
    assert_eq!(cli, visible);
    // Low over N43E006, 8 km west of the border, looking west: only N43E006 is in view; a
    // 50 km memory radius holds N43E007 too.
    let west = Camera::on_globe(43.4, 6.9, 1000.0, 270.0, -10.0);
    let scene = ds.scene_on_globe(&west, &SceneOptions::new(1.0)).unwrap();
    assert!(scene.blocks.iter().all(|b| b.tile == 0));
    let ringed = ScheduleOptions {
        memory_radius: 50_000.0,
        ..globe
    };
    let in_view = DatasetScheduler::new(&ds, globe)
        .unwrap()
        .frame(&west)
        .unwrap();
    assert_eq!(in_view.tiles, 1);
    let near = DatasetScheduler::new(&ds, ringed)
        .unwrap()
        .frame(&west)
        .unwrap();
    assert_eq!(near.tiles, 2);
    assert_eq!(near.stats.visible, in_view.stats.visible);
    // Looking west from 5.5° E, neither tile is in view; N43E006 (40 km east) is within
    // the radius, N43E007 (120 km) is not.
    let far_west = Camera::on_globe(43.4, 5.5, 1000.0, 270.0, -10.0);
    let far = DatasetScheduler::new(&ds, ringed)
        .unwrap()
        .frame(&far_west)
        .unwrap();
    assert_eq!(far.tiles, 1);
    assert_eq!(far.stats.visible, 0);
}
