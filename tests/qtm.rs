//! The QTM (`fmrh::curve::qtm`, seed 003) tiles the globe and its curve is a space-filling
//! order of it. Checked against the geometry computed here, not the module's own tables:
//!
//! * **one cover**: every point of the globe, the poles, the equator, the octants' meridians
//!   and the antimeridian included, lies in the cell [`QtmCell::locate`] gives, and a point
//!   off the edges lies in no other cell of its level;
//! * **nesting**: the cell of a point at level `L + 1` is a child of its cell at level `L`,
//!   and a cell's children are four cells whose vertices are its vertices and its edges'
//!   midpoints (in the ZOT plane);
//! * **codes**: a cell's code names it, in writing too;
//! * **the curve**: at every level up to 6 the curve visits each of the `8 · 4^L` cells once,
//!   consecutive cells share at least a vertex (on the globe: the same point, the poles and
//!   octant edges included), and each cell's descendants are one contiguous run.

use std::collections::HashSet;

use fmrh::curve::qtm::{LonLat, QTM_MAX_LEVEL};
use fmrh::curve::{QtmCell, QtmCode};
use fmrh::globe;
use proptest::prelude::*;

/// Every cell of `level`, by octant and grid.
fn all_cells(level: u8) -> Vec<QtmCell> {
    let n = 1u32 << level;
    let mut out = Vec::new();
    for o in 0..8 {
        for i in 0..n {
            for j in 0..n - i {
                out.extend(QtmCell::new(o, level, i, j, true));
                out.extend(QtmCell::new(o, level, i, j, false));
            }
        }
    }
    out
}

/// A vertex as a point of the globe, rounded to a tenth of a millimetre, so that the same
/// point reached from two octants (or a pole at any longitude) is one key.
fn key(v: LonLat) -> (i64, i64, i64) {
    let p = globe::ecef(v.lon, v.lat, 0.0);
    let r = |x: f64| (x * 1e4).round() as i64;
    (r(p[0]), r(p[1]), r(p[2]))
}

fn shared_vertices(a: &QtmCell, b: &QtmCell) -> usize {
    let kb: Vec<_> = b.vertices().iter().map(|v| key(*v)).collect();
    a.vertices()
        .iter()
        .filter(|v| kb.contains(&key(**v)))
        .count()
}

#[test]
fn the_curve_visits_every_cell_once_through_touching_cells() {
    for level in 0..=6u8 {
        let cells = all_cells(level);
        let count = 8u64 << (2 * u32::from(level));
        assert_eq!(cells.len() as u64, count, "level {level}");
        let mut seen = HashSet::new();
        for c in &cells {
            let i = c.curve_index();
            assert!(i < count, "{c:?}: index {i} of {count}");
            assert!(seen.insert(i), "{c:?}: index {i} twice");
            assert_eq!(QtmCell::from_curve_index(level, i), Some(*c));
        }
        let order: Vec<QtmCell> = (0..count)
            .map(|i| QtmCell::from_curve_index(level, i).unwrap())
            .collect();
        let mut edges = 0;
        for w in order.windows(2) {
            let s = shared_vertices(&w[0], &w[1]);
            assert!(
                s >= 1,
                "level {level}: {:?} and {:?} do not touch",
                w[0],
                w[1]
            );
            if s >= 2 {
                edges += 1;
            }
        }
        // The ring closes: the last cell touches the first.
        assert!(shared_vertices(&order[0], &order[order.len() - 1]) >= 1);
        if level >= 2 {
            // Across edges more often than not (see the module doc for why never always).
            let share = edges as f64 / (count - 1) as f64;
            assert!(share > 0.5, "level {level}: only {share:.2} share an edge");
        }
        // Descendants are contiguous: each index's parent is index >> 2.
        if level > 0 {
            for (i, c) in order.iter().enumerate() {
                let p = c.parent().unwrap();
                assert_eq!(p.curve_index(), i as u64 >> 2);
                assert!(p.curve_range(level).contains(&(i as u64)));
            }
        }
    }
}

#[test]
fn octant_vertices_are_the_octahedron() {
    for o in 0..8u8 {
        let c = QtmCell::octant_cell(o).unwrap();
        let [pole, a, b] = c.vertices();
        let lat = if o < 4 { 90.0 } else { -90.0 };
        assert_eq!(pole.lat, lat);
        let west = 90.0 * f64::from(o % 4);
        let wrap = |x: f64| if x > 180.0 { x - 360.0 } else { x };
        assert_eq!((a.lon, a.lat), (wrap(west), 0.0));
        assert_eq!((b.lon, b.lat), (wrap(west + 90.0), 0.0));
    }
    assert!(QtmCell::octant_cell(8).is_none());
    assert!(QtmCell::new(0, 2, 3, 1, true).is_none());
    assert!(QtmCell::new(0, 2, 2, 1, false).is_none());
    assert!(QtmCell::new(0, QTM_MAX_LEVEL + 1, 0, 0, true).is_none());
}

