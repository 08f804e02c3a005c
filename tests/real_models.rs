//! Models of the real DEMs in `../shared/data`. Every dataset builds. The small ones pass the
//! full invariant check, including every error recomputed naively. The large ones pass the
//! structural checks (cover, bound, minimality, monotonicity) plus exactness on a random sample
//! of nodes. On the SRTM tiles with voids, and on St Helens with voids along its data edge, the
//! void rule gives no fake spikes: every stand-in is the nearest valid height in its row or
//! column, and no node's range or error leaves the valid data's range.

mod common;

use common::oracle::{assert_cut_covers, assert_measured_exactly, check_model, NaiveModel};
use common::{data, fields::Rng};
use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model, NO_PARENT};
use fmrh::Heightfield;

fn read(rel: &str) -> Heightfield {
    load(&data(rel), &IngestOptions::default()).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

const SMALL: [&str; 5] = [
    "pysheds-dem/pysheds_dem.json",
    "gdal-rs-dem-hills/dem_hills.json",
    "mount-st-helens-usgs/SainteHelens.json",
    "fuji-terrain-rgb/fuji.json",
    "puget-sound-east-512/ps-e_lg.json",
];

const LARGE: [&str; 10] = [
    "puget-sound-1k/ps_height_1k.json",
    "topotoolbox-bigtujunga/bigtujunga.json",
    "srtm3-srtmpy/N19W155.json",
    "srtm3-srtmpy/N22W160.json",
    "srtm3-srtmpy/N44W072.json",
    "srtm3-srtmpy/S16E166.json",
    "srtm3-pyhgtmap/N43E006.json",
    "srtm3-pyhgtmap/N43E007.json",
    "srtm1-asmyasnikov/S46W066.json",
    "puget-sound-4k-jpg/ps_height_4k_jpg.json",
];

#[test]
fn small_datasets_pass_every_invariant() {
    for rel in SMALL {
        let source = read(rel);
        for b in [17, 65] {
            let model = Model::build(
                source.clone(),
                &BuildOptions {
                    block_size: b,
                    ..BuildOptions::default()
                },
            )
            .unwrap();
            check_model(&model, &source);
        }
    }
}

/// Cover, bound, minimality, monotonicity, and exactness on `samples` random nodes.
fn check_large(model: &Model, source: &Heightfield, samples: usize, seed: u64) {
    let tree = model.tree();
    let nodes = tree.nodes();
    for n in nodes.iter().filter(|n| n.parent != NO_PARENT) {
        assert!(n.monotone_error <= nodes[n.parent as usize].monotone_error);
    }
    for c in model.clusters() {
        assert_cut_covers(model, c);
    }
    let naive = NaiveModel::new(source, *model.domain());
    let mut rng = Rng::new(seed);
    for _ in 0..samples {
        let n = &nodes[(rng.next_u64() % nodes.len() as u64) as usize];
        assert_measured_exactly(&naive, n);
    }
}

#[test]
fn large_datasets_build_and_hold_their_invariants() {
    for (i, rel) in LARGE.iter().enumerate() {
        let source = read(rel);
        let model = Model::build(source.clone(), &BuildOptions::default()).unwrap();
        assert!(
            model.clusters().len() >= 2,
            "{rel}: a ladder, not just the lossless cluster"
        );
        assert_eq!(model.clusters()[0].threshold, 0.0);
        check_large(&model, &source, 12, i as u64);
    }
}

#[test]
fn voids_make_no_fake_spikes() {
    for rel in [
        "srtm3-srtmpy/N22W160.json",
        "srtm3-srtmpy/S16E166.json",
        "mount-st-helens-usgs/SainteHelens.json",
        "gdal-rs-dem-hills/dem_hills.json",
    ] {
        let source = read(rel);
        assert!(source.void_count() > 0, "{rel} has voids");
        let (w, h) = (source.width() as usize, source.height() as usize);
        let s = source.samples();
        let valid: Vec<f32> = s.iter().copied().filter(|v| !v.is_nan()).collect();
        let (lo, hi) = valid
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let model = Model::build(source.clone(), &BuildOptions::default()).unwrap();
        let raster = model.raster();
        // Every stand-in is a valid height from its own row or column (rule 1; no sample of
        // these datasets has both its row and its column void, so rule 2 never applies).
        for y in 0..h {
            for x in 0..w {
                if !s[y * w + x].is_nan() {
                    continue;
                }
                let v = raster.value(x as u64, y as u64);
                let in_row = (0..w).any(|xx| s[y * w + xx] == v);
                let in_col = (0..h).any(|yy| s[yy * w + x] == v);
                assert!(
                    in_row || in_col,
                    "{rel}: stand-in {v} at ({x}, {y}) is no neighbour's height"
                );
            }
        }
        for n in model.tree().nodes() {
            assert!(
                lo <= n.min_height && n.max_height <= hi,
                "{rel}: node range leaves the data's"
            );
            assert!(n.monotone_error.is_finite() && n.monotone_error <= f64::from(hi - lo));
        }
        check_large(&model, &source, 30, 99);
    }
}
