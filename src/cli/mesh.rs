//! `fmrh mesh`: a scene as triangles (`fmrh::mesh`), crack-free, written as one glTF 2.0
//! binary (`fmrh::export::gltf`): one node per block, with its level, error and key.

use std::path::PathBuf;
use std::process::ExitCode;

use serde_json::{json, Value};

use fmrh::export::gltf::{glb, GltfBlock};
use fmrh::heightfield::Georeference;
use fmrh::mesh::{build, BlockMesh, Cracks, GridBlock};
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
    /// The .glb to write (`-`: standard output).
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
    let bytes = encode(&parts, &meshes, &context, cracks)?;
    super::write_output(&args.output, args.force, &bytes)?;
    let triangles: usize = meshes.iter().map(|m| m.triangles.len()).sum();
    let stitched = meshes.iter().filter(|m| m.stitched.contains(&true)).count();
    eprintln!(
        "fmrh: meshed {} blocks ({} stitched to a neighbour) as {} triangles, {} bytes{}",
        meshes.len(),
        stitched,
        triangles,
        bytes.len(),
        if args.output == std::path::Path::new("-") {
            String::new()
        } else {
            format!(" in {}", args.output.display())
        }
    );
    Ok(ExitCode::SUCCESS)
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
            GltfBlock {
                mesh: m,
                name: match p.tile {
                    Some(t) => format!("tile {t} level {} key {}", b.level, b.key),
                    None => format!("level {} key {}", b.level, b.key),
                },
                level: b.level,
                extras: json!({ "fmrh": extras }),
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
