//! `fmrh mesh`: a scene as triangles (`fmrh::mesh`), crack-free, written as one glTF 2.0
//! binary (`fmrh::export::gltf`): one node per block, with its level, error and key; or as
//! a directory of Cesium quantized-mesh tiles and their `layer.json`
//! (`fmrh::export::quantized_mesh`), one tile per block.

use std::path::PathBuf;
use std::process::ExitCode;

use serde_json::{json, Value};

use fmrh::export::gltf::{glb, GltfBlock};
use fmrh::export::quantized_mesh::{self, QuantizedTile};
use fmrh::heightfield::Georeference;
use fmrh::mesh::{build, BlockMesh, Cracks, GridBlock};
use fmrh::model::SampleRect;
use fmrh::scene::{load_blocks, LoadedBlock, SceneBlock, Terrain, WorldFrame, PAYLOAD_GAP};
use fmrh::Error;

/// How the mesh closes cracks, as `--cracks` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CracksArg {
    /// A block meeting a coarser one takes its vertices along the shared edge: no crack,
    /// no T-junction.
    Stitch,
    /// Every block keeps its own surface and hangs a curtain below edges that meet
    /// another block, as deep as both blocks' errors.
    Skirts,
}

/// What `fmrh mesh` writes, as `--format` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MeshFormat {
    /// One glTF 2.0 binary: a node and a mesh per block.
    Glb,
    /// A directory: `layer.json` and one quantized-mesh-1.0 tile per block, at
    /// `LEVEL/X/Y.terrain` (y counted from the south).
    QuantizedMesh,
}

#[derive(clap::Args)]
pub struct MeshArgs {
    /// The container or a dataset's directory (a path or an http(s):// or s3:// URL).
    file: PathBuf,
    #[command(flatten)]
    camera: super::scene::CameraArgs,
    #[command(flatten)]
    view: super::scene::ViewArgs,
    /// Mesh only this window, inclusive samples c0,r0,c1,r1 (default: what the frustum
    /// sees).
    #[arg(long)]
    window: Option<String>,
    /// How cracks between blocks of different levels are closed.
    #[arg(long, value_enum, default_value = "stitch")]
    cracks: CracksArg,
    /// What to write.
    #[arg(long, value_enum, default_value = "glb")]
    format: MeshFormat,
    /// The .glb to write (`-`: standard output), or the tile directory to create.
    #[arg(short, long)]
    output: PathBuf,
    /// Replace an existing output.
    #[arg(long)]
    force: bool,
}

/// A block of the scene to mesh, wherever it came from.
struct Part {
    block: SceneBlock,
    tile: Option<u64>,
    loaded: LoadedBlock,
    stride: u64,
    /// The node's whole footprint, padding included (its tile's rectangle).
    footprint: SampleRect,
}

/// What the scene's `extras` say besides the blocks.
struct Context {
    frame: WorldFrame,
    georeference: Option<Georeference>,
    tau: f64,
    mode: fmrh::scene::Mode,
}

/// Runs `fmrh mesh`.
pub fn run(args: &MeshArgs) -> Result<ExitCode, Error> {
    super::check_output(&args.output, args.force)?;
    if args.format == MeshFormat::QuantizedMesh
        && (args.output == std::path::Path::new("-") || super::is_dataset(&args.file)?)
    {
        return Err(Error::InvalidArgument(
            "quantized-mesh tiles are written to a directory (not `-`), from one container \
             (a dataset's tiles would share tile addresses)"
                .into(),
        ));
    }
    let camera = args.camera.camera(&args.view)?;
    let options = args.view.options_in(args.window.as_deref())?;
    let (parts, context) = if super::is_dataset(&args.file)? {
        let ds = fmrh::dataset::Dataset::open(&args.file)?;
        let spacing = args.view.given_spacing()?;
        let scene = ds.scene(&camera, &options, spacing)?;
        let loaded = ds.load_blocks(&scene)?;
        let parts = scene
            .blocks
            .iter()
            .zip(loaded)
            .map(|(b, (loaded, stride))| Part {
                block: b.block,
                tile: Some(b.tile),
                loaded,
                stride,
                footprint: b.block.rect(),
            })
            .collect();
        let context = Context {
            frame: WorldFrame::new(spacing.or(ds.spacing_m())),
            georeference: ds.georeference(),
            tau: scene.tau,
            mode: scene.mode,
        };
        (parts, context)
    } else if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        {
            tile_parts(args, &fmrh::Store::open_url(url)?, &camera, &options)?
        }
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    } else {
        tile_parts(args, &super::open(&args.file)?, &camera, &options)?
    };
    if parts.is_empty() {
        return Err(Error::InvalidArgument(
            "the camera sees no terrain: there is nothing to mesh (give --window)".into(),
        ));
    }
    let cracks = match args.cracks {
        CracksArg::Stitch => Cracks::Stitch,
        CracksArg::Skirts => Cracks::Skirts,
    };
    let grids: Vec<GridBlock<'_>> = parts
        .iter()
        .map(|p| GridBlock {
            rect: p.block.rect(),
            stride: p.stride,
            grid_width: p.loaded.width,
            grid_height: p.loaded.height,
            heights: &p.loaded.heights,
            error: p.block.error,
        })
        .collect();
    let meshes = build(&grids, &context.frame, cracks)?;
    let triangles: usize = meshes.iter().map(|m| m.triangles.len()).sum();
    let stitched = meshes.iter().filter(|m| m.stitched.contains(&true)).count();
    let bytes = match args.format {
        MeshFormat::Glb => {
            let bytes = encode(&parts, &meshes, &context, cracks)?;
            super::write_output(&args.output, args.force, &bytes)?;
            bytes.len() as u64
        }
        MeshFormat::QuantizedMesh => write_tiles(args, &parts, &meshes, &context)?,
    };
    eprintln!(
        "fmrh: meshed {} blocks ({} stitched to a neighbour) as {} triangles, {} bytes{}",
        meshes.len(),
        stitched,
        triangles,
        bytes,
        if args.output == std::path::Path::new("-") {
            String::new()
        } else {
            format!(" in {}", args.output.display())
        }
    );
    Ok(ExitCode::SUCCESS)
}

