//! `fmrh mesh`: a scene as triangles (`crate::mesh`), crack-free, written as one glTF 2.0
//! binary (`crate::export::gltf`): one node per block, with its level, error and key; or as
//! a directory of Cesium quantized-mesh tiles and their `layer.json` ([`tiles`]): the
//! global-geodetic pyramid over georeferenced data, or one tile per block.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use serde_json::{json, Value};

use super::args::RefineArg;
use crate::export::gltf::{glb_in, GltfBlock, GltfFrame};
use crate::heightfield::Georeference;
use crate::mesh::{build_in, build_tin_in, fractal, BlockMesh, Cracks};
use crate::model::SampleRect;
use crate::scene::surface::GridBlock;
use crate::scene::{load_blocks, LoadedBlock, SceneBlock, Terrain, WorldFrame, PAYLOAD_GAP};
use crate::Error;

mod tiles;

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
    /// A directory: `layer.json` and quantized-mesh-1.0 tiles at `LEVEL/X/Y.terrain` (y
    /// counted from the south): the global-geodetic pyramid over georeferenced data, else
    /// one tile per block (see --tiling).
    QuantizedMesh,
}

/// How quantized-mesh tiles are laid out, as `--tiling` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TilingArg {
    /// Geodetic when the data's georeference can be placed on the globe, else nodes.
    Auto,
    /// Cesium's global-geodetic pyramid (EPSG:4326, two root tiles): a tileset Cesium can
    /// load as it is. Needs a georeference with a CRS.
    Geodetic,
    /// One tile per block, addressed by its fmrh node, in a local frame.
    Nodes,
}

#[derive(clap::Args)]
pub struct MeshArgs {
    /// The container or a dataset's directory (a path or an http(s):// or s3:// URL).
    file: PathBuf,
    #[command(flatten)]
    camera: super::args::CameraArgs,
    #[command(flatten)]
    view: super::args::ViewArgs,
    /// Mesh only this window, inclusive samples c0,r0,c1,r1 (default: what the frustum
    /// sees).
    #[arg(long)]
    window: Option<String>,
    /// How cracks between blocks of different levels are closed (default: stitch; skirts
    /// with --max-error).
    #[arg(long, value_enum)]
    cracks: Option<CracksArg>,
    /// Mesh each block as a TIN within this many metres of its grid (the coarsest
    /// right-triangulated network; each block's measured error is in its extras) instead
    /// of every grid point. TINs keep their own edge vertices, so cracks close with skirts.
    #[arg(long, value_name = "METRES")]
    max_error: Option<f64>,
    /// What to write.
    #[arg(long, value_enum, default_value = "glb")]
    format: MeshFormat,
    /// The tiling of quantized-mesh tiles.
    #[arg(long, value_enum, default_value = "auto")]
    tiling: TilingArg,
    /// Store quantized-mesh tiles gzipped, for a server that sends them with
    /// `Content-Encoding: gzip` (as the specification says tiles are served): a regular
    /// geodetic tile keeps about a fifteenth of its bytes.
    #[arg(long)]
    gzip: bool,
    /// Refine past the data where the camera is closer than the data's detail: synthetic
    /// nodes below the physical blocks, deterministic, marked synthetic in every output.
    #[arg(long, value_enum)]
    refine: Option<RefineArg>,
    /// What to write, by its name: `X.glb` a binary glTF (`-`: to standard output), `X.gltf`
    /// a JSON glTF with its buffer in `X.bin` beside it; with --format quantized-mesh the
    /// tile directory to create. Any other name is refused.
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

    /// The part as the mesh and the surface take it.
    fn grid(&self) -> GridBlock<'_> {
        GridBlock {
            rect: self.rect,
            stride: self.stride,
            grid_width: self.width,
            grid_height: self.height,
            heights: &self.heights,
            error: self.error(),
        }
    }
}

