//! Planet scale, by simulation (issue 16). SRTM1 covers the land in about 14,300 1° tiles of
//! 3601² samples (about 1.9 × 10¹¹ samples). This writes a manifest of that many tiles,
//! placed as SRTM1's are (columns `(lon + 180) · 3600`, rows `(60 - lat - 1) · 3600`, sharing
//! their edges) on a procedural land mask, and measures what grows with the tile count:
//! the manifest's size, opening it (time and bytes), and the metadata a scene spanning 4
//! tiles reads. Four tiles are real containers (3601², procedural hills) where that scene
//! looks; the other records are stand-ins whose files do not exist, which is what the
//! measurement needs: a scene (here with a window around the corner of the four) opens only
//! the tiles it meets, so the stand-ins are never
//! opened (the dataset's validator would report them missing). Written to a temporary
//! directory, never committed.

use std::time::Instant;

use glam::DVec3;

use fmrh::dataset::manifest::{write_state, Contents, MANIFEST_NAME};
use fmrh::dataset::Dataset;
use fmrh::format::manifest::{StatePin, TileRecord, SEAM_STRICT};
use fmrh::heightfield::Georeference;
use fmrh::model::{BuildOptions, Model, SampleRect};
use fmrh::scene::{Camera, Mode, SceneOptions};
use fmrh::store::{write_file, Store, WriteOptions};

const SIDE: u64 = 3600;

