//! `fmrh mesh`: a scene as triangles (`fmrh::mesh`), crack-free, written as one glTF 2.0
//! binary (`fmrh::export::gltf`): one node per block, with its level, error and key; or as
//! a directory of Cesium quantized-mesh tiles and their `layer.json`
//! (`fmrh::export::quantized_mesh`), one tile per block.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use serde_json::{json, Value};

use fmrh::export::gltf::{glb, GltfBlock};
use fmrh::export::quantized_mesh::{self, QuantizedTile};
use fmrh::heightfield::Georeference;
use fmrh::mesh::{build, fractal, BlockMesh, Cracks, GridBlock};
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

/// Refinement past the data, as `--refine` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RefineArg {
    /// Seed 004's fractal nodes: noise seeded by the block's key, amplitude from its
    /// roughness, each depth's error half the one above.
    Fractal,
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
    /// Refine past the data where the camera is closer than the data's detail: synthetic
    /// nodes below the physical blocks, deterministic, marked synthetic in every output.
    #[arg(long, value_enum)]
    refine: Option<RefineArg>,
    /// The .glb to write (`-`: standard output), or the tile directory to create.
    #[arg(short, long)]
    output: PathBuf,
    /// Replace an existing output.
    #[arg(long)]
    force: bool,
}

/// A block to mesh, wherever it came from: a scene block, or a synthetic node below one.
/// Rectangles and strides are in mesh units (`Context::units` a sample).
struct Part {
    /// The scene block (a synthetic node's physical block).
    block: SceneBlock,
    tile: Option<u64>,
    rect: SampleRect,
    stride: u64,
    width: u32,
    height: u32,
    heights: Arc<[f32]>,
    /// The node's whole footprint, padding included (its quantized-mesh tile).
    footprint: SampleRect,
    /// Depth, column and row below the physical block, and declared error.
    synthetic: Option<(u8, u32, u32, f64)>,
}

impl Part {
    fn of(
        block: SceneBlock,
        tile: Option<u64>,
        loaded: LoadedBlock,
        stride: u64,
        footprint: SampleRect,
    ) -> Part {
        Part {
            block,
            tile,
            rect: block.rect(),
            stride,
            width: loaded.width,
            height: loaded.height,
            heights: loaded.heights,
            footprint,
            synthetic: None,
        }
    }

    /// Level, column and row in the quadtree (a synthetic node's below its block's).
    fn node(&self) -> (u8, u32, u32) {
        let b = &self.block;
        match self.synthetic {
            Some((d, x, y, _)) => (b.level + d, (b.x << d) + x, (b.y << d) + y),
            None => (b.level, b.x, b.y),
        }
    }

    fn error(&self) -> f64 {
        self.synthetic.map_or(self.block.error, |s| s.3)
    }
}

/// What the scene's `extras` say besides the blocks.
struct Context {
    /// The world frame of samples.
    frame: WorldFrame,
    georeference: Option<Georeference>,
    tau: f64,
    mode: fmrh::scene::Mode,
    /// Mesh units a sample: 1, or `fractal::SCALE` when refined past the data.
    units: u64,
}

impl Context {
    /// The frame of mesh units.
    fn mesh_frame(&self) -> WorldFrame {
        let k = self.units as f64;
        WorldFrame {
            dx: self.frame.dx / k,
            dy: self.frame.dy / k,
        }
    }
}

