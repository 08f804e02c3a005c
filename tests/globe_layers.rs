//! Layers on the globe (`fmrh::scene::Layers`): the bundled whole-Earth grid (ETOPO1 at
//! 0.5°) with the two bundled SRTM3 tiles N43E006 and N43E007 above it, seen from orbit down
//! to a few hundred metres over the tiles. For random cameras and tolerances:
//!
//! * **no hole, no overlap**: every sample seen (in the frustum, above the horizon, at its
//!   own layer's height) is drawn by exactly one block of the highest layer whose footprint
//!   holds it (samples on a footprint edge by at least one), and every sample of a lower
//!   layer under a higher footprint lies in a cut-out of every block of its layer holding it,
//!   while samples outside every higher footprint lie in no cut-out;
//! * **no crack**: at points all along every seam between two layers' blocks (their grid
//!   points, and points between them that no grid has), the side that is higher hangs a skirt
//!   at least as deep as the gap;
//! * **within tau** in every layer.
//!
//! Dropping the cut-outs fails the first property; measuring the skirts at the blocks' own
//! grid points only (not at every sample) fails the second (`skirts_are_measured_between_grid_points`).

mod common;

use fmrh::globe;
use fmrh::scene::surface::Surface;
use fmrh::scene::{Camera, Layers, SceneOptions, Terrain};
use fmrh::Heightfield;
use proptest::prelude::*;

struct Built {
    _dir: tempfile::TempDir,
    files: Vec<std::path::PathBuf>,
    fields: Vec<Heightfield>,
}

fn built() -> &'static Built {
    static B: std::sync::OnceLock<Built> = std::sync::OnceLock::new();
    B.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let (files, fields) = [
            ("earth", "etopo1-pybacktrack/etopo1-bed-0.5deg.tif"),
            ("n6", "srtm3-pyhgtmap/N43E006.hgt.gz"),
            ("n7", "srtm3-pyhgtmap/N43E007.hgt.gz"),
        ]
        .iter()
        .map(|(name, rel)| common::globe::container(dir.path(), name, rel))
        .unzip();
        Built {
            _dir: dir,
            files,
            fields,
        }
    })
}

/// The built files, opened.
fn stores() -> Vec<fmrh::store::Store> {
    built()
        .files
        .iter()
        .map(|f| fmrh::store::Store::open(f).unwrap())
        .collect()
}

/// The stores as layers on the globe, the base first.
fn layers_of(stores: &[fmrh::store::Store]) -> Layers<'_, fmrh::store::FileSource> {
    Layers::new(
        stores
            .iter()
            .map(|s| Terrain::on_globe(s).unwrap())
            .collect(),
    )
    .unwrap()
}

/// Longitude, latitude and height of sample `(col, row)` of `f`.
fn sample(f: &Heightfield, col: u32, row: u32) -> (f64, f64, f64) {
    let g = f.metadata.georeference.as_ref().unwrap();
    let lon = g.origin[0] + f64::from(col) * g.step[0];
    let lat = (g.origin[1] + f64::from(row) * g.step[1]).clamp(-90.0, 90.0);
    let z = f.samples()[(row * f.width() + col) as usize];
    (lon, lat, f64::from(if z.is_nan() { 0.0 } else { z }))
}

/// A change made to the skirts before they are checked (to show the check can fail).
type SkirtEdit = dyn Fn(&[f64]) -> Vec<f64>;

