//! Bytes per scene against a Cloud-Optimized GeoTIFF, at equal error: the same cameras and
//! tolerances answered by fmrh (view-dependent scene, its blocks loaded and decoded) and by
//! a COG reader that knows every tile's true error (issue 15's yardstick).
//!
//! **The COG** is made the standard way, from the same samples fmrh stores:
//! `gdal_translate -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2|3 -co OVERVIEWS=AUTO` (Int16
//! for integer sources, as a GIS user would keep them). GDAL is only run here, never linked.
//!
//! **The COG reader** (written here, with the `tiff` crate): for every tile of every level
//! (the full resolution and each overview) it measures, once, the tile's true error: the
//! largest `|source - bilinear(tile)|` over the valid source samples of the tile's
//! footprint, the tile sampled on its own (pixel-is-area, edges clamped to the tile, as a
//! tile-at-a-time renderer draws it). A scene is then chosen as fmrh chooses one: from the
//! coarsest level down, a tile that meets the frustum is kept when its error covers at most
//! `tau` pixels at its distance (the same `View::screen_error`, the same boxes: footprint by
//! the source's height range), else replaced by the finer level's tiles under it. Its bytes
//! are the COG's metadata prefix (every IFD and tile index, up to the first tile) and the
//! chosen tiles; its reads, one for the prefix and one per run of touching tiles.
//!
//! **fmrh** opens the container (lean), schedules the view-dependent scene and loads its
//! blocks with touching payloads in one read (`scene::load_blocks`, gap 0), from a `pread`
//! file. Both answers meet `tau` everywhere (fmrh's errors are measured, the COG tiles' too).
//! Times are wall-clock, warm (best of 5), for open + select + read + decode; the COG's
//! decode is the `tiff` crate's DEFLATE and predictor.
//!
//! `cargo bench --bench scenes_vs_cog` (needs gdal-bin; the large DEMs need `../shared/data`).

use std::collections::{BTreeSet, HashMap};
use std::fs::File;
use std::io::{BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::DVec3;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model};
use fmrh::scene::{load_blocks, Aabb, Camera, SceneOptions, Terrain, View, WorldFrame};
use fmrh::store::{write_file, WriteOptions};
use fmrh::{Heightfield, Store};

/// One level of the COG: the full resolution (0) or an overview.
struct Level {
    width: usize,
    height: usize,
    tile: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// Per tile: true error, and the source's height range over its footprint.
    error: Vec<f64>,
    range: Vec<(f32, f32)>,
}

impl Level {
    fn tiles_across(&self) -> (usize, usize) {
        (
            self.width.div_ceil(self.tile),
            self.height.div_ceil(self.tile),
        )
    }
}

struct Cog {
    path: PathBuf,
    prefix: u64,
    levels: Vec<Level>,
    src_w: usize,
    src_h: usize,
}

fn decoded(r: DecodingResult, nodata_i16: bool) -> Vec<f32> {
    match r {
        DecodingResult::F32(v) => v,
        DecodingResult::I16(v) => v
            .into_iter()
            .map(|x| {
                if nodata_i16 && x == i16::MIN {
                    f32::NAN
                } else {
                    f32::from(x)
                }
            })
            .collect(),
        _ => panic!("the COG holds f32 or i16"),
    }
}

