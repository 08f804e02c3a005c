//! An orbit-to-ground fly-through on the globe (issue 19): the whole-Earth layer (bundled
//! ETOPO1 at 0.5°) with the two bundled SRTM3 tiles N43E006 and N43E007 above it, flown from
//! 20,000 km straight down towards the highest summit of N43E006 and on to 800 m above it,
//! at tau = 1 px.
//!
//! The path: `FRAMES` frames, the eye's height above the summit falling geometrically from
//! 20,000 km to 800 m, the pitch rising from -90° (straight down) to -20°, the heading 30°
//! (towards north-north-east), and the eye placed so that its line of sight passes through the
//! summit. Every frame is one `Layers::scene`, `Layers::load` and `Layers::skirts`: what a
//! renderer waits for before it can draw the frame with no hole and no crack (the properties
//! `tests/globe_layers.rs` checks on the same data).
//!
//! Per frame: the blocks, the payload bytes the frame draws, and the bytes *new* to it (not
//! drawn in the frame before: what a client keeping the last frame's blocks fetches), and the
//! time to schedule, to load and decode, and to measure the skirts, each the median of
//! `RUNS` passes over the whole path from a warm mapping. The table prints every
//! `FRAMES / 16`-th frame; the summary covers all.
//!
//! **Beside COG** (when `gdal_translate` is installed): the same three grids as COGs (DEFLATE,
//! predictor, 512² tiles, overviews: `benches/common/cog.rs`), each tile's true error
//! measured against its source, and for each frame the tiles a COG reader with fmrh's rule
//! reads: the coarsest whose measured error covers at most tau pixels at its true 3D
//! distance, none wholly below the horizon, none of the base wholly under an SRTM tile. The
//! COG bytes are tile bytes only (the header is read once; fmrh's index pages likewise are
//! not counted); the COG's times are not measured (its tiles are chosen by this harness,
//! not by GDAL).
//!
//! `cargo bench --bench globe_fly` (bundled data only).

#[path = "common/cog.rs"]
mod cog;

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::Instant;

use fmrh::scene::{
    Camera, GlobeFrame, LayeredScene, Layers, LonLatRect, SceneOptions, Terrain, TerrainFrame,
};
use fmrh::{store::Store, Heightfield};

/// Frames on the path.
const FRAMES: usize = 160;
/// Passes over the path; each frame's times are the median.
const RUNS: usize = 5;
/// Heights above the summit at the two ends of the path, metres.
const TOP: f64 = 2.0e7;
const BOTTOM: f64 = 800.0;
const HEADING: f64 = 30.0;
const TAU: f64 = 1.0;

fn bundled(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(rel)
}

/// The camera of frame `i`, looking through the summit at `(lat, lon, z)`.
fn camera(i: usize, lat: f64, lon: f64, z: f64) -> (f64, Camera) {
    let t = i as f64 / (FRAMES - 1) as f64;
    let above = TOP * (BOTTOM / TOP).powf(t);
    let pitch = -90.0 + 70.0 * t;
    // Ground distance back from the summit along the heading (flat to first order: where it
    // is large the pitch is near -90° and the distance small).
    let back = above / (-pitch).to_radians().tan();
    let (h, s) = (HEADING.to_radians(), 6_371_000.0f64);
    let lat_e = lat - (back * h.cos() / s).to_degrees();
    let lon_e = lon - (back * h.sin() / (s * lat.to_radians().cos())).to_degrees();
    let c = Camera::on_globe(lat_e, lon_e, z + above, HEADING, pitch);
    (above, c)
}

