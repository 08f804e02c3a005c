//! Datasets for tests: a field cut into tiles that share their edge rows and columns (as
//! SRTM's do), written as `.f32` + `.json` tiles with a layout, and built with the library.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::fields::Rng;
use fmrh::dataset::{DatasetOptions, DatasetScene, SeamPolicy, TileInput};
use fmrh::model::{BuildOptions, SampleRect, Thresholds};
use fmrh::scene::{Camera, Mode};
use fmrh::store::WriteOptions;
use fmrh::Heightfield;

/// Writes `hf` as `dir/name.f32` and its sidecar (with `spacing` metres between samples).
pub fn write_f32(dir: &Path, name: &str, hf: &Heightfield, spacing: f64) -> PathBuf {
    let f32_path = dir.join(format!("{name}.f32"));
    let bytes: Vec<u8> = hf.samples().iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&f32_path, bytes).unwrap();
    let json = serde_json::json!({
        "width": hf.width(),
        "height": hf.height(),
        "f32_file": format!("{name}.f32"),
        "nodata_in_f32": "NaN",
        "spacing_m": [spacing, spacing],
    });
    std::fs::write(dir.join(format!("{name}.json")), json.to_string()).unwrap();
    f32_path
}

/// The samples of `field` in `rect`.
pub fn crop(field: &Heightfield, rect: &SampleRect) -> Heightfield {
    let w = field.width() as u64;
    Heightfield::from_fn(
        (rect.col1 - rect.col0 + 1) as u32,
        (rect.row1 - rect.row0 + 1) as u32,
        |x, y| {
            field.samples()[((rect.row0 + u64::from(y)) * w + rect.col0 + u64::from(x)) as usize]
        },
    )
    .unwrap()
}

/// The tiles of `field` cut at columns `cols` and rows `rows` (each cut a shared line, so
/// neighbours overlap by it), with `holes` (indexes in row-major tile order) left out.
pub fn split(field: &Heightfield, cols: &[u64], rows: &[u64], holes: &[usize]) -> Vec<SampleRect> {
    let edges = |cuts: &[u64], n: u64| {
        let mut e = vec![0];
        e.extend_from_slice(cuts);
        e.push(n - 1);
        e
    };
    let (cx, cy) = (
        edges(cols, u64::from(field.width())),
        edges(rows, u64::from(field.height())),
    );
    let mut out = Vec::new();
    let mut i = 0;
    for ry in cy.windows(2) {
        for rx in cx.windows(2) {
            if !holes.contains(&i) {
                out.push(SampleRect {
                    col0: rx[0],
                    row0: ry[0],
                    col1: rx[1],
                    row1: ry[1],
                });
            }
            i += 1;
        }
    }
    out
}

/// The dataset validator's report on `dir`, in `mode`.
pub fn verify(dir: &Path, mode: fmrh::store::VerifyMode) -> fmrh::dataset::DatasetReport {
    fmrh::dataset::verify(dir, mode, &fmrh::progress::Silent).unwrap()
}

/// Options for small test datasets: blocks of 9, `thresholds` (or the ladder), 1 KiB pages.
pub fn options(thresholds: Option<Vec<f64>>) -> DatasetOptions {
    DatasetOptions {
        ingest: fmrh::ingest::IngestOptions::default(),
        build: BuildOptions {
            block_size: 9,
            thresholds: thresholds.map_or(Thresholds::Ladder, Thresholds::Explicit),
            precision: None,
            thin: Default::default(),
        },
        write: WriteOptions {
            page_size: 1024,
            ..WriteOptions::default()
        },
        seam: SeamPolicy::Strict,
        spacing_m: None,
        tile_size: None,
    }
}

/// Writes the tiles `rects` of `field` into `dir/tiles` and builds the dataset `dir/ds`
/// from them by a layout.
pub fn build(
    dir: &Path,
    field: &Heightfield,
    rects: &[SampleRect],
    options: &DatasetOptions,
) -> PathBuf {
    let tiles = dir.join("tiles");
    std::fs::create_dir_all(&tiles).unwrap();
    let inputs: Vec<TileInput> = rects
        .iter()
        .enumerate()
        .map(|(i, r)| TileInput {
            path: write_f32(&tiles, &format!("t{i}"), &crop(field, r), 10.0),
            at: Some((r.col0, r.row0)),
        })
        .collect();
    let out = dir.join("ds");
    fmrh::dataset::build(
        &inputs,
        &out,
        options,
        &fmrh::progress::Silent,
        &mut |_, _, _, _| {},
    )
    .unwrap();
    out
}