/// Builds the COG of `hf` and measures every tile.
fn make_cog(dir: &Path, name: &str, hf: &Heightfield) -> Option<Cog> {
    let (w, h) = (hf.width() as usize, hf.height() as usize);
    let bin = dir.join(format!("{name}.bin"));
    let mut f = File::create(&bin).ok()?;
    for v in hf.samples() {
        f.write_all(&v.to_le_bytes()).ok()?;
    }
    std::fs::write(
        dir.join(format!("{name}.hdr")),
        format!(
            "ENVI\nsamples = {w}\nlines = {h}\nbands = 1\nheader offset = 0\nfile type = ENVI Standard\ndata type = 4\ninterleave = bsq\nbyte order = 0\n"
        ),
    )
    .ok()?;
    let voids = hf.samples().iter().any(|v| v.is_nan());
    let integral = hf
        .samples()
        .iter()
        .all(|v| v.is_nan() || (v.fract() == 0.0 && (-32767.0..=32767.0).contains(v)));
    let tif = dir.join(format!("{name}.tif"));
    let mut cmd = Command::new("gdal_translate");
    cmd.arg("-q");
    if integral {
        cmd.args(["-ot", "Int16"]);
        if voids {
            cmd.args(["-a_nodata", "-32768"]);
        }
        cmd.args(["-co", "PREDICTOR=2"]);
    } else {
        if voids {
            cmd.args(["-a_nodata", "nan"]);
        }
        cmd.args(["-co", "PREDICTOR=3"]);
    }
    cmd.args([
        "-of",
        "COG",
        "-co",
        "COMPRESS=DEFLATE",
        "-co",
        "OVERVIEWS=AUTO",
    ]);
    cmd.arg(&bin).arg(&tif);
    match cmd.status() {
        Ok(s) if s.success() => {}
        other => {
            eprintln!("gdal_translate failed or is missing ({other:?}): no COG for {name}");
            return None;
        }
    }
    let mut dec = Decoder::new(BufReader::new(File::open(&tif).ok()?)).ok()?;
    let src = hf.samples();
    let mut levels = Vec::new();
    let mut prefix = u64::MAX;
    let mut i = 0;
    loop {
        if dec.seek_to_image(i).is_err() {
            break;
        }
        let (lw, lh) = dec.dimensions().ok()?;
        let (tw, _) = dec.chunk_dimensions();
        let offsets = dec.get_tag_u64_vec(Tag::TileOffsets).ok()?;
        let counts = dec.get_tag_u64_vec(Tag::TileByteCounts).ok()?;
        prefix = prefix.min(
            offsets
                .iter()
                .copied()
                .filter(|&o| o > 0)
                .min()
                .unwrap_or(u64::MAX),
        );
        let raster = decoded(dec.read_image().ok()?, integral && voids);
        let mut level = Level {
            width: lw as usize,
            height: lh as usize,
            tile: tw as usize,
            offsets,
            counts,
            error: Vec::new(),
            range: Vec::new(),
        };
        measure(&mut level, &raster, src, w, h);
        levels.push(level);
        i += 1;
    }
    Some(Cog {
        path: tif,
        prefix,
        levels,
        src_w: w,
        src_h: h,
    })
}

/// The source columns (or rows) `[lo, hi)` a level's pixel range `[p0, p1)` covers.
fn footprint(p0: usize, p1: usize, level_len: usize, src_len: usize) -> (usize, usize) {
    let f = src_len as f64 / level_len as f64;
    let lo = (p0 as f64 * f).floor() as usize;
    let hi = ((p1 as f64 * f).ceil() as usize).min(src_len);
    (lo, hi)
}

fn measure(level: &mut Level, raster: &[f32], src: &[f32], w: usize, h: usize) {
    let (tx_n, ty_n) = level.tiles_across();
    let (fx, fy) = (
        w as f64 / level.width as f64,
        h as f64 / level.height as f64,
    );
    for ty in 0..ty_n {
        for tx in 0..tx_n {
            let (px0, px1) = (tx * level.tile, ((tx + 1) * level.tile).min(level.width));
            let (py0, py1) = (ty * level.tile, ((ty + 1) * level.tile).min(level.height));
            let (c0, c1) = footprint(px0, px1, level.width, w);
            let (r0, r1) = footprint(py0, py1, level.height, h);
            let at = |i: usize, j: usize| raster[j * level.width + i];
            let mut err = 0.0f64;
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for r in r0..r1 {
                let v = ((r as f64 + 0.5) / fy - 0.5).clamp(py0 as f64, (py1 - 1) as f64);
                let (j0, t) = (v.floor() as usize, v - v.floor());
                let j1 = (j0 + 1).min(py1 - 1);
                for c in c0..c1 {
                    let s = src[r * w + c];
                    if s.is_nan() {
                        continue;
                    }
                    lo = lo.min(s);
                    hi = hi.max(s);
                    let u = ((c as f64 + 0.5) / fx - 0.5).clamp(px0 as f64, (px1 - 1) as f64);
                    let (i0, q) = (u.floor() as usize, u - u.floor());
                    let i1 = (i0 + 1).min(px1 - 1);
                    let z = (1.0 - t)
                        * ((1.0 - q) * f64::from(at(i0, j0)) + q * f64::from(at(i1, j0)))
                        + t * ((1.0 - q) * f64::from(at(i0, j1)) + q * f64::from(at(i1, j1)));
                    let e = (f64::from(s) - z).abs();
                    err = if e.is_nan() {
                        f64::INFINITY
                    } else {
                        err.max(e)
                    };
                }
            }
            level.error.push(err);
            level
                .range
                .push(if lo <= hi { (lo, hi) } else { (0.0, 0.0) });
        }
    }
}