/// The highest sample of `field` and where it is: latitude, longitude, height.
fn summit(field: &Heightfield) -> (f64, f64, f64) {
    let w = field.width() as usize;
    let (k, z) = field
        .samples()
        .iter()
        .enumerate()
        .filter(|(_, v)| !v.is_nan())
        .fold(
            (0, f32::NEG_INFINITY),
            |a, (k, &v)| if v > a.1 { (k, v) } else { a },
        );
    let g = field.metadata.georeference.as_ref().expect("georeferenced");
    let frame = GlobeFrame::of(g).expect("geographic");
    let (lon, lat) = frame.lon_lat((k % w) as f64, (k / w) as f64);
    (lat, lon, f64::from(z))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One grid as a COG, with its place on the globe and the footprints above it.
struct CogLayer {
    cog: cog::Cog,
    frame: GlobeFrame,
    above: Vec<LonLatRect>,
}

/// The COG tiles (layer, level, tile) a frame reads, and their largest screen error.
fn cog_frame(layers: &[CogLayer], camera: &Camera) -> (HashSet<(usize, usize, usize)>, f64) {
    let view = camera.view().expect("camera");
    let mut out = HashSet::new();
    let mut worst = 0.0f64;
    for (i, l) in layers.iter().enumerate() {
        let (tiles, px) = cog::cog_scene(&l.cog, TerrainFrame::Globe(l.frame), &view, TAU);
        for (lv, t) in tiles {
            let rect = cog::tile_rect(&l.cog, lv, t);
            let r = LonLatRect::of_samples(&l.frame, &rect);
            let cuts: Vec<LonLatRect> = l.above.iter().flat_map(|f| r.clips(f)).collect();
            if !cuts.is_empty() && r.covered_by(&cuts) {
                continue;
            }
            out.insert((i, lv, t));
        }
        worst = worst.max(px);
    }
    (out, worst)
}

fn cog_bytes(layers: &[CogLayer], tiles: &HashSet<(usize, usize, usize)>) -> u64 {
    tiles
        .iter()
        .map(|&(i, lv, t)| layers[i].cog.levels[lv].counts[t])
        .sum()
}

/// One frame's figures.
#[derive(Default, Clone)]
struct Row {
    above: f64,
    blocks: [u64; 3],
    bytes: u64,
    new_bytes: u64,
    max_px: f64,
    skirted: usize,
    schedule: Vec<f64>,
    load: Vec<f64>,
    skirts: Vec<f64>,
    cog_tiles: usize,
    cog_bytes: u64,
    cog_new: u64,
    cog_px: f64,
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sources = [
        "etopo1-pybacktrack/etopo1-bed-0.5deg.tif",
        "srtm3-pyhgtmap/N43E006.hgt.gz",
        "srtm3-pyhgtmap/N43E007.hgt.gz",
    ];
    let mut fields = Vec::new();
    let mut stores = Vec::new();
    for (k, rel) in sources.iter().enumerate() {
        let field = fmrh::ingest::load(&bundled(rel), &fmrh::ingest::IngestOptions::default())
            .expect("bundled DEM");
        let file = dir.path().join(format!("layer{k}.fmrh"));
        fmrh::create(&file, field.clone(), &fmrh::CreateOptions::default()).expect("build");
        println!(
            "layer {k}: {rel}, {} x {}, container {} bytes",
            field.width(),
            field.height(),
            std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0)
        );
        stores.push(Store::open(&file).expect("open"));
        fields.push(field);
    }
    let terrains = stores
        .iter()
        .map(|s| Terrain::on_globe(s).expect("geographic"))
        .collect();
    let layers = Layers::new(terrains).expect("layers");
    let (lat, lon, z) = summit(&fields[1]);
    println!(
        "summit of N43E006: {lat:.4} N, {lon:.4} E, {z:.0} m; {FRAMES} frames from {:.0} km to \
         {BOTTOM:.0} m above it, tau {TAU} px, times the median of {RUNS} passes\n",
        TOP / 1000.0
    );

    // COGs of the same grids, when GDAL is here.
    let footprints: Vec<LonLatRect> = layers.layers().iter().map(|l| l.footprint).collect();
    let cogs: Option<Vec<CogLayer>> = fields
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let c = cog::make_cog(dir.path(), &format!("cog{k}"), f)?;
            Some(CogLayer {
                cog: c,
                frame: layers.layers()[k].frame,
                above: footprints[k + 1..].to_vec(),
            })
        })
        .collect();
    if cogs.is_none() {
        println!("(no gdal_translate: the COG columns are left out)\n");
    }

    let options = SceneOptions::new(TAU);
    let mut rows = vec![Row::default(); FRAMES];
    for run in 0..RUNS {
        let mut held: HashSet<(usize, u64)> = HashSet::new();
        let mut cog_held = HashSet::new();
        for (i, row) in rows.iter_mut().enumerate() {
            let (above, cam) = camera(i, lat, lon, z);
            let t0 = Instant::now();
            let scene: LayeredScene = layers.scene(&cam, &options).expect("scene");
            let t1 = Instant::now();
            let loaded = layers.load(&scene).expect("load");
            let t2 = Instant::now();
            let skirts = layers.skirts(&scene, &loaded).expect("skirts");
            let t3 = Instant::now();
            row.schedule.push((t1 - t0).as_secs_f64());
            row.load.push((t2 - t1).as_secs_f64());
            row.skirts.push((t3 - t2).as_secs_f64());
            if run > 0 {
                continue;
            }
            // The figures that do not change from run to run, once.
            let ids: HashSet<(usize, u64)> = scene
                .blocks
                .iter()
                .map(|b| (b.layer, b.block.payload.offset))
                .collect();
            row.above = above;
            for b in &scene.blocks {
                row.blocks[b.layer] += 1;
            }
            row.bytes = scene.stats.bytes + loaded.iter().map(|l| l.parent_bytes).sum::<u64>();
            row.new_bytes = scene
                .blocks
                .iter()
                .zip(&loaded)
                .filter(|(b, _)| !held.contains(&(b.layer, b.block.payload.offset)))
                .map(|(b, l)| u64::from(b.block.payload.len) + l.parent_bytes)
                .sum();
            held = ids;
            row.max_px = scene.stats.max_screen_error;
            row.skirted = skirts.iter().filter(|&&d| d > 0.0).count();
            if let Some(cogs) = &cogs {
                let (tiles, px) = cog_frame(cogs, &cam);
                row.cog_tiles = tiles.len();
                row.cog_bytes = cog_bytes(cogs, &tiles);
                row.cog_new = cog_bytes(cogs, &tiles.difference(&cog_held).copied().collect());
                row.cog_px = px;
                cog_held = tiles;
            }
        }
    }

    println!(
        "| frame | above summit | blocks (ETOPO/E006/E007) | KB drawn | KB new | max px | skirted | schedule µs | load µs | skirts µs | frame ms | COG tiles | COG KB | COG KB new | COG px |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let step = (FRAMES / 16).max(1);
    let mut frame_ms = Vec::new();
    for (i, r) in rows.iter_mut().enumerate() {
        let (s, l, k) = (
            median(&mut r.schedule),
            median(&mut r.load),
            median(&mut r.skirts),
        );
        frame_ms.push((s + l + k) * 1e3);
        if i % step == 0 || i == FRAMES - 1 {
            let above = if r.above >= 1e4 {
                format!("{:.0} km", r.above / 1e3)
            } else {
                format!("{:.0} m", r.above)
            };
            let cog = if cogs.is_some() {
                format!(
                    "{} | {:.1} | {:.1} | {:.2}",
                    r.cog_tiles,
                    r.cog_bytes as f64 / 1024.0,
                    r.cog_new as f64 / 1024.0,
                    r.cog_px
                )
            } else {
                "- | - | - | -".into()
            };
            println!(
                "| {i} | {above} | {}/{}/{} | {:.1} | {:.1} | {:.2} | {} | {:.0} | {:.0} | {:.0} | {:.2} | {cog} |",
                r.blocks[0],
                r.blocks[1],
                r.blocks[2],
                r.bytes as f64 / 1024.0,
                r.new_bytes as f64 / 1024.0,
                r.max_px,
                r.skirted,
                s * 1e6,
                l * 1e6,
                k * 1e6,
                (s + l + k) * 1e3,
            );
        }
    }
    let total = |f: &dyn Fn(&Row) -> u64| rows.iter().map(f).sum::<u64>();
    let (drawn, fetched) = (total(&|r| r.bytes), total(&|r| r.new_bytes));
    let mut sorted = frame_ms.clone();
    sorted.sort_by(f64::total_cmp);
    let pct = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
    println!(
        "\nfmrh, {FRAMES} frames: frame time median {:.2} ms, p95 {:.2} ms, max {:.2} ms; \
         {:.0} KB drawn in all, {:.0} KB fetched keeping the last frame's blocks; \
         max screen error {:.2} px",
        pct(0.5),
        pct(0.95),
        pct(1.0),
        drawn as f64 / 1024.0,
        fetched as f64 / 1024.0,
        rows.iter().map(|r| r.max_px).fold(0.0, f64::max)
    );
    if cogs.is_some() {
        let (cd, cf) = (total(&|r| r.cog_bytes), total(&|r| r.cog_new));
        println!(
            "COG,  {FRAMES} frames: {:.0} KB drawn in all, {:.0} KB fetched keeping the last \
             frame's tiles; max screen error {:.2} px; fmrh/COG bytes fetched {:.2}",
            cd as f64 / 1024.0,
            cf as f64 / 1024.0,
            rows.iter().map(|r| r.cog_px).fold(0.0, f64::max),
            fetched as f64 / cf.max(1) as f64
        );
    }
}
