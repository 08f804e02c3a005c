//! `fmrh scene`: one camera and a tolerance in pixels, the blocks that view needs out; with
//! `--reconstruct`, the surface they draw at full resolution.

use std::path::PathBuf;
use std::process::ExitCode;

use serde::Serialize;

use super::args::{CameraArgs, RefineArg, ViewArgs};
use fmrh::mesh::fractal;
use fmrh::model::SampleRect;
use fmrh::scene::surface::GridBlock;
use fmrh::scene::{
    load_blocks, reconstruct, Camera, LoadedBlock, Mode, Scene, SceneBlock, SceneOptions, Terrain,
    WorldFrame, PAYLOAD_GAP,
};
use fmrh::store::{ReadStats, RequestStats};
use fmrh::Error;

#[derive(clap::Args)]
pub struct SceneArgs {
    /// The container, or a dataset's directory (the camera is then in the dataset's world
    /// frame, the window in dataset samples).
    file: PathBuf,
    #[command(flatten)]
    camera: CameraArgs,
    #[command(flatten)]
    view: ViewArgs,
    /// Restrict the scene to this window, inclusive samples c0,r0,c1,r1 (default: what the
    /// frustum sees).
    #[arg(long)]
    window: Option<String>,
    /// Write the window at full resolution as the scene's blocks draw it (.f32 + .json, or
    /// a GeoTIFF when the name ends in .tif or with --format tif).
    #[arg(long)]
    reconstruct: Option<PathBuf>,
    /// The --reconstruct file's format (default: from its name).
    #[arg(long, value_enum, requires = "reconstruct")]
    format: Option<super::sidecar::RasterFormat>,
    /// Replace existing --reconstruct files.
    #[arg(long)]
    force: bool,
    /// Read and decode every block's payload, as a renderer would (adjacent payloads in one
    /// read), and report what that read.
    #[arg(long)]
    load: bool,
    /// Refine past the data where the camera is closer than the data's detail, and report
    /// the synthetic nodes (`fmrh mesh --refine` draws them). Reads the blocks' payloads.
    #[arg(long, value_enum, conflicts_with = "reconstruct")]
    refine: Option<RefineArg>,
    /// A geographic container drawn above FILE where it has data, on the globe (repeatable:
    /// each above those before; needs --eye-geo or --globe). FILE is then the base layer,
    /// e.g. a whole-Earth grid, and each block of a lower layer lists the parts the layers
    /// above draw instead (its cut-outs); with --load, each block's skirt along the seams.
    #[arg(long = "layer", value_name = "FILE", conflicts_with_all = ["window", "reconstruct", "refine"])]
    layers: Vec<PathBuf>,
    /// Print the scene as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What the scene read from the file, by phase.
#[derive(Serialize)]
struct Reads {
    /// Opening: the commit slots, the dataset header, the cluster directory.
    open: ReadStats,
    /// Scheduling: index and node pages (each read once, then cached).
    schedule: ReadStats,
    /// Loading the blocks (--load, --reconstruct or --refine): their payloads.
    load: Option<ReadStats>,
}

/// `--refine fractal`: the synthetic nodes that replace the physical blocks the camera sees
/// closer than their data's detail (`fmrh::mesh::fractal`). Generated, never stored.
#[derive(Serialize)]
struct FractalReport {
    /// A synthetic grid's units a sample (`fractal::SCALE`).
    scale: u64,
    /// The most depths below a physical block.
    max_depth: u8,
    /// Physical blocks replaced by synthetic nodes.
    refined_blocks: usize,
    /// The largest declared error of a synthetic node, in pixels (0 without nodes).
    max_screen_error: f64,
    nodes: Vec<FractalNode>,
}

/// One synthetic node.
#[derive(Serialize)]
struct FractalNode {
    /// Always true: the node is generated, never stored.
    synthetic: bool,
    /// The physical block it replaces part of.
    physical: PhysicalRef,
    /// Depth below it.
    depth: u8,
    /// Level, column and row in the quadtree, past the stored levels.
    level: u8,
    x: u32,
    y: u32,
    /// Footprint in samples (fractions of a sample), c0, r0, c1, r1.
    footprint: [f64; 4],
    /// Grid spacing in samples.
    stride: f64,
    /// Declared error `e_k`, metres.
    error: f64,
    /// It in pixels.
    screen_error: f64,
}

/// A physical block, by tile (datasets), level, position and key.
#[derive(Serialize)]
struct PhysicalRef {
    #[serde(skip_serializing_if = "Option::is_none")]
    tile: Option<u64>,
    level: u8,
    x: u32,
    y: u32,
    key: u64,
}

/// Refines each loaded block (`(block, tile, loaded, stride)`) for `camera` at `tau`.
fn fractal_report(
    blocks: &[(SceneBlock, Option<u64>, LoadedBlock, u64)],
    camera: &Camera,
    frame: &WorldFrame,
    tau: f64,
) -> Result<FractalReport, Error> {
    let view = camera.view()?;
    let k = fractal::SCALE as f64;
    let mut report = FractalReport {
        scale: fractal::SCALE,
        max_depth: fractal::MAX_DEPTH,
        refined_blocks: 0,
        max_screen_error: 0.0,
        nodes: Vec::new(),
    };
    for (b, tile, loaded, stride) in blocks {
        let grid = GridBlock::of(b, loaded, *stride);
        let nodes = fractal::refine_block(b.key, &grid, &view, frame, tau);
        if !nodes.is_empty() {
            report.refined_blocks += 1;
        }
        for n in nodes {
            let screen_error = n.screen_error(&view, frame);
            report.max_screen_error = report.max_screen_error.max(screen_error);
            let r = &n.rect;
            report.nodes.push(FractalNode {
                synthetic: true,
                physical: PhysicalRef {
                    tile: *tile,
                    level: b.level,
                    x: b.x,
                    y: b.y,
                    key: b.key,
                },
                depth: n.depth,
                level: b.level + n.depth,
                x: (b.x << n.depth) + n.x,
                y: (b.y << n.depth) + n.y,
                footprint: [
                    r.col0 as f64 / k,
                    r.row0 as f64 / k,
                    r.col1 as f64 / k,
                    r.row1 as f64 / k,
                ],
                stride: n.stride as f64 / k,
                error: n.error,
                screen_error,
            });
        }
    }
    Ok(report)
}

fn print_fractal(f: &FractalReport) {
    println!(
        "  fractal: {} blocks refined into {} synthetic nodes, max screen-space error {:.4} px",
        f.refined_blocks,
        f.nodes.len(),
        f.max_screen_error
    );
    if f.nodes.is_empty() {
        return;
    }
    println!(
        "  {:>5} {:>6} {:>6} {:>5}  {:>31}  {:>12} {:>9}  below",
        "level", "x", "y", "depth", "col0,row0..col1,row1", "error m", "px"
    );
    for n in &f.nodes {
        let [c0, r0, c1, r1] = n.footprint;
        let p = &n.physical;
        println!(
            "  {:>5} {:>6} {:>6} {:>5}  {:>31}  {:>12.4} {:>9.4}  {}level {} ({},{}) key {}",
            n.level,
            n.x,
            n.y,
            n.depth,
            format!("{c0},{r0}..{c1},{r1}"),
            n.error,
            n.screen_error,
            p.tile.map_or(String::new(), |t| format!("tile {t} ")),
            p.level,
            p.x,
            p.y,
            p.key
        );
    }
}

/// The JSON report.
#[derive(Serialize)]
struct Report<'a> {
    mode: Mode,
    tau: f64,
    /// Uniform mode: the chosen static bound in metres.
    threshold: Option<f64>,
    window: Option<SampleRect>,
    blocks: &'a [fmrh::scene::SceneBlock],
    stats: &'a fmrh::scene::SceneStats,
    /// --reconstruct: samples of the window no block owns (written as NaN).
    uncovered_samples: Option<u64>,
    /// What was read, by phase.
    reads: Reads,
    /// --refine fractal: the synthetic nodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    fractal: Option<FractalReport>,
    /// A remote container: the request plan, by phase.
    #[serde(skip_serializing_if = "Option::is_none")]
    requests: Option<RequestPlan>,
}

