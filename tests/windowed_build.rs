//! A raster larger than the memory budget is still built (issue 39, point 2): read in windows
//! and built into a dataset of tiles, in the memory of one tile. The properties checked:
//!
//! * **Windows are the whole read, cut.** For random rasters as `.f32` pairs, tiled and
//!   striped GeoTIFFs, in every orientation a file can store (south-up, east-to-west), any
//!   window [`WindowedRaster`] reads holds exactly the samples, bit for bit, and the
//!   georeference that a whole [`load`] gives that part of the raster.
//! * **A raster past the budget is built within it.** A 4,100 × 3,100 `f32` GeoTIFF (51 MB of
//!   samples) under `--max-memory 48M`: `fmrh build` refuses it and names the way out; `fmrh
//!   dataset build` cuts it into tiles, peaks below the budget (the process's own `VmHWM`),
//!   and the dataset verifies and extracts to every sample the file holds.
//! * **`--tile-size` cuts every larger input**, placed by a layout or by georeference, and
//!   the tiles put back together are the input.

mod common;
#[path = "common/tiff.rs"]
mod tiff;

use fmrh::ingest::{load, IngestOptions, WindowedRaster};
use fmrh::model::SampleRect;
use proptest::prelude::*;
use tiff::Value;

/// How a generated raster is stored.
#[derive(Clone, Copy, Debug)]
enum Stored {
    F32,
    Tiled(u32),
    Striped(u32),
}

/// Writes `samples` (row-major as stored, `w × h`) in the form `stored`, its steps' signs
/// `flip` (east-to-west columns, south-up rows), under `dir`; returns the path to read.
fn write(
    dir: &std::path::Path,
    stored: Stored,
    w: u32,
    h: u32,
    samples: &[f32],
    flip: [bool; 2],
) -> std::path::PathBuf {
    let step = [
        if flip[0] { -10.0 } else { 10.0 },
        if flip[1] { 10.0 } else { -10.0 },
    ];
    let origin = [1000.0, 9000.0];
    match stored {
        Stored::F32 => {
            let path = dir.join("r.f32");
            let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
            std::fs::write(&path, bytes).unwrap();
            let sidecar = serde_json::json!({
                "width": w, "height": h,
                "georeference": {"crs": "EPSG:32610", "origin": origin, "step": step},
            });
            std::fs::write(dir.join("r.json"), sidecar.to_string()).unwrap();
            path
        }
        Stored::Tiled(_) | Stored::Striped(_) => {
            // ModelPixelScale is (step x, -step y); the tie point is the corner of pixel 0.
            let scale = vec![step[0], -step[1], 0.0];
            let tie = vec![
                0.0,
                0.0,
                0.0,
                origin[0] - step[0] / 2.0,
                origin[1] - step[1] / 2.0,
                0.0,
            ];
            let mut tags = vec![
                (256, Value::Long(vec![w])),
                (257, Value::Long(vec![h])),
                (258, Value::Short(vec![32])),
                (259, Value::Short(vec![1])),
                (262, Value::Short(vec![1])),
                (277, Value::Short(vec![1])),
                (339, Value::Short(vec![3])),
                (33550, Value::Double(scale)),
                (33922, Value::Double(tie)),
            ];
            let at = |x: u32, y: u32| -> f32 {
                if x < w && y < h {
                    samples[(y * w + x) as usize]
                } else {
                    -1.0 // padding of an edge tile
                }
            };
            let bytes = match stored {
                Stored::Tiled(t) => {
                    let mut chunks = Vec::new();
                    for ty in 0..h.div_ceil(t) {
                        for tx in 0..w.div_ceil(t) {
                            let chunk: Vec<u8> = (0..t * t)
                                .flat_map(|i| at(tx * t + i % t, ty * t + i / t).to_le_bytes())
                                .collect();
                            chunks.push(chunk);
                        }
                    }
                    let mut data = Vec::new();
                    let (mut offsets, mut counts) = (Vec::new(), Vec::new());
                    for c in &chunks {
                        offsets.push(8 + data.len() as u32);
                        counts.push(c.len() as u32);
                        data.extend_from_slice(c);
                    }
                    tags.push((322, Value::Long(vec![t])));
                    tags.push((323, Value::Long(vec![t])));
                    tags.push((324, Value::Long(offsets)));
                    tags.push((325, Value::Long(counts)));
                    tiff::tiff_raw(tags, &data)
                }
                Stored::Striped(rows) => {
                    let strips: Vec<Vec<u8>> = (0..h.div_ceil(rows))
                        .map(|s| {
                            let (y0, y1) = (s * rows, ((s + 1) * rows).min(h));
                            (y0 * w..y1 * w)
                                .flat_map(|i| samples[i as usize].to_le_bytes())
                                .collect()
                        })
                        .collect();
                    tags.push((278, Value::Long(vec![rows])));
                    tiff::tiff(tags, &strips)
                }
                Stored::F32 => unreachable!(),
            };
            let path = dir.join("r.tif");
            std::fs::write(&path, bytes).unwrap();
            path
        }
    }
}

