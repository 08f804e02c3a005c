//! `fmrh mesh --format quantized-mesh` on georeferenced data writes Cesium's global-geodetic
//! pyramid, and every tile holds what it claims. Read back by the reference decoder
//! (`common::quantized_mesh`, written from the public specification), with the geometry
//! computed here from the WGS 84 formulas:
//!
//! * the tileset can be walked from its two roots: `layer.json`'s `available` and the root
//!   tiles' availability metadata name exactly the tiles on disk, each tile's parent is
//!   among them, and every scene block's area has tiles at least as fine as its grid;
//! * each tile is the 65x65 lattice of quantized positions over its whole rectangle, two
//!   counter-clockwise triangles a cell, its edge lists exactly its edge vertices;
//! * **its error holds**: at every valid source sample inside the tile, the height the tile
//!   draws there (linear in `u, v` over the triangle holding it, found here by search) is
//!   within the tile's declared `error` of the source, and the tile measured exactly those
//!   samples; where every sample it draws from is a physical block's, the error is what it
//!   measured against the source itself;
//! * two tiles of one level that share an edge draw the same heights along it, to their
//!   quantization;
//! * the header's bounding sphere holds every vertex in ECEF, its height range holds every
//!   height, and from any camera that sees a vertex above the horizon the occlusion point is
//!   above it too (Cesium's test, written here); the normals point the way the decoded
//!   surface faces.
//!
//! Run on the bundled SRTM tile N43E006 (geographic) and Mount St Helens (UTM zone 10 on
//! NAD27, voids included), and on a two-tile dataset; a property test does the same for
//! random georeferenced fields and cameras through the library, and the CLI refuses what it
//! cannot place on the globe, and a TIN budget for these grid tiles.

mod common;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use common::quantized_mesh::{ecef, listed, oct_decode, read_tiles, scaled, visible, Source, Tile};
use fmrh::Heightfield;
use proptest::prelude::*;

