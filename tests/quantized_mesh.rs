//! `fmrh mesh --format quantized-mesh` writes tiles that a decoder written here from the
//! public specification (github.com/CesiumGS/quantized-mesh) reads back to the library's
//! stitched mesh: every vertex at its sample to within one quantization step, every height
//! to within half a step of the tile's height range, the same triangles counter-clockwise,
//! the edge lists exactly the vertices on each edge, the oct-encoded normals within their
//! precision, and each tile's metadata naming its block. `layer.json` lists exactly the
//! tiles written, level by level. The decoder shares no code with the encoder.

mod common;

use std::collections::{BTreeSet, HashMap};
use std::path::Path;

use fmrh::mesh::{build, Cracks, GridBlock};
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain, WorldFrame, PAYLOAD_GAP};

/// A tile as the specification describes it.
struct Decoded {
    min_height: f32,
    max_height: f32,
    u: Vec<u16>,
    v: Vec<u16>,
    h: Vec<u16>,
    triangles: Vec<[u32; 3]>,
    /// West, south, east, north.
    edges: [Vec<u32>; 4],
    normals: Option<Vec<[u8; 2]>>,
    metadata: Option<serde_json::Value>,
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> &[u8] {
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        s
    }
    fn u8(&mut self) -> u8 {
        self.take(1)[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take(2).try_into().unwrap())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take(8).try_into().unwrap())
    }
}

fn decode(bytes: &[u8]) -> Decoded {
    let mut r = Reader { bytes, at: 0 };
    // QuantizedMeshHeader: centre (3 doubles), min and max height (2 floats), bounding
    // sphere (4 doubles), horizon occlusion point (3 doubles).
    for _ in 0..3 {
        r.f64();
    }
    let (min_height, max_height) = (r.f32(), r.f32());
    for _ in 0..7 {
        r.f64();
    }
    assert_eq!(r.at, 88);
    let n = r.u32() as usize;
    let mut arrays: Vec<Vec<u16>> = Vec::new();
    for _ in 0..3 {
        let mut value: i32 = 0;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let z = i32::from(r.u16());
            value += (z >> 1) ^ -(z & 1);
            out.push(u16::try_from(value).expect("a value in 0..=32767"));
        }
        arrays.push(out);
    }
    let wide = n > 65536;
    let align = if wide { 4 } else { 2 };
    while !r.at.is_multiple_of(align) {
        r.u8();
    }
    let index = |r: &mut Reader<'_>| if wide { r.u32() } else { u32::from(r.u16()) };
    let triangle_count = r.u32() as usize;
    let mut highest = 0u32;
    let mut flat = Vec::with_capacity(3 * triangle_count);
    for _ in 0..3 * triangle_count {
        let code = index(&mut r);
        flat.push(highest - code);
        if code == 0 {
            highest += 1;
        }
    }
    let triangles = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let edges: [Vec<u32>; 4] = std::array::from_fn(|_| {
        let count = r.u32() as usize;
        (0..count).map(|_| index(&mut r)).collect()
    });
    let (mut normals, mut metadata) = (None, None);
    while r.at < bytes.len() {
        let id = r.u8();
        let len = r.u32() as usize;
        let body = r.take(len).to_vec();
        match id {
            1 => normals = Some(body.chunks_exact(2).map(|c| [c[0], c[1]]).collect()),
            4 => {
                let json_len = u32::from_le_bytes(body[0..4].try_into().unwrap()) as usize;
                metadata = Some(serde_json::from_slice(&body[4..4 + json_len]).unwrap());
            }
            _ => panic!("unknown extension {id}"),
        }
    }
    let mut it = arrays.into_iter();
    Decoded {
        min_height,
        max_height,
        u: it.next().unwrap(),
        v: it.next().unwrap(),
        h: it.next().unwrap(),
        triangles,
        edges,
        normals,
        metadata,
    }
}

/// An oct-encoded normal, decoded (the inverse of the specification's reference).
fn oct_decode(e: [u8; 2]) -> [f64; 3] {
    let f = |b: u8| f64::from(b) / 255.0 * 2.0 - 1.0;
    let (mut x, mut y) = (f(e[0]), f(e[1]));
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * ox.signum();
        y = (1.0 - ox.abs()) * oy.signum();
    }
    let l = (x * x + y * y + z * z).sqrt();
    [x / l, y / l, z / l]
}

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

    let store = fmrh::Store::open(&file).unwrap();
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
        .map(|(b, l)| GridBlock {
            rect: b.rect(),
            stride: d.stride(b.level),
            grid_width: l.width,
            grid_height: l.height,
            heights: &l.heights,
            error: b.error,
        })
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
        .filter(|e| e.file_name().to_string_lossy().starts_with(".fmrh-tiles"))
        .collect();
    assert!(strays.is_empty());
}
