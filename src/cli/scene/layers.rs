//! `--layer`: a base grid with layers above it, all on the globe.

use std::process::ExitCode;

use serde::Serialize;

use super::SceneArgs;

use crate::scene::{Camera, SceneOptions, Terrain};
use crate::Error;

/// The JSON report of a layered scene.
#[derive(Serialize)]
struct LayersReport<'a> {
    tau: f64,
    /// The layers' files, the base first.
    layers: Vec<String>,
    blocks: &'a [crate::scene::LayerBlock],
    /// With --load: each block's skirt depth along the seams, metres, in block order.
    #[serde(skip_serializing_if = "Option::is_none")]
    skirts: Option<Vec<f64>>,
    hidden_by_layers: u64,
    stats: &'a crate::scene::SceneStats,
    layer_stats: &'a [crate::scene::SceneStats],
}

/// `--layer`: FILE as the base, each --layer above it, all on the globe.
pub(super) fn run(
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
        .map(|p| crate::cli::open(p))
        .collect::<Result<Vec<_>, Error>>()?;
    let terrains = stores
        .iter()
        .map(Terrain::on_globe)
        .collect::<Result<Vec<_>, Error>>()?;
    let layers = crate::scene::Layers::new(terrains)?;
    let scene = layers.scene(camera, options)?;
    let skirts = if args.load {
        let loaded = layers.load(&scene)?;
        Some(layers.skirts(&scene, &loaded)?)
    } else {
        None
    };
    if args.json {
        crate::cli::print_json(&LayersReport {
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
