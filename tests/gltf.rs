//! The `.glb` that `fmrh mesh` writes is the scene's mesh, as glTF 2.0 says to write it: a
//! valid GLB container (magic, version, lengths, a JSON chunk and a binary chunk, each
//! padded to four bytes), one node per scene block whose `extras` name the block's level,
//! key and error, positions that are the library's mesh in the documented axes (X east, Y
//! up, Z south, from the origin the scene's `extras` give), with POSITION's min and max
//! exact, unit normals pointing up, and indices in range. Both ways of closing cracks
//! write, and so does a TIN within `--max-error`; an existing file is kept without
//! --force, and a camera that sees no terrain is a clear error. (The Khronos validator
//! checks the same files in the large-data suite, `tests/mesh_real.rs`.)

mod common;

use std::path::Path;

use fmrh::mesh::{build, build_in, build_tin_in, Cracks};
use fmrh::scene::surface::GridBlock;
use fmrh::scene::{
    load_blocks, Camera, SceneOptions, Terrain, TerrainFrame, WorldFrame, PAYLOAD_GAP,
};
use serde_json::Value;

use common::gltf::{chunks, read_accessor};

/// A 200 × 160 container of hills at 10 m, in `dir`.
fn container(dir: &Path) -> std::path::PathBuf {
    let mut field = common::fields::make(200, 160, common::fields::Character::Hills, 0.01, 9);
    field.metadata.spacing_m = Some([10.0, 10.0]);
    let path = dir.join("hills.fmrh");
    fmrh::create(
        &path,
        field,
        &fmrh::CreateOptions {
            block_size: 17,
            ..fmrh::CreateOptions::default()
        },
    )
    .unwrap();
    path
}

const EYE: &str = "-2000,4000,2500";
const TARGET: &str = "1000,700,0";

fn mesh_cli(file: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "mesh",
        file.to_str().unwrap(),
        "--eye",
        EYE,
        "--target",
        TARGET,
        "--tau",
        "6",
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    common::fmrh(&args)
}

