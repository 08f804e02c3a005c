//! Thinning by area (the study of `benches/common/thinning_study.rs`): a node's grid thinned `k` times east-west and
//! its measured static error. Checked here: with `k = 1` the error is the stored static
//! error bit for bit; for any `k` it equals a naive recomputation from the thinned grid's own
//! heights, cell by cell; a plane is reproduced by every thinned grid; the factor follows the
//! true ground spacing (1 at the equator, 2 from 60°, 4 from about 76°); the thinned
//! monotone errors never grow downwards; and a cut at any threshold covers the data exactly
//! once with every node within the threshold.

mod common;

#[path = "../benches/common/thinning_study.rs"]
mod study;

use common::fields::any_field;
use fmrh::model::thinning::LatLonSpacing;
use fmrh::model::{BuildOptions, Model, SampleRect, Thresholds};
use fmrh::Heightfield;
use proptest::prelude::*;
use study::{cut, rect_surface, thinned_error, thinned_grid, AreaThinning};

fn build(field: Heightfield, b: u32) -> Model {
    Model::build(
        field,
        &BuildOptions {
            block_size: b,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap()
}

/// The naive thinned error: every cell of the thinned grid (its heights as `thinned_grid`
/// gives them), every valid sample in the cell's closed rectangle, the largest distance.
fn naive_error(model: &Model, index: u32, k: u32) -> f64 {
    let n = *model.tree().node(index);
    let d = model.domain();
    let (cols, grid) = thinned_grid(model.raster(), d, n.level, n.x, n.y, k);
    let (b, s) = (u64::from(d.block_size()), d.stride(n.level));
    let (sx, sy) = (s * u64::from(k), s);
    let fp = d.footprint(n.level, n.x, n.y);
    let at = |i: u64, j: u64| grid[(j * u64::from(cols) + i) as usize];
    let mut worst = 0.0f64;
    for j in 0..b - 1 {
        for i in 0..u64::from(cols) - 1 {
            for v in 0..=sy {
                for u in 0..=sx {
                    let (col, row) = (fp.col0 + i * sx + u, fp.row0 + j * sy + v);
                    let Some(h) = model.raster().original(col, row) else {
                        continue;
                    };
                    let z = rect_surface(
                        at(i, j),
                        at(i + 1, j),
                        at(i, j + 1),
                        at(i + 1, j + 1),
                        sx,
                        sy,
                        u,
                        v,
                    );
                    worst = worst.max((f64::from(h) - z).abs());
                }
            }
        }
    }
    worst
}

fn block_size() -> impl Strategy<Value = u32> {
    prop_oneof![Just(9u32), Just(17)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Unthinned, the measure is the model's own, bit for bit.
    #[test]
    fn k1_is_the_static_error(field in any_field(60), b in block_size()) {
        let model = build(field, b);
        let d = model.domain();
        for n in model.tree().nodes() {
            let e = thinned_error(model.raster(), d, n.level, n.x, n.y, 1);
            prop_assert_eq!(e.to_bits(), n.static_error.to_bits(), "node {:?}", (n.level, n.x, n.y));
        }
    }

    /// Thinned, the measure is the largest distance from the thinned grid's surface.
    #[test]
    fn thinned_error_is_exact(field in any_field(60), b in block_size(), log_k in 1u32..4) {
        let model = build(field, b);
        let d = model.domain();
        let k = (1u32 << log_k).min(b - 1);
        for (i, n) in model.tree().nodes().iter().enumerate() {
            let e = thinned_error(model.raster(), d, n.level, n.x, n.y, k);
            let naive = naive_error(&model, i as u32, k);
            prop_assert!((e - naive).abs() <= 1e-9 * (1.0 + naive.abs()),
                "node {:?}: {e} against {naive}", (n.level, n.x, n.y));
        }
    }

    /// A cell stretched east-west is the square cell's surface, stretched: the barycentric
    /// weights of a point are those of its image in the square cell.
    #[test]
    fn rectangular_cells_are_stretched_squares(
        c in proptest::array::uniform4(-1000.0f32..1000.0), log_s in 0u32..5, log_k in 1u32..4,
        fu in 0.0f64..=1.0, fv in 0.0f64..=1.0,
    ) {
        let (s, k) = (1u64 << log_s, 1u64 << log_k);
        let (u, v) = ((fu * s as f64) as u64, (fv * s as f64) as u64);
        let square = fmrh::model::surface::surface(c[0], c[1], c[2], c[3], s, u, v);
        let stretched = rect_surface(c[0], c[1], c[2], c[3], k * s, s, k * u, v);
        prop_assert!((square - stretched).abs() <= 1e-9 * (1.0 + square.abs()), "{square} against {stretched}");
    }

    /// A plane is drawn exactly by any grid over it, thinned or not.
    #[test]
    fn planes_are_reproduced(w in 2u32..70, h in 2u32..70, a in -50.0f64..50.0, c in -50.0f64..50.0, log_k in 0u32..4) {
        let field = Heightfield::from_fn(w, h, |x, y| (a * f64::from(x) + c * f64::from(y) + 100.0) as f32).unwrap();
        let model = build(field, 17);
        let d = model.domain();
        let k = 1u32 << log_k;
        for n in model.tree().nodes() {
            // Padding clamps the plane at the data's edge, so only nodes within the data.
            let fp = d.footprint(n.level, n.x, n.y);
            if fp.col1 >= u64::from(w) || fp.row1 >= u64::from(h) {
                continue;
            }
            let e = thinned_error(model.raster(), d, n.level, n.x, n.y, k);
            prop_assert!(e <= 1e-3, "node {:?}: {e}", (n.level, n.x, n.y));
        }
    }

    /// The thinned monotone error never grows downwards and bounds the node's own; a cut
    /// covers every data sample exactly once, each node in it within the threshold (or a
    /// physical block, error 0).
    #[test]
    fn cuts_cover_once_within_the_threshold(field in any_field(60), b in block_size(), lat0 in 50.0f64..89.0, frac in 0.0f64..1.0) {
        let (w, h) = (field.width(), field.height());
        let model = build(field, b);
        let spacing = LatLonSpacing { lat0, dlat: -0.01, dlon: 0.01 };
        let t = AreaThinning::measure(model.raster(), model.tree(), &spacing);
        let tree = model.tree();
        for (i, n) in tree.nodes().iter().enumerate() {
            prop_assert!(t.monotone_error[i] >= t.static_error[i]);
            if i > 0 {
                prop_assert!(t.monotone_error[n.parent as usize] >= t.monotone_error[i]);
            }
        }
        let delta = t.monotone_error[0] * frac;
        let mut hits = vec![0u8; w as usize * h as usize];
        let d = model.domain();
        for (index, level, x, y) in cut(tree, &t.monotone_error, delta) {
            if let Some(i) = index {
                prop_assert!(t.monotone_error[i as usize] <= delta || level == d.finest_level());
            }
            let fp = d.footprint(level, x, y);
            // Each node owns its footprint but its south and east edges (shared with the
            // next), except at the data's edge.
            let end = |last: u64, n: u32| if last + 1 >= u64::from(n) { u64::from(n) } else { last };
            for row in fp.row0..end(fp.row1, h) {
                for col in fp.col0..end(fp.col1, w) {
                    hits[row as usize * w as usize + col as usize] += 1;
                }
            }
        }
        prop_assert!(hits.iter().all(|&c| c == 1), "every sample once");
    }
}

/// The factor at a few latitudes, for a grid as fine in latitude as in longitude (SRTM,
/// ETOPO): 1 up to 60°, 2 to about 75.5°, 4 to about 82.8°, capped at `b - 1` by the pole.
#[test]
fn the_factor_follows_the_ground_spacing() {
    let s = LatLonSpacing {
        lat0: 0.0,
        dlat: -1.0 / 1200.0,
        dlon: 1.0 / 1200.0,
    };
    let at = |lat: f64| {
        let row = (-lat / s.dlat) as u64;
        s.factor(
            &SampleRect {
                col0: 0,
                row0: row,
                col1: 64,
                row1: row,
            },
            64,
        )
    };
    assert_eq!(at(0.0), 1);
    assert_eq!(at(43.5), 1);
    assert_eq!(at(59.0), 1);
    assert_eq!(at(61.0), 2);
    assert_eq!(at(75.0), 2);
    assert_eq!(at(77.0), 4);
    assert_eq!(at(84.0), 8);
    assert_eq!(at(89.99), 64);
    // A rectangle across the equator, or reaching it, is as wide as at the equator.
    let across = SampleRect {
        col0: 0,
        row0: 0,
        col1: 10,
        row1: 100_000,
    };
    assert_eq!(s.factor(&across, 64), 1);
    // The south pole as the north.
    let south = LatLonSpacing { lat0: -80.0, ..s };
    assert_eq!(
        south.factor(
            &SampleRect {
                col0: 0,
                row0: 0,
                col1: 1,
                row1: 1
            },
            64
        ),
        4
    );
}

/// A bump on a column the thinned grid skips is missed by its surface: the error is the
/// bump, where the square grid (which samples that column) draws it.
#[test]
fn a_skipped_column_shows_in_the_error() {
    let field = Heightfield::from_fn(17, 17, |x, _| if x == 1 { 10.0 } else { 0.0 }).unwrap();
    let model = build(field, 17);
    let d = model.domain();
    let n = *model.tree().node(0);
    assert_eq!(d.stride(n.level), 1, "one block: the root is the data");
    assert_eq!(thinned_error(model.raster(), d, n.level, n.x, n.y, 1), 0.0);
    assert_eq!(thinned_error(model.raster(), d, n.level, n.x, n.y, 2), 10.0);
}
