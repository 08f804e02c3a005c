//! The dataset format is pinned: a three-tile dataset (tiles of different sizes, a shared
//! column, a shared row, a hole, a georeference) is rebuilt from fixed heightfields and must
//! come out byte for byte as `format-spec/vectors/dataset-3-tiles/` holds it, its MANIFEST
//! and its tile files, and `fmrh info --json` on the stored copy must print exactly the
//! stored `info.json`. The manifest's fields are also read at the byte offsets
//! `format-spec/dataset.md` gives, so the spec's tables and the code cannot drift apart.
//! A deliberate change is a format change: bump the manifest version per the spec's policy,
//! then regenerate with `FMRH_BLESS=1 cargo test --release --test golden_dataset`.

mod common;

use std::path::{Path, PathBuf};

use fmrh::dataset::{DatasetOptions, SeamPolicy, TileInput};
use fmrh::format::crc32;
use fmrh::model::{BuildOptions, Thresholds};
use fmrh::store::WriteOptions;
use fmrh::Heightfield;

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("format-spec/vectors/dataset-3-tiles")
}

/// One fixed terrain, 25 x 13, cut into three tiles: A (columns 0..=16, rows 0..=8), B
/// (16..=24, 0..=8: A's last column is its first) and C (0..=16, 8..=12: A's last row is its
/// first); columns 17..=24 of rows 9..=12 are a hole.
fn terrain(x: u32, y: u32) -> f32 {
    if (x, y) == (5, 3) {
        return f32::NAN;
    }
    ((x as f32 * 0.6).sin() * 30.0 + (y as f32 * 0.5).cos() * 20.0 + 100.0).round()
}

