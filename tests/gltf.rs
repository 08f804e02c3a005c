//! The `.glb` that `fmrh mesh` writes is the scene's mesh, as glTF 2.0 says to write it: a
//! valid GLB container (magic, version, lengths, a JSON chunk and a binary chunk, each
//! padded to four bytes), one node per scene block whose `extras` name the block's level,
//! key and error, positions that are the library's mesh in the documented axes (X east, Y
//! up, Z south, from the origin the scene's `extras` give), with POSITION's min and max
//! exact, unit normals pointing up, and indices in range. Both ways of closing cracks
//! write; an existing file is kept without --force, and a camera that sees no terrain is a
//! clear error. (The Khronos validator checks the same files in the large-data suite,
//! `tests/mesh_real.rs`.)

mod common;

use std::path::Path;

use fmrh::mesh::{build, Cracks, GridBlock};
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain, WorldFrame, PAYLOAD_GAP};
use serde_json::Value;

/// The JSON and binary chunks of a GLB, after checking its framing.
fn chunks(glb: &[u8]) -> (Value, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(word(4), 2, "version");
    assert_eq!(word(8), glb.len(), "the header's length");
    let json_len = word(12);
    assert_eq!(&glb[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let json: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let at = 20 + json_len;
    let bin_len = word(at);
    assert_eq!(&glb[at + 4..at + 8], b"BIN\0");
    assert_eq!(bin_len % 4, 0);
    assert_eq!(at + 8 + bin_len, glb.len());
    (json, glb[at + 8..].to_vec())
}

/// The `count` elements of accessor `a`, as f32 components (or integers, widened).
fn read_accessor(json: &Value, bin: &[u8], a: u64) -> Vec<f64> {
    let acc = &json["accessors"][a as usize];
    let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let start =
        (view["byteOffset"].as_u64().unwrap() + acc["byteOffset"].as_u64().unwrap()) as usize;
    let count = acc["count"].as_u64().unwrap() as usize;
    let comps = match acc["type"].as_str().unwrap() {
        "VEC3" => 3,
        "SCALAR" => 1,
        t => panic!("type {t}"),
    };
    let n = count * comps;
    let bytes = &bin[start..];
    match acc["componentType"].as_u64().unwrap() {
        5126 => (0..n)
            .map(|i| {
                f64::from(f32::from_le_bytes(
                    bytes[4 * i..4 * i + 4].try_into().unwrap(),
                ))
            })
            .collect(),
        5123 => (0..n)
            .map(|i| {
                f64::from(u16::from_le_bytes(
                    bytes[2 * i..2 * i + 2].try_into().unwrap(),
                ))
            })
            .collect(),
        5125 => (0..n)
            .map(|i| {
                f64::from(u32::from_le_bytes(
                    bytes[4 * i..4 * i + 4].try_into().unwrap(),
                ))
            })
            .collect(),
        c => panic!("component type {c}"),
    }
}

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
    let store = fmrh::Store::open(&file).unwrap();
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
            .map(|(b, l)| GridBlock {
                rect: b.rect(),
                stride: d.stride(b.level),
                grid_width: l.width,
                grid_height: l.height,
                heights: &l.heights,
                error: b.error,
            })
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