/// Checks the module's properties for one camera; returns the samples seen.
fn check(
    camera: &Camera,
    tau: f64,
    skirts_override: Option<&SkirtEdit>,
) -> Result<usize, TestCaseError> {
    let b = built();
    let stores = stores();
    let layers = layers_of(&stores);
    let scene = layers.scene(camera, &SceneOptions::new(tau)).unwrap();
    let view = camera.view().unwrap();
    let eye = camera.eye;
    let foot: Vec<_> = layers.layers().iter().map(|l| l.footprint).collect();
    prop_assert!(scene.stats.max_screen_error <= tau * (1.0 + 1e-9));

    // No hole, no overlap.
    let mut seen = 0;
    for (li, f) in b.fields.iter().enumerate() {
        let (w, h) = (f.width(), f.height());
        // The base around the tiles (and its whole grid, coarsely); the tiles every 6th
        // sample and their edges.
        let step = if li == 0 { 1 } else { 6 };
        let (c0, c1, r0, r1) = if li == 0 {
            (352, 400, 80, 110)
        } else {
            (0, w - 1, 0, h - 1)
        };
        let mut cells: Vec<(u32, u32)> = Vec::new();
        for row in (r0..=r1).step_by(step) {
            for col in (c0..=c1).step_by(step) {
                cells.push((col, row));
            }
        }
        if li > 0 {
            for t in (0..w).step_by(3) {
                cells.extend([(t, 0), (t, h - 1), (0, t), (w - 1, t)]);
            }
        }
        if li == 0 {
            for row in (0..h).step_by(8) {
                for col in (0..w).step_by(8) {
                    cells.push((col, row));
                }
            }
        }
        for (col, row) in cells {
            let (lon, lat, z) = sample(f, col, row);
            let strictly_inside = |r: &fmrh::scene::LonLatRect| {
                lon > r.lon0 + 1e-9
                    && lon < r.lon1 - 1e-9
                    && lat > r.lat0 + 1e-9
                    && lat < r.lat1 - 1e-9
            };
            let on_edge_of_higher = foot[li + 1..]
                .iter()
                .any(|r| r.contains(lon, lat) && !strictly_inside(r));
            let under_higher = foot[li + 1..].iter().any(strictly_inside);
            let (c, r) = (u64::from(col), u64::from(row));
            let holders: Vec<&fmrh::scene::LayerBlock> = scene
                .blocks
                .iter()
                .filter(|lb| lb.layer == li)
                .filter(|lb| {
                    let x = &lb.block;
                    c >= x.col0 && c <= x.col1 && r >= x.row0 && r <= x.row1
                })
                .collect();
            let in_cutout =
                |lb: &fmrh::scene::LayerBlock| lb.cutouts.iter().any(|k| k.contains(lon, lat));
            if under_higher {
                for lb in &holders {
                    prop_assert!(
                        in_cutout(lb),
                        "layer {} sample {},{} under a higher layer drawn",
                        li,
                        col,
                        row
                    );
                }
                continue;
            }
            if !on_edge_of_higher {
                for lb in &holders {
                    prop_assert!(
                        !lb.cutouts.iter().any(|k| lon > k.lon0 + 1e-9
                            && lon < k.lon1 - 1e-9
                            && lat > k.lat0 + 1e-9
                            && lat < k.lat1 - 1e-9),
                        "layer {} sample {},{} outside the layers above is cut out",
                        li,
                        col,
                        row
                    );
                }
            }
            let p = globe::ecef_point(lon, lat, z);
            let in_frustum = view
                .planes
                .iter()
                .all(|pl| pl.normal.dot(p) + pl.offset >= 0.0);
            if !(in_frustum && common::globe::above_horizon(eye, p)) {
                continue;
            }
            seen += 1;
            // Owned: half-open footprints, closed at the data's last column and row.
            let owners = holders
                .iter()
                .filter(|lb| {
                    let x = &lb.block;
                    (c < x.col1 || c == u64::from(w - 1)) && (r < x.row1 || r == u64::from(h - 1))
                })
                .count();
            let on_own_edge = li > 0 && (col == 0 || row == 0 || col == w - 1 || row == h - 1);
            if on_edge_of_higher || on_own_edge {
                prop_assert!(
                    !holders.is_empty() || on_edge_of_higher,
                    "layer {} edge sample {},{} drawn by no block",
                    li,
                    col,
                    row
                );
            } else {
                prop_assert_eq!(
                    owners,
                    1,
                    "layer {} sample {},{} seen, drawn by {} blocks",
                    li,
                    col,
                    row,
                    owners
                );
            }
        }
    }

    // No crack: the skirts reach across every seam, between grid points too.
    let loaded = layers.load(&scene).unwrap();
    let mut skirts = layers.skirts(&scene, &loaded).unwrap();
    if let Some(f) = skirts_override {
        skirts = f(&skirts);
    }
    let n = layers.layers().len();
    let index: Vec<Vec<usize>> = (0..n)
        .map(|i| {
            (0..scene.blocks.len())
                .filter(|&k| scene.blocks[k].layer == i)
                .collect()
        })
        .collect();
    let surfaces: Vec<Surface<'_>> = index
        .iter()
        .map(|ks| {
            Surface::new(
                ks.iter()
                    .map(|&k| layers.grid(&scene, &loaded, k))
                    .collect(),
            )
        })
        .collect();
    for j in 1..n {
        let l = &layers.layers()[j];
        let data = l.terrain.domain().data_rect();
        let (w, h) = (data.col1 as f64, data.row1 as f64);
        // Quarter-sample steps along the four footprint edges.
        let mut pts = Vec::new();
        for q in 0..=(4 * data.col1) {
            let t = q as f64 / 4.0;
            pts.extend([(t, 0.0), (t, h), (0.0, t), (w, t)]);
        }
        for (c, r) in pts {
            let Some(own) = surfaces[j].at(c, r) else {
                continue;
            };
            let (lon, lat) = l.frame.lon_lat(c, r);
            for i in (0..n).rev().filter(|&i| i != j) {
                let o = &layers.layers()[i];
                if !o.footprint.contains(lon, lat) {
                    continue;
                }
                let oc = (lon - o.frame.lon0) / o.frame.dlon;
                let or = (lat - o.frame.lat0) / o.frame.dlat;
                let Some(other) = surfaces[i].at(oc, or) else {
                    continue;
                };
                let (kj, ki) = (index[j][own.block], index[i][other.block]);
                let gap = own.height - other.height;
                let tol = 1e-6 * (1.0 + gap.abs());
                if gap > 0.0 {
                    prop_assert!(
                        skirts[kj] + tol >= gap,
                        "layer {} block {} at ({:.4}, {:.4}): {} above layer {}, skirt {}",
                        j,
                        kj,
                        lon,
                        lat,
                        gap,
                        i,
                        skirts[kj]
                    );
                } else {
                    prop_assert!(
                        skirts[ki] + tol >= -gap,
                        "layer {} block {} at ({:.4}, {:.4}): {} above layer {}, skirt {}",
                        i,
                        ki,
                        lon,
                        lat,
                        -gap,
                        j,
                        skirts[ki]
                    );
                }
                break;
            }
        }
    }
    Ok(seen)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]
    #[test]
    fn layered_scenes_have_no_hole_no_overlap_and_no_crack(
        lat in 42.5f64..44.5, lon in 5.5f64..8.5, log_h in 2.5f64..7.3,
        heading in 0.0f64..360.0, pitch in -90.0f64..-5.0,
        tau in 0.5f64..4.0,
    ) {
        let h = 10f64.powf(log_h);
        check(&Camera::on_globe(lat, lon, h, heading, pitch), tau, None)?;
    }
}