fn write_tile(dir: &Path, name: &str, col0: u32, row0: u32, w: u32, h: u32) -> PathBuf {
    let hf = Heightfield::from_fn(w, h, |x, y| terrain(col0 + x, row0 + y)).unwrap();
    let path = dir.join(format!("{name}.f32"));
    std::fs::write(
        &path,
        hf.samples()
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    let json = serde_json::json!({
        "width": w,
        "height": h,
        "f32_file": format!("{name}.f32"),
        "nodata_in_f32": "NaN",
        "units": "metres",
        "spacing_m": [30.0, 30.0],
        "georeference": {
            "crs": "EPSG:4326",
            "origin": [10.0 + f64::from(col0) * 0.001, 45.0 - f64::from(row0) * 0.001],
            "step": [0.001, -0.001]
        }
    });
    std::fs::write(dir.join(format!("{name}.json")), json.to_string()).unwrap();
    path
}

fn build(out: &Path) {
    let inputs_dir = tempfile::tempdir().unwrap();
    let d = inputs_dir.path();
    let inputs = vec![
        TileInput {
            path: write_tile(d, "A", 0, 0, 17, 9),
            at: None,
        },
        TileInput {
            path: write_tile(d, "B", 16, 0, 9, 9),
            at: None,
        },
        TileInput {
            path: write_tile(d, "C", 0, 8, 17, 5),
            at: None,
        },
    ];
    let options = DatasetOptions {
        ingest: Default::default(),
        build: BuildOptions {
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: Default::default(),
        },
        write: WriteOptions {
            page_size: 1024,
            ..WriteOptions::default()
        },
        seam: SeamPolicy::Strict,
        spacing_m: None,
        tile_size: None,
    };
    fmrh::dataset::build(
        &inputs,
        out,
        &options,
        &fmrh::progress::Silent,
        &mut |_, _, _, _| {},
    )
    .unwrap();
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_name() != "info.json")
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

fn info_json(dir: &Path) -> String {
    let out = common::fmrh(&["info", "--json", dir.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The path is the test's; the stored copy names the vector's directory.
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn the_dataset_vector_is_rebuilt_byte_for_byte() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ds");
    build(&out);
    let golden = golden_dir();
    if std::env::var_os("FMRH_BLESS").is_some() {
        let _ = std::fs::remove_dir_all(&golden);
        std::fs::create_dir_all(&golden).unwrap();
        for (name, bytes) in files(&out) {
            std::fs::write(golden.join(name), bytes).unwrap();
        }
        std::fs::write(golden.join("info.json"), info_json(&golden)).unwrap();
    }
    let (built, stored) = (files(&out), files(&golden));
    assert_eq!(
        built.iter().map(|f| &f.0).collect::<Vec<_>>(),
        stored.iter().map(|f| &f.0).collect::<Vec<_>>(),
        "the dataset's files"
    );
    for ((name, a), (_, b)) in built.iter().zip(&stored) {
        assert!(a == b, "{name} differs from format-spec/vectors/dataset-3-tiles/{name} (a format change? see the module docs)");
    }
    let info = std::fs::read_to_string(golden.join("info.json")).unwrap();
    assert_eq!(info_json(&golden), info);
    let v = common::ok_json(&common::fmrh(&[
        "verify",
        "--full",
        "--json",
        golden.to_str().unwrap(),
    ]));
    assert_eq!(v["valid"], true);
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

#[test]
fn the_manifest_fields_lie_where_the_spec_says() {
    let m = std::fs::read(golden_dir().join("MANIFEST")).unwrap();
    const P: usize = 4096;
    // §2: the record in slot 0; slot 1 empty.
    assert_eq!(&m[0..8], b"FMDS\r\n\x1a\n");
    assert_eq!(
        (u16_at(&m, 8), u16_at(&m, 10), u32_at(&m, 12)),
        (1, 1, 4096)
    );
    assert_eq!(u64_at(&m, 16), 1, "txn_id");
    assert_eq!(u32_at(&m, 252), crc32(&m[..252]), "the record's CRC");
    assert!(m[P..P + 256].iter().all(|&b| b == 0), "slot 1 is empty");
    let (file_length, head, head_len, head_crc) = (
        u64_at(&m, 24),
        u64_at(&m, 32) as usize,
        u32_at(&m, 40) as usize,
        u32_at(&m, 44),
    );
    let (tiles, columns, rows) = (u64_at(&m, 48), u64_at(&m, 56), u64_at(&m, 64));
    assert_eq!((tiles, columns, rows), (3, 25, 13));
    assert_eq!((f64_at(&m, 72), f64_at(&m, 80), m[88]), (30.0, 30.0, 0));
    let adjacency_len = u64_at(&m, 96) as usize;
    assert!(
        m[89..96].iter().chain(&m[104..252]).all(|&b| b == 0),
        "reserved"
    );
    assert_eq!(file_length as usize, head + head_len);
    assert_eq!(head_len, 256 + 64, "one tile page");
    assert_eq!(u32_at(&m, 44), head_crc);
    assert_eq!(crc32(&m[head..head + head_len]), head_crc);
    // §3.1: the head.
    let h = &m[head..head + head_len];
    assert_eq!(&h[0..4], b"FMDH");
    assert_eq!((u32_at(h, 4), u64_at(h, 8), u32_at(h, 16)), (1, 3, 1));
    assert_eq!(
        (f64_at(h, 24), f64_at(h, 32), f64_at(h, 40), f64_at(h, 48)),
        (10.0, 45.0, 0.001, -0.001)
    );
    assert_eq!(&h[56..65], b"EPSG:4326");
    // Minor 1: the tiles' vertical datum (synthetic tiles: 1, unknown), then zeros.
    assert_eq!(h[20], 1, "vertical datum");
    assert!(h[21..24].iter().all(|&b| b == 0), "reserved");
    let body = head - adjacency_len - P;
    let e = &h[256..320];
    assert_eq!(u64_at(e, 0) as usize, body, "the tile page opens the body");
    assert_eq!(
        (u32_at(e, 8), u32_at(e, 16), u32_at(e, 20)),
        (3 * 128, 0, 3)
    );
    assert_eq!(
        (u64_at(e, 24), u64_at(e, 32), u64_at(e, 40), u64_at(e, 48)),
        (0, 0, 24, 12)
    );
    let page = &m[body..body + 384];
    assert_eq!(u32_at(e, 12), crc32(page));
    // §3.2, §3.3: the records, in Hilbert order of their first samples: A (0,0), C (0,8),
    // B (16,0) on the 2^32 curve.
    let rec = |i: usize| &page[i * 128..(i + 1) * 128];
    let name = |r: &[u8]| {
        String::from_utf8(r[72..].iter().copied().take_while(|&b| b != 0).collect()).unwrap()
    };
    let placed: Vec<(String, u64, u64, u32, u32)> = (0..3)
        .map(|i| {
            (
                name(rec(i)),
                u64_at(rec(i), 0),
                u64_at(rec(i), 8),
                u32_at(rec(i), 16),
                u32_at(rec(i), 20),
            )
        })
        .collect();
    assert_eq!(
        placed,
        vec![
            ("A.fmrh".into(), 0, 0, 17, 9),
            ("C.fmrh".into(), 0, 8, 17, 5),
            ("B.fmrh".into(), 16, 0, 9, 9),
        ]
    );
    // §3.4: each pin is its file's state.
    for i in 0..3 {
        let r = rec(i);
        let tile = std::fs::read(golden_dir().join(name(r))).unwrap();
        assert_eq!(u64_at(r, 24), u64_at(&tile, 168), "pages_txn");
        assert_eq!(u32_at(r, 32), crc32(&tile[40..200]), "state_crc");
    }
    // §3.5: A stores its east border (B) and its south border (C); C and B store none.
    let area = head - adjacency_len;
    let (a_at, a_len, a_crc) = (
        u64_at(rec(0), 48) as usize,
        u32_at(rec(0), 56) as usize,
        u32_at(rec(0), 60),
    );
    assert!(a_len > 0);
    assert_eq!((u32_at(rec(1), 56), u32_at(rec(2), 56)), (0, 0));
    let blob = &m[area + a_at..area + a_at + a_len];
    assert_eq!(crc32(blob), a_crc);
    assert_eq!(u32_at(blob, 0), 2, "two borders");
    // East border first: B is 16 columns east, shares column 16, along rows 0..=8.
    assert_eq!(
        (
            u64_at(blob, 8) as i64,
            u64_at(blob, 16) as i64,
            blob[24],
            blob[25]
        ),
        (16, 0, 1, 0)
    );
    assert_eq!((u64_at(blob, 32), u64_at(blob, 40)), (0, 8));
}