fn stored() -> impl Strategy<Value = Stored> {
    prop_oneof![
        Just(Stored::F32),
        prop_oneof![Just(16u32), Just(32)].prop_map(Stored::Tiled),
        (1u32..9).prop_map(Stored::Striped),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn windows_are_the_whole_read_cut(
        (w, h, samples) in (1u32..60, 1u32..60).prop_flat_map(|(w, h)| {
            let n = (w * h) as usize;
            (Just(w), Just(h), proptest::collection::vec(
                prop_oneof![9 => (-500i32..5000).prop_map(|v| v as f32 * 0.25), 1 => Just(f32::NAN)],
                n,
            ))
        }),
        stored in stored(),
        flip in any::<[bool; 2]>(),
        corners in any::<[u32; 4]>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), stored, w, h, &samples, flip);
        let whole = load(&path, &IngestOptions::default()).unwrap();
        let mut raster = WindowedRaster::open(&path, &IngestOptions::default()).unwrap();
        prop_assert_eq!((raster.width(), raster.height()), (u64::from(w), u64::from(h)));
        let (a, b) = (corners[0] % w, corners[1] % w);
        let (c, d) = (corners[2] % h, corners[3] % h);
        let window = SampleRect {
            col0: u64::from(a.min(b)),
            row0: u64::from(c.min(d)),
            col1: u64::from(a.max(b)),
            row1: u64::from(c.max(d)),
        };
        let part = raster.read(window).unwrap();
        let ww = window.col1 - window.col0 + 1;
        prop_assert_eq!(u64::from(part.width()), ww);
        for (i, v) in part.samples().iter().enumerate() {
            let (x, y) = (window.col0 + i as u64 % ww, window.row0 + i as u64 / ww);
            let want = whole.samples()[(y * u64::from(w) + x) as usize];
            prop_assert_eq!(v.to_bits(), want.to_bits(), "sample ({}, {})", x, y);
        }
        let (g, gw) = (
            part.metadata.georeference.clone().unwrap(),
            whole.metadata.georeference.clone().unwrap(),
        );
        prop_assert_eq!(g.step, gw.step);
        prop_assert_eq!(g.origin[0], gw.origin[0] + window.col0 as f64 * gw.step[0]);
        prop_assert_eq!(g.origin[1], gw.origin[1] + window.row0 as f64 * gw.step[1]);
        prop_assert_eq!(part.metadata.spacing_m, whole.metadata.spacing_m);
    }
}

/// Every sample of the dataset `ds`, as `fmrh extract` writes them (into `scratch`).
fn extracted(ds: &std::path::Path, scratch: &std::path::Path) -> Vec<f32> {
    let f32_out = scratch.join("extracted.f32");
    let out = common::fmrh(&[
        "extract",
        "-q",
        ds.to_str().unwrap(),
        "-o",
        f32_out.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    std::fs::read(&f32_out)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

#[test]
fn a_raster_larger_than_the_budget_is_built_in_windows_within_it() {
    const W: u32 = 4100;
    const H: u32 = 3100;
    const TILE: u32 = 256;
    const BUDGET: u64 = 48 << 20;
    let dir = tempfile::tempdir().unwrap();
    let tif = dir.path().join("big.tif");
    std::fs::write(&tif, tiff::packbits_tiled(W, H, TILE)).unwrap();
    let tif_s = tif.to_str().unwrap();
    // The samples alone are more than the budget: no whole read can fit it.
    assert!(u64::from(W) * u64::from(H) * 4 > BUDGET);

    // `fmrh build` holds the whole grid: refused, with the way out.
    let whole = dir.path().join("whole.fmrh");
    let out = common::fmrh(&[
        "build",
        tif_s,
        "-o",
        whole.to_str().unwrap(),
        "--max-memory",
        "48M",
    ]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("fmrh dataset build"), "{err}");
    assert!(!whole.exists());

    let ds = dir.path().join("ds");
    let ds_s = ds.to_str().unwrap();
    let report = common::ok_json(&common::fmrh(&[
        "dataset",
        "build",
        "-q",
        "--json",
        "-o",
        ds_s,
        tif_s,
        "--max-memory",
        "48M",
    ]));
    let tiles = report["tiles"].as_array().unwrap();
    // 2,049² samples a tile fit 48 MiB (6 bytes a sample); 4,100 x 3,100 takes 3 x 2.
    assert_eq!(tiles.len(), 6, "{report}");
    assert_eq!(
        (report["columns"].as_u64(), report["rows"].as_u64()),
        (Some(4100), Some(3100))
    );
    let peak = report["peak_memory_bytes"]
        .as_u64()
        .expect("Linux reports VmHWM");
    assert!(
        peak <= BUDGET,
        "peak {peak} bytes over the {BUDGET}-byte budget"
    );

    let verify = common::fmrh(&["verify", "--full", ds_s]);
    assert!(verify.status.success(), "{verify:?}");
    let samples = extracted(&ds, dir.path());
    assert_eq!(samples.len(), (W * H) as usize);
    let across = W.div_ceil(TILE);
    for (i, v) in samples.iter().enumerate() {
        let (x, y) = (i as u32 % W, i as u32 / W);
        let want = tiff::tile_value((y / TILE) * across + x / TILE);
        assert_eq!(v.to_bits(), want.to_bits(), "sample ({x}, {y})");
    }
    // The dataset's georeference is the raster's: the centre of sample (0, 0).
    let info = common::ok_json(&common::fmrh(&["info", "--json", ds_s]));
    let text = info.to_string();
    assert!(
        text.contains("500005") && text.contains("5299995"),
        "{text}"
    );
}

/// A smooth synthetic grid with a void, as a north-up `.f32` pair at `dir/name`.
fn f32_pair(dir: &std::path::Path, name: &str, w: u32, h: u32, seed: f32) -> Vec<f32> {
    let samples: Vec<f32> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            if (x - 40.0).abs() < 3.0 && (y - 30.0).abs() < 2.0 {
                f32::NAN
            } else {
                ((x * 0.07 + seed).sin() * 300.0 + y * 1.5).round() * 0.5
            }
        })
        .collect();
    let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.join(format!("{name}.f32")), bytes).unwrap();
    std::fs::write(
        dir.join(format!("{name}.json")),
        serde_json::json!({"width": w, "height": h, "spacing_m": [5.0, 5.0]}).to_string(),
    )
    .unwrap();
    samples
}