/// Writes one quantized-mesh tile per block and `layer.json` into a new directory beside
/// `args.output`, then renames it into place (an existing directory is replaced only with
/// --force). Returns the bytes of the tiles.
fn write_tiles(
    args: &MeshArgs,
    parts: &[Part],
    meshes: &[BlockMesh],
    context: &Context,
) -> Result<u64, Error> {
    let out = &args.output;
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let temp = tempfile::Builder::new()
        .prefix(".fmrh-tiles-")
        .tempdir_in(&parent)
        .map_err(|e| Error::io(&parent, e))?;
    let mut total = 0u64;
    // Per level: the tiles written, as (x, y) with y counted from the south.
    let mut levels: std::collections::BTreeMap<u8, Vec<(u32, u32)>> = Default::default();
    for m in meshes {
        let p = &parts[m.block];
        let b = &p.block;
        let y = (1u32 << b.level) - 1 - b.y;
        let f = &p.footprint;
        let tile = QuantizedTile {
            mesh: m,
            rect: [f.col0, f.row0, f.col1, f.row1],
            metadata: json!({ "fmrh": block_extras(p, m) }),
        };
        let bytes = quantized_mesh::encode(&tile, &context.frame)?;
        let dir = temp.path().join(b.level.to_string()).join(b.x.to_string());
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let path = dir.join(format!("{y}.terrain"));
        std::fs::write(&path, &bytes).map_err(|e| Error::io(&path, e))?;
        total += bytes.len() as u64;
        levels.entry(b.level).or_default().push((b.x, y));
    }
    let layer = layer_json(parts, meshes, context, &levels);
    let path = temp.path().join("layer.json");
    let text =
        serde_json::to_vec_pretty(&layer).map_err(|e| Error::InvalidArgument(e.to_string()))?;
    std::fs::write(&path, text).map_err(|e| Error::io(&path, e))?;
    let kept = temp.keep();
    if out.exists() {
        if !args.force {
            let _ = std::fs::remove_dir_all(&kept);
            return super::check_output(out, false).map(|()| 0);
        }
        let old = parent.join(format!(".fmrh-tiles-old-{}", std::process::id()));
        std::fs::rename(out, &old).map_err(|e| Error::io(out, e))?;
        std::fs::rename(&kept, out).map_err(|e| Error::io(out, e))?;
        let _ = std::fs::remove_dir_all(&old);
    } else {
        std::fs::rename(&kept, out).map_err(|e| Error::io(out, e))?;
    }
    Ok(total)
}