/// What the scene's `extras` say besides the blocks.
struct Context {
    /// The world frame of samples.
    frame: WorldFrame,
    /// With a camera on the globe: where the samples are on it (the meshes' vertices then
    /// go into a local east-north-up frame).
    globe: Option<crate::scene::GlobeFrame>,
    georeference: Option<Georeference>,
    tau: f64,
    mode: crate::scene::Mode,
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
/// synthetic nodes (`crate::mesh::fractal`), and puts every part in mesh units.
fn refine_fractal(
    parts: Vec<Part>,
    camera: &crate::scene::Camera,
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
        let nodes =
            fractal::refine_block(p.block.key, &p.grid(), &view, &context.frame, context.tau);
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

/// A glTF output, as its name says.
enum GltfOutput {
    /// Binary glTF to this path or `-`.
    Glb,
    /// JSON glTF, its buffer in the `.bin` of this path and named by this URI.
    Gltf { bin: PathBuf, uri: String },
}

/// What `output` asks for: `.glb` or `-`, or `.gltf` (its `.bin` beside it, checked as an
/// output too). Anything else is refused, so `-o mesh.obj` never gets GLB bytes.
fn gltf_output(output: &std::path::Path, force: bool) -> Result<GltfOutput, Error> {
    if output == std::path::Path::new("-") {
        return Ok(GltfOutput::Glb);
    }
    let ext = output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("glb") => Ok(GltfOutput::Glb),
        Some("gltf") => {
            let bin = output.with_extension("bin");
            super::check_output(&bin, force)?;
            let uri = bin
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            Ok(GltfOutput::Gltf { bin, uri })
        }
        other => Err(Error::InvalidArgument(format!(
            "-o {}: fmrh mesh writes glTF, as `X.glb` (binary) or `X.gltf` (JSON, with \
             `X.bin` beside it){}",
            output.display(),
            match other {
                Some(e) => format!("; it does not write .{e}"),
                None => String::new(),
            }
        ))),
    }
}

/// Runs `fmrh mesh`.
pub fn run(args: &MeshArgs) -> Result<ExitCode, Error> {
    super::check_output(&args.output, args.force)?;
    let gltf = if args.format == MeshFormat::Glb {
        Some(gltf_output(&args.output, args.force)?)
    } else {
        None
    };
    if args.format == MeshFormat::QuantizedMesh && args.output == std::path::Path::new("-") {
        return Err(Error::InvalidArgument(
            "quantized-mesh tiles are written to a directory, not `-`".into(),
        ));
    }
    let camera = args.camera.camera(&args.view)?;
    let globe = args.camera.globe();
    args.view.flat_spacing_only(globe)?;
    if globe && args.format == MeshFormat::QuantizedMesh {
        return Err(Error::InvalidArgument(
            "quantized-mesh tiles follow their own geodetic tiling from a flat-frame camera; \
             on the globe (--eye-geo, --globe) fmrh mesh writes a .glb"
                .into(),
        ));
    }
    if globe && args.refine.is_some() {
        return Err(Error::InvalidArgument(
            "--refine takes flat-frame cameras only so far (no --globe or --eye-geo)".into(),
        ));
    }
    let options = args.view.options_in(args.window.as_deref())?;
    let style = args.style()?;
    if args.format == MeshFormat::QuantizedMesh {
        return tiles::run_tiles(args, &camera, &options);
    }
    if args.gzip {
        return Err(Error::InvalidArgument(
            "--gzip applies to quantized-mesh tiles, not to a .glb".into(),
        ));
    }
    let meshed = mesh_scene(
        &args.file,
        &args.view,
        &camera,
        &options,
        style,
        args.refine,
        globe,
    )?;
    let meshes = &meshed.meshes;
    let triangles = meshed.triangles();
    let stitched = meshes.iter().filter(|m| m.stitched.contains(&true)).count();
    let synthetic = meshed.synthetic();
    let bytes = meshed.glb()?;
    let bytes = match gltf {
        Some(GltfOutput::Gltf { bin, uri }) => {
            let (json, buffer) = crate::export::gltf::gltf_from_glb(&bytes, &uri)?;
            // The buffer first: the JSON that names it appears only once it is there.
            super::write_output(&bin, args.force, &buffer)?;
            super::write_output(&args.output, args.force, &json)?;
            (json.len() + buffer.len()) as u64
        }
        _ => {
            super::write_output(&args.output, args.force, &bytes)?;
            bytes.len() as u64
        }
    };
    let how = match style {
        MeshStyle::Grid(_) => format!("{stitched} stitched to a neighbour"),
        MeshStyle::Tin(budget) => format!(
            "TINs within {budget} m, measured {} m at most",
            meshes.iter().map(|m| m.tin_error).fold(0.0, f64::max)
        ),
    };
    eprintln!(
        "fmrh: meshed {} blocks ({how}{}) as {} triangles, {} bytes{}",
        meshes.len(),
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

impl MeshArgs {
    /// The mesh style `--cracks` and `--max-error` ask for.
    fn style(&self) -> Result<MeshStyle, Error> {
        let cracks = match self.cracks {
            Some(CracksArg::Skirts) => Cracks::Skirts,
            Some(CracksArg::Stitch) | None => Cracks::Stitch,
        };
        match self.max_error {
            None => Ok(MeshStyle::Grid(cracks)),
            Some(_) if self.cracks == Some(CracksArg::Stitch) => Err(Error::InvalidArgument(
                "--max-error meshes TINs, whose cracks close with skirts: leave out \
                 --cracks stitch"
                    .into(),
            )),
            Some(m) => MeshStyle::tin(m, "--max-error"),
        }
    }
}

/// How a block becomes triangles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeshStyle {
    /// Every grid point, cracks closed as the value says.
    Grid(Cracks),
    /// A TIN within the value's metres of the block's grid, with skirts
    /// ([`crate::mesh::build_tin_in`]).
    Tin(f64),
}

impl MeshStyle {
    /// A TIN within `metres`, which `name` gave: a finite number from 0 up.
    pub fn tin(metres: f64, name: &str) -> Result<MeshStyle, Error> {
        if metres >= 0.0 && metres.is_finite() {
            Ok(MeshStyle::Tin(metres))
        } else {
            Err(Error::InvalidArgument(format!(
                "{name} {metres}: must be a number of metres >= 0"
            )))
        }
    }

    /// How cracks are closed.
    fn cracks(self) -> Cracks {
        match self {
            MeshStyle::Grid(c) => c,
            MeshStyle::Tin(_) => Cracks::Skirts,
        }
    }
}

/// A scene meshed: its parts (blocks and synthetic nodes), their meshes, and what the
/// extras say. `fmrh mesh` writes it; `fmrh serve` sends it to the viewer.
pub struct Meshed {
    parts: Vec<Part>,
    meshes: Vec<BlockMesh>,
    context: Context,
    style: MeshStyle,
}

impl Meshed {
    /// The scene as one glTF 2.0 binary.
    pub fn glb(&self) -> Result<Vec<u8>, Error> {
        encode(&self.parts, &self.meshes, &self.context, self.style)
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
/// with `options`, each block meshed as `style` says, refined past the data as `refine`
/// says; `globe`: the camera is in ECEF and the data on the WGS 84 ellipsoid. An error when
/// the camera sees no terrain.
pub fn mesh_scene(
    file: &std::path::Path,
    view: &super::args::ViewArgs,
    camera: &crate::scene::Camera,
    options: &crate::scene::SceneOptions,
    style: MeshStyle,
    refine: Option<RefineArg>,
    globe: bool,
) -> Result<Meshed, Error> {
    let (parts, _, context) = scene_parts(file, view, camera, options, |_| false, globe)?;
    finish_meshes(parts, context, camera, style, refine)
}

/// Meshes the scene blocks `parts` (refined past the data as `refine` says) with their
/// each meshed as `style` says.
fn finish_meshes(
    parts: Vec<Part>,
    mut context: Context,
    camera: &crate::scene::Camera,
    style: MeshStyle,
    refine: Option<RefineArg>,
) -> Result<Meshed, Error> {
    if parts.is_empty() {
        return Err(Error::InvalidArgument(
            "the camera sees no terrain: there is nothing to mesh (give --window)".into(),
        ));
    }
    let parts = match refine {
        Some(RefineArg::Fractal) => refine_fractal(parts, camera, &mut context)?,
        None => parts,
    };
    let grids: Vec<GridBlock<'_>> = parts.iter().map(Part::grid).collect();
    let frame = match context.globe {
        Some(g) if context.units == 1 => crate::scene::TerrainFrame::Globe(g),
        Some(_) => {
            return Err(Error::Internal(
                "a refined mesh on the globe (refinement is refused there)".into(),
            ))
        }
        None => crate::scene::TerrainFrame::Flat(context.mesh_frame()),
    };
    let meshes = match style {
        MeshStyle::Grid(cracks) => build_in(&grids, &frame, cracks)?,
        MeshStyle::Tin(budget) => build_tin_in(&grids, &frame, budget)?,
    };
    Ok(Meshed {
        parts,
        meshes,
        context,
        style,
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
        "tin_error": m.tin_error,
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

/// The scene `camera` sees of `file` (a container, a dataset, or a URL of either) with
/// `options`, opened once, its blocks read and decoded; when `cover` says so of the data's
/// georeference, also the scene of the whole data from the same camera
/// ([`cover_options`]), which answers where the camera's scene is silent.
fn scene_parts(
    file: &std::path::Path,
    view: &super::args::ViewArgs,
    camera: &crate::scene::Camera,
    options: &crate::scene::SceneOptions,
    cover: impl Fn(Option<&Georeference>) -> bool,
    globe: bool,
) -> Result<(Vec<Part>, Vec<Part>, Context), Error> {
    if super::is_dataset(file)? {
        let ds = crate::dataset::Dataset::open(file)?;
        let spacing = view.given_spacing()?;
        let frame = WorldFrame::new(spacing.or(ds.spacing_m()));
        let on_globe = globe.then(|| ds.globe_frame()).transpose()?;
        let parts_of = |camera: &crate::scene::Camera, options: &crate::scene::SceneOptions| {
            let scene = if globe {
                ds.scene_on_globe(camera, options)?
            } else {
                ds.scene(camera, options, spacing)?
            };
            let loaded = ds.load_blocks(&scene)?;
            let parts: Vec<Part> = scene
                .blocks
                .iter()
                .zip(loaded)
                .map(|(b, (loaded, stride))| {
                    Part::of(b.block, Some(b.tile), loaded, stride, b.block.rect())
                })
                .collect();
            Ok::<_, Error>((parts, scene.tau, scene.mode))
        };
        let georeference = ds.georeference();
        let wanted = cover(georeference.as_ref());
        let (parts, covering, tau, mode) =
            with_cover(parts_of, camera, options, ds.grid(), wanted)?;
        let context = Context {
            frame,
            globe: on_globe,
            georeference,
            tau,
            mode,
            units: 1,
        };
        Ok((parts, covering, context))
    } else if let Some(url) = super::url_of(file) {
        #[cfg(feature = "remote")]
        {
            tile_parts(
                file,
                view,
                &crate::store::Store::open_url(url)?,
                camera,
                options,
                cover,
                globe,
            )
        }
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    } else {
        tile_parts(
            file,
            view,
            &super::open(file)?,
            camera,
            options,
            cover,
            globe,
        )
    }
}

/// A scene's parts, with its tolerance and mode.
type SceneParts = (Vec<Part>, f64, crate::scene::Mode);

/// The scene `parts_of` gives for `camera` and `options`, its tolerance and mode, and with
/// `cover` the cover of `data` ([`cover_options`]) too.
fn with_cover(
    parts_of: impl Fn(&crate::scene::Camera, &crate::scene::SceneOptions) -> Result<SceneParts, Error>,
    camera: &crate::scene::Camera,
    options: &crate::scene::SceneOptions,
    data: SampleRect,
    cover: bool,
) -> Result<(Vec<Part>, Vec<Part>, f64, crate::scene::Mode), Error> {
    let (parts, tau, mode) = parts_of(camera, options)?;
    let covering = if cover {
        parts_of(camera, &cover_options(options, data))?.0
    } else {
        Vec::new()
    };
    Ok((parts, covering, tau, mode))
}

/// The options of the scene that covers all of `data` as `options` would from the same
/// camera: the same tolerance and mode over the whole data, blocks out of the frustum
/// meeting the tolerance as if they were in it. Where the camera's own scene stops, its
/// blocks are the camera's scene's neighbours in resolution.
fn cover_options(
    options: &crate::scene::SceneOptions,
    data: SampleRect,
) -> crate::scene::SceneOptions {
    let mut cover = *options;
    cover.window = Some(data);
    cover
}

/// The scene of one container, its blocks read and decoded, and when `cover` says so of its
/// georeference the scene of all its data from the same camera.
fn tile_parts<S: crate::store::Source>(
    file: &std::path::Path,
    view: &super::args::ViewArgs,
    store: &crate::store::Store<S>,
    camera: &crate::scene::Camera,
    options: &crate::scene::SceneOptions,
    cover: impl Fn(Option<&Georeference>) -> bool,
    globe: bool,
) -> Result<(Vec<Part>, Vec<Part>, Context), Error> {
    let (spacing, terrain) = if globe {
        (None, Terrain::on_globe(store)?)
    } else {
        let spacing = view.spacing(store, file)?;
        (spacing, Terrain::with_spacing(store, spacing)?)
    };
    let on_globe = match terrain.world() {
        crate::scene::TerrainFrame::Globe(g) => Some(g),
        crate::scene::TerrainFrame::Flat(_) => None,
    };
    let d = *store.domain();
    let metadata = &store.header().metadata;
    let frame = WorldFrame::new(spacing.or(metadata.spacing_m));
    let parts_of = |camera: &crate::scene::Camera, options: &crate::scene::SceneOptions| {
        let scene = terrain.scene(camera, options)?;
        let loaded = load_blocks(store, &scene.blocks, PAYLOAD_GAP)?;
        let parts: Vec<Part> = scene
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
        Ok::<_, Error>((parts, scene.tau, scene.mode))
    };
    let wanted = cover(metadata.georeference.as_ref());
    let (parts, covering, tau, mode) =
        with_cover(parts_of, camera, options, d.data_rect(), wanted)?;
    let context = Context {
        frame,
        globe: on_globe,
        georeference: metadata.georeference.clone(),
        tau,
        mode,
        units: 1,
    };
    Ok((parts, covering, context))
}

/// The GLB: each block's node named by its level and key, with its facts in `extras`; the
/// scene's `extras` say where the origin is and how the axes run.
fn encode(
    parts: &[Part],
    meshes: &[BlockMesh],
    context: &Context,
    style: MeshStyle,
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
    let place = match context.globe {
        None => GltfFrame::Flat {
            frame: *frame,
            origin,
        },
        Some(g) => {
            // The middle of what is meshed, on the ellipsoid.
            let col1 = meshes.iter().map(|m| parts[m.block].rect.col1).max();
            let row1 = meshes.iter().map(|m| parts[m.block].rect.row1).max();
            let (c1, r1) = (col1.unwrap_or(col0), row1.unwrap_or(row0));
            let (lon, lat) = g.lon_lat((col0 + c1) as f64 / 2.0, (row0 + r1) as f64 / 2.0);
            GltfFrame::Globe {
                frame: g,
                lon,
                lat: lat.clamp(-90.0, 90.0),
            }
        }
    };
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
    let axes = match place {
        GltfFrame::Flat { .. } => {
            "X east, Y up (height), Z south, in metres; X and Z from the origin"
        }
        GltfFrame::Globe { lon, lat, .. } => {
            origin_extras = json!({
                "lon_lat_h": [lon, lat, 0.0],
                "ecef": crate::globe::ecef(lon, lat, 0.0),
            });
            "WGS 84: X east, Y up, Z south at the origin (a local east-north-up frame, height 0), in metres"
        }
    };
    let scene_extras = json!({
        "fmrh": {
            "axes": axes,
            "origin": origin_extras,
            "spacing_m": [context.frame.dx, context.frame.dy],
            "refine": if context.units > 1 { "fractal" } else { "none" },
            "cracks": style.cracks(),
            "tin_max_error_m": match style {
                MeshStyle::Tin(budget) => json!(budget),
                MeshStyle::Grid(_) => Value::Null,
            },
            "tau": context.tau,
            "mode": context.mode,
            "blocks": meshes.len(),
        }
    });
    glb_in(&blocks, &place, scene_extras)
}