/// Everything the module's paragraph promises of the tileset in `dir`, made from `source`.
/// Returns the largest error of the deepest level's tiles.
fn check_tileset(dir: &Path, source: &Source) -> f64 {
    let layer: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("layer.json")).unwrap()).unwrap();
    assert_eq!(layer["format"], "quantized-mesh-1.0");
    assert_eq!(layer["scheme"], "tms");
    assert_eq!(layer["projection"], "EPSG:4326");
    assert_eq!(layer["fmrh"]["tiling"], "geodetic");
    let tiles = read_tiles(dir);
    let on_disk: BTreeSet<_> = tiles.keys().copied().collect();
    assert_eq!(listed(&layer["available"], 0), on_disk);
    assert!(on_disk.contains(&(0, 0, 0)) && on_disk.contains(&(0, 1, 0)));
    for &(z, x, y) in &on_disk {
        if z > 0 {
            assert!(
                on_disk.contains(&(z - 1, x / 2, y / 2)),
                "{z}/{x}/{y} has no parent"
            );
        }
    }
    // The roots' metadata lists every tile below them, levels 1 up to metadataAvailability.
    let deepest = on_disk.iter().map(|t| t.0).max().unwrap();
    assert_eq!(
        layer["metadataAvailability"].as_u64(),
        Some(u64::from(deepest.max(1)))
    );
    let mut below = BTreeSet::new();
    for root in [0, 1] {
        let t = &tiles[&(0, root, 0)];
        let avail = &t.d.metadata.as_ref().unwrap()["available"];
        for (z, x, y) in listed(avail, 1) {
            assert_eq!(x >> z, root, "{z}/{x}/{y} listed under root {root}");
            below.insert((z, x, y));
        }
    }
    let not_roots: BTreeSet<_> = on_disk.iter().filter(|t| t.0 > 0).copied().collect();
    assert_eq!(below, not_roots);

    let grid: Vec<u16> = (0..65)
        .map(|i| (32767.0 * f64::from(i) / 64.0).round() as u16)
        .collect();
    let mut deepest_error = 0.0f64;
    for tile in tiles.values() {
        let d = &tile.d;
        let name = format!("{}/{}/{}", tile.z, tile.x, tile.y);
        // The lattice, whole: every (u, v) of the grid once.
        assert_eq!(d.u.len(), 65 * 65, "{name}");
        let positions: BTreeSet<(u16, u16)> = d.u.iter().zip(&d.v).map(|(&u, &v)| (u, v)).collect();
        let lattice: BTreeSet<(u16, u16)> = grid
            .iter()
            .flat_map(|&v| grid.iter().map(move |&u| (u, v)))
            .collect();
        assert_eq!(positions, lattice, "{name}");
        // Triangles: counter-clockwise, covering the square once.
        assert_eq!(d.triangles.len(), 2 * 64 * 64);
        let mut area = 0.0;
        for t in &d.triangles {
            let p = t.map(|i| (f64::from(d.u[i as usize]), f64::from(d.v[i as usize])));
            let a = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
            assert!(a > 0.0, "{name}: a triangle turns clockwise");
            area += a / 2.0;
        }
        assert!((area - 32767.0 * 32767.0).abs() < 1e-6, "{name}: {area}");
        // Edge lists: west u = 0, south v = 0, east u = max, north v = max.
        let on = [
            |u: u16, _v: u16| u == 0,
            |_u: u16, v: u16| v == 0,
            |u: u16, _v: u16| u == 32767,
            |_u: u16, v: u16| v == 32767,
        ];
        for (e, list) in d.edges.iter().enumerate() {
            let got: BTreeSet<u32> = list.iter().copied().collect();
            let want: BTreeSet<u32> = (0..d.u.len() as u32)
                .filter(|&k| on[e](d.u[k as usize], d.v[k as usize]))
                .collect();
            assert_eq!(got, want, "{name}: edge {e}");
        }
        // Header: heights within the range, vertices within the sphere.
        let [w, s, e, n] = tile.bounds();
        let mut points = Vec::new();
        for k in 0..d.u.len() {
            let lon = w + f64::from(d.u[k]) / 32767.0 * (e - w);
            let lat = s + f64::from(d.v[k]) / 32767.0 * (n - s);
            let h = d.height(k);
            assert!(h >= f64::from(d.min_height) - 1e-9 && h <= f64::from(d.max_height) + 1e-9);
            let p = ecef(lon, lat, h);
            let r = ((p[0] - d.sphere[0]).powi(2)
                + (p[1] - d.sphere[1]).powi(2)
                + (p[2] - d.sphere[2]).powi(2))
            .sqrt();
            assert!(
                r <= d.sphere[3],
                "{name}: a vertex {r} m from the sphere's centre, radius {}",
                d.sphere[3]
            );
            points.push(p);
        }
        // The occlusion point is above the horizon whenever a vertex is.
        let mut rng = common::fields::Rng::new(
            u64::from(tile.z) << 40 | u64::from(tile.x) << 20 | u64::from(tile.y),
        );
        for _ in 0..40 {
            let lon = -180.0 + 360.0 * rng.unit();
            let lat = -90.0 + 180.0 * rng.unit();
            let h = 10.0 * 10f64.powf(6.5 * rng.unit());
            let camera = scaled(ecef(lon, lat, h));
            if points.iter().any(|&p| visible(camera, scaled(p))) {
                assert!(
                    visible(camera, d.horizon),
                    "{name}: occlusion point hidden from {lon},{lat},{h}"
                );
            }
        }
        // Normals face the way the decoded surface does (interior vertices).
        let normals = d.normals.as_ref().expect("octvertexnormals");
        let at: HashMap<(u16, u16), usize> =
            (0..d.u.len()).map(|k| ((d.u[k], d.v[k]), k)).collect();
        for j in 1..64 {
            for i in 1..64 {
                let k = at[&(grid[i], grid[j])];
                let p = |i: usize, j: usize| points[at[&(grid[i], grid[j])]];
                let (pe, pw, pn, ps) = (p(i + 1, j), p(i - 1, j), p(i, j + 1), p(i, j - 1));
                let east = [pe[0] - pw[0], pe[1] - pw[1], pe[2] - pw[2]];
                let north = [pn[0] - ps[0], pn[1] - ps[1], pn[2] - ps[2]];
                let c = [
                    east[1] * north[2] - east[2] * north[1],
                    east[2] * north[0] - east[0] * north[2],
                    east[0] * north[1] - east[1] * north[0],
                ];
                let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                let nn = oct_decode(normals[k]);
                let dot = (nn[0] * c[0] + nn[1] * c[1] + nn[2] * c[2]) / l;
                assert!(
                    dot > 0.99,
                    "{name}: normal {nn:?} against the surface's {dot}"
                );
            }
        }
        // The error holds at every valid sample inside the tile, measured at exactly those.
        let meta = tile.meta();
        let error = meta["error"].as_f64().unwrap();
        let mut inside = 0u64;
        let mut worst = 0.0f64;
        for (k, &[lon, lat]) in source.lon_lat.iter().enumerate() {
            if !(lon >= w && lon <= e && lat >= s && lat <= n) {
                continue;
            }
            inside += 1;
            let z = source.samples[k];
            if z.is_nan() {
                continue;
            }
            let drawn = tile.height_at(lon, lat);
            let off = (drawn - f64::from(z)).abs();
            worst = worst.max(off);
            assert!(
                off <= error + 1e-6 * (1.0 + off),
                "{name}: sample {} of {}x{} drawn at {drawn}, source {z}: {off} m past the declared {error}",
                k, source.width, source.height
            );
        }
        assert_eq!(meta["measured_samples"].as_u64(), Some(inside), "{name}");
        // Drawn only from blocks of error 0 (physical ones) over valid samples, the declared
        // error is what was measured against the source itself.
        let exact = meta["block_error"].as_f64() == Some(0.0);
        let voids = source
            .lon_lat
            .iter()
            .zip(&source.samples)
            .any(|(&[lon, lat], z)| z.is_nan() && lon >= w && lon <= e && lat >= s && lat <= n);
        if inside > 0 && exact && !voids {
            assert!(
                (worst - error).abs() <= 1e-6 * (1.0 + error),
                "{name}: {worst} against {error}"
            );
        }
        if tile.z == deepest {
            deepest_error = deepest_error.max(error);
        }
    }
    // Same-level neighbours draw their shared edges alike, to their quantization.
    for (&(z, x, y), t) in &tiles {
        let step = |t: &Tile| (f64::from(t.d.max_height) - f64::from(t.d.min_height)) / 32767.0;
        let by = |t: &Tile| -> HashMap<(u16, u16), f64> {
            (0..t.d.u.len())
                .map(|k| ((t.d.u[k], t.d.v[k]), t.d.height(k)))
                .collect()
        };
        for (dx, dy) in [(1u32, 0u32), (0, 1)] {
            let Some(o) = tiles.get(&(z, x + dx, y + dy)) else {
                continue;
            };
            let (a, b) = (by(t), by(o));
            let tol = (step(t) + step(o)) / 2.0 + 1e-6;
            for &g in &grid {
                let (pa, pb) = if dx == 1 {
                    ((32767, g), (0, g))
                } else {
                    ((g, 32767), (g, 0))
                };
                let (ha, hb) = (a[&pa], b[&pb]);
                assert!(
                    (ha - hb).abs() <= tol,
                    "{z}/{x}/{y} and its neighbour: {ha} against {hb}"
                );
            }
        }
    }
    deepest_error
}

