//! Geodetic tiles cut as error-bounded TINs (`fmrh::export::tin_tile`), read back by the
//! reference decoder (`common::quantized_mesh`, written from the public specification):
//!
//! * **the declared error holds**: at every source sample inside a tile, the height the
//!   decoded tile draws there (linear in `u, v` over the triangle holding it, found here by
//!   search) is within the tile's measured `error` of the source;
//! * **neighbours share their edges**: two tiles of one level that meet have the same
//!   vertices along their common edge, at the same decoded heights;
//! * what a tile computes of its neighbours' edges (which the server keeps) is what each
//!   neighbour computes of itself;
//! * the mesh is a TIN, not the grid: flat ground is two triangles, and no tile has more
//!   triangles than the full 65² grid.
//!
//! Random georeferenced fields (hills, cliffs, spikes, noise) anywhere off the poles,
//! random budgets, cut from `Terrain::cut` at a random bound.

mod common;

use fmrh::export::geodetic::{tiles_meeting, GeodeticTile};
use fmrh::export::geodetic_mesh::{level_for_step, Placement};
use fmrh::export::quantized_mesh;
use fmrh::export::tin_tile::{neighbour, tin_tile, Quanta};
use fmrh::scene::surface::{GridBlock, Surface};
use fmrh::types::SampleRect;
use fmrh::{CreateOptions, Terrain};
use proptest::prelude::*;