/// The tileset's `layer.json`: TileJSON as Cesium reads it, with the tiles available at
/// each level, and an `fmrh` object saying what the tiles are.
fn layer_json(
    parts: &[Part],
    meshes: &[BlockMesh],
    context: &Context,
    levels: &std::collections::BTreeMap<u8, Vec<(u32, u32)>>,
) -> Value {
    let available: Vec<Value> = (0..=levels.keys().max().copied().unwrap_or(0))
        .map(|l| {
            let mut tiles = levels.get(&l).cloned().unwrap_or_default();
            tiles.sort_unstable_by_key(|&(x, y)| (y, x));
            // Runs of neighbours along a row, as ranges.
            let mut ranges: Vec<Value> = Vec::new();
            let mut i = 0;
            while i < tiles.len() {
                let (x0, y) = tiles[i];
                let mut x1 = x0;
                while i + 1 < tiles.len() && tiles[i + 1] == (x1 + 1, y) {
                    i += 1;
                    x1 += 1;
                }
                ranges.push(json!({ "startX": x0, "startY": y, "endX": x1, "endY": y }));
                i += 1;
            }
            Value::Array(ranges)
        })
        .collect();
    let level_notes: Vec<Value> = levels
        .iter()
        .map(|(l, tiles)| {
            let p = meshes
                .iter()
                .map(|m| &parts[m.block])
                .find(|p| p.block.level == *l);
            let side = p.map_or(0, |p| p.footprint.col1 - p.footprint.col0);
            json!({
                "level": l,
                "tiles": tiles.len(),
                "tile_side_samples": side,
                "tile_side_m": [side as f64 * context.frame.dx, side as f64 * context.frame.dy],
                "stride_samples": p.map_or(0, |p| p.stride),
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
        "available": available,
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

/// What a block's node (glTF) or tile (quantized-mesh) says of it.
fn block_extras(p: &Part, m: &BlockMesh) -> Value {
    let b = &p.block;
    let mut extras = json!({
        "level": b.level,
        "error": b.error,
        "key": b.key,
        "x": b.x,
        "y": b.y,
        "footprint": [b.col0, b.row0, b.col1, b.row1],
        "synthetic": false,
        "stitched": m.stitched,
    });
    if let Some(t) = p.tile {
        extras["tile"] = json!(t);
    }
    extras
}

/// The scene of one container, its blocks read and decoded.
fn tile_parts<S: fmrh::store::Source>(
    args: &MeshArgs,
    store: &fmrh::Store<S>,
    camera: &fmrh::scene::Camera,
    options: &fmrh::scene::SceneOptions,
) -> Result<(Vec<Part>, Context), Error> {
    let spacing = args.view.spacing(store, &args.file)?;
    let terrain = Terrain::with_spacing(store, spacing)?;
    let scene = terrain.scene(camera, options)?;
    let loaded = load_blocks(store, &scene.blocks, PAYLOAD_GAP)?;
    let d = *store.domain();
    let parts = scene
        .blocks
        .iter()
        .zip(loaded)
        .map(|(b, loaded)| Part {
            block: *b,
            tile: None,
            loaded,
            stride: d.stride(b.level),
            footprint: d.footprint(b.level, b.x, b.y),
        })
        .collect();
    let metadata = &store.header().metadata;
    let context = Context {
        frame: WorldFrame::new(spacing.or(metadata.spacing_m)),
        georeference: metadata.georeference.clone(),
        tau: scene.tau,
        mode: scene.mode,
    };
    Ok((parts, context))
}

/// The GLB: each block's node named by its level and key, with its facts in `extras`; the
/// scene's `extras` say where the origin is and how the axes run.
fn encode(
    parts: &[Part],
    meshes: &[BlockMesh],
    context: &Context,
    cracks: Cracks,
) -> Result<Vec<u8>, Error> {
    let frame = &context.frame;
    let col0 = meshes.iter().map(|m| parts[m.block].block.col0).min();
    let row0 = meshes.iter().map(|m| parts[m.block].block.row0).min();
    let (Some(col0), Some(row0)) = (col0, row0) else {
        return Err(Error::InvalidArgument(
            "nothing to mesh: no block has an area".into(),
        ));
    };
    let origin = [col0 as f64 * frame.dx, row0 as f64 * frame.dy];
    let blocks: Vec<GltfBlock<'_>> = meshes
        .iter()
        .map(|m| {
            let p = &parts[m.block];
            let b = &p.block;
            GltfBlock {
                mesh: m,
                name: match p.tile {
                    Some(t) => format!("tile {t} level {} key {}", b.level, b.key),
                    None => format!("level {} key {}", b.level, b.key),
                },
                level: b.level,
                extras: json!({ "fmrh": block_extras(p, m) }),
            }
        })
        .collect();
    let mut origin_extras = json!({
        "sample": [col0, row0],
        "world_m": origin,
    });
    if let Some(g) = &context.georeference {
        origin_extras["map"] = json!([
            g.origin[0] + col0 as f64 * g.step[0],
            g.origin[1] + row0 as f64 * g.step[1]
        ]);
        origin_extras["crs"] = g.crs.clone().map_or(Value::Null, Value::from);
    }
    let scene_extras = json!({
        "fmrh": {
            "axes": "X east, Y up (height), Z south, in metres; X and Z from the origin",
            "origin": origin_extras,
            "spacing_m": [frame.dx, frame.dy],
            "cracks": cracks,
            "tau": context.tau,
            "mode": context.mode,
            "blocks": meshes.len(),
        }
    });
    glb(&blocks, frame, origin, scene_extras)
}
