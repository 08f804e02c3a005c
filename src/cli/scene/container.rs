//! A container's scene: select, load or reconstruct, refine, report.

use std::process::ExitCode;

use serde::Serialize;

use super::{print_text, Reads, SceneArgs};

use crate::model::SampleRect;
use crate::scene::{
    load_blocks, reconstruct, Camera, Mode, SceneOptions, Terrain, WorldFrame, PAYLOAD_GAP,
};
use crate::store::RequestStats;
use crate::Error;

/// The JSON report.
#[derive(Serialize)]
struct Report<'a> {
    mode: Mode,
    tau: f64,
    /// Uniform mode: the chosen static bound in metres.
    threshold: Option<f64>,
    window: Option<SampleRect>,
    blocks: &'a [crate::scene::SceneBlock],
    stats: &'a crate::scene::SceneStats,
    /// --reconstruct: samples of the window no block owns (written as NaN).
    uncovered_samples: Option<u64>,
    /// What was read, by phase.
    reads: Reads,
    /// --refine fractal: the synthetic nodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    fractal: Option<super::fractal::FractalReport>,
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

pub(super) fn run<S: crate::store::Source>(
    args: &SceneArgs,
    store: &crate::store::Store<S>,
    camera: Camera,
    options: SceneOptions,
    output: Option<crate::cli::sidecar::RasterOutput>,
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
        fractal = Some(super::fractal::report(&blocks, &camera, &frame, scene.tau)?);
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
        crate::cli::print_json(&Report {
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
            super::fractal::print(f);
        }
        if let Some(plan) = &requests {
            print_plan(plan);
        }
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
