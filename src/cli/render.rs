//! `fmrh render`: a picture of a scene, drawn on the CPU (`crate::render`): the surface its
//! blocks draw through the camera, or from overhead (`--top`) with the camera's view on the
//! ground. The pictures in docs/scenes.md are made with it.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::heightfield::Georeference;
use crate::model::SampleRect;
use crate::render::{perspective, top, MapGround, Surface};
use crate::scene::{reconstruct, Camera, SceneBlock, Terrain, WorldFrame};
use crate::Error;

#[derive(clap::Args)]
pub struct RenderArgs {
    /// The container or a dataset's directory (a path or an http(s):// or s3:// URL).
    file: PathBuf,
    #[command(flatten)]
    camera: super::args::CameraArgs,
    #[command(flatten)]
    view: super::args::ViewArgs,
    /// Draw only this window, inclusive samples c0,r0,c1,r1 (default: what the frustum
    /// sees; with --top, the whole terrain up to 64 Mi samples).
    #[arg(long)]
    window: Option<String>,
    /// An overhead map instead: the blocks the camera selected, tinted by level, and its
    /// view drawn on the ground.
    #[arg(long)]
    top: bool,
    /// The overhead map's longer side in pixels (the perspective picture is the
    /// viewport's size).
    #[arg(long, default_value_t = 1024)]
    size: u32,
    /// The PNG to write (`-`: standard output).
    #[arg(short, long)]
    output: PathBuf,
    /// Replace an existing output.
    #[arg(long)]
    force: bool,
}

/// An overhead map of the whole terrain is drawn when it has at most this many samples;
/// a larger one (a big dataset) is drawn over what the camera sees.
const WHOLE_MAP_SAMPLES: u64 = 1 << 26;

/// Runs `fmrh render`.
pub fn run(args: &RenderArgs) -> Result<ExitCode, Error> {
    super::check_output(&args.output, args.force)?;
    if super::is_dataset(&args.file)? {
        return render_dataset(args);
    }
    if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        return render(args, &crate::store::Store::open_url(url)?);
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    render(args, &super::open(&args.file)?)
}

/// The window to draw: `--window`; else, overhead, the whole terrain (`all`) when it is
/// not too large, so that the camera's view is seen in its place (what the scene left out
/// stays blank); else what the camera sees.
fn window_to_draw(
    args: &RenderArgs,
    given: Option<SampleRect>,
    seen: Option<SampleRect>,
    all: SampleRect,
) -> Result<SampleRect, Error> {
    let samples = (all.col1 - all.col0 + 1) * (all.row1 - all.row0 + 1);
    match (given, args.top && samples <= WHOLE_MAP_SAMPLES, seen) {
        (Some(w), _, _) => Ok(w),
        (None, true, _) => Ok(all),
        (None, false, Some(w)) => Ok(w),
        (None, false, None) => Err(Error::InvalidArgument(
            "the camera sees no terrain: there is nothing to draw (give --window)".into(),
        )),
    }
}

fn render<S: crate::store::Source>(
    args: &RenderArgs,
    store: &crate::store::Store<S>,
) -> Result<ExitCode, Error> {
    let camera = args.camera.camera(&args.view)?;
    args.camera.flat_only("fmrh render")?;
    let options = args.view.options_in(args.window.as_deref())?;
    let spacing = args.view.spacing(store, &args.file)?;
    let terrain = Terrain::with_spacing(store, spacing)?;
    let scene = terrain.scene(&camera, &options)?;
    let window = window_to_draw(
        args,
        options.window,
        scene.window,
        store.domain().data_rect(),
    )?;
    let rec = reconstruct(store, &scene, window)?;
    let surface = Surface {
        window,
        heights: &rec.values,
        blocks: &scene.blocks,
        frame: WorldFrame::new(spacing.or(store.header().metadata.spacing_m)),
    };
    draw(
        args,
        &camera,
        &surface,
        store.header().metadata.georeference.as_ref(),
    )
}

/// A dataset's scene, across its tiles, in the dataset's world frame.
fn render_dataset(args: &RenderArgs) -> Result<ExitCode, Error> {
    let camera = args.camera.camera(&args.view)?;
    args.camera.flat_only("fmrh render")?;
    let options = args.view.options_in(args.window.as_deref())?;
    let ds = crate::dataset::Dataset::open(&args.file)?;
    let spacing = args.view.given_spacing()?;
    let scene = ds.scene(&camera, &options, spacing)?;
    let window = window_to_draw(args, options.window, scene.window, ds.grid())?;
    let rec = ds.reconstruct(&scene, window)?;
    let blocks: Vec<SceneBlock> = scene.blocks.iter().map(|b| b.block).collect();
    let surface = Surface {
        window,
        heights: &rec.values,
        blocks: &blocks,
        frame: WorldFrame::new(spacing.or(ds.spacing_m())),
    };
    draw(args, &camera, &surface, ds.georeference().as_ref())
}

/// Draws `surface` as `args` asks and writes the PNG. An overhead map lays the ground out
/// as `georef` says (see `crate::render::top`).
fn draw(
    args: &RenderArgs,
    camera: &Camera,
    surface: &Surface<'_>,
    georef: Option<&Georeference>,
) -> Result<ExitCode, Error> {
    let (image, map) = if args.top {
        let w = surface.window;
        let ground = MapGround::of(
            georef,
            (w.col0 + w.col1) as f64 / 2.0,
            (w.row0 + w.row1) as f64 / 2.0,
        );
        let map = top(surface, camera, args.size, ground)?;
        let scale = format!(
            " ({} a pixel, scale bar {}, {})",
            metres(map.metres_per_pixel),
            metres(map.scale_bar_m),
            match map.north_deg {
                Some(d) if d.abs() < 0.05 => "north up".to_string(),
                Some(d) => format!("true north {d:+.1}° from up"),
                None => "grid north up, true north unknown".to_string(),
            }
        );
        (map.image, scale)
    } else {
        (perspective(surface, camera)?, String::new())
    };
    let mut png = Vec::new();
    image.write_png(&mut png)?;
    super::write_output(&args.output, args.force, &png)?;
    eprintln!(
        "fmrh: drew {} blocks (levels {}) as a {}x{} picture{}{map}",
        surface.blocks.len(),
        levels(surface.blocks),
        image.width,
        image.height,
        if args.output == std::path::Path::new("-") {
            String::new()
        } else {
            format!(" in {}", args.output.display())
        }
    );
    Ok(ExitCode::SUCCESS)
}

/// A length for people: metres below 10 km, else kilometres.
fn metres(m: f64) -> String {
    if m >= 10_000.0 {
        let km = format!("{:.3}", m / 1000.0);
        format!("{} km", km.trim_end_matches('0').trim_end_matches('.'))
    } else if m >= 10.0 {
        format!("{m:.0} m")
    } else {
        format!("{m:.2} m")
    }
}

/// `a-b`: the coarsest and finest levels among `blocks`.
fn levels(blocks: &[SceneBlock]) -> String {
    let lo = blocks.iter().map(|b| b.level).min();
    let hi = blocks.iter().map(|b| b.level).max();
    match (lo, hi) {
        (Some(a), Some(b)) if a == b => a.to_string(),
        (Some(a), Some(b)) => format!("{a}-{b}"),
        _ => "none".into(),
    }
}
