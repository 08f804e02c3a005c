//! fmrh's RTIN (`mesh::rtin`, exact triangle errors) beside pymartini (mapbox/martini's
//! RTIN, midpoint error estimates) and pydelatin (mapbox/delatin, greedy Delaunay
//! insertion) on the same grid at the same max error, in one run: triangles, vertices, the
//! max error each mesh really has (measured here, the same way for all three: every grid
//! point against the plane of the triangle holding it) and the time each took.
//!
//! The grid: all of Puget Sound 1k (1025², `../shared/data/puget-sound-1k`), and its
//! sixteen 257² quarters of quarters as tiles (the size a tile's grid would have). The
//! libraries run in Python (`pip install pymartini pydelatin numpy`; `benches/tin/others.py`).
//! Run: `cargo bench --bench tin_compare`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use fmrh::mesh::rtin::{Grid, Rtin};

struct Mesh {
    vertices: Vec<[f64; 2]>,
    triangles: Vec<[u32; 3]>,
}

fn read_mesh(path: &Path) -> Mesh {
    let b = std::fs::read(path).expect("a mesh file from others.py");
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let (nv, nt) = (u32_at(0) as usize, u32_at(4) as usize);
    let f64_at = |o: usize| f64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    let vertices = (0..nv)
        .map(|i| [f64_at(8 + 16 * i), f64_at(16 + 16 * i)])
        .collect();
    let base = 8 + 16 * nv;
    let triangles = (0..nt)
        .map(|i| {
            let o = base + 12 * i;
            [u32_at(o), u32_at(o + 4), u32_at(o + 8)]
        })
        .collect();
    Mesh {
        vertices,
        triangles,
    }
}

/// The largest `|height - plane|` over every grid point in every triangle (vertices at grid
/// points), and whether every grid point lies in some triangle.
fn true_error(heights: &[f32], side: usize, mesh: &Mesh) -> (f64, bool) {
    let h = |x: i64, y: i64| f64::from(heights[y as usize * side + x as usize]);
    let mut covered = vec![false; side * side];
    let mut worst = 0.0f64;
    for t in &mesh.triangles {
        let p: Vec<[i64; 2]> = t
            .iter()
            .map(|&k| {
                let v = mesh.vertices[k as usize];
                [v[0].round() as i64, v[1].round() as i64]
            })
            .collect();
        let cross = |o: [i64; 2], a: [i64; 2], b: [i64; 2]| {
            (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
        };
        let area = cross(p[0], p[1], p[2]);
        if area == 0 {
            continue;
        }
        let hs = [
            h(p[0][0], p[0][1]),
            h(p[1][0], p[1][1]),
            h(p[2][0], p[2][1]),
        ];
        let (x0, x1) = (
            p.iter().map(|q| q[0]).min().unwrap(),
            p.iter().map(|q| q[0]).max().unwrap(),
        );
        let (y0, y1) = (
            p.iter().map(|q| q[1]).min().unwrap(),
            p.iter().map(|q| q[1]).max().unwrap(),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let q = [x, y];
                let w = [
                    cross(p[1], p[2], q),
                    cross(p[2], p[0], q),
                    cross(p[0], p[1], q),
                ];
                let inside = if area > 0 {
                    w.iter().all(|&v| v >= 0)
                } else {
                    w.iter().all(|&v| v <= 0)
                };
                if !inside {
                    continue;
                }
                let plane =
                    (w[0] as f64 * hs[0] + w[1] as f64 * hs[1] + w[2] as f64 * hs[2]) / area as f64;
                worst = worst.max((h(x, y) - plane).abs());
                covered[y as usize * side + x as usize] = true;
            }
        }
    }
    (worst, covered.iter().all(|&c| c))
}

/// One row of the table: method, triangles, vertices, true error, seconds.
type Row = (String, usize, usize, f64, bool, f64);

fn compare(heights: &[f32], side: usize, max_error: f64, scratch: &Path) -> Vec<Row> {
    let grid_file = scratch.join("grid.f32");
    let bytes: Vec<u8> = heights.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&grid_file, bytes).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/tin/others.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(&grid_file)
        .arg(side.to_string())
        .arg(max_error.to_string())
        .arg(scratch)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "others.py (pip install pymartini pydelatin numpy): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut rows = Vec::new();
    let grid: Vec<f64> = heights.iter().map(|&v| f64::from(v)).collect();
    let started = Instant::now();
    let rtin = Rtin::new(&Grid::new(side - 1, &grid).expect("a (2^k + 1)² grid"));
    let ours = rtin.mesh(max_error);
    let seconds = started.elapsed().as_secs_f64();
    let mesh = Mesh {
        vertices: ours
            .vertices
            .iter()
            .map(|v| [f64::from(v[0]), f64::from(v[1])])
            .collect(),
        triangles: ours.triangles.clone(),
    };
    let (e, covered) = true_error(heights, side, &mesh);
    rows.push((
        "fmrh rtin".into(),
        mesh.triangles.len(),
        mesh.vertices.len(),
        e,
        covered,
        seconds,
    ));
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let name = v["name"].as_str().unwrap().to_string();
        let mesh = read_mesh(&scratch.join(format!("{name}.mesh")));
        let (e, covered) = true_error(heights, side, &mesh);
        rows.push((
            name,
            mesh.triangles.len(),
            mesh.vertices.len(),
            e,
            covered,
            v["seconds"].as_f64().unwrap(),
        ));
    }
    rows
}

fn main() {
    let path: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/puget-sound-1k/ps_height_1k.f32");
    let bytes = std::fs::read(&path).expect("../shared/data/puget-sound-1k/ps_height_1k.f32");
    let side = 1025;
    let heights: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(heights.len(), side * side);
    let scratch = tempfile::tempdir().unwrap();
    println!(
        "Puget Sound 1k (1025², metres): triangles at a max error, the error each mesh really has"
    );
    println!("| grid | max error asked | method | triangles | vertices | true max error | covers the grid | seconds |");
    println!("|---|---|---|---|---|---|---|---|");
    for max_error in [1.0, 5.0] {
        for (name, t, v, e, covered, s) in compare(&heights, side, max_error, scratch.path()) {
            println!(
                "| 1025² | {max_error} m | {name} | {t} | {v} | {e:.3} m | {covered} | {s:.3} |"
            );
        }
    }
    // Sixteen 257² tiles (they share edges), summed.
    let tile = 257;
    for max_error in [1.0, 5.0] {
        let mut sums: Vec<Row> = Vec::new();
        for ty in 0..4 {
            for tx in 0..4 {
                let part: Vec<f32> = (0..tile)
                    .flat_map(|j| {
                        let row = (ty * 256 + j) * side + tx * 256;
                        heights[row..row + tile].to_vec()
                    })
                    .collect();
                for (k, row) in compare(&part, tile, max_error, scratch.path())
                    .into_iter()
                    .enumerate()
                {
                    if sums.len() <= k {
                        sums.push((row.0.clone(), 0, 0, 0.0, true, 0.0));
                    }
                    let s = &mut sums[k];
                    s.1 += row.1;
                    s.2 += row.2;
                    s.3 = s.3.max(row.3);
                    s.4 &= row.4;
                    s.5 += row.5;
                }
            }
        }
        for (name, t, v, e, covered, s) in sums {
            println!("| 16 × 257² | {max_error} m | {name} | {t} | {v} | {e:.3} m | {covered} | {s:.3} |");
        }
    }
}
