//! `Terrain::fly` (the door's moving camera) gives, frame by frame, exactly the scene
//! `Terrain::scene` gives for the same camera (the same blocks, rectangles, levels, errors
//! and heights bit for bit), while decoding only what entered the view: `loaded` is the
//! visible blocks the last frame did not have, `evicted` the last frame's blocks that left
//! the view, and a block held across frames is the same value. Over the shipped camera path
//! on the bundled SRTM tile (a container) and over a two-tile dataset built from it.

mod common;

use common::cuts::same_block as same;
use std::collections::HashSet;

use fmrh::glam::DVec3;
use fmrh::types::BlockKey;
use fmrh::{Block, Camera, SceneOptions, Terrain};

fn cameras() -> Vec<Camera> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/paths/n43e007-low-pass.csv");
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .step_by(3)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            Camera::looking_at(DVec3::new(v[0], v[1], v[2]), DVec3::new(v[3], v[4], v[5]))
        })
        .collect()
}

/// Flies `terrain` along `path`, checking every frame against a fresh scene; returns the
/// blocks loaded and the blocks visible, summed over the frames.
fn check(terrain: &Terrain, path: &[Camera], tau: f64) -> (usize, usize) {
    let options = SceneOptions::new(tau);
    let mut flight = terrain.fly(options, false);
    let mut last: Vec<BlockKey> = Vec::new();
    let mut held: std::collections::HashMap<BlockKey, std::sync::Arc<Block>> = Default::default();
    let (mut loaded, mut visible) = (0, 0);
    for (i, camera) in path.iter().enumerate() {
        let frame = flight.frame(camera).unwrap();
        assert_eq!(frame.index, i as u64);
        let scene = terrain.scene(camera, &options).unwrap();
        assert_eq!(frame.blocks.len(), scene.blocks.len(), "frame {i}");
        assert_eq!(frame.keys.len(), frame.blocks.len());
        for (a, b) in frame.blocks.iter().zip(&scene.blocks) {
            assert!(
                same(a, b),
                "frame {i}: block {:?} differs from the scene's",
                a.rect
            );
        }
        let now: HashSet<BlockKey> = frame.keys.iter().copied().collect();
        let before: HashSet<BlockKey> = last.iter().copied().collect();
        let want_loaded: HashSet<BlockKey> = now.difference(&before).copied().collect();
        let want_evicted: HashSet<BlockKey> = before.difference(&now).copied().collect();
        assert_eq!(
            frame.loaded.iter().copied().collect::<HashSet<_>>(),
            want_loaded
        );
        assert_eq!(
            frame.loaded.len(),
            want_loaded.len(),
            "a block loaded twice"
        );
        assert_eq!(
            frame.evicted.iter().copied().collect::<HashSet<_>>(),
            want_evicted
        );
        // A block kept from the last frame is the very value given then.
        for (k, b) in frame.keys.iter().zip(&frame.blocks) {
            if let Some(old) = held.get(k) {
                assert!(
                    std::sync::Arc::ptr_eq(old, b),
                    "frame {i}: a kept block was decoded again"
                );
            }
        }
        held = frame
            .keys
            .iter()
            .copied()
            .zip(frame.blocks.iter().cloned())
            .collect();
        loaded += frame.loaded.len();
        visible += frame.blocks.len();
        last = frame.keys;
    }
    (loaded, visible)
}

/// The bundled SRTM tile N43E007 built (defaults) into `dir`.
fn n43e007(dir: &std::path::Path) -> std::path::PathBuf {
    let out = dir.join("n43e007.fmrh");
    common::fmrh_ok(&[
        "build",
        "-q",
        common::bundled_dir()
            .join("srtm3-pyhgtmap/N43E007.hgt.gz")
            .to_str()
            .unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    out
}

#[test]
fn a_flight_over_a_container_gives_each_scene_and_decodes_only_what_entered() {
    let dir = tempfile::tempdir().unwrap();
    let out = n43e007(dir.path());
    let terrain = Terrain::open(&out).unwrap();
    let path = cameras();
    assert!(path.len() >= 10);
    let (loaded, visible) = check(&terrain, &path, 1.0);
    // The point of a flight: far fewer decodes than scenes from scratch.
    assert!(loaded * 2 < visible, "{loaded} loaded of {visible} visible");
}

/// Within the store's budget for decoded ancestors, a flight decodes no ancestor twice: the
/// grids its blocks are coded against, decoded for one frame, serve every later frame that
/// needs them. With a budget of one grid the same path decodes some again (what the
/// budget saves, and proof that the count can tell).
#[test]
fn a_flight_decodes_no_ancestor_twice_within_the_cache_budget() {
    let dir = tempfile::tempdir().unwrap();
    let out = n43e007(dir.path());
    let path = cameras();
    let fly = |budget: Option<u64>| {
        let terrain = Terrain::open(&out).unwrap();
        let store = terrain.store().unwrap();
        if let Some(b) = budget {
            store.set_ancestor_budget(b);
        }
        let mut flight = terrain.fly(SceneOptions::new(0.5), false);
        for camera in &path {
            flight.frame(camera).unwrap();
        }
        (store.ancestors_decoded(), store.ancestors_decoded_again())
    };
    let (decoded, again) = fly(None);
    assert!(decoded > 0, "the path needs ancestors");
    assert_eq!(again, 0, "{again} of {decoded} ancestors decoded again");
    let (tiny, tiny_again) = fly(Some(20_000));
    assert!(
        tiny_again > 0 && tiny > decoded,
        "a one-grid budget decoded {tiny} ({tiny_again} again) against {decoded}"
    );
}

#[test]
fn a_flight_over_a_dataset_gives_each_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let srtm = common::bundled_dir().join("srtm3-pyhgtmap");
    common::fmrh_ok(&[
        "dataset",
        "build",
        "-q",
        "--seam",
        "first",
        srtm.join("N43E006.hgt.gz").to_str().unwrap(),
        srtm.join("N43E007.hgt.gz").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let terrain = Terrain::open(&out).unwrap();
    // The path over N43E007, moved into the dataset's frame (its tile is east of N43E006).
    let spacing = terrain.info().unwrap().spacing_m.unwrap();
    let shift = DVec3::new(1200.0 * spacing[0], 0.0, 0.0);
    let path: Vec<Camera> = cameras()
        .into_iter()
        .map(|c| Camera {
            eye: c.eye + shift,
            target: c.target + shift,
            ..c
        })
        .collect();
    let (loaded, visible) = check(&terrain, &path, 2.0);
    assert!(loaded < visible, "{loaded} loaded of {visible} visible");
}
