//! `fmrh build`: DEM in, container out (or a dry-run report).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use serde::Serialize;

use crate::format::page_size_for;
use crate::ingest;
use crate::model::{precision, Model, Precision};
use crate::store::{write_file, WriteSummary};
use crate::Error;

#[derive(clap::Args)]
pub struct BuildArgs {
    /// The DEM to read.
    input: PathBuf,
    /// The container to write. It appears only once complete (temporary file, fsync,
    /// rename); an existing file is kept unless --force.
    #[arg(
        short,
        long,
        required_unless_present = "dry_run",
        conflicts_with = "dry_run"
    )]
    output: Option<PathBuf>,
    /// Build the model in memory and report on it without writing anything.
    #[arg(long)]
    dry_run: bool,
    /// Replace OUTPUT if it exists (atomically: the old file stays whole until the new one is
    /// complete).
    #[arg(long)]
    force: bool,
    /// Quiet: no progress bar, and no report on success (warnings and errors still go to
    /// standard error).
    #[arg(long, short)]
    quiet: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// The CRS of the input's georeference, over what the input says: `EPSG:N`, WKT (WKT1,
    /// ESRI or WKT2; resolved to its EPSG code when one has its datum, projection and
    /// parameters) or a PROJ string the EPSG registry has.
    #[arg(long, value_name = "CRS")]
    crs: Option<String>,
    #[command(flatten)]
    model: super::args::ModelArgs,
}

#[derive(Serialize)]
struct ClusterReport {
    threshold: f64,
    nodes: usize,
    max_error: f64,
}

#[derive(Serialize)]
struct BuildReport {
    input: String,
    format: String,
    width: u32,
    height: u32,
    block_size: u32,
    levels: u8,
    finest_level: u8,
    padded_side: u64,
    padding_samples: u64,
    valid_samples: u64,
    void_samples: u64,
    units: Option<String>,
    spacing_m: Option<[f64; 2]>,
    nodes: usize,
    nodes_per_level: Vec<u64>,
    max_error: f64,
    /// The storage step heights were kept to, when they were not kept bit for bit.
    precision: Option<f64>,
    /// Nodes whose grids are stored thinned by area, per thinning factor (absent when none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    thinned_nodes: Vec<ThinnedCount>,
    /// How far a stored height may be from its source (9/16 of the step; 0 when bit for bit).
    storage_error: f64,
    /// The largest |stored - source| over real heights, measured (at most precision / 2).
    storage_error_measured: Option<f64>,
    clusters: Vec<ClusterReport>,
    ingest_time_ms: f64,
    build_time_ms: f64,
    /// Present when a container was written.
    output: Option<OutputReport>,
    peak_memory_bytes: Option<u64>,
}

#[derive(Serialize)]
struct ThinnedCount {
    /// Columns kept: every `factor`-th.
    factor: u32,
    nodes: usize,
}

#[derive(Serialize)]
struct OutputReport {
    path: String,
    /// Bytes of the samples as raw f32 (width x height x 4).
    raw_f32_bytes: u64,
    /// File length over raw f32 bytes.
    size_ratio: f64,
    write_time_ms: f64,
    #[serde(flatten)]
    summary: WriteSummary,
}

/// Peak resident memory of this process (Linux `VmHWM`), if the system tells.
pub(super) fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// `--crs`: the georeference's CRS becomes `text` (as `EPSG:N` when it resolves to one),
/// and the spacing in metres follows from it.
fn override_crs(
    heightfield: &mut crate::Heightfield,
    text: &str,
    input: &std::path::Path,
) -> Result<(), Error> {
    let crs = crate::crs::Crs::from_user(text).map_err(Error::InvalidArgument)?;
    let h = heightfield.height();
    let Some(g) = heightfield.metadata.georeference.as_mut() else {
        return Err(Error::InvalidArgument(format!(
            "--crs: {} has no georeference (origin and step) for a CRS to apply to",
            input.display()
        )));
    };
    g.crs = Some(match crs.epsg {
        Some(code) => format!("EPSG:{code}"),
        None => text.trim().to_string(),
    });
    let centre_lat = g.origin[1] + g.step[1] * f64::from(h.max(1) - 1) / 2.0;
    heightfield.metadata.spacing_m = crs.spacing(g.step, centre_lat);
    Ok(())
}