fn build(dem: &Path, out: &Path) {
    let run = common::fmrh(&[
        "build",
        dem.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

fn mesh_tiles(input: &Path, eye: &str, target: &str, tau: &str, out: &Path) -> String {
    mesh_tiles_with(input, eye, target, tau, out, &[])
}

fn mesh_tiles_with(
    input: &Path,
    eye: &str,
    target: &str,
    tau: &str,
    out: &Path,
    extra: &[&str],
) -> String {
    let mut args = vec![
        "mesh",
        input.to_str().unwrap(),
        "--eye",
        eye,
        "--target",
        target,
        "--tau",
        tau,
        "--format",
        "quantized-mesh",
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    let run = common::fmrh(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8_lossy(&run.stderr).into_owned()
}

/// Every file under `dir`, by its path inside it.
fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

fn read_dem(path: &Path) -> Heightfield {
    fmrh::ingest::load(path, &fmrh::ingest::IngestOptions::default()).unwrap()
}

#[test]
fn srtm_tiles_decode_and_keep_their_error() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::data("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = dir.path().join("n43.fmrh");
    build(&dem, &file);
    let out = dir.path().join("tiles");
    // Low over the hills north of Cannes, looking north-east: physical blocks near the eye.
    mesh_tiles(&file, "40000,50000,3000", "42000,52000,1500", "0.5", &out);
    let deepest = check_tileset(&out, &Source::of(&read_dem(&dem)));
    let layer: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("layer.json")).unwrap()).unwrap();
    // The physical blocks' resolution (1/1200°) maps to level 12 (0.0439° tiles, 1/1456°
    // grid), the first whose grid is finer.
    let physical = layer["fmrh"]["blocks_to_levels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["stride_samples"] == 1.0)
        .expect("physical blocks in the scene");
    assert_eq!(physical["tile_levels"], serde_json::json!([12, 12]));
    assert_eq!(layer["maxzoom"], 12);
    assert!(deepest > 0.0);
}

#[test]
fn projected_tiles_with_voids_keep_their_error() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::data("mount-st-helens-usgs/SainteHelens.dem");
    let file = dir.path().join("msh.fmrh");
    build(&dem, &file);
    let out = dir.path().join("tiles");
    mesh_tiles(&file, "-2000,16000,4000", "5000,7000,1500", "1", &out);
    check_tileset(&out, &Source::of(&read_dem(&dem)));
}

/// The two bundled SRTM tiles as a dataset (their shared column as the western tile has
/// it): the tileset spans both, and the error holds against both sources.
#[test]
fn a_dataset_s_tiles_keep_their_error() {
    let dir = tempfile::tempdir().unwrap();
    let west = common::data("srtm3-pyhgtmap/N43E006.hgt.gz");
    let east = common::data("srtm3-pyhgtmap/N43E007.hgt.gz");
    let ds = dir.path().join("ds");
    let run = common::fmrh(&[
        "dataset",
        "build",
        west.to_str().unwrap(),
        east.to_str().unwrap(),
        "--seam",
        "first",
        "-o",
        ds.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let out = dir.path().join("tiles");
    // From the south over the sea, looking north across both tiles.
    mesh_tiles(&ds, "81000,160000,9000", "81000,60000,0", "1", &out);
    check_tileset(&out, &Source::beside(&read_dem(&west), &read_dem(&east)));
    // Gzipped, the same tiles: each file gunzips to the plain one, and is much smaller.
    let zipped = dir.path().join("zipped");
    mesh_tiles_with(
        &ds,
        "81000,160000,9000",
        "81000,60000,0",
        "1",
        &zipped,
        &["--gzip"],
    );
    let (plain, packed) = (files(&out), files(&zipped));
    assert_eq!(
        plain.keys().collect::<Vec<_>>(),
        packed.keys().collect::<Vec<_>>()
    );
    let (mut a, mut b) = (0, 0);
    for (path, bytes) in &plain {
        let z = &packed[path];
        if path.ends_with("layer.json") {
            let l: serde_json::Value = serde_json::from_slice(z).unwrap();
            assert_eq!(l["fmrh"]["gzip"], true);
            continue;
        }
        assert!(
            z.starts_with(&[0x1f, 0x8b]),
            "{} is not gzipped",
            path.display()
        );
        let mut unpacked = Vec::new();
        std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&z[..]), &mut unpacked)
            .unwrap();
        assert_eq!(&unpacked, bytes, "{}", path.display());
        (a, b) = (a + bytes.len(), b + z.len());
    }
    assert!(b * 4 < a, "gzip kept {b} of {a} bytes");
}

#[test]
fn tiles_need_a_placeable_georeference() {
    let dir = tempfile::tempdir().unwrap();
    let mut field = common::fields::make(120, 90, common::fields::Character::Hills, 0.0, 3);
    field.metadata.spacing_m = Some([30.0, 30.0]);
    let plain = dir.path().join("plain.fmrh");
    fmrh::create(&plain, field.clone(), &fmrh::CreateOptions::default()).unwrap();
    let args = |file: &Path, tiling: &str, out: &str| {
        common::fmrh(&[
            "mesh",
            file.to_str().unwrap(),
            "--eye",
            "-500,-500,800",
            "--target",
            "1500,1200,0",
            "--tau",
            "2",
            "--format",
            "quantized-mesh",
            "--tiling",
            tiling,
            "-o",
            out,
        ])
    };
    let out = dir.path().join("t1");
    let r = args(&plain, "geodetic", out.to_str().unwrap());
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("no georeference"));
    assert!(!out.exists());
    // Without a georeference, auto writes node tiles.
    let r = args(&plain, "auto", out.to_str().unwrap());
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let layer: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("layer.json")).unwrap()).unwrap();
    assert_eq!(layer["fmrh"]["tiling"], "fmrh-nodes");
    // A CRS fmrh cannot place (not in the registry) is refused by name.
    field.metadata.georeference = Some(fmrh::heightfield::Georeference {
        crs: Some("LOCAL_CS[\"site grid\",UNIT[\"metre\",1]]".into()),
        origin: [0.0, 0.0],
        step: [30.0, -30.0],
    });
    let local = dir.path().join("local.fmrh");
    fmrh::create(&local, field, &fmrh::CreateOptions::default()).unwrap();
    let out2 = dir.path().join("t2");
    let r = args(&local, "geodetic", out2.to_str().unwrap());
    assert!(!r.status.success());
    assert!(
        String::from_utf8_lossy(&r.stderr).contains("cannot be placed on the globe"),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    assert!(!out2.exists());
}

/// Geodetic tiles from `fmrh mesh` are grids (TINs are `fmrh serve`'s): `--max-error` with
/// them is refused by name and writes nothing, while node tiles take it.
#[test]
fn geodetic_tiles_refuse_max_error_and_node_tiles_take_it() {
    let dir = tempfile::tempdir().unwrap();
    let field = field_at(6.0, 43.5, 5);
    let file = dir.path().join("geo.fmrh");
    fmrh::create(&file, field.clone(), &fmrh::CreateOptions::default()).unwrap();
    let [dx, dy] = field.metadata.spacing_m.unwrap();
    let (w, h) = (97.0 * dx, 81.0 * dy);
    let (eye, target) = (
        format!("{},{},{}", -0.3 * w, -0.3 * h, 2000.0),
        format!("{},{},0", w / 2.0, h / 2.0),
    );
    let run = |tiling: &str, out: &Path| {
        common::fmrh(&[
            "mesh",
            file.to_str().unwrap(),
            "--eye",
            &eye,
            "--target",
            &target,
            "--tau",
            "2",
            "--format",
            "quantized-mesh",
            "--tiling",
            tiling,
            "--max-error",
            "3",
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let out = dir.path().join("geodetic");
    let r = run("geodetic", &out);
    assert!(!r.status.success());
    assert!(
        String::from_utf8_lossy(&r.stderr).contains("--max-error"),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    assert!(!out.exists());
    let out = dir.path().join("nodes");
    let r = run("nodes", &out);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(out.join("layer.json").exists());
}

/// A georeferenced field (geographic, 1/1200° steps) with its north-west sample at
/// `lon`, `lat`.
fn field_at(lon: f64, lat: f64, seed: u64) -> Heightfield {
    let mut f = common::fields::make(97, 81, common::fields::Character::Hills, 0.0, seed);
    let step = 1.0 / 1200.0;
    f.metadata.georeference = Some(fmrh::heightfield::Georeference {
        crs: Some("EPSG:4326".into()),
        origin: [lon, lat],
        step: [step, -step],
    });
    f.metadata.spacing_m =
        fmrh::crs::Crs::from_epsg(4326).and_then(|c| c.spacing([step, -step], lat));
    f
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]
    /// Random fields anywhere but the poles (the antimeridian's neighbourhood included),
    /// random cameras and tolerances.
    #[test]
    fn random_fields_and_cameras_keep_the_tiles_promises(
        lon in -179.0f64..178.0, lat in -80.0f64..80.0, seed in 0u64..1000,
        ex in -0.5f64..1.5, ey in -0.5f64..1.5, ez in 200.0f64..6000.0, tau in 0.5f64..4.0,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let field = field_at(lon, lat, seed);
        let file = dir.path().join("f.fmrh");
        fmrh::create(&file, field.clone(), &fmrh::CreateOptions { block_size: 17, ..fmrh::CreateOptions::default() }).unwrap();
        let [dx, dy] = field.metadata.spacing_m.unwrap();
        let (w, h) = (97.0 * dx, 81.0 * dy);
        let out = dir.path().join("tiles");
        mesh_tiles(
            &file,
            &format!("{},{},{}", ex * w, ey * h, ez),
            &format!("{},{},0", w / 2.0, h / 2.0),
            &format!("{tau}"),
            &out,
        );
        check_tileset(&out, &Source::of(&field));
    }
}