/// Replaces each physical block that the camera sees closer than its data's detail with
/// synthetic nodes (`fmrh::mesh::fractal`), and puts every part in mesh units.
fn refine_fractal(
    parts: Vec<Part>,
    camera: &fmrh::scene::Camera,
    context: &mut Context,
) -> Result<Vec<Part>, Error> {
    let view = camera.view()?;
    let k = fractal::SCALE;
    context.units = k;
    let scaled = |r: SampleRect| SampleRect {
        col0: r.col0 * k,
        row0: r.row0 * k,
        col1: r.col1 * k,
        row1: r.row1 * k,
    };
    let mut out = Vec::new();
    for mut p in parts {
        let grid = GridBlock {
            rect: p.rect,
            stride: p.stride,
            grid_width: p.width,
            grid_height: p.height,
            heights: &p.heights,
            error: p.block.error,
        };
        let nodes = fractal::refine_block(p.block.key, &grid, &view, &context.frame, context.tau);
        p.rect = scaled(p.rect);
        p.footprint = scaled(p.footprint);
        p.stride *= k;
        if nodes.is_empty() {
            out.push(p);
            continue;
        }
        for n in nodes {
            out.push(Part {
                block: p.block,
                tile: p.tile,
                rect: n.rect,
                stride: n.stride,
                width: p.width,
                height: p.width,
                heights: n.heights.into(),
                footprint: n.rect,
                synthetic: Some((n.depth, n.x, n.y, n.error)),
            });
        }
    }
    Ok(out)
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
    let cracks = match args.cracks {
        CracksArg::Stitch => Cracks::Stitch,
        CracksArg::Skirts => Cracks::Skirts,
    };
    let meshed = mesh_scene(
        &args.file,
        &args.view,
        &camera,
        &options,
        cracks,
        args.refine,
    )?;
    let (parts, meshes, context) = (&meshed.parts, &meshed.meshes, &meshed.context);
    let triangles = meshed.triangles();
    let stitched = meshes.iter().filter(|m| m.stitched.contains(&true)).count();
    let synthetic = meshed.synthetic();
    let bytes = match args.format {
        MeshFormat::Glb => {
            let bytes = meshed.glb()?;
            super::write_output(&args.output, args.force, &bytes)?;
            bytes.len() as u64
        }
        MeshFormat::QuantizedMesh => write_tiles(args, parts, meshes, context)?,
    };
    eprintln!(
        "fmrh: meshed {} blocks ({} stitched to a neighbour{}) as {} triangles, {} bytes{}",
        meshes.len(),
        stitched,
        if args.refine.is_some() {
            format!(", {synthetic} synthetic")
        } else {
            String::new()
        },
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

/// A scene meshed: its parts (blocks and synthetic nodes), their meshes, and what the
/// extras say. `fmrh mesh` writes it; `fmrh serve` sends it to the viewer.
pub struct Meshed {
    parts: Vec<Part>,
    meshes: Vec<BlockMesh>,
    context: Context,
    cracks: Cracks,
}

impl Meshed {
    /// The scene as one glTF 2.0 binary.
    pub fn glb(&self) -> Result<Vec<u8>, Error> {
        encode(&self.parts, &self.meshes, &self.context, self.cracks)
    }

    /// Triangles of all the meshes.
    pub fn triangles(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// Meshes of synthetic nodes.
    pub fn synthetic(&self) -> usize {
        self.parts.iter().filter(|p| p.synthetic.is_some()).count()
    }
}

/// Meshes the scene `camera` sees of `file` (a container, a dataset, or a URL of either)
/// with `options`, its cracks closed as `cracks` says, refined past the data as `refine`
/// says. An error when the camera sees no terrain.
pub fn mesh_scene(
    file: &std::path::Path,
    view: &super::scene::ViewArgs,
    camera: &fmrh::scene::Camera,
    options: &fmrh::scene::SceneOptions,
    cracks: Cracks,
    refine: Option<RefineArg>,
) -> Result<Meshed, Error> {
    let (parts, mut context) = if super::is_dataset(file)? {
        let ds = fmrh::dataset::Dataset::open(file)?;
        let spacing = view.given_spacing()?;
        let scene = ds.scene(camera, options, spacing)?;
        let loaded = ds.load_blocks(&scene)?;
        let parts = scene
            .blocks
            .iter()
            .zip(loaded)
            .map(|(b, (loaded, stride))| {
                Part::of(b.block, Some(b.tile), loaded, stride, b.block.rect())
            })
            .collect();
        let context = Context {
            frame: WorldFrame::new(spacing.or(ds.spacing_m())),
            georeference: ds.georeference(),
            tau: scene.tau,
            mode: scene.mode,
            units: 1,
        };
        (parts, context)
    } else if let Some(url) = super::url_of(file) {
        #[cfg(feature = "remote")]
        {
            tile_parts(file, view, &fmrh::Store::open_url(url)?, camera, options)?
        }
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    } else {
        tile_parts(file, view, &super::open(file)?, camera, options)?
    };
    if parts.is_empty() {
        return Err(Error::InvalidArgument(
            "the camera sees no terrain: there is nothing to mesh (give --window)".into(),
        ));
    }
    let parts = match refine {
        Some(RefineArg::Fractal) => refine_fractal(parts, camera, &mut context)?,
        None => parts,
    };
    let grids: Vec<GridBlock<'_>> = parts
        .iter()
        .map(|p| GridBlock {
            rect: p.rect,
            stride: p.stride,
            grid_width: p.width,
            grid_height: p.height,
            heights: &p.heights,
            error: p.error(),
        })
        .collect();
    let meshes = build(&grids, &context.mesh_frame(), cracks)?;
    Ok(Meshed {
        parts,
        meshes,
        context,
        cracks,
    })
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
        let (level, x, y) = p.node();
        let y = (1u32 << level) - 1 - y;
        let f = &p.footprint;
        let tile = QuantizedTile {
            mesh: m,
            rect: [f.col0, f.row0, f.col1, f.row1],
            metadata: json!({ "fmrh": block_extras(p, m, context.units) }),
        };
        let bytes = quantized_mesh::encode(&tile, &context.mesh_frame())?;
        let dir = temp.path().join(level.to_string()).join(x.to_string());
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let path = dir.join(format!("{y}.terrain"));
        std::fs::write(&path, &bytes).map_err(|e| Error::io(&path, e))?;
        total += bytes.len() as u64;
        levels.entry(level).or_default().push((x, y));
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
fn block_extras(p: &Part, m: &BlockMesh, units: u64) -> Value {
    let b = &p.block;
    let (level, x, y) = p.node();
    let k = units as f64;
    let r = &p.rect;
    let mut extras = json!({
        "level": level,
        "error": p.error(),
        "key": b.key,
        "x": x,
        "y": y,
        "footprint": [r.col0 as f64 / k, r.row0 as f64 / k, r.col1 as f64 / k, r.row1 as f64 / k],
        "synthetic": p.synthetic.is_some(),
        "stitched": m.stitched,
    });
    if let Some((depth, ..)) = p.synthetic {
        // Generated below a physical block (its key and level), never stored.
        extras["depth"] = json!(depth);
        extras["physical_level"] = json!(b.level);
    }
    if let Some(t) = p.tile {
        extras["tile"] = json!(t);
    }
    extras
}

/// The scene of one container, its blocks read and decoded.
fn tile_parts<S: fmrh::store::Source>(
    file: &std::path::Path,
    view: &super::scene::ViewArgs,
    store: &fmrh::Store<S>,
    camera: &fmrh::scene::Camera,
    options: &fmrh::scene::SceneOptions,
) -> Result<(Vec<Part>, Context), Error> {
    let spacing = view.spacing(store, file)?;
    let terrain = Terrain::with_spacing(store, spacing)?;
    let scene = terrain.scene(camera, options)?;
    let loaded = load_blocks(store, &scene.blocks, PAYLOAD_GAP)?;
    let d = *store.domain();
    let parts = scene
        .blocks
        .iter()
        .zip(loaded)
        .map(|(b, loaded)| {
            Part::of(
                *b,
                None,
                loaded,
                d.stride(b.level),
                d.footprint(b.level, b.x, b.y),
            )
        })
        .collect();
    let metadata = &store.header().metadata;
    let context = Context {
        frame: WorldFrame::new(spacing.or(metadata.spacing_m)),
        georeference: metadata.georeference.clone(),
        tau: scene.tau,
        mode: scene.mode,
        units: 1,
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
    let frame = &context.mesh_frame();
    let col0 = meshes.iter().map(|m| parts[m.block].rect.col0).min();
    let row0 = meshes.iter().map(|m| parts[m.block].rect.row0).min();
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
            let (level, key) = (p.node().0, p.block.key);
            let kind = if p.synthetic.is_some() {
                " synthetic"
            } else {
                ""
            };
            GltfBlock {
                mesh: m,
                name: match p.tile {
                    Some(t) => format!("tile {t} level {level} key {key}{kind}"),
                    None => format!("level {level} key {key}{kind}"),
                },
                level,
                extras: json!({ "fmrh": block_extras(p, m, context.units) }),
            }
        })
        .collect();
    let (c, r) = (
        col0 as f64 / context.units as f64,
        row0 as f64 / context.units as f64,
    );
    let mut origin_extras = json!({
        "sample": [c, r],
        "world_m": origin,
    });
    if let Some(g) = &context.georeference {
        origin_extras["map"] = json!([g.origin[0] + c * g.step[0], g.origin[1] + r * g.step[1]]);
        origin_extras["crs"] = g.crs.clone().map_or(Value::Null, Value::from);
    }
    let scene_extras = json!({
        "fmrh": {
            "axes": "X east, Y up (height), Z south, in metres; X and Z from the origin",
            "origin": origin_extras,
            "spacing_m": [context.frame.dx, context.frame.dy],
            "refine": if context.units > 1 { "fractal" } else { "none" },
            "cracks": cracks,
            "tau": context.tau,
            "mode": context.mode,
            "blocks": meshes.len(),
        }
    });
    glb(&blocks, frame, origin, scene_extras)
}