#[test]
fn tile_size_cuts_every_larger_input_placed_by_a_layout() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two inputs side by side sharing column 250 (the west one's last), each cut.
    let west = f32_pair(d, "west", 251, 180, 0.0);
    let mut east = f32_pair(d, "east", 120, 180, 1.0);
    for y in 0..180 {
        east[y * 120] = west[y * 251 + 250];
    }
    let bytes: Vec<u8> = east.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(d.join("east.f32"), bytes).unwrap();
    std::fs::write(d.join("layout.csv"), "west.f32,0,0\neast.f32,250,0\n").unwrap();
    let ds = d.join("ds");
    let ds_s = ds.to_str().unwrap();
    let layout = d.join("layout.csv");
    let report = common::ok_json(&common::fmrh(&[
        "dataset",
        "build",
        "-q",
        "--json",
        "-o",
        ds_s,
        "--layout",
        layout.to_str().unwrap(),
        "--tile-size",
        "100",
    ]));
    // west: 251 columns in 3 windows (250 steps of at most 99), 180 rows in 2; east: 120
    // columns in 2.
    assert_eq!(
        report["tiles"].as_array().unwrap().len(),
        3 * 2 + 2 * 2,
        "{report}"
    );
    for t in report["tiles"].as_array().unwrap() {
        let r = &t["rect"];
        let w = r["col1"].as_u64().unwrap() - r["col0"].as_u64().unwrap() + 1;
        let h = r["row1"].as_u64().unwrap() - r["row0"].as_u64().unwrap() + 1;
        assert!(w <= 100 && h <= 100, "{t}");
    }
    let got = extracted(&ds, d);
    assert_eq!(got.len(), 370 * 180);
    for y in 0..180 {
        for x in 0..370 {
            let want = if x <= 250 {
                west[y * 251 + x]
            } else {
                east[y * 120 + x - 250]
            };
            let v = got[y * 370 + x];
            assert_eq!(v.to_bits(), want.to_bits(), "sample ({x}, {y})");
        }
    }
    let verify = common::fmrh(&["verify", "--full", ds_s]);
    assert!(verify.status.success(), "{verify:?}");

    // A tile must share an edge with its neighbour: 1 is refused as a bad argument.
    let out = common::fmrh(&[
        "dataset",
        "build",
        "-o",
        d.join("ds1").to_str().unwrap(),
        "--layout",
        layout.to_str().unwrap(),
        "--tile-size",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(!d.join("ds1").exists());
}

#[test]
fn tile_size_cuts_a_georeferenced_input_placed_by_its_georeference() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let samples: Vec<f32> = (0..300 * 200u32)
        .map(|i| ((i % 300) as f32 * 0.5 + (i / 300) as f32).round())
        .collect();
    // South-up on disk: the windows are read from the mirrored rows.
    let path = write(d, Stored::Tiled(32), 300, 200, &samples, [false, true]);
    let whole = load(&path, &IngestOptions::default()).unwrap();
    let ds = d.join("ds");
    let report = common::ok_json(&common::fmrh(&[
        "dataset",
        "build",
        "-q",
        "--json",
        "-o",
        ds.to_str().unwrap(),
        path.to_str().unwrap(),
        "--tile-size",
        "129",
    ]));
    assert_eq!(report["tiles"].as_array().unwrap().len(), 3 * 2, "{report}");
    let got = extracted(&ds, d);
    assert_eq!(got.len(), whole.samples().len());
    assert!(got
        .iter()
        .zip(whole.samples())
        .all(|(a, b)| a.to_bits() == b.to_bits()));
}