/// How many scene blocks cover each cell (unit square between samples) of `window`.
pub fn cell_counts(scene: &DatasetScene, window: &SampleRect) -> Vec<u32> {
    let (w, h) = (window.col1 - window.col0, window.row1 - window.row0);
    let mut counts = vec![0u32; (w * h) as usize];
    for b in &scene.blocks {
        let r = b.block.rect();
        let (c0, c1) = (r.col0.max(window.col0), r.col1.min(window.col1));
        let (r0, r1) = (r.row0.max(window.row0), r.row1.min(window.row1));
        for row in r0..r1 {
            for col in c0..c1 {
                counts[((row - window.row0) * w + col - window.col0) as usize] += 1;
            }
        }
    }
    counts
}

/// Whether cell `(col, row)` lies in some tile.
pub fn in_a_tile(rects: &[SampleRect], col: u64, row: u64) -> bool {
    rects
        .iter()
        .any(|r| col >= r.col0 && col < r.col1 && row >= r.row0 && row < r.row1)
}

/// Checks `scene` of `camera` over the tiles `rects` of `field` (10 m spacing): within
/// tau (the screen error recomputed here, in the dataset's frame) or the uniform bound; a
/// window's cells each covered once where a tile lies, no cell twice; and, without a
/// window, every sample the frustum sees inside some block.
pub fn check_scene(
    scene: &DatasetScene,
    field: &fmrh::Heightfield,
    rects: &[SampleRect],
    camera: &Camera,
    mode: Mode,
    tau: f64,
    window: Option<SampleRect>,
) {
    let view = camera.view().unwrap();
    let world = |col: u64, row: u64, z: f64| DVec3::new(col as f64 * 10.0, row as f64 * 10.0, z);
    for b in &scene.blocks {
        let r = b.block.rect();
        let bx = fmrh::scene::Aabb {
            min: world(r.col0, r.row0, f64::from(b.block.min_height)),
            max: world(r.col1, r.row1, f64::from(b.block.max_height)),
        };
        let px = view.screen_error(b.block.error, bx.distance(view.eye));
        match mode {
            Mode::View => assert!(
                px <= tau * (1.0 + 1e-9) || b.block.error == 0.0,
                "block {r:?} of tile {} is {px} px > tau {tau}",
                b.tile,
            ),
            Mode::Uniform => {
                let allowed = scene
                    .stats
                    .allowed_error
                    .expect("uniform scenes state their bound");
                assert!(
                    b.block.error <= allowed.max(scene.stats.threshold.unwrap_or(0.0)) + 1e-9,
                    "block error {} above the bound {allowed}",
                    b.block.error
                );
            }
        }
    }
    let grid = SampleRect {
        col0: 0,
        row0: 0,
        col1: rects.iter().map(|r| r.col1).max().unwrap(),
        row1: rects.iter().map(|r| r.row1).max().unwrap(),
    };
    let area = window.unwrap_or(grid);
    let counts = cell_counts(scene, &area);
    let w = area.col1 - area.col0;
    for (i, &c) in counts.iter().enumerate() {
        let (col, row) = (
            area.col0 + i as u64 % w.max(1),
            area.row0 + i as u64 / w.max(1),
        );
        assert!(c <= 1, "cell ({col}, {row}) is covered {c} times");
        if window.is_some() {
            let expect = u32::from(in_a_tile(rects, col, row));
            assert_eq!(
                c, expect,
                "cell ({col}, {row}) covered {c} times, expected {expect}"
            );
        }
    }
    if window.is_none() {
        let w = u64::from(field.width());
        for row in 0..u64::from(field.height()) {
            for col in 0..w {
                let z = field.samples()[(row * w + col) as usize];
                if z.is_nan() || !rects.iter().any(|r| r.contains(col, row)) {
                    continue;
                }
                let p = world(col, row, f64::from(z));
                if view
                    .planes
                    .iter()
                    .any(|pl| pl.normal.dot(p) + pl.offset < 0.0)
                {
                    continue;
                }
                assert!(
                    scene
                        .blocks
                        .iter()
                        .any(|b| b.block.rect().contains(col, row)),
                    "visible sample ({col}, {row}) lies in no block"
                );
            }
        }
    }
}

pub fn camera(rng: &mut Rng, w: f64, h: f64) -> Camera {
    let eye = DVec3::new(
        (rng.unit() * 2.0 - 0.5) * w * 10.0,
        (rng.unit() * 2.0 - 0.5) * h * 10.0,
        20.0 + rng.unit() * 1500.0,
    );
    let target = DVec3::new(rng.unit() * w * 10.0, rng.unit() * h * 10.0, 0.0);
    let mut c = Camera::looking_at(eye, target);
    c.viewport = [640, 480];
    c
}

/// A cut strategy: `k` distinct interior cut lines of `0..n`.
pub fn cuts(n: u64, k: usize, rng: &mut Rng) -> Vec<u64> {
    let mut c: Vec<u64> = (0..k).map(|_| 1 + rng.next_u64() % (n - 2)).collect();
    c.sort_unstable();
    c.dedup();
    c
}
