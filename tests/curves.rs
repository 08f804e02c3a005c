//! The curves against independent definitions. Hilbert: the table-driven encoder equals the
//! textbook rotate-and-flip index at every order up to 32, and decoding inverts it. A node's key
//! is the smallest index of its finest cells. Seed 000's Algorithm 2 (type I–IV production
//! rules) visits any cut of a random tree in key order. Morton: seed 001's Tables I and II hold,
//! and the non-pointer bounds equal each node's geometric footprint.

mod common;

use common::fields::any_field;
use common::oracle::{algorithm2, hilbert_by_rotation};
use fmrh::curve::{hilbert_decode, hilbert_encode, HilbertKey, MortonKey};
use fmrh::model::{cluster, BuildOptions, Domain, Model, Thresholds};
use proptest::prelude::*;

fn coordinate(order: u32) -> impl Strategy<Value = u32> {
    let max = if order == 32 {
        u32::MAX
    } else {
        (1u32 << order).wrapping_sub(1)
    };
    prop_oneof![Just(0), Just(max), 0..=max]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn encode_equals_the_textbook_index((order, x, y) in (0u32..=32).prop_flat_map(|o| (Just(o), coordinate(o), coordinate(o)))) {
        let d = hilbert_encode(order, x, y);
        prop_assert_eq!(d, hilbert_by_rotation(order, u64::from(x), u64::from(y)));
        prop_assert_eq!(hilbert_decode(order, d), (x, y));
    }

    #[test]
    fn keys_are_prefixes((finest, level, x, y) in (0u8..=16).prop_flat_map(|l| (Just(l), 0..=l)).prop_flat_map(|(l, lv)| (Just(l), Just(lv), coordinate(u32::from(lv)), coordinate(u32::from(lv))))) {
        let key = HilbertKey::of_node(finest, level, x, y);
        let shift = u32::from(finest - level);
        // The key is the index of the node's first (north-west) finest cell, rounded down to
        // the node's run; every finest cell of the node is inside the run.
        let corner = hilbert_encode(u32::from(finest), x << shift, y << shift);
        let span = HilbertKey::span(finest, level);
        prop_assert_eq!(key.0, corner - corner % span);
        let (dx, dy) = ((1u32 << shift) - 1, (1u32 << shift) - 1);
        for (cx, cy) in [(0, 0), (dx, 0), (0, dy), (dx, dy), (dx / 2, dy / 3)] {
            let d = hilbert_encode(u32::from(finest), (x << shift) + cx, (y << shift) + cy);
            prop_assert!(key.0 <= d && d <= key.last(finest, level));
        }
    }

    #[test]
    fn morton_bounds_are_the_footprint(field_w in 1u32..3000, field_h in 1u32..3000, b in prop_oneof![Just(9u32), Just(65), Just(257)], pick in any::<(u64, u64, u64)>()) {
        let domain = Domain::new(field_w, field_h, b).unwrap();
        let level = (pick.0 % u64::from(domain.levels())) as u8;
        let (cols, rows) = domain.nodes_across(level);
        let (x, y) = ((pick.1 % u64::from(cols)) as u32, (pick.2 % u64::from(rows)) as u32);
        let key = MortonKey::from_node(level, x, y);
        prop_assert_eq!((key.x(), key.row(), key.level()), (x, y, level));
        let cells = domain.side() - 1;
        let bounds = key.bounds(cells);
        let fp = domain.footprint(level, x, y);
        // Seed 001's frame is south-up: raster row r is at height cells - r.
        prop_assert_eq!((bounds.left, bounds.right), (fp.col0, fp.col1));
        prop_assert_eq!((bounds.top, bounds.bottom), (cells - fp.row0, cells - fp.row1));
        let parsed = MortonKey::from_paper_str(&key.to_paper_string());
        prop_assert_eq!(parsed, Some(key));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Random thresholds give random cuts; Algorithm 2 visits each in key order.
    #[test]
    fn algorithm2_order_is_key_order(field in any_field(90), cuts in prop::collection::vec(0.0..1.0f64, 1..6)) {
        let model = Model::build(field, &BuildOptions { block_size: 9, thresholds: Thresholds::Explicit(vec![0.0]), precision: None, thin: Default::default() }).unwrap();
        let root = model.max_error();
        for t in cuts {
            let nodes = cluster::cut(model.tree(), t * root);
            let mut by_key = nodes.clone();
            by_key.sort_by_key(|&i| model.tree().node(i).key);
            prop_assert_eq!(algorithm2(&model, &nodes), by_key);
        }
    }
}

/// Seed 001, Table I: the first line (south row) of a four-level tree, codes against the left
/// coordinate in eighths of the terrain's width W.
#[test]
fn morton_table_one() {
    let codes = [
        "00000000", "00000010", "00001000", "00001010", "00100000", "00100010", "00101000",
        "00101010",
    ];
    let w = 8 * 1000;
    for (i, code) in codes.iter().enumerate() {
        let key = MortonKey::from_paper_str(code).unwrap();
        let b = key.bounds(w);
        assert_eq!((b.left, b.bottom), (i as u64 * w / 8, 0), "{code}");
        assert_eq!(b.right - b.left, w / 8);
    }
}

/// Seed 001, Table II: the first column (west), codes against the bottom coordinate.
#[test]
fn morton_table_two() {
    let codes = [
        "00000000", "00000001", "00000100", "00000101", "00010000", "00010001", "00010100",
        "00010101",
    ];
    let w = 8 * 1000;
    for (i, code) in codes.iter().enumerate() {
        let key = MortonKey::from_paper_str(code).unwrap();
        let b = key.bounds(w);
        assert_eq!((b.left, b.bottom), (0, i as u64 * w / 8), "{code}");
        assert_eq!(b.top - b.bottom, w / 8);
    }
}

/// Seed 000's worked example (§4.2): a type-I block's children 3 and 4 are of types I and IV,
/// and type IV visits its children in the order 3, 2, 1, 4 of the type-I numbering.
#[test]
fn paper_worked_example() {
    use fmrh::curve::HilbertType;
    let one = HilbertType::I;
    assert_eq!(one.child_types()[2], HilbertType::I);
    assert_eq!(one.child_types()[3], HilbertType::IV);
    let base = HilbertType::I.quadrant_order();
    let four: Vec<usize> = HilbertType::IV
        .quadrant_order()
        .iter()
        .map(|q| base.iter().position(|b| b == q).unwrap() + 1)
        .collect();
    assert_eq!(four, vec![3, 2, 1, 4]);
}
