//! `fmrh scene`: one camera and a tolerance in pixels, the blocks that view needs out; with
//! `--reconstruct`, the surface they draw at full resolution. The arguments and the dispatch
//! live here; a container's scene, a dataset's, layers on the globe, and `--refine fractal`'s
//! report each have a room of their own.

mod container;
mod dataset;
mod fractal;
mod layers;

use std::path::PathBuf;
use std::process::ExitCode;

use serde::Serialize;

use super::args::{CameraArgs, RefineArg, ViewArgs};
use crate::scene::{Mode, Scene};
use crate::store::ReadStats;
use crate::Error;

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
        return layers::run(args, &camera, &options);
    }
    if super::is_dataset(&args.file)? {
        return dataset::run(args, camera, options, output);
    }
    if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        return container::run(
            args,
            &crate::store::Store::open_url(url)?,
            camera,
            options,
            output,
        );
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    if args.view.mmap && crate::store::lock::SUPPORTED {
        // SAFETY: the --mmap contract, stated in its help: the state is registered, so fmrh
        // writers leave its pages alone, and no other tool modifies the file meanwhile.
        let store = unsafe { crate::store::Store::open_mapped(&args.file) }?;
        container::run(args, &store, camera, options, output)
    } else {
        container::run(args, &super::open(&args.file)?, camera, options, output)
    }
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
            "  window {},{},{},{} ({} quadrants, {} range scans, {} index pages, {} node reads, {} from the top)",
            w.col0, w.row0, w.col1, w.row1, s.quadrants, s.ranges, s.index_pages, s.node_reads, s.top_reads
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
    let nb = |n: Option<crate::scene::NeighbourLevels>| match n {
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
