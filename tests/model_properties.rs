//! Property tests of the terrain model on random heightfields of every character (ties, noise,
//! hills, cliffs, spikes, flats), with and without voids, at several block sizes and with both
//! the default ladder and random user thresholds. For each model, `check_model` asserts:
//! cover (every data cell in exactly one node of every cluster), bound (`e* <= δ`), minimality
//! (the parent's `e* > δ`), monotonicity of `e*`, exactness (every error, height range and valid
//! count equal to a naive recomputation, bit for bit), pruning, Hilbert order equal to seed
//! 000's Algorithm 2 order, and keys equal to the textbook Hilbert index.

mod common;

use common::fields::any_field;
use common::oracle::{check_model, NaiveModel};
use fmrh::model::{BuildOptions, MendedRaster, Model, Thresholds};
use proptest::prelude::*;

fn block_size() -> impl Strategy<Value = u32> {
    prop_oneof![Just(9u32), Just(9), Just(17), Just(33)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn invariants_hold_with_the_default_ladder(field in any_field(70), b in block_size()) {
        let model = Model::build(field.clone(), &BuildOptions { block_size: b, thresholds: Thresholds::Ladder, precision: None, thin: Default::default() }).unwrap();
        check_model(&model, &field);
    }

    #[test]
    fn invariants_hold_with_user_thresholds(
        field in any_field(50),
        b in block_size(),
        thresholds in prop::collection::vec(prop_oneof![Just(0.0), 0.0..200.0f64, 0.0..2.0f64], 1..6),
    ) {
        let options = BuildOptions { block_size: b, thresholds: Thresholds::Explicit(thresholds.clone()), precision: None, thin: Default::default() };
        let model = Model::build(field.clone(), &options).unwrap();
        let mut expected = thresholds.clone();
        expected.sort_by(f64::total_cmp);
        expected.dedup();
        let got: Vec<f64> = model.clusters().iter().map(|c| c.threshold).collect();
        prop_assert_eq!(got, expected, "user thresholds are kept as given");
        check_model(&model, &field);
    }

    #[test]
    fn mending_equals_the_naive_rule(field in any_field(40)) {
        let domain = fmrh::model::Domain::new(field.width(), field.height(), 9).unwrap();
        let naive = NaiveModel::new(&field, domain);
        let raster = MendedRaster::new(field.clone());
        for row in 0..domain.side() {
            for col in 0..domain.side() {
                prop_assert_eq!(raster.value(col, row).to_bits(), naive.mended(col, row).to_bits(), "({}, {})", col, row);
            }
        }
        // The raster is lossless.
        let back = raster.to_heightfield();
        prop_assert!(back.samples().iter().zip(field.samples()).all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())));
    }

    #[test]
    fn node_grids_are_nested_point_decimations(field in any_field(60), b in block_size()) {
        let model = Model::build(field.clone(), &BuildOptions { block_size: b, thresholds: Thresholds::Ladder, precision: None, thin: Default::default() }).unwrap();
        let tree = model.tree();
        let b = model.domain().block_size() as usize;
        for i in 0..tree.nodes().len() as u32 {
            let grid = model.node_grid(i);
            let fp = tree.footprint(i);
            let s = model.domain().stride(tree.node(i).level);
            for j in 0..b {
                for k in 0..b {
                    let (col, row) = (fp.col0 + k as u64 * s, fp.row0 + j as u64 * s);
                    let original = if col < u64::from(field.width()) && row < u64::from(field.height()) {
                        field.get(col as u32, row as u32)
                    } else {
                        None
                    };
                    prop_assert_eq!(grid.void[j * b + k], original.is_none());
                    if let Some(h) = original {
                        prop_assert_eq!(grid.heights[j * b + k], h);
                    }
                }
            }
            for c in tree.children(i) {
                // A child's grid holds its parent's samples (nesting).
                let child = model.node_grid(c);
                let cfp = tree.footprint(c);
                let off_x = ((cfp.col0 - fp.col0) / s) as usize;
                let off_y = ((cfp.row0 - fp.row0) / s) as usize;
                for j in 0..b.div_ceil(2) {
                    for k in 0..b.div_ceil(2) {
                        prop_assert_eq!(child.heights[2 * j * b + 2 * k], grid.heights[(off_y + j) * b + off_x + k]);
                    }
                }
            }
        }
    }
}