/// A fly-through from orbit down to the Massif des Maures (N43E006): every frame passes.
#[test]
fn orbit_to_ground_without_holes_or_cracks() {
    let mut seen_any = 0;
    for h in [2.0e7, 5.0e6, 1.0e6, 2.0e5, 5.0e4, 1.0e4, 3.0e3, 800.0] {
        let seen = check(&Camera::on_globe(43.25, 6.35, h, 20.0, -55.0), 1.0, None).unwrap();
        seen_any += usize::from(seen > 0);
    }
    assert_eq!(seen_any, 8, "every frame of the fly-through sees terrain");
}

/// The skirts must be measured at every sample along a seam, not only at the blocks' grid
/// points: a coarse layer's sample lines fall between a fine block's grid points.
#[test]
fn skirts_are_measured_between_grid_points() {
    let stores = stores();
    let layers = layers_of(&stores);
    let camera = Camera::on_globe(43.25, 6.35, 2.0e5, 20.0, -55.0);
    let scene = layers.scene(&camera, &SceneOptions::new(1.0)).unwrap();
    let loaded = layers.load(&scene).unwrap();
    let skirts = layers.skirts(&scene, &loaded).unwrap();
    assert!(
        skirts.iter().any(|&d| d > 0.0),
        "the seams need skirts here"
    );
    // Shallower skirts (by a tenth) leave cracks the check finds.
    let shallower = |d: &[f64]| d.iter().map(|x| x * 0.9).collect::<Vec<_>>();
    let r = check(&camera, 1.0, Some(&shallower));
    assert!(r.is_err(), "a tenth less skirt must leave a crack");
}

