//! `fmrh mesh --format quantized-mesh`: a directory of Cesium quantized-mesh-1.0 tiles and
//! their `layer.json`, in one of two tilings.
//!
//! * **geodetic** (the default for georeferenced data): Cesium's global-geodetic pyramid,
//!   every tile a 65² grid in longitude and latitude sampled from the scene's surface
//!   (`crate::export::geodetic_mesh`), down to the level each scene block's resolution maps
//!   to, with every ancestor; a tileset `Cesium.CesiumTerrainProvider` loads as it is. The
//!   surface is the scene's blocks where the camera looks, and the coarsest cover of the
//!   data elsewhere; the ellipsoid (height 0) away from the data.
//! * **nodes**: one tile per scene block, addressed by its fmrh node, its stitched mesh in
//!   a local frame (`crate::export::quantized_mesh::encode`).
//!
//! Either way the directory is written beside the output under a temporary name and
//! renamed into place, so a failure leaves no half-written tileset.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::ExitCode;

use rayon::prelude::*;
use serde_json::{json, Value};

use super::super::args::RefineArg;
use crate::export::geodetic::{self, GeodeticTile};
use crate::export::geodetic_mesh::{self, Placement, GRID};
use crate::export::quantized_mesh::{self, QuantizedTile};
use crate::mesh::BlockMesh;
use crate::model::SampleRect;
use crate::scene::surface::{GridBlock, Surface};
use crate::Error;

use super::{
    block_extras, finish_meshes, refine_fractal, scene_parts, Context, MeshArgs, Part, TilingArg,
};

/// The most tiles a geodetic tileset is written with: past it, the scene asks for more
/// detail over more ground than a tileset from one command should hold.
const MAX_TILES: usize = 200_000;

