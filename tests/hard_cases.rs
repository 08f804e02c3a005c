//! Numerical and structural edge cases, one named test each: flat ground, spikes, cliffs,
//! checkerboards, sine ridges, huge offsets, values near ±1e30, tiny ranges, voids (all,
//! islands, a single valid sample), degenerate sizes (1x1, 2x2, thin, non-square), the
//! diagonal's orientation and thresholds exactly equal to node errors. Every model here also
//! passes the full invariant check (`check_model`: cover, bound, minimality, monotonicity,
//! exactness, Hilbert order).

mod common;

use common::fields::Rng;
use common::oracle::check_model;
use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::Heightfield;

fn build(field: &Heightfield, b: u32, thresholds: Thresholds) -> Model {
    let model = Model::build(
        field.clone(),
        &BuildOptions {
            block_size: b,
            thresholds,
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap();
    check_model(&model, field);
    model
}

fn ladder(field: &Heightfield, b: u32) -> Model {
    build(field, b, Thresholds::Ladder)
}

fn field(w: u32, h: u32, f: impl FnMut(u32, u32) -> f32) -> Heightfield {
    Heightfield::from_fn(w, h, f).unwrap()
}

#[test]
fn constant_field() {
    let f = field(100, 77, |_, _| 123.5);
    let m = ladder(&f, 9);
    assert!(m
        .tree()
        .nodes()
        .iter()
        .all(|n| n.static_error == 0.0 && n.monotone_error == 0.0));
    // Flat ground stops at the root.
    assert_eq!(m.tree().nodes().len(), 1);
    assert_eq!(m.clusters().len(), 1);
    assert_eq!(m.clusters()[0].threshold, 0.0);
    // Ties at every threshold: every cluster is the root alone.
    let m = build(&f, 9, Thresholds::Explicit(vec![0.0, 1.0, 10.0]));
    assert!(m.clusters().iter().all(|c| c.nodes == vec![0]));
}

#[test]
fn single_spike() {
    let f = field(
        129,
        129,
        |x, y| if (x, y) == (37, 91) { 250.0 } else { 0.0 },
    );
    let m = ladder(&f, 17);
    // The spike is on no coarse grid point; its coarse cells' corners are 0, so each ancestor
    // measures it exactly.
    assert_eq!(m.max_error(), 250.0);
    let tree = m.tree();
    for n in tree.nodes() {
        let fp = m.domain().footprint(n.level, n.x, n.y);
        let holds = fp.contains(37, 91);
        let is_grid_point = (37 - fp.col0).is_multiple_of(m.domain().stride(n.level))
            && (91 - fp.row0).is_multiple_of(m.domain().stride(n.level));
        let expect = if holds && !is_grid_point { 250.0 } else { 0.0 };
        assert_eq!(
            n.static_error, expect,
            "node level {} ({}, {})",
            n.level, n.x, n.y
        );
    }
}

#[test]
fn vertical_cliff() {
    let f = field(200, 150, |x, _| if x < 77 { 0.0 } else { 1000.0 });
    let m = ladder(&f, 9);
    assert!(m.max_error() > 0.0 && m.max_error() <= 1000.0);
    // Blocks away from the cliff are flat and are never subdivided.
    let tree = m.tree();
    let far = tree
        .nodes()
        .iter()
        .filter(|n| n.monotone_error == 0.0)
        .count();
    assert!(far > 0);
    assert!(tree.nodes().iter().all(|n| n.monotone_error == 0.0 || {
        let fp = m.domain().footprint(n.level, n.x, n.y);
        fp.col0 <= 77 && 76 <= fp.col1
    }));
}

#[test]
fn checkerboard() {
    let f = field(65, 65, |x, y| ((x + y) % 2) as f32);
    let m = ladder(&f, 9);
    // Coarse grids sample only even points (value 0), so every coarse node misses the odd ones
    // by exactly 1; the blocks are exact.
    let finest = m.domain().finest_level();
    for n in m.tree().nodes() {
        let expect = if n.level == finest { 0.0 } else { 1.0 };
        assert_eq!(n.static_error, expect);
    }
    let thresholds: Vec<f64> = m.clusters().iter().map(|c| c.threshold).collect();
    assert_eq!(thresholds, vec![0.0, 1.0]);
    assert_eq!(m.clusters()[1].nodes, vec![0]);
}

#[test]
fn sine_ridges() {
    let f = field(257, 190, |x, y| {
        (300.0 * (f64::from(x) * 0.05).sin() * (f64::from(y) * 0.03).cos()) as f32
    });
    let m = ladder(&f, 17);
    let tree = m.tree();
    // Smooth terrain: errors shrink level by level on average.
    let mean = |level: u8| {
        let v: Vec<f64> = tree
            .nodes()
            .iter()
            .filter(|n| n.level == level)
            .map(|n| n.static_error)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    for level in 1..m.domain().finest_level() {
        assert!(mean(level) < mean(level - 1), "level {level}");
    }
}

#[test]
fn huge_offset_with_millimetre_detail() {
    // Detail in steps of 2^-10 m (~1 mm), small enough that 8848 + detail is exact in f32.
    let mut rng = Rng::new(7);
    let detail: Vec<f32> = (0..97 * 97)
        .map(|_| (rng.next_u64() % 8) as f32 / 1024.0)
        .collect();
    let plain = Heightfield::new(97, 97, detail.clone()).unwrap();
    let lifted = Heightfield::new(97, 97, detail.iter().map(|d| 8848.0 + d).collect()).unwrap();
    assert!(
        lifted
            .samples()
            .iter()
            .zip(&detail)
            .all(|(l, d)| l - 8848.0 == *d),
        "exact in f32"
    );
    let (a, b) = (ladder(&plain, 9), ladder(&lifted, 9));
    assert_eq!(a.tree().nodes().len(), b.tree().nodes().len());
    for (n, m) in a.tree().nodes().iter().zip(b.tree().nodes()) {
        assert!(
            (n.static_error - m.static_error).abs() < 1e-9,
            "{} vs {}",
            n.static_error,
            m.static_error
        );
        assert!(m.static_error <= 7.0 / 1024.0 + 1e-9);
    }
    assert!(b.max_error() > 0.0);
}

#[test]
fn values_near_plus_minus_1e30() {
    let mut rng = Rng::new(11);
    let f = field(80, 80, |_, _| match rng.next_u64() % 3 {
        0 => 1e30,
        1 => -1e30,
        _ => 0.0,
    });
    let m = ladder(&f, 9);
    assert!(m.max_error().is_finite());
    assert!(m.max_error() <= 2e30 * (1.0 + 1e-6));
    assert!(m.max_error() >= 1e30);
}

#[test]
fn tiny_range() {
    let mut rng = Rng::new(3);
    let f = field(70, 70, |_, _| (1.0 + rng.unit() * 1e-6) as f32);
    let m = ladder(&f, 9);
    assert!(m.max_error() > 0.0);
    assert!(m.max_error() < 2e-6);
    // The ladder resolves the tiny errors: more than the lossless cluster.
    assert!(m.clusters().len() > 2);
}

#[test]
fn all_void() {
    let f = field(40, 30, |_, _| f32::NAN);
    let m = ladder(&f, 9);
    assert_eq!(m.raster().valid_count(), 0);
    assert_eq!(m.tree().nodes().len(), 1);
    assert_eq!(m.max_error(), 0.0);
    assert_eq!(m.tree().node(0).valid_samples, 0);
    assert!(m.node_grid(0).void.iter().all(|&v| v));
}

#[test]
fn void_islands() {
    let f = field(150, 120, |x, y| {
        let island = ((x / 10 + y / 10) % 5 == 0) && x % 10 > 2 && y % 10 > 3;
        if island {
            f32::NAN
        } else {
            (f64::from(x) * 0.7 + (f64::from(y) * 0.2).sin() * 40.0) as f32
        }
    });
    let m = ladder(&f, 9);
    let valid: Vec<f32> = f
        .samples()
        .iter()
        .copied()
        .filter(|v| !v.is_nan())
        .collect();
    let (lo, hi) = valid
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    // Stand-ins are real heights: no node's range leaves the valid data's, no error exceeds it.
    for n in m.tree().nodes() {
        assert!(lo <= n.min_height && n.max_height <= hi);
        assert!(n.monotone_error <= f64::from(hi - lo));
    }
}

#[test]
fn single_valid_sample() {
    let f = field(
        50,
        50,
        |x, y| if (x, y) == (31, 17) { 9.25 } else { f32::NAN },
    );
    let m = ladder(&f, 9);
    // Every stand-in is that sample's height, so every surface is flat at it: no error.
    assert_eq!(m.max_error(), 0.0);
    assert_eq!(m.tree().nodes().len(), 1);
    assert_eq!(m.tree().node(0).valid_samples, 1);
    assert_eq!(
        (m.tree().node(0).min_height, m.tree().node(0).max_height),
        (9.25, 9.25)
    );
}

#[test]
fn one_by_one() {
    let f = field(1, 1, |_, _| 5.0);
    let m = ladder(&f, 9);
    assert_eq!((m.domain().levels(), m.domain().side()), (1, 9));
    assert_eq!(m.tree().nodes().len(), 1);
    assert_eq!(m.tree().node(0).valid_samples, 1);
}

#[test]
fn two_by_two() {
    let f = field(2, 2, |x, y| (x * 2 + y) as f32);
    let m = ladder(&f, 9);
    assert_eq!(m.tree().nodes().len(), 1);
    assert_eq!(m.max_error(), 0.0);
}

#[test]
fn non_square_and_thin() {
    let mut rng = Rng::new(5);
    for (w, h) in [(100, 7), (7, 100), (1, 300), (300, 1), (2, 257), (129, 3)] {
        let f = field(w, h, |_, _| (rng.next_u64() % 100) as f32);
        let m = ladder(&f, 9);
        // Padding is never a node: every node's footprint starts inside the data.
        for n in m.tree().nodes() {
            let fp = m.domain().footprint(n.level, n.x, n.y);
            assert!(fp.col0 < u64::from(w.max(2) - 1) && fp.row0 < u64::from(h.max(2) - 1));
        }
    }
}

#[test]
fn diagonal_is_north_west_to_south_east() {
    // 65 x 65 samples in blocks of 9: the root's grid has stride 8. The data is the hat
    // function of grid vertex (8, 0) on the NW-SE triangulation: max(0, min(x-y, 16-x, 8-y))
    // north of row 8, 0 elsewhere. The NW-SE split reproduces it exactly at every level. A
    // NE-SW split would put 4 at (4, 4), where the data is 0.
    let hat = |x: u32, y: u32| {
        let (x, y) = (i64::from(x), i64::from(y));
        if y > 8 {
            0.0
        } else {
            (x - y).min(16 - x).min(8 - y).max(0) as f32
        }
    };
    let f = field(65, 65, hat);
    assert_eq!(
        (hat(8, 0), hat(4, 4), hat(4, 0), hat(12, 4)),
        (8.0, 0.0, 4.0, 4.0)
    );
    let m = build(&f, 9, Thresholds::Explicit(vec![0.0]));
    assert_eq!(m.domain().stride(0), 8);
    assert!(m.tree().nodes().iter().all(|n| n.static_error == 0.0));
    // The mirrored hat (x -> 16 - x) lies on the NE-SW triangulation, which the NW-SE split
    // cannot draw: the root misses it by 4 at (4, 4) and (12, 4).
    let g = field(65, 65, |x, y| if x <= 16 { hat(16 - x, y) } else { 0.0 });
    let m = build(&g, 9, Thresholds::Explicit(vec![0.0]));
    assert_eq!(m.tree().node(0).static_error, 4.0);
}

#[test]
fn thresholds_exactly_equal_to_node_errors() {
    let mut rng = Rng::new(13);
    let f = field(90, 90, |x, y| {
        ((x / 7 + y / 5) % 4) as f32 * 3.0 + (rng.next_u64() % 3) as f32
    });
    let probe = ladder(&f, 9);
    let mut errors: Vec<f64> = probe
        .tree()
        .nodes()
        .iter()
        .map(|n| n.monotone_error)
        .collect();
    errors.sort_by(f64::total_cmp);
    errors.dedup();
    let m = build(&f, 9, Thresholds::Explicit(errors.clone()));
    assert_eq!(m.clusters().len(), errors.len());
    for c in m.clusters() {
        // A node whose e* equals the threshold belongs to the cut (<=), its parent does not.
        assert!(c
            .nodes
            .iter()
            .any(|&i| m.tree().node(i).monotone_error == c.threshold));
        assert_eq!(c.max_error, c.threshold);
    }
}