/// A smooth procedural land mask on the 1° grid: about a third of the cells between 56° S
/// and 60° N are land, in continent-sized blobs.
fn land(lon: i32, lat: i32) -> bool {
    let (x, y) = (f64::from(lon).to_radians(), f64::from(lat).to_radians());
    let v = (2.0 * x).sin() * (3.0 * y + 0.5).cos()
        + 0.6 * (5.0 * x + 1.3).sin() * (4.0 * y).sin()
        + 0.3 * (11.0 * x + 2.0 * y).cos();
    v > 0.25
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let cells: Vec<(i32, i32)> = (-56..60)
        .flat_map(|lat| (-180..180).map(move |lon| (lon, lat)))
        .filter(|&(lon, lat)| land(lon, lat))
        .collect();
    // The scene's four tiles: the first 2 x 2 block of land cells.
    let corner = *cells
        .iter()
        .find(|&&(lon, lat)| {
            lat >= 30
                && [(1, 0), (0, -1), (1, -1)]
                    .iter()
                    .all(|(a, b)| land(lon + a, lat + b))
        })
        .expect("a 2 x 2 block of land");
    let real: Vec<(i32, i32)> = vec![
        corner,
        (corner.0 + 1, corner.1),
        (corner.0, corner.1 - 1),
        (corner.0 + 1, corner.1 - 1),
    ];
    let place = |lon: i32, lat: i32| ((lon + 180) as u64 * SIDE, (59 - lat) as u64 * SIDE);
    let t0 = Instant::now();
    let mut records = Vec::with_capacity(cells.len());
    for &(lon, lat) in &cells {
        let (c, r) = place(lon, lat);
        let rect = SampleRect {
            col0: c,
            row0: r,
            col1: c + SIDE,
            row1: r + SIDE,
        };
        let name = format!(
            "{}{:02}{}{:03}.fmrh",
            if lat >= 0 { 'N' } else { 'S' },
            lat.abs(),
            if lon >= 0 { 'E' } else { 'W' },
            lon.abs()
        );
        if real.contains(&(lon, lat)) {
            let (lon0, lat0) = (f64::from(lon), f64::from(lat));
            let hf = fmrh::Heightfield::from_fn(3601, 3601, |x, y| {
                let (gx, gy) = (
                    lon0 + f64::from(x) / 3600.0,
                    lat0 + 1.0 - f64::from(y) / 3600.0,
                );
                (800.0
                    + 600.0 * (gx * 7.0).sin() * (gy * 5.0).cos()
                    + 150.0 * (gx * 41.0 + gy * 37.0).sin()) as f32
            })
            .unwrap();
            let model = Model::build(hf, &BuildOptions::default()).unwrap();
            let meta = fmrh::heightfield::Metadata {
                spacing_m: Some([30.0, 30.0]),
                ..Default::default()
            };
            write_file(
                &model,
                &meta,
                &dir.path().join(&name),
                &WriteOptions::default(),
                false,
            )
            .unwrap();
            let store = Store::open(&dir.path().join(&name)).unwrap();
            let root = store.node(0).unwrap();
            records.push(TileRecord::new(
                &name,
                rect,
                store.pin(),
                (root.min_height, root.max_height),
            ));
        } else {
            records.push(TileRecord::new(
                &name,
                rect,
                StatePin {
                    pages_txn: 1,
                    state_crc: 0,
                },
                (0.0, 4000.0),
            ));
        }
    }
    let built = t0.elapsed().as_secs_f64();
    let path = dir.path().join(MANIFEST_NAME);
    std::fs::File::create(&path).unwrap();
    let t1 = Instant::now();
    {
        let io = fmrh::store::io::FileIo::open(&path).unwrap();
        write_state(
            &io,
            None,
            &Contents {
                tiles: records,
                spacing_m: Some([30.0, 30.0]),
                georeference: Some(Georeference {
                    crs: Some("EPSG:4326".into()),
                    origin: [-180.0, 60.0],
                    step: [1.0 / 3600.0, -1.0 / 3600.0],
                }),
                seam: SEAM_STRICT,
                vertical_datum: Some(fmrh::types::VerticalDatum::Egm96),
                // The stand-ins have no edge lists to merge: no tables (what the tables
                // cost is measured on the real 64-tile mosaic, benches/dataset_scale.rs).
                adjacency: Default::default(),
            },
        )
        .unwrap();
    }
    let write_ms = t1.elapsed().as_secs_f64() * 1e3;
    let size = std::fs::metadata(&path).unwrap().len();
    let ds = Dataset::open(dir.path()).unwrap();
    let grid = ds.grid();
    println!(
        "planet simulation: {} tiles of 3601^2 ({:.3e} samples) in a {} x {} grid; 4 real tiles built in {built:.1} s",
        ds.tile_count(),
        ds.tile_count() as f64 * 3601.0 * 3601.0,
        grid.col1 + 1,
        grid.row1 + 1
    );
    let mut times = Vec::new();
    for _ in 0..200 {
        let t = Instant::now();
        let d = Dataset::open(dir.path()).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e6);
        assert_eq!(d.tiles_opened(), 0);
    }
    let open = ds.open_reads();
    println!("| measure | value |");
    println!("|---|---|");
    println!("| manifest file | {size} bytes (one state; {write_ms:.1} ms to write and sync) |");
    println!(
        "| bytes per tile | {:.1} |",
        size as f64 / ds.tile_count() as f64
    );
    println!(
        "| tile pages | {} (32 records each) |",
        ds.state().head.pages.len()
    );
    println!(
        "| open: reads, bytes | {}, {} |",
        open.reads(),
        open.bytes()
    );
    println!("| open: median time | {:.1} us |", median(times));
    // A scene over the corner where the four real tiles meet, from 3 km up.
    let (c, r) = {
        let (lon, lat) = corner;
        ((lon + 181) as u64 * SIDE, (60 - lat) as u64 * SIDE)
    };
    let (x, y) = (c as f64 * 30.0, r as f64 * 30.0);
    let cam = Camera::looking_at(
        DVec3::new(x - 4000.0, y - 4000.0, 3000.0),
        DVec3::new(x + 2000.0, y + 2000.0, 0.0),
    );
    let d = Dataset::open(dir.path()).unwrap();
    let t = Instant::now();
    // The window: 2,000 x 2,000 samples centred on the corner (a frustum with no far plane
    // would also meet stand-ins farther along the view).
    let window = SampleRect {
        col0: c - 1000,
        row0: r - 1000,
        col1: c + 1000,
        row1: r + 1000,
    };
    let scene = d
        .scene(
            &cam,
            &SceneOptions {
                tau: 1.0,
                mode: Mode::View,
                window: Some(window),
                gap: 4,
            },
            None,
        )
        .unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let manifest = d.manifest_reads();
    let tiles_open: u64 = scene
        .tiles
        .iter()
        .map(|p| {
            d.open_tile(&d.tile(p.tile).unwrap())
                .unwrap()
                .open_reads()
                .bytes()
        })
        .sum();
    let schedule: u64 = scene.tiles.iter().map(|p| p.reads.bytes()).sum();
    println!(
        "| scene over 4 tiles: tiles met, opened | {}, {} |",
        scene.tiles.len(),
        d.tiles_opened()
    );
    println!(
        "| scene: manifest tile pages read | {} reads, {} bytes |",
        manifest.reads(),
        manifest.bytes()
    );
    println!("| scene: tile opens (slots, header, directory) | {tiles_open} bytes |");
    println!("| scene: tile index and node pages | {schedule} bytes |");
    println!(
        "| scene: metadata in all, with the manifest's open | {} bytes |",
        open.bytes() + manifest.bytes() + tiles_open + schedule
    );
    println!(
        "| scene: blocks, payload bytes, first-call time | {}, {}, {ms:.2} ms |",
        scene.stats.blocks, scene.stats.bytes
    );
    assert_eq!(scene.tiles.len(), 4, "the scene spans the four real tiles");
}