/// Runs `fmrh mesh --format quantized-mesh`.
pub(super) fn run_tiles(
    args: &MeshArgs,
    camera: &crate::scene::Camera,
    options: &crate::scene::SceneOptions,
) -> Result<ExitCode, Error> {
    // The cover is for geodetic tiles only: a scene over the whole data, not made for nothing.
    let geodetic_wanted = |g: Option<&crate::heightfield::Georeference>| {
        args.tiling != TilingArg::Nodes && g.is_some_and(|g| Placement::new(g, 1.0).is_ok())
    };
    let (parts, cover, context) = scene_parts(
        &args.file,
        &args.view,
        camera,
        options,
        geodetic_wanted,
        false,
    )?;
    if parts.is_empty() {
        return Err(Error::InvalidArgument(
            "the camera sees no terrain: there is nothing to mesh (give --window)".into(),
        ));
    }
    let placeable = context
        .georeference
        .as_ref()
        .map(|g| Placement::new(g, 1.0));
    let geodetic = match (args.tiling, placeable) {
        (TilingArg::Nodes, _) => false,
        (TilingArg::Geodetic, Some(Ok(_))) | (TilingArg::Auto, Some(Ok(_))) => true,
        (TilingArg::Geodetic, Some(Err(e))) => return Err(e),
        (TilingArg::Geodetic, None) => {
            return Err(Error::InvalidArgument(format!(
                "{}: no georeference, so no geodetic tiles (--tiling nodes writes fmrh's own)",
                args.file.display()
            )))
        }
        (TilingArg::Auto, _) => false,
    };
    if geodetic {
        return run_geodetic(args, camera, parts, cover, context);
    }
    if super::super::is_dataset(&args.file)? {
        return Err(Error::InvalidArgument(
            "node-addressed quantized-mesh tiles come from one container (a dataset's tiles \
             would share tile addresses); a georeferenced dataset gets geodetic tiles"
                .into(),
        ));
    }
    let meshed = finish_meshes(parts, context, camera, args.style()?, args.refine)?;
    let bytes = crate::store::write::write_dir_atomically(&args.output, args.force, |dir| {
        write_node_tiles(
            dir,
            &meshed.parts,
            &meshed.meshes,
            &meshed.context,
            args.gzip,
        )
    })?;
    eprintln!(
        "fmrh: wrote {} quantized-mesh tiles, one per block ({} synthetic), {} bytes in {}",
        meshed.meshes.len(),
        meshed.synthetic(),
        bytes,
        args.output.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Writes `bytes` as tile `z/x/y.terrain` under `dir`, gzipped with `gzip`; returns the
/// bytes written.
fn put_tile(dir: &Path, z: u8, x: u32, y: u32, bytes: &[u8], gzip: bool) -> Result<u64, Error> {
    let column = dir.join(z.to_string()).join(x.to_string());
    std::fs::create_dir_all(&column).map_err(|e| Error::io(&column, e))?;
    let path = column.join(format!("{y}.terrain"));
    let stored = if gzip {
        use std::io::Write;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        enc.write_all(bytes)
            .and_then(|()| enc.finish())
            .map_err(|e| Error::io(&path, e))?
    } else {
        bytes.to_vec()
    };
    std::fs::write(&path, &stored).map_err(|e| Error::io(&path, e))?;
    Ok(stored.len() as u64)
}

/// Writes `layer.json` under `dir`.
fn put_layer(dir: &Path, layer: &Value) -> Result<(), Error> {
    let path = dir.join("layer.json");
    let text = serde_json::to_vec_pretty(layer)
        .map_err(|e| Error::Internal(format!("layer.json: {e}")))?;
    std::fs::write(&path, text).map_err(|e| Error::io(&path, e))
}

/// TileJSON's `available`: for each level from 0 to the deepest, the tiles written, as
/// rectangles of `(x, y)` (runs along a row, merged with the rows above when they match).
fn available(levels: &BTreeMap<u8, Vec<(u32, u32)>>) -> Vec<Value> {
    (0..=levels.keys().max().copied().unwrap_or(0))
        .map(|l| {
            let mut tiles = levels.get(&l).cloned().unwrap_or_default();
            tiles.sort_unstable_by_key(|&(x, y)| (y, x));
            tiles.dedup();
            // Runs along each row: (x0, x1, y).
            let mut runs: Vec<(u32, u32, u32)> = Vec::new();
            for (x, y) in tiles {
                match runs.last_mut() {
                    Some((_, x1, ry)) if *ry == y && *x1 + 1 == x => *x1 = x,
                    _ => runs.push((x, x, y)),
                }
            }
            // Rectangles: a run extends the rectangle whose columns match and whose last
            // row is the row below.
            let mut rects: Vec<[u32; 4]> = Vec::new();
            for (x0, x1, y) in runs {
                match rects
                    .iter_mut()
                    .find(|r| r[0] == x0 && r[2] == x1 && r[3] + 1 == y)
                {
                    Some(r) => r[3] = y,
                    None => rects.push([x0, y, x1, y]),
                }
            }
            Value::Array(
                rects
                    .into_iter()
                    .map(|[x0, y0, x1, y1]| {
                        json!({ "startX": x0, "startY": y0, "endX": x1, "endY": y1 })
                    })
                    .collect(),
            )
        })
        .collect()
}

/// Writes one quantized-mesh tile per block (its stitched mesh over its footprint, in the
/// local frame) and `layer.json` into `dir`. Returns the bytes of the tiles.
fn write_node_tiles(
    dir: &Path,
    parts: &[Part],
    meshes: &[BlockMesh],
    context: &Context,
    gzip: bool,
) -> Result<u64, Error> {
    let mut total = 0u64;
    // Per level: the tiles written, as (x, y) with y counted from the south.
    let mut levels: BTreeMap<u8, Vec<(u32, u32)>> = BTreeMap::new();
    for m in meshes {
        let p = &parts[m.block];
        let (level, x, y) = p.node();
        let y = (1u32 << level) - 1 - y;
        let f = &p.footprint;
        let tile = QuantizedTile {
            mesh: m,
            rect: [f.col0, f.row0, f.col1, f.row1],
            metadata: json!({ "fmrh": block_extras(p, m, context.units) }),
        };
        let bytes = quantized_mesh::encode(&tile, &context.mesh_frame())?;
        total += put_tile(dir, level, x, y, &bytes, gzip)?;
        levels.entry(level).or_default().push((x, y));
    }
    let mut layer = node_layer_json(parts, meshes, context, &levels);
    layer["fmrh"]["gzip"] = json!(gzip);
    put_layer(dir, &layer)?;
    Ok(total)
}

/// The node tileset's `layer.json`: TileJSON as Cesium reads it, with the tiles available
/// at each level, and an `fmrh` object saying what the tiles are.
fn node_layer_json(
    parts: &[Part],
    meshes: &[BlockMesh],
    context: &Context,
    levels: &BTreeMap<u8, Vec<(u32, u32)>>,
) -> Value {
    let level_notes: Vec<Value> = levels
        .iter()
        .map(|(l, tiles)| {
            let p = meshes
                .iter()
                .map(|m| &parts[m.block])
                .find(|p| p.node().0 == *l);
            let side = p.map_or(0.0, |p| {
                (p.footprint.col1 - p.footprint.col0) as f64 / context.units as f64
            });
            json!({
                "level": l,
                "tiles": tiles.len(),
                "tile_side_samples": side,
                "tile_side_m": [side * context.frame.dx, side * context.frame.dy],
                "stride_samples": p.map_or(0.0, |p| p.stride as f64 / context.units as f64),
                "synthetic": p.is_some_and(|p| p.synthetic.is_some()),
            })
        })
        .collect();
    let mut origin = json!({ "sample": [0, 0], "world_m": [0.0, 0.0] });
    if let Some(g) = &context.georeference {
        origin["map"] = json!(g.origin);
        origin["crs"] = g.crs.clone().map_or(Value::Null, Value::from);
    }
    json!({
        "tilejson": "2.1.0",
        "name": "fmrh scene",
        "description": "One tile per block of an fmrh scene: tile LEVEL/X/Y is the fmrh node \
            at that level, column X and row 2^LEVEL - 1 - Y (Y counted from the south). \
            The tiles are fmrh's quadtree over the data's samples, not the global-geodetic \
            grid, in a local frame (x east, y north, z up, metres from the data's \
            north-west sample).",
        "version": "1.0.0",
        "format": "quantized-mesh-1.0",
        "scheme": "tms",
        "tiles": ["{z}/{x}/{y}.terrain?v={version}"],
        "minzoom": levels.keys().min(),
        "maxzoom": levels.keys().max(),
        "extensions": ["octvertexnormals", "metadata"],
        "available": available(levels),
        "fmrh": {
            "tiling": "fmrh-nodes",
            "frame": "local: x east, y north, z up, metres; the data's north-west sample at x = y = 0",
            "origin": origin,
            "spacing_m": [context.frame.dx, context.frame.dy],
            "levels": level_notes,
            "tau": context.tau,
            "mode": context.mode,
        }
    })
}

/// What one geodetic tile came to.
struct TileSummary {
    tile: GeodeticTile,
    bytes: u64,
    error: f64,
    resampling: f64,
    /// The fmrh levels it draws from (a synthetic node's own), ascending.
    levels: Vec<u8>,
    synthetic: bool,
}

/// The geodetic tileset: samples the scene (refined if asked), the cover beneath it, into
/// every tile the scene's blocks map to, with their ancestors.
fn run_geodetic(
    args: &MeshArgs,
    camera: &crate::scene::Camera,
    parts: Vec<Part>,
    cover: Vec<Part>,
    mut context: Context,
) -> Result<ExitCode, Error> {
    if args.max_error.is_some() {
        return Err(Error::InvalidArgument(
            "--max-error: `fmrh mesh` writes geodetic quantized-mesh tiles as regular grids; \
             `fmrh serve` cuts them as TINs within --max-error (or --tiling nodes meshes \
             fmrh's blocks as TINs)"
                .into(),
        ));
    }
    let parts = match args.refine {
        Some(RefineArg::Fractal) => refine_fractal(parts, camera, &mut context)?,
        None => parts,
    };
    // The cover in the scene's units (a refined scene's are finer than samples).
    let k = context.units;
    let cover: Vec<Part> = cover
        .into_iter()
        .map(|mut p| {
            for r in [&mut p.rect, &mut p.footprint] {
                *r = SampleRect {
                    col0: r.col0 * k,
                    row0: r.row0 * k,
                    col1: r.col1 * k,
                    row1: r.row1 * k,
                };
            }
            p.stride *= k;
            p
        })
        .collect();
    let georeference = context
        .georeference
        .clone()
        .ok_or_else(|| Error::Internal("geodetic tiles without a georeference".into()))?;
    let placement = Placement::new(&georeference, k as f64)?;
    let scene_blocks = parts.len();
    let all: Vec<&Part> = parts.iter().chain(&cover).collect();
    let grids: Vec<GridBlock<'_>> = all.iter().map(|p| p.grid()).collect();
    let surface = Surface::new(grids);
    let data_box = surface
        .bounds()
        .and_then(|b| placement.box_of(&b))
        .ok_or_else(|| Error::InvalidArgument("the data cannot be placed on the globe".into()))?;
    // Each scene block's tile level: the shallowest whose grid is as fine as the block's.
    let mut areas = Vec::with_capacity(scene_blocks);
    let mut block_levels: BTreeMap<(u8, bool), (u64, u64, u8, u8)> = BTreeMap::new();
    for p in &parts {
        let r = &p.rect;
        if r.col0 >= r.col1 || r.row0 >= r.row1 {
            continue;
        }
        let Some(b) = placement.box_of(r) else {
            continue;
        };
        let across = ((r.col1 - r.col0) as f64 / p.stride as f64).max(1.0);
        let down = ((r.row1 - r.row0) as f64 / p.stride as f64).max(1.0);
        let step = ((b[2] - b[0]) / across).min((b[3] - b[1]) / down);
        let z = geodetic_mesh::level_for_step(step);
        areas.push((b, z));
        let e = block_levels
            .entry((p.node().0, p.synthetic.is_some()))
            .or_insert((0, p.stride, z, z));
        e.0 += 1;
        e.2 = e.2.min(z);
        e.3 = e.3.max(z);
    }
    let tiles: Vec<GeodeticTile> = geodetic_mesh::tiles_for(&areas).into_iter().collect();
    if tiles.len() > MAX_TILES {
        return Err(Error::TooLarge {
            what: "the geodetic tileset".into(),
            detail: format!(
                "{} tiles, over the {MAX_TILES} one command writes: raise --tau or give a \
                 smaller --window",
                tiles.len()
            ),
        });
    }
    // CesiumJS reads a tile's metadata extension only in a layer that takes availability
    // from tiles (`metadataAvailability`; otherwise it fails on the first tile), so the
    // two root tiles carry the availability of every level below them.
    let maxzoom = tiles.iter().map(|t| t.z).max().unwrap_or(0);
    let below_root = |root: u32| -> Value {
        let mut levels: BTreeMap<u8, Vec<(u32, u32)>> = BTreeMap::new();
        for t in tiles.iter().filter(|t| t.z > 0 && t.x >> t.z == root) {
            levels.entry(t.z).or_default().push((t.x, t.y));
        }
        levels.entry(maxzoom.max(1)).or_default();
        Value::Array(available(&levels).into_iter().skip(1).collect())
    };
    let root_availability = [below_root(0), below_root(1)];
    let summaries = crate::store::write::write_dir_atomically(&args.output, args.force, |dir| {
        let summaries: Vec<TileSummary> = tiles
            .par_iter()
            .map(|&t| {
                let mut sampled = geodetic_mesh::sample_tile(t, &surface, &placement, data_box)?;
                let levels: BTreeSet<u8> =
                    sampled.blocks.iter().map(|&b| all[b].node().0).collect();
                let synthetic = sampled.blocks.iter().any(|&b| all[b].synthetic.is_some());
                let coverage =
                    sampled.inside.iter().filter(|&&i| i).count() as f64 / (GRID * GRID) as f64;
                sampled.data.metadata = json!({ "fmrh": {
                    "tile": [t.z, t.x, t.y],
                    "error": sampled.error,
                    "resampling": sampled.resampling,
                    "measured_samples": sampled.measured,
                    "block_error": sampled.block_error,
                    "coverage": coverage,
                    "levels": levels,
                    "synthetic": synthetic,
                }});
                if t.z == 0 {
                    sampled.data.metadata["available"] = root_availability[t.x as usize].clone();
                }
                let bytes = quantized_mesh::write(&sampled.data)?;
                let stored = put_tile(dir, t.z, t.x, t.y, &bytes, args.gzip)?;
                Ok(TileSummary {
                    tile: t,
                    bytes: stored,
                    error: sampled.error,
                    resampling: sampled.resampling,
                    levels: levels.into_iter().collect(),
                    synthetic,
                })
            })
            .collect::<Result<_, Error>>()?;
        let mut layer =
            geodetic_layer_json(&summaries, &block_levels, &context, &georeference, data_box);
        layer["fmrh"]["gzip"] = json!(args.gzip);
        put_layer(dir, &layer)?;
        Ok(summaries)
    })?;
    let bytes: u64 = summaries.iter().map(|s| s.bytes).sum();
    let deepest = summaries.iter().map(|s| s.tile.z).max().unwrap_or(0);
    let deepest_error = summaries
        .iter()
        .filter(|s| s.tile.z == deepest)
        .map(|s| s.error)
        .fold(0.0f64, f64::max);
    eprintln!(
        "fmrh: wrote {} geodetic quantized-mesh tiles (levels 0 to {deepest}) from {} blocks \
         ({} synthetic), {} bytes in {}; the deepest tiles are within {:.3} m of the source",
        summaries.len(),
        scene_blocks,
        parts.iter().filter(|p| p.synthetic.is_some()).count(),
        bytes,
        args.output.display(),
        deepest_error,
    );
    Ok(ExitCode::SUCCESS)
}

/// The geodetic tileset's `layer.json`: TileJSON as Cesium reads it (the global-geodetic
/// pyramid, with the tiles available at each level), and an `fmrh` object saying which fmrh
/// levels went to which tile levels and what each level's tiles measure.
fn geodetic_layer_json(
    summaries: &[TileSummary],
    block_levels: &BTreeMap<(u8, bool), (u64, u64, u8, u8)>,
    context: &Context,
    georeference: &crate::heightfield::Georeference,
    data_box: [f64; 4],
) -> Value {
    let mut levels: BTreeMap<u8, Vec<(u32, u32)>> = BTreeMap::new();
    let mut per_level: BTreeMap<u8, (usize, f64, f64, BTreeSet<u8>, bool)> = BTreeMap::new();
    for s in summaries {
        levels
            .entry(s.tile.z)
            .or_default()
            .push((s.tile.x, s.tile.y));
        let e = per_level
            .entry(s.tile.z)
            .or_insert((0, 0.0, 0.0, BTreeSet::new(), false));
        e.0 += 1;
        e.1 = e.1.max(s.error);
        e.2 = e.2.max(s.resampling);
        e.3.extend(&s.levels);
        e.4 |= s.synthetic;
    }
    let level_notes: Vec<Value> = per_level
        .iter()
        .map(|(z, (tiles, error, resampling, from, synthetic))| {
            json!({
                "level": z,
                "tiles": tiles,
                "tile_degrees": geodetic::tile_degrees(*z),
                "grid_step_degrees": geodetic::tile_degrees(*z) / (GRID - 1) as f64,
                "cesium_geometric_error_m": geodetic::geometric_error(*z),
                "max_error_m": error,
                "max_resampling_m": resampling,
                "from_fmrh_levels": from,
                "synthetic": synthetic,
            })
        })
        .collect();
    let block_notes: Vec<Value> = block_levels
        .iter()
        .map(|((level, synthetic), (blocks, stride, z0, z1))| {
            json!({
                "fmrh_level": level,
                "synthetic": synthetic,
                "blocks": blocks,
                "stride_samples": *stride as f64 / context.units as f64,
                "tile_levels": [z0, z1],
            })
        })
        .collect();
    json!({
        "tilejson": "2.1.0",
        "name": "fmrh scene",
        "description": "Cesium's global-geodetic pyramid (EPSG:4326, TMS, y from the south) \
            sampled from an fmrh scene: each tile a 65x65 grid in longitude and latitude, \
            its heights the scene's surface where the camera looked, the data's coarsest \
            cover elsewhere, and height 0 on the ellipsoid away from the data. Tiles exist \
            down to the level each scene block's resolution maps to, with every ancestor.",
        "version": "1.0.0",
        "format": "quantized-mesh-1.0",
        "scheme": "tms",
        "projection": "EPSG:4326",
        "bounds": [-180.0, -90.0, 180.0, 90.0],
        "tiles": ["{z}/{x}/{y}.terrain?v={version}"],
        "minzoom": 0,
        "maxzoom": levels.keys().max(),
        "extensions": ["octvertexnormals", "metadata"],
        "available": available(&levels),
        // The root tiles' metadata lists every level's tiles below them (CesiumJS reads it
        // from there when this is given, and `available` above otherwise).
        "metadataAvailability": levels.keys().max().copied().unwrap_or(0).max(1),
        "fmrh": {
            "tiling": "geodetic",
            "grid": GRID,
            "heights": "metres as the data's heights are (above its vertical datum, taken as the ellipsoid)",
            "crs": georeference.crs,
            "data_lon_lat_box": data_box,
            "blocks_to_levels": block_notes,
            "levels": level_notes,
            "error": "each tile's metadata: error = max over the data samples inside it of \
                |tile - scene surface| + the owning block's e*, so |tile - source| <= error",
            "tau": context.tau,
            "mode": context.mode,
        }
    })
}