/// A layer whose edges do not follow the grid below is refused; so is a layer off the globe.
#[test]
fn misaligned_layers_are_refused() {
    let b = built();
    let dir = tempfile::tempdir().unwrap();
    let mut f = b.fields[1].clone();
    let g = f.metadata.georeference.as_mut().unwrap();
    g.origin[0] += 0.1; // 6.1° E: not on ETOPO1's half degrees
    let file = dir.path().join("moved.fmrh");
    fmrh::create(&file, f, &fmrh::CreateOptions::default()).unwrap();
    let base = fmrh::store::Store::open(&b.files[0]).unwrap();
    let moved = fmrh::store::Store::open(&file).unwrap();
    let r = Layers::new(vec![
        Terrain::on_globe(&base).unwrap(),
        Terrain::on_globe(&moved).unwrap(),
    ]);
    let e = r.err().expect("refused").to_string();
    assert!(e.contains("longitude") && e.contains("sample line"), "{e}");
    let flat = Terrain::new(&base).unwrap();
    assert!(Layers::new(vec![flat]).is_err());
    // The CLI says so and exits non-zero.
    let out = common::fmrh(&[
        "scene",
        b.files[0].to_str().unwrap(),
        "--layer",
        file.to_str().unwrap(),
        "--eye-geo",
        "43.5,6.5,100000",
        "--tau",
        "1",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("sample line"));
}

/// `fmrh scene BASE --layer A --layer B --eye-geo … --json --load` is the library's layered
/// scene, with its skirts.
#[test]
fn the_cli_draws_layers() {
    let b = built();
    let out = common::fmrh(&[
        "scene",
        b.files[0].to_str().unwrap(),
        "--layer",
        b.files[1].to_str().unwrap(),
        "--layer",
        b.files[2].to_str().unwrap(),
        "--eye-geo",
        "43.25,6.35,200000",
        "--look",
        "20,-55",
        "--tau",
        "1",
        "--load",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let stores = stores();
    let layers = layers_of(&stores);
    let scene = layers
        .scene(
            &Camera::on_globe(43.25, 6.35, 2.0e5, 20.0, -55.0),
            &SceneOptions::new(1.0),
        )
        .unwrap();
    let blocks = j["blocks"].as_array().unwrap();
    assert_eq!(blocks.len(), scene.blocks.len());
    for (x, y) in blocks.iter().zip(&scene.blocks) {
        assert_eq!(x["layer"].as_u64(), Some(y.layer as u64));
        assert_eq!(x["key"].as_u64(), Some(y.block.key));
        assert_eq!(x["cutouts"].as_array().unwrap().len(), y.cutouts.len());
    }
    let loaded = layers.load(&scene).unwrap();
    let skirts = layers.skirts(&scene, &loaded).unwrap();
    let js: Vec<f64> = j["skirts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(js, skirts);
    // Layers need the globe.
    let flat = common::fmrh(&[
        "scene",
        b.files[0].to_str().unwrap(),
        "--layer",
        b.files[1].to_str().unwrap(),
        "--eye",
        "0,0,100",
        "--target",
        "1,1,0",
        "--tau",
        "1",
    ]);
    assert!(!flat.status.success());
    assert!(String::from_utf8_lossy(&flat.stderr).contains("--eye-geo"));
}
