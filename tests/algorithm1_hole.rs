//! Regression for seed 000's Algorithm 1. Taken literally (a node joins the cluster of the
//! interval `[δᵢ, δᵢ₊₁]` holding its error, unless an ancestor is already in it), it leaves a
//! hole when errors jump across an interval. Here the root is rough (above the interval) and a
//! flat quadrant's subtree is exact (below it). No node of that quadrant's path lies in the
//! interval, so the literal algorithm's cluster misses the quadrant. The cut `C(δ)` that fmrh
//! builds covers it.

mod common;

use common::oracle::{algorithm1_literal, cover_counts};
use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::Heightfield;

/// 33 x 33 samples, blocks of 9: a flat north-west quadrant and rough terrain elsewhere.
fn field() -> Heightfield {
    Heightfield::from_fn(33, 33, |x, y| {
        if x <= 16 && y <= 16 {
            0.0
        } else {
            ((x * 7 + y * 13) % 11) as f32 * 10.0
        }
    })
    .unwrap()
}

#[test]
fn literal_algorithm_one_leaves_a_hole_the_cut_does_not() {
    let source = field();
    // Thresholds 0 < 1 < 2: interval [1, 2] lies between the flat quadrant (e* = 0) and the
    // rough root (e* far above 2).
    let thresholds = vec![0.0, 1.0, 2.0];
    let model = Model::build(
        source,
        &BuildOptions {
            block_size: 9,
            thresholds: Thresholds::Explicit(thresholds.clone()),
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap();
    let tree = model.tree();
    let flat = tree.find(1, 0, 0).expect("the north-west quadrant");
    assert_eq!(tree.node(flat).monotone_error, 0.0);
    assert!(tree.node(0).monotone_error > 2.0);

    let literal = algorithm1_literal(&model, &thresholds);
    let interval = &literal[1]; // [1, 2]
    let counts = cover_counts(&model, interval);
    let holes = counts.iter().filter(|&&c| c == 0).count();
    assert!(
        holes > 0,
        "the literal algorithm covers everything here: {counts:?}"
    );
    // The hole is the flat quadrant: 16 x 16 cells.
    assert!(holes >= 16 * 16, "{holes} uncovered cells");

    // fmrh's cut at δ = 2 (and at every threshold) covers each cell once.
    for c in model.clusters() {
        assert!(
            cover_counts(&model, &c.nodes).iter().all(|&k| k == 1),
            "cut {}",
            c.threshold
        );
    }
    let cut = &model.clusters()[2];
    assert_eq!(cut.threshold, 2.0);
    assert!(
        cut.nodes.contains(&flat),
        "the cut takes the flat quadrant whole"
    );
}