/// The tiles (level, index) the COG reader chooses for `view` at `tau`.
fn cog_scene(cog: &Cog, frame: WorldFrame, view: &View, tau: f64) -> (Vec<(usize, usize)>, f64) {
    let top = cog.levels.len() - 1;
    let tile_box = |l: usize, t: usize| -> (Aabb, (usize, usize, usize, usize)) {
        let lv = &cog.levels[l];
        let (tx_n, _) = lv.tiles_across();
        let (tx, ty) = (t % tx_n, t / tx_n);
        let (c0, c1) = footprint(
            tx * lv.tile,
            ((tx + 1) * lv.tile).min(lv.width),
            lv.width,
            cog.src_w,
        );
        let (r0, r1) = footprint(
            ty * lv.tile,
            ((ty + 1) * lv.tile).min(lv.height),
            lv.height,
            cog.src_h,
        );
        let (lo, hi) = lv.range[t];
        (
            Aabb {
                min: frame.point(c0 as f64, r0 as f64, f64::from(lo)),
                max: frame.point((c1 - 1) as f64, (r1 - 1) as f64, f64::from(hi)),
            },
            (c0, c1, r0, r1),
        )
    };
    let mut chosen = Vec::new();
    let mut worst = 0.0f64;
    let (tx_n, ty_n) = cog.levels[top].tiles_across();
    let mut todo: Vec<(usize, usize)> = (0..tx_n * ty_n).map(|t| (top, t)).collect();
    let mut seen: BTreeSet<(usize, usize)> = BTreeSet::new();
    while let Some((l, t)) = todo.pop() {
        if !seen.insert((l, t)) {
            continue;
        }
        let (bx, (c0, c1, r0, r1)) = tile_box(l, t);
        if !view.intersects(&bx) {
            continue;
        }
        let se = view.screen_error(cog.levels[l].error[t], bx.distance(view.eye));
        if se <= tau || l == 0 {
            worst = worst.max(se);
            chosen.push((l, t));
            continue;
        }
        // The finer level's tiles under this footprint.
        let fine = &cog.levels[l - 1];
        let (ftx, fty) = fine.tiles_across();
        for fy in 0..fty {
            for fx in 0..ftx {
                let (_, (d0, d1, e0, e1)) = tile_box(l - 1, fy * ftx + fx);
                if d0 < c1 && c0 < d1 && e0 < r1 && r0 < e1 {
                    todo.push((l - 1, fy * ftx + fx));
                }
            }
        }
    }
    (chosen, worst)
}

/// Bytes and reads of the chosen tiles, with the metadata prefix.
fn cog_reads(cog: &Cog, tiles: &[(usize, usize)]) -> (u64, u64) {
    let mut ranges: Vec<(u64, u64)> = tiles
        .iter()
        .map(|&(l, t)| {
            let lv = &cog.levels[l];
            (lv.offsets[t], lv.offsets[t] + lv.counts[t])
        })
        .collect();
    ranges.sort_unstable();
    let mut runs = 0u64;
    let mut end = u64::MAX;
    let mut bytes = cog.prefix;
    for (a, b) in ranges {
        if a != end {
            runs += 1;
        }
        end = b;
        bytes += b - a;
    }
    (bytes, 1 + runs)
}

/// Opens the COG and decodes the chosen tiles (what a reader does after choosing).
fn cog_decode(cog: &Cog, tiles: &[(usize, usize)]) -> usize {
    let mut dec = Decoder::new(BufReader::new(File::open(&cog.path).unwrap())).unwrap();
    let mut by_level: HashMap<usize, Vec<usize>> = HashMap::new();
    for &(l, t) in tiles {
        by_level.entry(l).or_default().push(t);
    }
    let mut n = 0;
    for (l, ts) in by_level {
        dec.seek_to_image(l).unwrap();
        for t in ts {
            let chunk = u32::try_from(t).unwrap();
            n += match dec.read_chunk(chunk).unwrap() {
                DecodingResult::F32(v) => v.len(),
                DecodingResult::I16(v) => v.len(),
                _ => 0,
            };
        }
    }
    n
}