const STEP: f64 = 1.0 / 1200.0;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn tin_tiles_keep_their_error_and_share_their_edges(
        lon in -179.0f64..178.0,
        lat in -80.0f64..80.0,
        character in common::fields::character(),
        seed in any::<u64>(),
        budget in prop_oneof![Just(0.0), 0.0f64..60.0],
        bound in prop_oneof![Just(0.0), 0.0f64..40.0],
        coarser in 0u8..3,
    ) {
        let (w, h) = (161u32, 129u32);
        let mut field = common::fields::make(w, h, character, 0.0, seed);
        let georeference = fmrh::heightfield::Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [lon, lat],
            step: [STEP, -STEP],
        };
        field.metadata.georeference = Some(georeference.clone());
        let source = field.clone();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.fmrh");
        fmrh::create(&path, field, &CreateOptions { block_size: 33, ..CreateOptions::default() })
            .unwrap();
        let terrain = Terrain::open(&path).unwrap();
        let all = SampleRect { col0: 0, row0: 0, col1: u64::from(w - 1), row1: u64::from(h - 1) };
        let cut = terrain.cut(all, bound).unwrap();
        let blocks: Vec<GridBlock<'_>> = cut
            .blocks
            .iter()
            .map(|b| GridBlock {
                rect: b.rect,
                stride: b.stride,
                grid_width: b.width,
                grid_height: b.height,
                heights: &b.heights,
                error: b.error,
            })
            .collect();
        let surface = Surface::new(blocks);
        let placement = Placement::new(&georeference, 1.0).unwrap();
        let data_box = placement.box_of(&all).unwrap();
        let (min, max) = source.samples().iter().filter(|v| v.is_finite())
            .fold((0.0f64, 0.0f64), |(a, b), &v| (a.min(f64::from(v)), b.max(f64::from(v))));
        let quanta = Quanta::for_range(min, max);
        let z = level_for_step(STEP).saturating_sub(coarser);
        let tiles: Vec<GeodeticTile> = tiles_meeting(z, data_box);
        let mut cut_tiles = std::collections::HashMap::new();
        let mut learnt_edges = std::collections::HashMap::new();
        for &t in &tiles {
            let (tin, learnt) =
                tin_tile(t, &surface, &placement, data_box, budget, quanta, &|_| None).unwrap();
            // What a tile learns of its neighbours is what each says of itself (the
            // server keeps it, and cuts later tiles from it).
            prop_assert_eq!(learnt[0].0, t);
            for (n, e) in learnt {
                if let Some(previous) = learnt_edges.insert(n, e.clone()) {
                    prop_assert_eq!(previous, e, "two tiles computed different edges for {:?}", n);
                }
            }
            let bytes = quantized_mesh::write(&tin.data).unwrap();
            let decoded = common::quantized_mesh::decode(&bytes);
            prop_assert!(decoded.triangles.len() <= 2 * 64 * 64);
            if matches!(character, common::fields::Character::Flat) && bound == 0.0 {
                // Flat data under a tile and its four neighbours (whose edge vertices it
                // takes): the two halves. A neighbour reaching past the data meshes the
                // drop there, and may hand this tile vertices on their shared edge.
                let inside = |t: GeodeticTile| {
                    let [tw, ts, te, tn] = t.bounds();
                    tw > data_box[0] && te < data_box[2] && ts > data_box[1] && tn < data_box[3]
                };
                if inside(t) && (0..4).all(|side| neighbour(t, side).is_some_and(inside)) {
                    prop_assert_eq!(decoded.triangles.len(), 2);
                }
            }
            let heights: Vec<f64> = decoded.h.iter().map(|&c| {
                let (lo, hi) = (f64::from(decoded.min_height), f64::from(decoded.max_height));
                lo + f64::from(c) / 32767.0 * (hi - lo)
            }).collect();
            // The declared error, against the source itself.
            let [tw, ts, te, tn] = t.bounds();
            for row in 0..h {
                for col in 0..w {
                    let (x, y) = (lon + f64::from(col) * STEP, lat - f64::from(row) * STEP);
                    if !(x >= tw && x <= te && y >= ts && y <= tn) {
                        continue;
                    }
                    let truth = f64::from(source.get(col, row).unwrap());
                    let fu = (x - tw) / (te - tw) * 32767.0;
                    let fv = (y - ts) / (tn - ts) * 32767.0;
                    let drawn = draw(&decoded, &heights, fu, fv);
                    prop_assert!(
                        (drawn - truth).abs() <= tin.error + 1e-6,
                        "tile {t:?}: {drawn} drawn at sample ({col}, {row}) where the source \
                         is {truth}, past the declared error {}", tin.error
                    );
                }
            }
            cut_tiles.insert(t, (decoded, heights));
        }
        // Shared edges: same vertices, same heights.
        for (&t, (d, hs)) in &cut_tiles {
            for (side, fixed, theirs_fixed) in [(1usize, 32767u16, 0u16), (2, 32767, 0)] {
                let Some(n) = neighbour(t, side) else { continue };
                let Some((dn, hn)) = cut_tiles.get(&n) else { continue };
                let along = |d: &common::quantized_mesh::Decoded, hs: &[f64], east: bool, at: u16| {
                    let mut v: Vec<(u16, f64)> = (0..d.u.len())
                        .filter(|&k| if east { d.u[k] == at } else { d.v[k] == at })
                        .map(|k| (if east { d.v[k] } else { d.u[k] }, hs[k]))
                        .collect();
                    v.sort_by_key(|a| a.0);
                    v
                };
                let (mine, theirs) = (along(d, hs, side == 1, fixed), along(dn, hn, side == 1, theirs_fixed));
                prop_assert_eq!(mine.len(), theirs.len(), "tiles {:?} and {:?} differ on their edge", t, n);
                for (a, b) in mine.iter().zip(&theirs) {
                    prop_assert_eq!(a.0, b.0);
                    prop_assert!((a.1 - b.1).abs() <= 1e-6, "heights {} and {} on a shared vertex", a.1, b.1);
                }
            }
        }
    }
}

/// The height the decoded tile draws at quantized `(fu, fv)`: linear over the triangle
/// holding it, found by search (the best barycentric margin).
fn draw(d: &common::quantized_mesh::Decoded, heights: &[f64], fu: f64, fv: f64) -> f64 {
    let mut best = (f64::NEG_INFINITY, f64::NAN);
    for t in &d.triangles {
        let p: Vec<[f64; 2]> = t
            .iter()
            .map(|&i| [f64::from(d.u[i as usize]), f64::from(d.v[i as usize])])
            .collect();
        let area =
            (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
        let b = |a: [f64; 2], c: [f64; 2]| {
            ((c[0] - a[0]) * (fv - a[1]) - (c[1] - a[1]) * (fu - a[0])) / area
        };
        let l = [b(p[1], p[2]), b(p[2], p[0]), b(p[0], p[1])];
        let margin = l[0].min(l[1]).min(l[2]);
        if margin > best.0 {
            let value = l[0] * heights[t[0] as usize]
                + l[1] * heights[t[1] as usize]
                + l[2] * heights[t[2] as usize];
            best = (margin, value);
        }
    }
    best.1
}
