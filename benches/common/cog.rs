//! The COG side of the benchmarks that compare fmrh with a Cloud-Optimized GeoTIFF
//! (`scenes_vs_cog`, `speed_vs_error`): making the COG with gdal_translate, measuring every
//! tile's true error against the source, choosing tiles for a view with fmrh's screen-error
//! rule, and counting the bytes and reads that costs (see `scenes_vs_cog.rs` for the method).

#![allow(dead_code)]

use std::collections::{BTreeSet, HashMap};
use std::fs::File;
use std::io::{BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::Command;

use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

use fmrh::model::SampleRect;
use fmrh::scene::{Aabb, TerrainFrame, View, WorldFrame};
use fmrh::Heightfield;

/// One level of the COG: the full resolution (0) or an overview.
pub struct Level {
    pub width: usize,
    pub height: usize,
    pub tile: usize,
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
    /// Per tile: true error, and the source's height range over its footprint.
    pub error: Vec<f64>,
    pub range: Vec<(f32, f32)>,
}

impl Level {
    pub fn tiles_across(&self) -> (usize, usize) {
        (
            self.width.div_ceil(self.tile),
            self.height.div_ceil(self.tile),
        )
    }
}

pub struct Cog {
    pub path: PathBuf,
    pub prefix: u64,
    pub levels: Vec<Level>,
    /// Each level's decoded samples (f32, voids NaN), row-major.
    pub rasters: Vec<Vec<f32>>,
    pub src_w: usize,
    pub src_h: usize,
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
pub fn make_cog(dir: &Path, name: &str, hf: &Heightfield) -> Option<Cog> {
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
    let mut rasters = Vec::new();
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
        rasters.push(raster);
        i += 1;
    }
    Some(Cog {
        path: tif,
        prefix,
        levels,
        rasters,
        src_w: w,
        src_h: h,
    })
}

/// The source columns (or rows) `[lo, hi)` a level's pixel range `[p0, p1)` covers.
pub fn footprint(p0: usize, p1: usize, level_len: usize, src_len: usize) -> (usize, usize) {
    let f = src_len as f64 / level_len as f64;
    let lo = (p0 as f64 * f).floor() as usize;
    let hi = ((p1 as f64 * f).ceil() as usize).min(src_len);
    (lo, hi)
}

/// Calls `f(col, row, source, surface)` for every valid source sample of tile `t` of
/// `level`, with the tile's bilinear surface there: the tile sampled on its own
/// (pixel-is-area, edges clamped to the tile).
fn for_each_sample(
    level: &Level,
    raster: &[f32],
    src: &[f32],
    (w, h): (usize, usize),
    t: usize,
    mut f: impl FnMut(usize, usize, f32, f64),
) {
    let (tx_n, _) = level.tiles_across();
    let (tx, ty) = (t % tx_n, t / tx_n);
    let (fx, fy) = (
        w as f64 / level.width as f64,
        h as f64 / level.height as f64,
    );
    let (px0, px1) = (tx * level.tile, ((tx + 1) * level.tile).min(level.width));
    let (py0, py1) = (ty * level.tile, ((ty + 1) * level.tile).min(level.height));
    let (c0, c1) = footprint(px0, px1, level.width, w);
    let (r0, r1) = footprint(py0, py1, level.height, h);
    let at = |i: usize, j: usize| f64::from(raster[j * level.width + i]);
    for r in r0..r1 {
        let v = ((r as f64 + 0.5) / fy - 0.5).clamp(py0 as f64, (py1 - 1) as f64);
        let (j0, t) = (v.floor() as usize, v - v.floor());
        let j1 = (j0 + 1).min(py1 - 1);
        for c in c0..c1 {
            let s = src[r * w + c];
            if s.is_nan() {
                continue;
            }
            let u = ((c as f64 + 0.5) / fx - 0.5).clamp(px0 as f64, (px1 - 1) as f64);
            let (i0, q) = (u.floor() as usize, u - u.floor());
            let i1 = (i0 + 1).min(px1 - 1);
            // Terms of weight 0 are left out, so that a void beside a sample (NaN) does not
            // spoil the surface where it has no weight (at level 0, every sample).
            let z = [
                ((1.0 - t) * (1.0 - q), i0, j0),
                ((1.0 - t) * q, i1, j0),
                (t * (1.0 - q), i0, j1),
                (t * q, i1, j1),
            ]
            .iter()
            .filter(|w| w.0 != 0.0)
            .map(|&(w, i, j)| w * at(i, j))
            .sum::<f64>();
            f(c, r, s, z);
        }
    }
}

/// Measures every tile of `level`: its true error and the source's height range.
fn measure(level: &mut Level, raster: &[f32], src: &[f32], w: usize, h: usize) {
    let (tx_n, ty_n) = level.tiles_across();
    for t in 0..tx_n * ty_n {
        let mut err = 0.0f64;
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for_each_sample(level, raster, src, (w, h), t, |_, _, s, z| {
            lo = lo.min(s);
            hi = hi.max(s);
            let e = (f64::from(s) - z).abs();
            err = if e.is_nan() {
                f64::INFINITY
            } else {
                err.max(e)
            };
        });
        level.error.push(err);
        level
            .range
            .push(if lo <= hi { (lo, hi) } else { (0.0, 0.0) });
    }
}

/// The source samples tile `t` of level `l` covers (inclusive).
pub fn tile_rect(cog: &Cog, l: usize, t: usize) -> SampleRect {
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
    SampleRect {
        col0: c0 as u64,
        row0: r0 as u64,
        col1: (c1 - 1) as u64,
        row1: (r1 - 1) as u64,
    }
}

/// The tiles (level, index) the COG reader chooses for `view` at `tau`, the tiles placed by
/// `frame` (flat, or on the globe, where tiles wholly below the horizon are not read).
pub fn cog_scene(
    cog: &Cog,
    frame: TerrainFrame,
    view: &View,
    tau: f64,
) -> (Vec<(usize, usize)>, f64) {
    let top = cog.levels.len() - 1;
    let tile_box = |l: usize, t: usize| -> (Aabb, bool, SampleRect) {
        let rect = tile_rect(cog, l, t);
        let (lo, hi) = cog.levels[l].range[t];
        (
            frame.rect_box(&rect, f64::from(lo), f64::from(hi)),
            frame.hidden(view.eye, &rect, f64::from(hi)),
            rect,
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
        let (bx, hidden, r) = tile_box(l, t);
        if hidden || !view.intersects(&bx) {
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
                let (_, _, f) = tile_box(l - 1, fy * ftx + fx);
                if f.intersect(&r).is_some() {
                    todo.push((l - 1, fy * ftx + fx));
                }
            }
        }
    }
    (chosen, worst)
}

/// Bytes and reads of the chosen tiles, with the metadata prefix.
pub fn cog_reads(cog: &Cog, tiles: &[(usize, usize)]) -> (u64, u64) {
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
pub fn cog_decode(cog: &Cog, tiles: &[(usize, usize)]) -> usize {
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

/// The COG answer's largest screen error against the source, measured: each chosen tile
/// sampled as [`measure`] samples it, at every valid source sample of its footprint the
/// frustum may see, `|source - surface|` in pixels at that sample's distance.
pub fn measured_px(
    cog: &Cog,
    source: &Heightfield,
    frame: WorldFrame,
    view: &View,
    tiles: &[(usize, usize)],
) -> f64 {
    let mut worst = 0.0f64;
    for &(l, t) in tiles {
        let dims = (cog.src_w, cog.src_h);
        for_each_sample(
            &cog.levels[l],
            &cog.rasters[l],
            source.samples(),
            dims,
            t,
            |c, r, s, z| {
                worst = worst.max(sample_px(view, frame, c as u64, r as u64, s, z));
            },
        );
    }
    worst
}

/// The screen error in pixels of drawing source height `h` at `(col, row)` as `z`, or 0 when
/// the sample lies outside the frustum (by the plane test).
pub fn sample_px(view: &View, frame: WorldFrame, col: u64, row: u64, h: f32, z: f64) -> f64 {
    let p = frame.point(col as f64, row as f64, f64::from(h));
    let b = Aabb { min: p, max: p };
    if matches!(view.classify(&b), fmrh::scene::Coverage::Outside) {
        return 0.0;
    }
    let e = (f64::from(h) - z).abs();
    if e.is_nan() {
        return f64::INFINITY;
    }
    view.screen_error(e, (p - view.eye).length())
}