fn cameras(extent: f64, ground: f64) -> Vec<(&'static str, Camera)> {
    let e = extent;
    vec![
        (
            "overview",
            Camera::looking_at(
                DVec3::new(0.5 * e, 1.4 * e, 0.5 * e),
                DVec3::new(0.5 * e, 0.5 * e, 0.0),
            ),
        ),
        (
            "oblique",
            Camera::looking_at(
                DVec3::new(0.1 * e, 0.9 * e, ground + 0.04 * e),
                DVec3::new(0.6 * e, 0.4 * e, 0.0),
            ),
        ),
        (
            "low",
            Camera::looking_at(
                DVec3::new(0.4 * e, 0.6 * e, ground + 300.0),
                DVec3::new(0.7 * e, 0.5 * e, ground * 0.5),
            ),
        ),
    ]
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut sets: Vec<(&str, Heightfield, f64)> = Vec::new();
    let puget = load(
        &root.join("data/puget-sound-1k/ps_height_1k.png"),
        &IngestOptions {
            z_scale: 0.1,
            ..Default::default()
        },
    )
    .expect("bundled Puget Sound 1k");
    sets.push(("puget-1k", puget, 160.0));
    for (name, rel, spacing) in [
        ("puget-4k", "puget-sound-4k-jpg/ps_height_4k_jpg.f32", 40.0),
        ("S46W066", "srtm1-asmyasnikov/S46W066.f32", 30.0),
    ] {
        match load(
            &root.join("../shared/data").join(rel),
            &IngestOptions::default(),
        ) {
            Ok(hf) => sets.push((name, hf, spacing)),
            Err(e) => eprintln!("skipping {name}: {e}"),
        }
    }
    println!(
        "| dataset | camera | tau | fmrh blocks | fmrh reads | fmrh bytes | fmrh max px | COG tiles | COG reads | COG bytes | COG max px | fmrh/COG bytes | fmrh us | COG us |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut ratios = Vec::new();
    for (name, mut hf, spacing) in sets {
        if hf.metadata.spacing_m.is_none() {
            hf.metadata.spacing_m = Some([spacing, spacing]);
        }
        let s = hf.metadata.spacing_m.unwrap_or([spacing, spacing]);
        let Some(cog) = make_cog(dir.path(), name, &hf) else {
            continue;
        };
        let extent = hf.width() as f64 * s[0];
        let ground = hf
            .samples()
            .iter()
            .filter(|v| !v.is_nan())
            .fold(0.0f32, |a, &b| a.max(b)) as f64;
        let metadata = hf.metadata.clone();
        let model = Model::build(hf, &BuildOptions::default()).expect("builds");
        let path = dir.path().join(format!("{name}.fmrh"));
        write_file(&model, &metadata, &path, &WriteOptions::default(), true).expect("writes");
        let frame = WorldFrame::new(Some(s));
        for (cam_name, cam) in cameras(extent, ground) {
            let view = cam.view().expect("camera");
            for tau in [0.5, 1.0, 2.0, 4.0] {
                let fmrh_run = || {
                    let store = Store::open(&path).expect("opens");
                    let terrain = Terrain::new(&store).expect("terrain");
                    let scene = terrain.scene(&cam, &SceneOptions::new(tau)).expect("scene");
                    load_blocks(&store, &scene.blocks, 0).expect("loads");
                    let r = store.open_reads();
                    let all = store.read_stats();
                    (
                        scene.blocks.len(),
                        r.reads() + all.reads(),
                        r.bytes() + all.bytes(),
                        scene.stats.max_screen_error,
                    )
                };
                let (blocks, reads, bytes, px) = fmrh_run();
                let fmrh_us = (0..5)
                    .map(|_| {
                        let t = Instant::now();
                        fmrh_run();
                        t.elapsed().as_secs_f64() * 1e6
                    })
                    .fold(f64::INFINITY, f64::min);
                let (tiles, cog_px) = cog_scene(&cog, frame, &view, tau);
                let (cog_bytes, cog_calls) = cog_reads(&cog, &tiles);
                let cog_us = (0..5)
                    .map(|_| {
                        let t = Instant::now();
                        let chosen = cog_scene(&cog, frame, &view, tau).0;
                        cog_decode(&cog, &chosen);
                        t.elapsed().as_secs_f64() * 1e6
                    })
                    .fold(f64::INFINITY, f64::min);
                let ratio = bytes as f64 / cog_bytes as f64;
                ratios.push(ratio);
                println!(
                    "| {name} | {cam_name} | {tau} | {blocks} | {reads} | {bytes} | {px:.2} | {} | {cog_calls} | {cog_bytes} | {cog_px:.2} | {ratio:.2} | {fmrh_us:.0} | {cog_us:.0} |",
                    tiles.len()
                );
            }
        }
    }
    ratios.sort_by(f64::total_cmp);
    if !ratios.is_empty() {
        println!(
            "\nfmrh bytes / COG bytes: median {:.2}, worst {:.2}, best {:.2}, {} of {} scenes at or below 1",
            ratios[ratios.len() / 2],
            ratios[ratios.len() - 1],
            ratios[0],
            ratios.iter().filter(|&&r| r <= 1.0).count(),
            ratios.len()
        );
    }
}
