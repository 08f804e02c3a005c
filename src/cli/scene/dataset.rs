//! A dataset's scene across its tiles.

use std::process::ExitCode;

use serde::Serialize;

use super::{print_text, Reads, SceneArgs};

use crate::model::SampleRect;
use crate::scene::{Camera, Mode, Scene, SceneOptions, WorldFrame};
use crate::store::{ReadStats, RequestStats};
use crate::Error;

/// The JSON report of a dataset scene: a container's, with each block's tile, and each
/// tile's part and reads.
#[derive(Serialize)]
struct DatasetReport<'a> {
    mode: Mode,
    tau: f64,
    threshold: Option<f64>,
    window: Option<SampleRect>,
    blocks: &'a [crate::dataset::DatasetBlock],
    stats: &'a crate::scene::SceneStats,
    uncovered_samples: Option<u64>,
    tiles: &'a [crate::dataset::TilePart],
    reads: DatasetReads,
    /// --refine fractal: the synthetic nodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    fractal: Option<super::fractal::FractalReport>,
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

pub(super) fn run(
    args: &SceneArgs,
    camera: Camera,
    options: SceneOptions,
    output: Option<crate::cli::sidecar::RasterOutput>,
) -> Result<ExitCode, Error> {
    let ds = crate::dataset::Dataset::open(&args.file)?;
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
        fractal = Some(super::fractal::report(&blocks, &camera, &frame, scene.tau)?);
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
        let metadata = crate::heightfield::Metadata {
            spacing_m: spacing.or(ds.spacing_m()),
            georeference: ds.georeference(),
            units: None,
            source_format: "fmrh-dataset".into(),
            vertical_datum: ds.vertical_datum()?,
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
        crate::cli::print_json(&DatasetReport {
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
        super::fractal::print(f);
    }
    Ok(ExitCode::SUCCESS)
}