#[test]
fn the_glb_is_the_scene_mesh_in_the_documented_axes() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let store = fmrh::store::Store::open(&file).unwrap();
    let camera = Camera::looking_at(
        glam::DVec3::new(-2000.0, 4000.0, 2500.0),
        glam::DVec3::new(1000.0, 700.0, 0.0),
    );
    let scene = Terrain::new(&store)
        .unwrap()
        .scene(&camera, &SceneOptions::new(6.0))
        .unwrap();
    let levels: std::collections::BTreeSet<u8> = scene.blocks.iter().map(|b| b.level).collect();
    assert!(levels.len() >= 2, "levels {levels:?}");
    let loaded = load_blocks(&store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let d = store.domain();
    for (cracks, name) in [(Cracks::Stitch, "stitch"), (Cracks::Skirts, "skirts")] {
        let grids: Vec<GridBlock<'_>> = scene
            .blocks
            .iter()
            .zip(&loaded)
            .map(|(b, l)| GridBlock::of(b, l, d.stride(b.level)))
            .collect();
        let frame = WorldFrame::new(Some([10.0, 10.0]));
        let meshes = build(&grids, &frame, cracks).unwrap();
        let out = dir.path().join(format!("{name}.glb"));
        let run = mesh_cli(&file, &out, &["--cracks", name]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let (json, bin) = chunks(&std::fs::read(&out).unwrap());
        let extras = &json["scenes"][0]["extras"]["fmrh"];
        assert_eq!(extras["cracks"], name);
        let origin = [
            extras["origin"]["world_m"][0].as_f64().unwrap(),
            extras["origin"]["world_m"][1].as_f64().unwrap(),
        ];
        let c0 = scene.blocks.iter().map(|b| b.col0).min().unwrap();
        let r0 = scene.blocks.iter().map(|b| b.row0).min().unwrap();
        assert_eq!(origin, [c0 as f64 * 10.0, r0 as f64 * 10.0]);
        let nodes = json["nodes"].as_array().unwrap();
        assert_eq!(nodes.len(), scene.blocks.len());
        assert_eq!(
            json["scenes"][0]["nodes"].as_array().unwrap().len(),
            nodes.len()
        );
        for (node, (block, m)) in nodes.iter().zip(scene.blocks.iter().zip(&meshes)) {
            let e = &node["extras"]["fmrh"];
            assert_eq!(e["level"].as_u64(), Some(u64::from(block.level)));
            assert_eq!(e["key"].as_u64(), Some(block.key));
            assert_eq!(e["error"].as_f64(), Some(block.error));
            assert_eq!(e["synthetic"], false);
            let prim = &json["meshes"][node["mesh"].as_u64().unwrap() as usize]["primitives"][0];
            let pa = prim["attributes"]["POSITION"].as_u64().unwrap();
            let positions = read_accessor(&json, &bin, pa);
            let normals =
                read_accessor(&json, &bin, prim["attributes"]["NORMAL"].as_u64().unwrap());
            let indices = read_accessor(&json, &bin, prim["indices"].as_u64().unwrap());
            assert_eq!(positions.len(), 3 * m.vertices.len());
            assert_eq!(indices.len(), 3 * m.triangles.len());
            for (k, v) in m.vertices.iter().enumerate() {
                let want = [
                    (v.col as f64 * 10.0 - origin[0]) as f32,
                    v.height as f32,
                    (v.row as f64 * 10.0 - origin[1]) as f32,
                ];
                let got = [
                    positions[3 * k] as f32,
                    positions[3 * k + 1] as f32,
                    positions[3 * k + 2] as f32,
                ];
                assert_eq!(got, want, "vertex {k} of block {}", block.key);
                let n = [normals[3 * k], normals[3 * k + 1], normals[3 * k + 2]];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-5 && n[1] > 0.0, "normal {n:?}");
            }
            for (t, i) in m.triangles.iter().flatten().zip(&indices) {
                assert_eq!(f64::from(*t), *i);
            }
            let acc = &json["accessors"][pa as usize];
            for a in 0..3 {
                let vals = positions.iter().skip(a).step_by(3);
                let min = vals.clone().cloned().fold(f64::INFINITY, f64::min);
                let max = vals.cloned().fold(f64::NEG_INFINITY, f64::max);
                assert_eq!(acc["min"][a].as_f64(), Some(min));
                assert_eq!(acc["max"][a].as_f64(), Some(max));
            }
        }
    }
}

