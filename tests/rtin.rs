//! The right-triangulated irregular network (`fmrh::mesh::rtin`) gives, for any grid of
//! heights and any budget, a mesh that covers the grid exactly once (triangle areas sum to
//! the grid's, counter-clockwise), is conforming (every inner edge is shared by exactly two
//! triangles, in opposite directions: no T-junction), and is within the budget of every grid
//! point, measured here against each triangle's plane. Two neighbouring grids meshed apart
//! and then given each other's vertices on their common edge end with the same vertices
//! there, and are still conforming and covering. Grids are random: smooth hills, rough
//! noise, single spikes, flat ground and cliffs.

use std::collections::HashMap;

use fmrh::mesh::rtin::{Grid, Rtin, RtinMesh};
use proptest::prelude::*;

/// A grid `cells` a side from a seed: `kind` picks flat, hills, noise, a spike or a cliff.
fn terrain(cells: usize, kind: u8, seed: u64) -> Vec<f64> {
    let mut state = seed | 1;
    let mut rand = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (si, sj) = (rand() * cells as f64, rand() * cells as f64);
    (0..=cells)
        .flat_map(|j| (0..=cells).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (x, y) = (i as f64, j as f64);
            match kind % 5 {
                0 => 120.0,
                1 => 40.0 * (x * 0.3).sin() * (y * 0.2).cos() + x * 0.5,
                2 => rand() * 100.0 - 50.0,
                3 => {
                    if (x - si).abs() < 0.5 && (y - sj).abs() < 0.5 {
                        900.0
                    } else {
                        1.0
                    }
                }
                _ => {
                    if x > si {
                        500.0 + y
                    } else {
                        y * 0.1
                    }
                }
            }
        })
        .collect()
}

fn area2(m: &RtinMesh, t: [u32; 3]) -> i64 {
    let p = t.map(|k| m.vertices[k as usize].map(i64::from));
    (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0])
}

/// Counter-clockwise triangles covering the grid once, and every inner edge shared by two
/// of them in opposite directions.
fn check_conforming(m: &RtinMesh) -> Result<(), TestCaseError> {
    let n = i64::from(m.cells);
    let mut total = 0i64;
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for &t in &m.triangles {
        let a = area2(m, t);
        prop_assert!(a > 0, "triangle {t:?} is not counter-clockwise ({a})");
        total += a;
        for e in 0..3 {
            *directed.entry((t[e], t[(e + 1) % 3])).or_default() += 1;
        }
    }
    prop_assert_eq!(total, 2 * n * n, "the triangles do not cover the grid once");
    let on_boundary = |a: [u32; 2], b: [u32; 2]| {
        let n = m.cells;
        (a[0] == b[0] && (a[0] == 0 || a[0] == n)) || (a[1] == b[1] && (a[1] == 0 || a[1] == n))
    };
    for (&(a, b), &count) in &directed {
        prop_assert_eq!(count, 1, "edge {:?} is used twice the same way", (a, b));
        let (pa, pb) = (m.vertices[a as usize], m.vertices[b as usize]);
        if !on_boundary(pa, pb) {
            prop_assert!(
                directed.contains_key(&(b, a)),
                "inner edge {pa:?}-{pb:?} has a triangle on one side only (a T-junction)"
            );
        }
    }
    Ok(())
}

/// The largest `|height - plane|` over every grid point in every triangle.
fn worst_error(m: &RtinMesh, heights: &[f64]) -> f64 {
    let side = m.cells as usize + 1;
    let h = |p: [i64; 2]| heights[p[1] as usize * side + p[0] as usize];
    let mut worst = 0.0f64;
    for &t in &m.triangles {
        let p = t.map(|k| m.vertices[k as usize].map(i64::from));
        let area = area2(m, t) as f64;
        let x0 = p.iter().map(|q| q[0]).min().unwrap();
        let x1 = p.iter().map(|q| q[0]).max().unwrap();
        let y0 = p.iter().map(|q| q[1]).min().unwrap();
        let y1 = p.iter().map(|q| q[1]).max().unwrap();
        let cross = |o: [i64; 2], a: [i64; 2], b: [i64; 2]| {
            (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
        };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let q = [x, y];
                let w = [
                    cross(p[1], p[2], q),
                    cross(p[2], p[0], q),
                    cross(p[0], p[1], q),
                ];
                if w.iter().any(|&v| v < 0) {
                    continue;
                }
                let plane =
                    (w[0] as f64 * h(p[0]) + w[1] as f64 * h(p[1]) + w[2] as f64 * h(p[2])) / area;
                worst = worst.max((h(q) - plane).abs());
            }
        }
    }
    worst
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn a_mesh_is_conforming_and_within_its_budget(
        log_cells in 1u32..=6,
        kind in 0u8..5,
        seed in any::<u64>(),
        budget in prop_oneof![Just(0.0), 0.0f64..200.0],
    ) {
        let cells = 1usize << log_cells;
        let heights = terrain(cells, kind, seed);
        let mesh = Rtin::new(&Grid::new(cells, &heights).unwrap()).mesh(budget);
        check_conforming(&mesh)?;
        let worst = worst_error(&mesh, &heights);
        prop_assert!(worst <= budget + 1e-9, "error {worst} past the budget {budget}");
        // Flat ground needs no more than the two halves.
        if kind == 0 {
            prop_assert_eq!(mesh.triangles.len(), 2);
        }
    }

    #[test]
    fn neighbours_given_each_others_edges_share_them(
        log_cells in 1u32..=6,
        kinds in (0u8..5, 0u8..5),
        seeds in (any::<u64>(), any::<u64>()),
        budget in 0.0f64..100.0,
        east in any::<bool>(),
    ) {
        let cells = 1usize << log_cells;
        let side = cells + 1;
        let first = terrain(cells, kinds.0, seeds.0);
        // The second grid continues the first across its east (or north) side: the line
        // they share holds the same heights.
        let mut second = terrain(cells, kinds.1, seeds.1);
        for k in 0..side {
            if east {
                second[k * side] = first[k * side + cells];
            } else {
                second[k] = first[cells * side + k];
            }
        }
        let (mine, theirs) = if east { (1, 3) } else { (2, 0) };
        let mut a = Rtin::new(&Grid::new(cells, &first).unwrap()).mesh(budget);
        let mut b = Rtin::new(&Grid::new(cells, &second).unwrap()).mesh(budget);
        let (ea, eb) = (a.edge(mine), b.edge(theirs));
        a.add_edge_vertices(mine, &eb);
        b.add_edge_vertices(theirs, &ea);
        prop_assert_eq!(a.edge(mine), b.edge(theirs));
        let mut union: Vec<u32> = ea.iter().chain(&eb).copied().collect();
        union.sort_unstable();
        union.dedup();
        prop_assert_eq!(a.edge(mine), union);
        check_conforming(&a)?;
        check_conforming(&b)?;
    }
}