/// What a remote container's scene asked its server for, by phase (`docs/remote-design.md`).
#[derive(Serialize)]
struct RequestPlan {
    /// Opening: the prefix and the suffix, one round.
    open: RequestStats,
    /// Scheduling: the metadata area (index, node and block pages).
    schedule: RequestStats,
    /// Loading the blocks: their payloads, in batches.
    load: Option<RequestStats>,
    /// Scheduling and loading: what the scene cost after opening.
    scene: RequestStats,
}

/// Runs `fmrh scene`.
pub fn run(args: &SceneArgs) -> Result<ExitCode, Error> {
    let camera = args.camera.camera(&args.view)?;
    args.view.flat_spacing_only(args.camera.globe())?;
    if args.camera.globe() && args.refine.is_some() {
        return Err(Error::InvalidArgument(
            "--refine takes flat-frame cameras only so far (no --globe or --eye-geo)".into(),
        ));
    }
    let options = args.view.options_in(args.window.as_deref())?;
    let output = args
        .reconstruct
        .as_deref()
        .map(|p| super::sidecar::RasterOutput::new(p, args.format, args.force))
        .transpose()?;
    if !args.layers.is_empty() {
        return run_layers(args, &camera, &options);
    }
    if super::is_dataset(&args.file)? {
        return run_dataset(args, camera, options, output);
    }
    if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        return run_on(args, &fmrh::Store::open_url(url)?, camera, options, output);
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    if args.view.mmap && fmrh::store::lock::SUPPORTED {
        // SAFETY: the --mmap contract, stated in its help: the state is registered, so fmrh
        // writers leave its pages alone, and no other tool modifies the file meanwhile.
        let store = unsafe { fmrh::Store::open_mapped(&args.file) }?;
        run_on(args, &store, camera, options, output)
    } else {
        run_on(args, &super::open(&args.file)?, camera, options, output)
    }
}

