//! `fmrh mesh --format quantized-mesh` writes tiles that a decoder written here from the
//! public specification (github.com/CesiumGS/quantized-mesh) reads back to the library's
//! stitched mesh: every vertex at its sample to within one quantization step, every height
//! to within half a step of the tile's height range, the same triangles counter-clockwise,
//! the edge lists exactly the vertices on each edge, the oct-encoded normals within their
//! precision, and each tile's metadata naming its block. `layer.json` lists exactly the
//! tiles written, level by level. The decoder shares no code with the encoder.

mod common;

use common::quantized_mesh::{decode, oct_decode};

use std::collections::{BTreeSet, HashMap};
use std::path::Path;

use fmrh::mesh::{build, Cracks};
use fmrh::scene::surface::GridBlock;
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain, WorldFrame, PAYLOAD_GAP};

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

#[test]
fn tiles_decode_to_the_stitched_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let out = dir.path().join("tiles");
    let run = common::fmrh(&[
        "mesh",
        file.to_str().unwrap(),
        "--eye",
        "-2000,4000,2500",
        "--target",
        "1000,700,0",
        "--tau",
        "6",
        "--format",
        "quantized-mesh",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );

    let store = fmrh::store::Store::open(&file).unwrap();
    let camera = Camera::looking_at(
        glam::DVec3::new(-2000.0, 4000.0, 2500.0),
        glam::DVec3::new(1000.0, 700.0, 0.0),
    );
    let scene = Terrain::new(&store)
        .unwrap()
        .scene(&camera, &SceneOptions::new(6.0))
        .unwrap();
    let d = *store.domain();
    let loaded = load_blocks(&store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let grids: Vec<GridBlock<'_>> = scene
        .blocks
        .iter()
        .zip(&loaded)
        .map(|(b, l)| GridBlock::of(b, l, d.stride(b.level)))
        .collect();
    let meshes = build(&grids, &WorldFrame::new(Some([10.0, 10.0])), Cracks::Stitch).unwrap();
    assert!(meshes.iter().any(|m| m.stitched.contains(&true)));

    let mut written: BTreeSet<(u64, u64, u64)> = BTreeSet::new();
    for (b, m) in scene.blocks.iter().zip(&meshes) {
        let y = (1u32 << b.level) - 1 - b.y;
        let path = out.join(format!("{}/{}/{y}.terrain", b.level, b.x));
        written.insert((u64::from(b.level), u64::from(b.x), u64::from(y)));
        let t = decode(&std::fs::read(&path).unwrap());
        let f = d.footprint(b.level, b.x, b.y);
        let (side_c, side_r) = ((f.col1 - f.col0) as f64, (f.row1 - f.row0) as f64);
        assert_eq!(t.u.len(), m.vertices.len());
        // Each decoded vertex is the library's vertex at that sample.
        let by_sample: HashMap<(u64, u64), usize> = m
            .vertices
            .iter()
            .enumerate()
            .map(|(i, v)| ((v.col, v.row), i))
            .collect();
        let step = (f64::from(t.max_height) - f64::from(t.min_height)) / 32767.0;
        let mut map = Vec::new();
        for k in 0..t.u.len() {
            let col = f.col0 as f64 + f64::from(t.u[k]) / 32767.0 * side_c;
            let row = f.row1 as f64 - f64::from(t.v[k]) / 32767.0 * side_r;
            let (c, r) = (col.round() as u64, row.round() as u64);
            assert!((col - c as f64).abs() <= side_c / 32767.0);
            assert!((row - r as f64).abs() <= side_r / 32767.0);
            let i = by_sample[&(c, r)];
            map.push(i);
            let height = f64::from(t.min_height) + f64::from(t.h[k]) * step;
            let want = m.vertices[i].height;
            assert!(
                (height - want).abs() <= step / 2.0 + 1e-6 * (1.0 + want.abs()),
                "({c}, {r}): {height} against {want} (step {step})"
            );
            if let Some(normals) = &t.normals {
                let n = oct_decode(normals[k]);
                let [e, s, up] = m.normals[i];
                let dot = n[0] * e - n[1] * s + n[2] * up;
                assert!(dot > 0.999, "normal {n:?} against {:?}", m.normals[i]);
            }
        }
        let distinct: BTreeSet<usize> = map.iter().copied().collect();
        assert_eq!(distinct.len(), map.len(), "two tile vertices at one sample");
        // The same triangles, in the same (counter-clockwise) turn.
        let norm = |t: [u32; 3]| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        let ours: BTreeSet<[u32; 3]> = m.triangles.iter().map(|&t| norm(t)).collect();
        let theirs: BTreeSet<[u32; 3]> = t
            .triangles
            .iter()
            .map(|tr| norm(tr.map(|i| map[i as usize] as u32)))
            .collect();
        assert_eq!(ours, theirs);
        // Edge lists: exactly the vertices on each edge of the tile.
        let on = [
            |v: &fmrh::mesh::MeshVertex, f: &fmrh::model::SampleRect| v.col == f.col0,
            |v: &fmrh::mesh::MeshVertex, f: &fmrh::model::SampleRect| v.row == f.row1,
            |v: &fmrh::mesh::MeshVertex, f: &fmrh::model::SampleRect| v.col == f.col1,
            |v: &fmrh::mesh::MeshVertex, f: &fmrh::model::SampleRect| v.row == f.row0,
        ];
        for (e, list) in t.edges.iter().enumerate() {
            let got: BTreeSet<usize> = list.iter().map(|&k| map[k as usize]).collect();
            let want: BTreeSet<usize> = (0..m.vertices.len())
                .filter(|&i| on[e](&m.vertices[i], &f))
                .collect();
            assert_eq!(got, want, "edge {e} of block {}", b.key);
        }
        let meta = &t.metadata.as_ref().expect("metadata")["fmrh"];
        assert_eq!(meta["level"].as_u64(), Some(u64::from(b.level)));
        assert_eq!(meta["key"].as_u64(), Some(b.key));
        assert_eq!(meta["error"].as_f64(), Some(b.error));
        assert_eq!(meta["synthetic"], false);
    }
    // layer.json lists exactly those tiles.
    let layer: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("layer.json")).unwrap()).unwrap();
    assert_eq!(layer["format"], "quantized-mesh-1.0");
    assert_eq!(layer["scheme"], "tms");
    let mut listed = BTreeSet::new();
    for (z, ranges) in layer["available"].as_array().unwrap().iter().enumerate() {
        for r in ranges.as_array().unwrap() {
            let g = |k: &str| r[k].as_u64().unwrap();
            for y in g("startY")..=g("endY") {
                for x in g("startX")..=g("endX") {
                    listed.insert((z as u64, x, y));
                }
            }
        }
    }
    assert_eq!(listed, written);
}

#[test]
fn quantized_mesh_refuses_what_it_cannot_write() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let args = |out: &str| {
        vec![
            "mesh".to_string(),
            file.display().to_string(),
            "--eye".into(),
            "-2000,4000,2500".into(),
            "--target".into(),
            "1000,700,0".into(),
            "--tau".into(),
            "6".into(),
            "--format".into(),
            "quantized-mesh".into(),
            "-o".into(),
            out.into(),
        ]
    };
    let run = |a: Vec<String>| common::fmrh(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!run(args("-")).status.success(), "tiles to standard output");
    let existing = dir.path().join("there");
    std::fs::create_dir(&existing).unwrap();
    std::fs::write(existing.join("keep"), b"x").unwrap();
    let r = run(args(existing.to_str().unwrap()));
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("--force"));
    assert!(existing.join("keep").exists());
    let mut forced = args(existing.to_str().unwrap());
    forced.push("--force".into());
    assert!(run(forced).status.success());
    assert!(existing.join("layer.json").exists() && !existing.join("keep").exists());
    // Nothing half-written is left beside it.
    let strays: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(strays.is_empty());
}
