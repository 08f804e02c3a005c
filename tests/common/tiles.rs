//! Datasets for tests: a field cut into tiles that share their edge rows and columns (as
//! SRTM's do), written as `.f32` + `.json` tiles with a layout, and built with the library.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use fmrh::dataset::{DatasetOptions, SeamPolicy, TileInput};
use fmrh::model::{BuildOptions, SampleRect, Thresholds};
use fmrh::store::WriteOptions;
use fmrh::Heightfield;

/// Writes `hf` as `dir/name.f32` and its sidecar (with `spacing` metres between samples).
pub fn write_f32(dir: &Path, name: &str, hf: &Heightfield, spacing: f64) -> PathBuf {
    let f32_path = dir.join(format!("{name}.f32"));
    let bytes: Vec<u8> = hf.samples().iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&f32_path, bytes).unwrap();
    let json = serde_json::json!({
        "width": hf.width(),
        "height": hf.height(),
        "f32_file": format!("{name}.f32"),
        "nodata_in_f32": "NaN",
        "spacing_m": [spacing, spacing],
    });
    std::fs::write(dir.join(format!("{name}.json")), json.to_string()).unwrap();
    f32_path
}

/// The samples of `field` in `rect`.
pub fn crop(field: &Heightfield, rect: &SampleRect) -> Heightfield {
    let w = field.width() as u64;
    Heightfield::from_fn(
        (rect.col1 - rect.col0 + 1) as u32,
        (rect.row1 - rect.row0 + 1) as u32,
        |x, y| {
            field.samples()[((rect.row0 + u64::from(y)) * w + rect.col0 + u64::from(x)) as usize]
        },
    )
    .unwrap()
}

/// The tiles of `field` cut at columns `cols` and rows `rows` (each cut a shared line, so
/// neighbours overlap by it), with `holes` (indexes in row-major tile order) left out.
pub fn split(field: &Heightfield, cols: &[u64], rows: &[u64], holes: &[usize]) -> Vec<SampleRect> {
    let edges = |cuts: &[u64], n: u64| {
        let mut e = vec![0];
        e.extend_from_slice(cuts);
        e.push(n - 1);
        e
    };
    let (cx, cy) = (
        edges(cols, u64::from(field.width())),
        edges(rows, u64::from(field.height())),
    );
    let mut out = Vec::new();
    let mut i = 0;
    for ry in cy.windows(2) {
        for rx in cx.windows(2) {
            if !holes.contains(&i) {
                out.push(SampleRect {
                    col0: rx[0],
                    row0: ry[0],
                    col1: rx[1],
                    row1: ry[1],
                });
            }
            i += 1;
        }
    }
    out
}

/// Options for small test datasets: blocks of 9, `thresholds` (or the ladder), 1 KiB pages.
pub fn options(thresholds: Option<Vec<f64>>) -> DatasetOptions {
    DatasetOptions {
        ingest: fmrh::ingest::IngestOptions::default(),
        build: BuildOptions {
            block_size: 9,
            thresholds: thresholds.map_or(Thresholds::Ladder, Thresholds::Explicit),
            precision: None,
        },
        write: WriteOptions {
            page_size: 1024,
            ..WriteOptions::default()
        },
        seam: SeamPolicy::Strict,
        spacing_m: None,
    }
}

/// Writes the tiles `rects` of `field` into `dir/tiles` and builds the dataset `dir/ds`
/// from them by a layout.
pub fn build(
    dir: &Path,
    field: &Heightfield,
    rects: &[SampleRect],
    options: &DatasetOptions,
) -> PathBuf {
    let tiles = dir.join("tiles");
    std::fs::create_dir_all(&tiles).unwrap();
    let inputs: Vec<TileInput> = rects
        .iter()
        .enumerate()
        .map(|(i, r)| TileInput {
            path: write_f32(&tiles, &format!("t{i}"), &crop(field, r), 10.0),
            at: Some((r.col0, r.row0)),
        })
        .collect();
    let out = dir.join("ds");
    fmrh::dataset::build(
        &inputs,
        &out,
        options,
        &fmrh::progress::Silent,
        &mut |_, _, _, _| {},
    )
    .unwrap();
    out
}