fn run_on<S: fmrh::store::Source>(
    args: &SceneArgs,
    store: &fmrh::Store<S>,
    camera: Camera,
    options: SceneOptions,
    output: Option<super::sidecar::RasterOutput>,
) -> Result<ExitCode, Error> {
    let before = store.read_stats();
    let asked = store.source().request_stats();
    let (spacing, terrain) = if args.camera.globe() {
        (None, Terrain::on_globe(store)?)
    } else {
        let spacing = args.view.spacing(store, &args.file)?;
        (spacing, Terrain::with_spacing(store, spacing)?)
    };
    let scene = terrain.scene(&camera, &options)?;
    let scheduled = store.read_stats();
    let asked_scheduled = store.source().request_stats();
    let mut uncovered = None;
    let mut fractal = None;
    if args.refine.is_some() {
        // --refine conflicts with --reconstruct: these are the only loads.
        let loaded = load_blocks(store, &scene.blocks, PAYLOAD_GAP)?;
        let d = *store.domain();
        let blocks: Vec<_> = scene
            .blocks
            .iter()
            .zip(loaded)
            .map(|(b, l)| (*b, None, l, d.stride(b.level)))
            .collect();
        let frame = WorldFrame::new(spacing.or(store.header().metadata.spacing_m));
        fractal = Some(fractal_report(&blocks, &camera, &frame, scene.tau)?);
    } else if args.load && output.is_none() {
        load_blocks(store, &scene.blocks, PAYLOAD_GAP)?;
    }
    if let Some(out) = &output {
        let window = scene.window.ok_or_else(|| {
            Error::InvalidArgument(
                "the camera sees no terrain: there is no window to reconstruct (give --window)"
                    .into(),
            )
        })?;
        let rec = reconstruct(store, &scene, window)?;
        uncovered = Some(rec.uncovered);
        let hf = rec.to_heightfield(&store.header().metadata)?;
        out.write(&hf, window, "fmrh scene --reconstruct", &args.file, store)?;
    }
    let reads = Reads {
        open: store.open_reads(),
        schedule: scheduled.since(&before),
        load: (args.load || output.is_some() || fractal.is_some())
            .then(|| store.read_stats().since(&scheduled)),
    };
    let requests = match (asked, asked_scheduled, store.source().request_stats()) {
        (Some(open), Some(scheduled), Some(end)) => Some(RequestPlan {
            open,
            schedule: scheduled.since(&open),
            load: (args.load || output.is_some() || fractal.is_some())
                .then(|| end.since(&scheduled)),
            scene: end.since(&open),
        }),
        _ => None,
    };
    if args.json {
        super::print_json(&Report {
            mode: scene.mode,
            tau: scene.tau,
            threshold: scene.stats.threshold,
            window: scene.window,
            blocks: &scene.blocks,
            stats: &scene.stats,
            uncovered_samples: uncovered,
            reads,
            fractal,
            requests,
        })?;
    } else {
        print_text(&scene, uncovered, &reads);
        if let Some(f) = &fractal {
            print_fractal(f);
        }
        if let Some(plan) = &requests {
            print_plan(plan);
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The JSON report of a layered scene.
#[derive(Serialize)]
struct LayersReport<'a> {
    tau: f64,
    /// The layers' files, the base first.
    layers: Vec<String>,
    blocks: &'a [fmrh::scene::LayerBlock],
    /// With --load: each block's skirt depth along the seams, metres, in block order.
    #[serde(skip_serializing_if = "Option::is_none")]
    skirts: Option<Vec<f64>>,
    hidden_by_layers: u64,
    stats: &'a fmrh::scene::SceneStats,
    layer_stats: &'a [fmrh::scene::SceneStats],
}

/// `--layer`: FILE as the base, each --layer above it, all on the globe.
fn run_layers(
    args: &SceneArgs,
    camera: &Camera,
    options: &SceneOptions,
) -> Result<ExitCode, Error> {
    if !args.camera.globe() {
        return Err(Error::InvalidArgument(
            "--layer places grids on the globe: give the camera with --eye-geo or --globe".into(),
        ));
    }
    let paths: Vec<&std::path::Path> = std::iter::once(args.file.as_path())
        .chain(args.layers.iter().map(|p| p.as_path()))
        .collect();
    let stores = paths
        .iter()
        .map(|p| super::open(p))
        .collect::<Result<Vec<_>, Error>>()?;
    let terrains = stores
        .iter()
        .map(Terrain::on_globe)
        .collect::<Result<Vec<_>, Error>>()?;
    let layers = fmrh::scene::Layers::new(terrains)?;
    let scene = layers.scene(camera, options)?;
    let skirts = if args.load {
        let loaded = layers.load(&scene)?;
        Some(layers.skirts(&scene, &loaded)?)
    } else {
        None
    };
    if args.json {
        super::print_json(&LayersReport {
            tau: scene.tau,
            layers: paths.iter().map(|p| p.display().to_string()).collect(),
            blocks: &scene.blocks,
            skirts,
            hidden_by_layers: scene.hidden_by_layers,
            stats: &scene.stats,
            layer_stats: &scene.layers,
        })?;
        return Ok(ExitCode::SUCCESS);
    }
    let s = &scene.stats;
    println!("scene on {} layers: tau {} px", paths.len(), scene.tau);
    for (i, (p, ls)) in paths.iter().zip(&scene.layers).enumerate() {
        let kept = scene.blocks.iter().filter(|b| b.layer == i).count();
        println!(
            "  layer {i}  {}: {} blocks of its scene, {kept} drawn",
            p.display(),
            ls.blocks
        );
    }
    println!(
        "  {} blocks, {} bytes ({} hidden by the layers above); scheduled in {:.1} us",
        s.blocks,
        s.bytes,
        scene.hidden_by_layers,
        s.schedule_ns as f64 / 1000.0
    );
    println!(
        "  max static error {:.4} m, max screen-space error {:.4} px",
        s.max_error, s.max_screen_error
    );
    if let Some(d) = &skirts {
        let on_seams = d.iter().filter(|&&x| x > 0.0).count();
        let deepest = d.iter().copied().fold(0.0, f64::max);
        println!("  skirts: {on_seams} blocks hang one along a seam, the deepest {deepest:.1} m");
    }
    if !scene.blocks.is_empty() {
        println!(
            "  {:>5} {:>5} {:>6} {:>6}  {:>23}  {:>12} {:>9}  cut-outs",
            "layer", "level", "x", "y", "col0,row0..col1,row1", "error m", "px"
        );
    }
    for lb in &scene.blocks {
        let b = &lb.block;
        println!(
            "  {:>5} {:>5} {:>6} {:>6}  {:>23}  {:>12.4} {:>9.4}  {}",
            lb.layer,
            b.level,
            b.x,
            b.y,
            format!("{},{}..{},{}", b.col0, b.row0, b.col1, b.row1),
            b.error,
            b.screen_error,
            lb.cutouts.len()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn print_plan(plan: &RequestPlan) {
    let r = |what: &str, s: &RequestStats| {
        println!(
            "  requests    {what}: {} requests, {} bytes, {} rounds ({} retries)",
            s.requests, s.bytes, s.rounds, s.retries
        );
    };
    r("open", &plan.open);
    r("schedule", &plan.schedule);
    if let Some(l) = &plan.load {
        r("load", l);
    }
    r("scene", &plan.scene);
}

fn print_text(scene: &Scene, uncovered: Option<u64>, reads: &Reads) {
    let s = &scene.stats;
    let mode = match scene.mode {
        Mode::Uniform => "uniform",
        Mode::View => "view-dependent",
    };
    println!("scene: {mode}, tau {} px", scene.tau);
    if let (Some(t), Some(e), Some(p)) = (s.threshold, s.allowed_error, s.p_min) {
        let cluster = s
            .cluster
            .map_or("physical blocks".to_string(), |c| format!("cluster {c}"));
        println!("  P_min {p:.3} m allows {e:.4} m: {cluster}, threshold {t} m");
    }
    match scene.window {
        Some(w) => println!(
            "  window {},{},{},{} ({} quadrants, {} range scans, {} index pages, {} node reads)",
            w.col0, w.row0, w.col1, w.row1, s.quadrants, s.ranges, s.index_pages, s.node_reads
        ),
        None => println!("  the camera sees no terrain"),
    }
    println!(
        "  {} blocks, {} samples, {} triangles, {} bytes; scheduled in {:.1} us",
        s.blocks,
        s.samples,
        s.triangles,
        s.bytes,
        s.schedule_ns as f64 / 1000.0
    );
    println!(
        "  max static error {:.4} m, max screen-space error {:.4} px",
        s.max_error, s.max_screen_error
    );
    if let Some(u) = uncovered {
        println!("  reconstruction: {u} samples of the window lie outside every block (NaN)");
    }
    let r = |what: &str, s: &ReadStats| {
        println!(
            "  read        {what}: {} calls, {} metadata bytes, {} payload bytes",
            s.reads(),
            s.metadata_bytes,
            s.payload_bytes
        );
    };
    r("open", &reads.open);
    r("schedule", &reads.schedule);
    if let Some(l) = &reads.load {
        r("load", l);
    }
    if scene.blocks.is_empty() {
        return;
    }
    println!(
        "  {:>5} {:>6} {:>6}  {:>23}  {:>12} {:>9}  neighbours N/E/S/W",
        "level", "x", "y", "col0,row0..col1,row1", "error m", "px"
    );
    let nb = |n: Option<fmrh::scene::NeighbourLevels>| match n {
        None => "-".to_string(),
        Some(n) if n.coarsest == n.finest => n.coarsest.to_string(),
        Some(n) => format!("{}-{}", n.coarsest, n.finest),
    };
    for b in &scene.blocks {
        println!(
            "  {:>5} {:>6} {:>6}  {:>23}  {:>12.4} {:>9.4}  {}/{}/{}/{}",
            b.level,
            b.x,
            b.y,
            format!("{},{}..{},{}", b.col0, b.row0, b.col1, b.row1),
            b.error,
            b.screen_error,
            nb(b.neighbours[0]),
            nb(b.neighbours[1]),
            nb(b.neighbours[2]),
            nb(b.neighbours[3]),
        );
    }
}

/// The JSON report of a dataset scene: a container's, with each block's tile, and each
/// tile's part and reads.
#[derive(Serialize)]
struct DatasetReport<'a> {
    mode: Mode,
    tau: f64,
    threshold: Option<f64>,
    window: Option<SampleRect>,
    blocks: &'a [fmrh::dataset::DatasetBlock],
    stats: &'a fmrh::scene::SceneStats,
    uncovered_samples: Option<u64>,
    tiles: &'a [fmrh::dataset::TilePart],
    reads: DatasetReads,
    /// --refine fractal: the synthetic nodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    fractal: Option<FractalReport>,
    /// A remote dataset: the request plan (tiles in parallel, see `Dataset::request_stats`).
    #[serde(skip_serializing_if = "Option::is_none")]
    requests: Option<DatasetRequests>,
}

/// What a remote dataset's scene asked its servers for.
#[derive(Serialize)]
struct DatasetRequests {
    /// Opening the dataset: the manifest's prefix and suffix.
    open: RequestStats,
    /// The scene after opening: tile pages, the tiles' opening, metadata and payloads.
    scene: RequestStats,
}

/// What a dataset scene read.
#[derive(Serialize)]
struct DatasetReads {
    /// Opening the dataset: the manifest's slots and head.
    open: ReadStats,
    /// The manifest's tile pages the scene needed.
    manifest: ReadStats,
    /// Opening the tiles the scene met (each one's slots, header and directory).
    tiles_open: ReadStats,
    /// Scheduling, over all tiles: index and node pages.
    schedule: ReadStats,
    /// Loading the blocks (--load or --reconstruct; not --refine's own loads).
    load: Option<ReadStats>,
    /// Tile files opened.
    tiles_opened: u64,
}

fn run_dataset(
    args: &SceneArgs,
    camera: Camera,
    options: SceneOptions,
    output: Option<super::sidecar::RasterOutput>,
) -> Result<ExitCode, Error> {
    let ds = fmrh::dataset::Dataset::open(&args.file)?;
    let asked = ds.request_stats();
    let spacing = args.view.given_spacing()?;
    let scene = if args.camera.globe() {
        ds.scene_on_globe(&camera, &options)?
    } else {
        ds.scene(&camera, &options, spacing)?
    };
    let schedule = scene
        .tiles
        .iter()
        .fold(ReadStats::default(), |a, t| a.plus(&t.reads));
    let mut tiles_open = ReadStats::default();
    for part in &scene.tiles {
        let tile = ds.tile(part.tile)?;
        tiles_open = tiles_open.plus(&ds.open_tile(&tile)?.open_reads());
    }
    let mut uncovered = None;
    let mut load = None;
    if args.load && output.is_none() {
        load = Some(ds.load(&scene)?);
    }
    let mut fractal = None;
    if args.refine.is_some() {
        let loaded = ds.load_blocks(&scene)?;
        let blocks: Vec<_> = scene
            .blocks
            .iter()
            .zip(loaded)
            .map(|(b, (l, stride))| (b.block, Some(b.tile), l, stride))
            .collect();
        let frame = WorldFrame::new(spacing.or(ds.spacing_m()));
        fractal = Some(fractal_report(&blocks, &camera, &frame, scene.tau)?);
    }
    if let Some(out) = &output {
        let window = scene.window.ok_or_else(|| {
            Error::InvalidArgument(
                "the camera sees no terrain: there is no window to reconstruct (give --window)"
                    .into(),
            )
        })?;
        let rec = ds.reconstruct(&scene, window)?;
        uncovered = Some(rec.uncovered);
        let metadata = fmrh::heightfield::Metadata {
            spacing_m: spacing.or(ds.spacing_m()),
            georeference: ds.georeference(),
            units: None,
            source_format: "fmrh-dataset".into(),
        };
        let hf = rec.to_heightfield(&metadata)?;
        out.write_dataset(&hf, window, &args.file, ds.txn_id())?;
    }
    let reads = DatasetReads {
        open: ds.open_reads(),
        manifest: ds.manifest_reads(),
        tiles_open,
        schedule,
        load,
        tiles_opened: ds.tiles_opened(),
    };
    if args.json {
        super::print_json(&DatasetReport {
            mode: scene.mode,
            tau: scene.tau,
            threshold: scene.stats.threshold,
            window: scene.window,
            blocks: &scene.blocks,
            stats: &scene.stats,
            uncovered_samples: uncovered,
            tiles: &scene.tiles,
            reads,
            fractal,
            requests: asked
                .zip(ds.request_stats())
                .map(|(open, end)| DatasetRequests {
                    open,
                    scene: end.since(&open),
                }),
        })?;
        return Ok(ExitCode::SUCCESS);
    }
    let as_scene = Scene {
        mode: scene.mode,
        tau: scene.tau,
        window: scene.window,
        blocks: scene.blocks.iter().map(|b| b.block).collect(),
        stats: scene.stats,
    };
    println!(
        "dataset {}: {} tiles met ({} opened), manifest read {} bytes at open and {} since",
        args.file.display(),
        scene.tiles.len(),
        reads.tiles_opened,
        reads.open.bytes(),
        reads.manifest.bytes()
    );
    for t in &scene.tiles {
        println!(
            "  tile {:>5} {:<28} {:>6} blocks{}",
            t.tile,
            t.name,
            t.blocks,
            t.cluster
                .map_or(String::new(), |c| format!(", cluster {c}"))
        );
    }
    let container_reads = Reads {
        open: reads.tiles_open,
        schedule: reads.schedule,
        load: reads.load,
    };
    print_text(&as_scene, uncovered, &container_reads);
    if let Some(f) = &fractal {
        print_fractal(f);
    }
    Ok(ExitCode::SUCCESS)
}