/// On the globe (`--eye-geo`), every vertex of the `.glb`, taken back from the local
/// east-north-up frame the scene's `extras` name to latitude, longitude and height, is its
/// mesh vertex's sample on WGS 84 at its ellipsoidal height (the stored EGM96 height plus
/// the geoid's undulation there), and every normal points away from the
/// Earth; the meshes are the library's (`build_in` on the globe frame) vertex for vertex.
#[test]
fn a_globe_glb_is_the_scene_mesh_on_the_ellipsoid() {
    let dir = tempfile::tempdir().unwrap();
    let (file, _) = common::globe::container(dir.path(), "n6", "srtm3-pyhgtmap/N43E006.hgt.gz");
    let store = fmrh::store::Store::open(&file).unwrap();
    let terrain = Terrain::on_globe(&store).unwrap();
    let TerrainFrame::Globe(g) = terrain.world() else {
        panic!("a geographic grid is on the globe")
    };
    let camera = Camera::on_globe(43.3, 6.4, 30_000.0, 30.0, -40.0);
    let scene = terrain.scene(&camera, &SceneOptions::new(1.0)).unwrap();
    let loaded = load_blocks(&store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let d = store.domain();
    let grids: Vec<GridBlock<'_>> = scene
        .blocks
        .iter()
        .zip(&loaded)
        .map(|(b, l)| GridBlock::of(b, l, d.stride(b.level)))
        .collect();
    let meshes = build_in(&grids, &TerrainFrame::Globe(g), Cracks::Stitch).unwrap();
    let out = dir.path().join("globe.glb");
    let run = common::fmrh(&[
        "mesh",
        file.to_str().unwrap(),
        "--eye-geo",
        "43.3,6.4,30000",
        "--look",
        "30,-40",
        "--tau",
        "1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let (json, bin) = chunks(&std::fs::read(&out).unwrap());
    let o = &json["scenes"][0]["extras"]["fmrh"]["origin"]["lon_lat_h"];
    let (lon0, lat0) = (o[0].as_f64().unwrap(), o[1].as_f64().unwrap());
    let origin = fmrh::globe::ecef_point(lon0, lat0, 0.0);
    let [east, north, upward] = fmrh::globe::enu(lon0, lat0);
    let to_ecef = |x: f64, y: f64, z: f64| origin + east * x + upward * y - north * z;
    let nodes = json["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), meshes.len());
    let mut checked = 0;
    for (node, m) in nodes.iter().zip(&meshes) {
        let prim = &json["meshes"][node["mesh"].as_u64().unwrap() as usize]["primitives"][0];
        let positions = read_accessor(
            &json,
            &bin,
            prim["attributes"]["POSITION"].as_u64().unwrap(),
        );
        let normals = read_accessor(&json, &bin, prim["attributes"]["NORMAL"].as_u64().unwrap());
        assert_eq!(positions.len(), 3 * m.vertices.len());
        for (k, v) in m.vertices.iter().enumerate() {
            let p = to_ecef(positions[3 * k], positions[3 * k + 1], positions[3 * k + 2]);
            let (lon, lat, h) = fmrh::globe::geodetic(p);
            let (want_lon, want_lat) = g.lon_lat(v.col as f64, v.row as f64);
            // Single-precision positions up to ~100 km from the origin: about a centimetre.
            assert!(
                (lon - want_lon).abs() < 2e-7 && (lat - want_lat).abs() < 2e-7,
                "vertex {k}: ({lon}, {lat}) for ({want_lon}, {want_lat})"
            );
            // SRTM heights are above EGM96 (recorded at build): on the ellipsoid each is
            // N higher, about 49 m here.
            let n96 = fmrh::geoid::egm96_undulation(want_lat, want_lon);
            assert!((45.0..55.0).contains(&n96), "N {n96}");
            assert!(
                (h - (v.height + n96)).abs() < 0.05,
                "vertex {k}: height {h} for {} + N {n96}",
                v.height
            );
            let n = to_ecef(normals[3 * k], normals[3 * k + 1], normals[3 * k + 2]) - origin;
            assert!((n.length() - 1.0).abs() < 1e-5);
            let local_up = glam::DVec3::from(fmrh::globe::up(lon, lat));
            assert!(
                n.dot(local_up) > 0.0,
                "vertex {k}: normal {n:?} points down"
            );
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked} vertices");
    // Tiles of quantized-mesh and refinement past the data stay flat-frame only.
    for extra in [
        &["--format", "quantized-mesh"][..],
        &["--refine", "fractal"][..],
    ] {
        let mut args = vec![
            "mesh",
            file.to_str().unwrap(),
            "--eye-geo",
            "43.3,6.4,30000",
            "--tau",
            "1",
            "-o",
        ];
        let o2 = dir.path().join("refused");
        args.push(o2.to_str().unwrap());
        args.extend_from_slice(extra);
        let r = common::fmrh(&args);
        assert_eq!(r.status.code(), Some(2), "{extra:?}");
        assert!(!o2.exists());
    }
}

#[test]
fn mesh_refuses_what_it_cannot_do_and_keeps_what_exists() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let out = dir.path().join("kept.glb");
    std::fs::write(&out, b"keep me").unwrap();
    let run = mesh_cli(&file, &out, &[]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("--force"));
    assert_eq!(std::fs::read(&out).unwrap(), b"keep me");
    assert!(mesh_cli(&file, &out, &["--force"]).status.success());
    assert_eq!(&std::fs::read(&out).unwrap()[0..4], b"glTF");
    // Looking up at the sky.
    let away = common::fmrh(&[
        "mesh",
        file.to_str().unwrap(),
        "--eye",
        "1000,800,500",
        "--target",
        "1000,801,5000",
        "--tau",
        "1",
        "-o",
        dir.path().join("none.glb").to_str().unwrap(),
    ]);
    assert!(!away.status.success());
    assert!(String::from_utf8_lossy(&away.stderr).contains("sees no terrain"));
    assert!(!dir.path().join("none.glb").exists());
    let bad = mesh_cli(&file, &dir.path().join("x.glb"), &["--cracks", "glue"]);
    assert!(!bad.status.success());
    assert!(!dir.path().join("x.glb").exists());
}

/// `--max-error M` writes the library's TINs (`build_tin_in`): each node's triangles and
/// vertices are the TIN's, its `extras` carry the TIN's measured error (≤ M), the scene's
/// carry the budget and `skirts`; a larger budget draws fewer triangles. A budget that is
/// not a number of metres ≥ 0, or one asked with `--cracks stitch`, is refused and writes
/// nothing.
#[test]
fn max_error_writes_the_library_tins_within_their_budget() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let store = fmrh::store::Store::open(&file).unwrap();
    let camera = Camera::looking_at(
        glam::DVec3::new(-2000.0, 4000.0, 2500.0),
        glam::DVec3::new(1000.0, 700.0, 0.0),
    );
    let scene = Terrain::new(&store)
        .unwrap()
        .scene(&camera, &SceneOptions::new(6.0))
        .unwrap();
    let loaded = load_blocks(&store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let d = store.domain();
    let grids: Vec<GridBlock<'_>> = scene
        .blocks
        .iter()
        .zip(&loaded)
        .map(|(b, l)| GridBlock::of(b, l, d.stride(b.level)))
        .collect();
    let frame = TerrainFrame::Flat(WorldFrame::new(Some([10.0, 10.0])));
    let mut drawn = Vec::new();
    for budget in ["0", "0.5", "4"] {
        let m: f64 = budget.parse().unwrap();
        let meshes = build_tin_in(&grids, &frame, m).unwrap();
        let out = dir.path().join(format!("tin{budget}.glb"));
        let run = mesh_cli(&file, &out, &["--max-error", budget]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let (json, bin) = chunks(&std::fs::read(&out).unwrap());
        let extras = &json["scenes"][0]["extras"]["fmrh"];
        assert_eq!(extras["cracks"], "skirts");
        assert_eq!(extras["tin_max_error_m"].as_f64(), Some(m));
        let nodes = json["nodes"].as_array().unwrap();
        assert_eq!(nodes.len(), meshes.len());
        let mut triangles = 0;
        for (node, mesh) in nodes.iter().zip(&meshes) {
            let e = node["extras"]["fmrh"]["tin_error"].as_f64().unwrap();
            assert_eq!(e, mesh.tin_error);
            assert!(e <= m, "{e} past {m}");
            let prim = &json["meshes"][node["mesh"].as_u64().unwrap() as usize]["primitives"][0];
            let positions = read_accessor(
                &json,
                &bin,
                prim["attributes"]["POSITION"].as_u64().unwrap(),
            );
            let indices = read_accessor(&json, &bin, prim["indices"].as_u64().unwrap());
            assert_eq!(positions.len(), 3 * mesh.vertices.len());
            let want: Vec<f64> = mesh
                .triangles
                .iter()
                .flatten()
                .map(|&i| f64::from(i))
                .collect();
            assert_eq!(indices, want);
            triangles += mesh
                .triangles
                .iter()
                .filter(|t| t.iter().all(|&i| !mesh.vertices[i as usize].skirt))
                .count();
        }
        drawn.push(triangles);
    }
    assert!(drawn[0] > drawn[1] && drawn[1] > drawn[2], "{drawn:?}");
    for bad in [
        vec!["--max-error=-1"],
        vec!["--max-error", "nan"],
        vec!["--max-error", "inf"],
        vec!["--max-error", "2", "--cracks", "stitch"],
    ] {
        let out = dir.path().join("refused.glb");
        let run = mesh_cli(&file, &out, &bad);
        assert!(!run.status.success(), "{bad:?} was taken");
        assert!(
            String::from_utf8_lossy(&run.stderr).contains("--max-error"),
            "{bad:?}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        assert!(!out.exists());
    }
}

/// `--refine fractal`: `scene --json` and `mesh` name the same synthetic nodes, every one
/// below a whole, void-free physical block, at the level, position and error the library
/// gives (`fmrh::mesh::fractal::refine_block`); the GLB marks them and only them synthetic,
/// and keeps the other blocks as stored. Without `--refine` the scene has no `fractal`
/// object, and `--refine` with `--reconstruct` is refused.
#[test]
fn refine_fractal_marks_the_same_synthetic_nodes_in_scene_and_mesh() {
    use fmrh::mesh::fractal;
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let (eye, target) = ("950,1650,140", "1000,800,0");
    let camera = Camera::looking_at(
        glam::DVec3::new(950.0, 1650.0, 140.0),
        glam::DVec3::new(1000.0, 800.0, 0.0),
    );
    let tau = 1.0;
    let f = file.to_str().unwrap();
    let scene_args = ["scene", f, "--eye", eye, "--target", target, "--tau", "1"];
    let run = common::fmrh(&[&scene_args[..], &["--json", "--refine", "fractal"]].concat());
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: Value = serde_json::from_slice(&run.stdout).unwrap();
    let plain = common::fmrh(&[&scene_args[..], &["--json"]].concat());
    assert!(plain.status.success());
    let plain: Value = serde_json::from_slice(&plain.stdout).unwrap();
    assert!(plain.get("fractal").is_none());
    assert_eq!(plain["blocks"], report["blocks"]);

    // The library's refinement of the same scene.
    let store = fmrh::store::Store::open(&file).unwrap();
    let scene = Terrain::new(&store)
        .unwrap()
        .scene(&camera, &SceneOptions::new(tau))
        .unwrap();
    let loaded = load_blocks(&store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let d = store.domain();
    let frame = WorldFrame::new(Some([10.0, 10.0]));
    let view = camera.view().unwrap();
    let mut want = Vec::new();
    let mut refined = 0;
    for (b, l) in scene.blocks.iter().zip(&loaded) {
        let grid = GridBlock::of(b, l, d.stride(b.level));
        let nodes = fractal::refine_block(b.key, &grid, &view, &frame, tau);
        if nodes.is_empty() {
            continue;
        }
        refined += 1;
        assert!(l.heights.iter().all(|h| h.is_finite()));
        for n in nodes {
            // Every node is within the block and finer than the data.
            let k = fractal::SCALE;
            assert!(n.rect.col0 >= b.col0 * k && n.rect.col1 <= b.col1 * k);
            assert!(n.rect.row0 >= b.row0 * k && n.rect.row1 <= b.row1 * k);
            assert!((1..=fractal::MAX_DEPTH).contains(&n.depth));
            want.push((b, n));
        }
    }
    assert!(refined >= 2, "the camera refines {refined} blocks");
    let depths: std::collections::BTreeSet<u8> = want.iter().map(|(_, n)| n.depth).collect();
    assert!(depths.len() >= 2, "depths {depths:?}");

    let fr = &report["fractal"];
    assert_eq!(fr["scale"].as_u64(), Some(fractal::SCALE));
    assert_eq!(fr["refined_blocks"].as_u64(), Some(refined));
    let nodes = fr["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), want.len());
    let mut max_px = 0.0f64;
    for (got, (b, n)) in nodes.iter().zip(&want) {
        let k = fractal::SCALE as f64;
        assert_eq!(got["synthetic"], true);
        assert_eq!(got["physical"]["key"].as_u64(), Some(b.key));
        assert_eq!(got["physical"]["level"].as_u64(), Some(u64::from(b.level)));
        assert_eq!(got["depth"].as_u64(), Some(u64::from(n.depth)));
        assert_eq!(got["level"].as_u64(), Some(u64::from(b.level + n.depth)));
        assert_eq!(got["x"].as_u64(), Some(u64::from((b.x << n.depth) + n.x)));
        assert_eq!(got["y"].as_u64(), Some(u64::from((b.y << n.depth) + n.y)));
        let footprint: Vec<f64> = got["footprint"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let r = &n.rect;
        assert_eq!(
            footprint,
            [r.col0, r.row0, r.col1, r.row1].map(|v| v as f64 / k)
        );
        assert_eq!(got["error"].as_f64(), Some(n.error));
        let px = n.screen_error(&view, &frame);
        assert_eq!(got["screen_error"].as_f64(), Some(px));
        // A node stops splitting at the tolerance, or at the last depth.
        assert!(
            px <= tau || n.depth == fractal::MAX_DEPTH,
            "{px} px at depth {}",
            n.depth
        );
        max_px = max_px.max(px);
    }
    assert_eq!(fr["max_screen_error"].as_f64(), Some(max_px));

    // The mesh: the same nodes synthetic, the other blocks as stored.
    let out = dir.path().join("fractal.glb");
    let run = common::fmrh(&[
        "mesh",
        f,
        "--eye",
        eye,
        "--target",
        target,
        "--tau",
        "1",
        "--refine",
        "fractal",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let (json, _) = chunks(&std::fs::read(&out).unwrap());
    assert_eq!(json["scenes"][0]["extras"]["fmrh"]["refine"], "fractal");
    let gltf_nodes = json["nodes"].as_array().unwrap();
    assert_eq!(
        gltf_nodes.len(),
        scene.blocks.len() - refined as usize + want.len()
    );
    let mut synthetic: Vec<(u64, u64, u64, u64)> = Vec::new();
    let mut stored = 0;
    for node in gltf_nodes {
        let e = &node["extras"]["fmrh"];
        let name = node["name"].as_str().unwrap();
        if e["synthetic"] == true {
            assert!(name.ends_with(" synthetic"), "{name}");
            let depth = e["depth"].as_u64().unwrap();
            assert_eq!(
                e["level"].as_u64().unwrap(),
                e["physical_level"].as_u64().unwrap() + depth
            );
            synthetic.push((
                e["key"].as_u64().unwrap(),
                e["level"].as_u64().unwrap(),
                e["x"].as_u64().unwrap(),
                e["y"].as_u64().unwrap(),
            ));
        } else {
            assert_eq!(e["synthetic"], false);
            assert!(e.get("depth").is_none() && !name.contains("synthetic"));
            stored += 1;
        }
    }
    assert_eq!(stored, scene.blocks.len() - refined as usize);
    let mut from_scene: Vec<(u64, u64, u64, u64)> = nodes
        .iter()
        .map(|n| {
            let u = |v: &Value| v.as_u64().unwrap();
            (
                u(&n["physical"]["key"]),
                u(&n["level"]),
                u(&n["x"]),
                u(&n["y"]),
            )
        })
        .collect();
    synthetic.sort_unstable();
    from_scene.sort_unstable();
    assert_eq!(synthetic, from_scene);

    // Synthetic detail has no place in a raster of samples.
    let refused = common::fmrh(
        &[
            &scene_args[..],
            &["--refine", "fractal", "--reconstruct"],
            &[dir.path().join("r.f32").to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("cannot be used with"));
    assert!(!dir.path().join("r.f32").exists());
}

/// `--refine fractal` on a dataset: the scene's synthetic nodes name their tile and
/// physical block, lie inside it, and are the mesh's synthetic nodes, tile for tile.
#[test]
fn refine_fractal_on_a_dataset_names_each_nodes_tile() {
    let dir = tempfile::tempdir().unwrap();
    let field = common::fields::make(150, 120, common::fields::Character::Hills, 0.0, 5);
    let rects = common::tiles::split(&field, &[37, 90], &[53], &[]);
    let ds = common::tiles::build(dir.path(), &field, &rects, &common::tiles::options(None));
    let d = ds.to_str().unwrap();
    let (eye, target) = ("700,560,120", "700,480,0");
    let scene_args = ["scene", d, "--eye", eye, "--target", target, "--tau", "1"];
    let run = common::fmrh(&[&scene_args[..], &["--json", "--refine", "fractal"]].concat());
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: Value = serde_json::from_slice(&run.stdout).unwrap();
    let nodes = report["fractal"]["nodes"].as_array().unwrap();
    let blocks = report["blocks"].as_array().unwrap();
    let u = |v: &Value| v.as_u64().unwrap();
    let mut tiles = std::collections::BTreeSet::new();
    for n in nodes {
        let p = &n["physical"];
        let block = blocks
            .iter()
            .find(|b| u(&b["tile"]) == u(&p["tile"]) && u(&b["key"]) == u(&p["key"]))
            .unwrap_or_else(|| panic!("no scene block for {p}"));
        assert_eq!(block["level"], p["level"]);
        let f: Vec<f64> = n["footprint"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let b = |k: &str| block[k].as_f64().unwrap();
        assert!(f[0] >= b("col0") && f[2] <= b("col1") && f[0] < f[2], "{n}");
        assert!(f[1] >= b("row0") && f[3] <= b("row1") && f[1] < f[3], "{n}");
        tiles.insert(u(&p["tile"]));
    }
    assert!(tiles.len() >= 2, "synthetic nodes in tiles {tiles:?}");

    let out = dir.path().join("ds.glb");
    let run = common::fmrh(&[
        "mesh",
        d,
        "--eye",
        eye,
        "--target",
        target,
        "--tau",
        "1",
        "--refine",
        "fractal",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let (json, _) = chunks(&std::fs::read(&out).unwrap());
    let mut from_mesh: Vec<(u64, u64, u64, u64, u64)> = json["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| &n["extras"]["fmrh"])
        .filter(|e| e["synthetic"] == true)
        .map(|e| {
            (
                u(&e["tile"]),
                u(&e["key"]),
                u(&e["level"]),
                u(&e["x"]),
                u(&e["y"]),
            )
        })
        .collect();
    let mut from_scene: Vec<(u64, u64, u64, u64, u64)> = nodes
        .iter()
        .map(|n| {
            let p = &n["physical"];
            (
                u(&p["tile"]),
                u(&p["key"]),
                u(&n["level"]),
                u(&n["x"]),
                u(&n["y"]),
            )
        })
        .collect();
    from_mesh.sort_unstable();
    from_scene.sort_unstable();
    assert_eq!(from_mesh, from_scene);
}

/// The output's name says what is written (issue 40: `-o x.gltf` and `-o x.obj` both got
/// GLB bytes): `.glb` a binary glTF; `.gltf` JSON glTF naming `x.bin` beside it, the same
/// document as the GLB's JSON chunk but for that URI, and the `.bin` its binary chunk byte
/// for byte; any other name refused (exit 2), nothing written. The Khronos validator
/// checks a `.gltf` and its `.bin` in the large-data suite (`tests/mesh_real.rs`).
#[test]
fn the_output_name_says_glb_or_gltf_and_anything_else_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let glb = dir.path().join("scene.glb");
    let gltf = dir.path().join("scene.gltf");
    for out in [&glb, &gltf] {
        let run = mesh_cli(&file, out, &[]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    let (glb_json, glb_bin) = chunks(&std::fs::read(&glb).unwrap());
    let text = std::fs::read_to_string(&gltf).unwrap();
    let mut doc: Value = serde_json::from_str(&text).expect("a .gltf is JSON");
    assert_eq!(doc["buffers"][0]["uri"], "scene.bin");
    assert_eq!(doc["buffers"][0]["byteLength"], glb_bin.len());
    doc["buffers"][0].as_object_mut().unwrap().remove("uri");
    assert_eq!(doc, glb_json);
    assert_eq!(
        std::fs::read(dir.path().join("scene.bin")).unwrap(),
        glb_bin
    );
    // Again without --force: refused, both files kept; with it, replaced.
    let run = mesh_cli(&file, &gltf, &[]);
    assert_eq!(run.status.code(), Some(2));
    std::fs::remove_file(&gltf).unwrap();
    let run = mesh_cli(&file, &gltf, &[]);
    assert_eq!(run.status.code(), Some(2), "the .bin is there");
    assert!(!gltf.exists());
    let run = mesh_cli(&file, &gltf, &["--force"]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for name in ["scene.obj", "scene.txt", "scene", "scene.GLB.tmp"] {
        let out = dir.path().join(name);
        let run = mesh_cli(&file, &out, &[]);
        assert_eq!(run.status.code(), Some(2), "{name}");
        let said = String::from_utf8_lossy(&run.stderr);
        assert!(
            said.contains(".glb") && said.contains(".gltf"),
            "{name}: {said}"
        );
        assert!(!out.exists(), "{name}");
    }
    // Upper case is the same extension.
    let upper = dir.path().join("SCENE.GLB");
    assert!(mesh_cli(&file, &upper, &[]).status.success());
    assert_eq!(&std::fs::read(&upper).unwrap()[..4], b"glTF");
}