#[test]
fn poles_equator_and_octant_edges_have_a_cell_that_holds_them() {
    let edges = [
        (0.0, 90.0),
        (123.0, 90.0),
        (0.0, -90.0),
        (-77.0, -90.0),
        (0.0, 0.0),
        (90.0, 0.0),
        (180.0, 0.0),
        (-180.0, 0.0),
        (-90.0, 0.0),
        (45.0, 0.0),
        (180.0, 45.0),
        (-180.0, -45.0),
        (90.0, -12.5),
        (0.0, 33.0),
        (-0.0, -33.0),
        (359.999_999_999, 10.0),
    ];
    for level in [0u8, 1, 5, 17, QTM_MAX_LEVEL] {
        for (lon, lat) in edges {
            let c = QtmCell::locate(lon, lat, level).unwrap();
            assert!(c.contains(lon, lat), "({lon}, {lat}) level {level}: {c:?}");
        }
    }
    assert!(QtmCell::locate(f64::NAN, 0.0, 3).is_none());
    assert!(QtmCell::locate(0.0, 90.5, 3).is_none());
    assert!(QtmCell::locate(0.0, 0.0, QTM_MAX_LEVEL + 1).is_none());
}

#[test]
fn codes_are_written_and_read_back() {
    let c = QtmCell::locate(6.5, 43.5, 12).unwrap();
    let code = c.code();
    assert_eq!(code.level(), 12);
    assert_eq!(code.octant(), 0);
    let text = code.to_string();
    assert_eq!(text.len(), 13);
    assert_eq!(QtmCode::parse(&text), Some(code));
    assert_eq!(QtmCell::from_code(code), Some(c));
    for bad in ["", "8", "04", "0x", "0123a"] {
        assert_eq!(QtmCode::parse(bad), None, "{bad:?}");
    }
    assert_eq!(QtmCode::parse("3").map(|c| c.level()), Some(0));
}

fn point() -> impl Strategy<Value = (f64, f64)> {
    prop_oneof![
        8 => (-180.0f64..=180.0, -90.0f64..=90.0),
        // On the octants' meridians and the equator.
        1 => (prop::sample::select(vec![-180.0, -90.0, 0.0, 90.0, 180.0]), -90.0f64..=90.0),
        1 => (-180.0f64..=180.0, Just(0.0)),
        // Near the poles.
        1 => (-180.0f64..=180.0, prop_oneof![89.9f64..=90.0, -90.0f64..=-89.9]),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn a_point_lies_in_its_cell_and_in_its_cells_parent((lon, lat) in point(), level in 0u8..=QTM_MAX_LEVEL) {
        let c = QtmCell::locate(lon, lat, level).unwrap();
        prop_assert!(c.contains(lon, lat));
        prop_assert_eq!(c.level(), level);
        if level < QTM_MAX_LEVEL {
            let child = QtmCell::locate(lon, lat, level + 1).unwrap();
            prop_assert_eq!(child.parent(), Some(c));
            prop_assert!(c.children().unwrap().contains(&child));
            prop_assert_eq!(c.children().unwrap()[child.digit().unwrap() as usize], child);
        }
        prop_assert_eq!(QtmCell::from_code(c.code()), Some(c));
        prop_assert_eq!(QtmCell::from_curve_index(level, c.curve_index()), Some(c));
    }

    #[test]
    fn a_point_inside_a_cell_is_in_no_other((lon, lat) in (-180.0f64..180.0, -89.0f64..89.0), level in 0u8..=4) {
        let own = QtmCell::locate(lon, lat, level).unwrap();
        let holders: Vec<QtmCell> = all_cells(level).into_iter().filter(|c| c.contains(lon, lat)).collect();
        prop_assert!(holders.contains(&own));
        // Random points miss every edge (a set of measure zero): one cell holds each.
        prop_assert_eq!(holders, vec![own], "({}, {})", lon, lat);
    }

    #[test]
    fn children_split_at_the_midpoints(index in 0u64..(8 << 10), extra in 0u8..3) {
        let c = QtmCell::from_curve_index(5, index).unwrap();
        let kids = c.children().unwrap();
        let own: HashSet<_> = c.vertices().iter().map(|v| key(*v)).collect();
        // The corner children keep one of the parent's vertices each; the centre keeps none.
        prop_assert_eq!(kids[0].vertices().iter().filter(|v| own.contains(&key(**v))).count(), 0);
        for (d, k) in kids.iter().enumerate().skip(1) {
            prop_assert_eq!(k.vertices().iter().filter(|v| own.contains(&key(**v))).count(), 1, "child {}", d);
            prop_assert_eq!(k.digit(), Some(d as u8));
        }
        // The first and last of its descendants at a finer level are descendants.
        let deeper = c.curve_range(5 + 1 + extra);
        prop_assert_eq!(deeper.end - deeper.start, 1u64 << (2 * (1 + u32::from(extra))));
        for i in [deeper.start, deeper.end - 1] {
            let d = QtmCell::from_curve_index(5 + 1 + extra, i).unwrap();
            let mut p = d;
            while p.level() > 5 {
                p = p.parent().unwrap();
            }
            prop_assert_eq!(p, c);
        }
    }
}