/// Warns when the input's CRS is one fmrh cannot place on the ground: a WKT no EPSG code
/// matches, or a CRS that is neither geographic nor projected in a known unit.
fn warn_of_unplaced_crs(heightfield: &crate::Heightfield, input: &std::path::Path) {
    let Some(name) = heightfield
        .metadata
        .georeference
        .as_ref()
        .and_then(|g| g.crs.as_deref())
    else {
        return;
    };
    let placed = crate::crs::Crs::parse(name).is_some_and(|c| c.epsg.is_some());
    if !placed {
        let shown =
            crate::crs::Crs::wkt_name(name).unwrap_or_else(|| name.chars().take(60).collect());
        eprintln!(
            "fmrh: warning: the CRS of {} (\"{shown}\") is not one fmrh can place on the ground: \
             no EPSG code has its datum, projection and parameters. It is kept as given; \
             longitude and latitude, geodetic tiling and --eye-geo are not available. Give \
             --crs EPSG:N if you know its code.",
            input.display()
        );
    }
}

/// Runs `fmrh build`.
pub fn run(args: &BuildArgs) -> Result<ExitCode, Error> {
    if args.output.as_deref() == Some(std::path::Path::new("-")) {
        return Err(Error::InvalidArgument(
            "-o -: a container cannot go to standard output (it is written with seeks, synced \
             and renamed into place); give a file name"
                .into(),
        ));
    }
    // One bar for every phase, unless told to be quiet or writing JSON; it draws only on a
    // terminal.
    let bar = (!args.quiet && !args.json).then(|| std::sync::Arc::new(super::progress::Bar::new()));
    let silent = crate::progress::Silent;
    let progress: &dyn crate::progress::Progress = match &bar {
        Some(b) => &**b,
        None => &silent,
    };
    let t0 = Instant::now();
    if let Some(b) = &bar {
        b.spin(&format!("reading {}", args.input.display()));
    }
    let loaded = ingest::load(&args.input, &args.model.ingest.options());
    progress.finish();
    let mut heightfield = loaded?;
    if let Some(text) = &args.crs {
        override_crs(&mut heightfield, text, &args.input)?;
    }
    if let Some(spacing) = args.model.spacing()? {
        heightfield.metadata.spacing_m = Some(spacing);
    }
    warn_of_unplaced_crs(&heightfield, &args.input);
    let ingest_time = t0.elapsed();
    if heightfield.metadata.spacing_m.is_none() {
        // Scenes measure distances in metres: without a spacing they take samples as 1 m apart.
        let hint = if heightfield.metadata.source_format == "srtm-hgt" {
            " Its name holds no tile name (such as N44W072): give --tile to place it."
        } else {
            ""
        };
        eprintln!(
            "fmrh: warning: {} says nothing of the distance between its samples (no CRS, or a \
             unit fmrh does not know). Scenes over it will need --spacing; give --spacing \
             DX[,DY] (metres) here to record it.{hint}",
            args.input.display()
        );
    }
    let metadata = heightfield.metadata.clone();
    let mut options = args.model.build_options()?;
    if let Some(p) = options.precision {
        if !precision::changes_any(p, heightfield.samples()) {
            eprintln!(
                "fmrh: note: every height of {} already lies on the lattice of step {}: it is \
                 stored bit for bit (lossless), with no storage error",
                args.input.display(),
                p.step()
            );
            options.precision = None;
        }
    }
    let t1 = Instant::now();
    let model = Model::build_with_progress(heightfield, &options, progress)?;
    let build_time = t1.elapsed();

    let output = match &args.output {
        Some(path) if !args.dry_run => {
            let t2 = Instant::now();
            let mut options = args.model.write_options(page_size_for(
                u64::from(model.domain().width()) * u64::from(model.domain().height()),
            ));
            if let Some(b) = &bar {
                options.progress = b.clone();
            }
            let summary = write_file(&model, &metadata, path, &options, args.force)?;
            let raw = 4 * u64::from(model.domain().width()) * u64::from(model.domain().height());
            Some(OutputReport {
                path: path.display().to_string(),
                raw_f32_bytes: raw,
                size_ratio: summary.file_length as f64 / raw as f64,
                write_time_ms: t2.elapsed().as_secs_f64() * 1e3,
                summary,
            })
        }
        _ => None,
    };
    let domain = model.domain();
    let report = BuildReport {
        input: args.input.display().to_string(),
        format: metadata.source_format.clone(),
        width: domain.width(),
        height: domain.height(),
        block_size: domain.block_size(),
        levels: domain.levels(),
        finest_level: domain.finest_level(),
        padded_side: domain.side(),
        padding_samples: domain.padding_samples(),
        valid_samples: model.raster().valid_count(),
        void_samples: model.raster().void_count(),
        units: metadata.units,
        spacing_m: metadata.spacing_m,
        nodes: model.tree().nodes().len(),
        nodes_per_level: model.tree().nodes_per_level(),
        max_error: model.max_error(),
        precision: model.precision().map(Precision::step),
        thinned_nodes: (1..=crate::model::thinning::MAX_THIN_LOG2)
            .map(|t| ThinnedCount {
                factor: 1 << t,
                nodes: model.tree().nodes().iter().filter(|n| n.thin == t).count(),
            })
            .filter(|c| c.nodes > 0)
            .collect(),
        storage_error: model.precision().map_or(0.0, Precision::bound),
        storage_error_measured: model.precision().and(model.storage_error_measured()),
        clusters: model
            .clusters()
            .iter()
            .map(|c| ClusterReport {
                threshold: c.threshold,
                nodes: c.nodes.len(),
                max_error: c.max_error,
            })
            .collect(),
        ingest_time_ms: ingest_time.as_secs_f64() * 1e3,
        build_time_ms: build_time.as_secs_f64() * 1e3,
        output,
        peak_memory_bytes: peak_memory_bytes(),
    };
    if args.json {
        super::print_json(&report)?;
    } else if !args.quiet {
        print_report(&report);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_report(r: &BuildReport) {
    println!("{} ({})", r.input, r.format);
    println!(
        "  grid        {} x {} samples, {} valid, {} void",
        r.width, r.height, r.valid_samples, r.void_samples
    );
    println!(
        "  blocks      {} samples a side; {} levels; domain padded to {} ({} padding samples)",
        r.block_size, r.levels, r.padded_side, r.padding_samples
    );
    println!(
        "  nodes       {} (per level: {:?})",
        r.nodes, r.nodes_per_level
    );
    println!("  max error   {}", r.max_error);
    match (r.precision, r.storage_error_measured) {
        (Some(q), Some(e)) => println!(
            "  precision   {q}: heights stored within {} of the source (measured max {e}); \
             every node error includes it",
            r.storage_error
        ),
        (Some(q), None) => println!("  precision   {q}"),
        _ => println!("  precision   lossless (every height bit for bit)"),
    }
    println!("  clusters    {}", r.clusters.len());
    println!("      threshold        nodes    max error");
    for c in &r.clusters {
        println!(
            "  {:>13.6} {:>12} {:>12.6}",
            c.threshold, c.nodes, c.max_error
        );
    }
    println!(
        "  time        ingest {:.1} ms, model {:.1} ms",
        r.ingest_time_ms, r.build_time_ms
    );
    if let Some(o) = &r.output {
        println!(
            "  written     {}: {} bytes = {:.3} x raw f32, in {:.1} ms",
            o.path, o.summary.file_length, o.size_ratio, o.write_time_ms
        );
    }
    if let Some(bytes) = r.peak_memory_bytes {
        println!("  peak memory {:.1} MiB", bytes as f64 / (1 << 20) as f64);
    }
}
