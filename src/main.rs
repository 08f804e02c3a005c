//! The `fmrh` command line: build terrain models from DEMs and report on them.
//!
//! Exit status: 0 on success; 2 when the input or the arguments are unusable (malformed or
//! unsupported file, bad option value, size beyond limits); 1 when the system fails (I/O).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand};
use serde::Serialize;

use fmrh::ingest::{self, ColorEncoding, Format, IngestOptions};
use fmrh::model::{BuildOptions, Model, Thresholds, DEFAULT_BLOCK_SIZE};
use fmrh::Error;

#[derive(Parser)]
#[command(
    name = "fmrh",
    version,
    about = "An embedded storage engine for multiresolution terrain",
    long_about = "fmrh turns a DEM (a grid of heights) into an FMRH: a quadtree of blocks, \
each with a measured error, grouped into error clusters in Hilbert order, so that a view \
becomes a few range scans.\n\nExit status: 0 success, 2 unusable input or arguments, 1 system error."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build the terrain model of a DEM: blocks, FMRH with measured errors, error clusters.
    ///
    /// Reads INPUT in any supported format (.f32+.json, .hgt[.gz], GeoTIFF, PNG, JPEG, .asc,
    /// USGS .dem), cuts it into blocks, measures every node's error and builds one cluster per
    /// threshold. With --dry-run nothing is written and a summary is printed (--json for
    /// machine-readable output).
    Build(BuildArgs),
}

#[derive(clap::Args)]
struct BuildArgs {
    /// The DEM to read.
    input: PathBuf,
    /// Build the model in memory and report on it without writing a container. Required for
    /// now: the container format arrives with its own issue.
    #[arg(long)]
    dry_run: bool,
    /// Samples along a block side: 2^k + 1, from 9 to 1025.
    #[arg(long, default_value_t = DEFAULT_BLOCK_SIZE)]
    block_size: u32,
    /// Cluster thresholds in height units, comma-separated (e.g. 0,1,5,20). Default: a √2
    /// ladder from the largest error down, plus 0 (lossless).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    thresholds: Option<Vec<f64>>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    ingest: IngestArgs,
}

#[derive(clap::Args)]
struct IngestArgs {
    /// Input format; guessed from the name and contents when absent.
    #[arg(long, value_enum)]
    format: Option<Format>,
    /// How an RGB(A) PNG encodes heights.
    #[arg(long, value_enum)]
    color_encoding: Option<ColorEncoding>,
    /// Multiply raw values by this (e.g. 0.1 for a decimetre 16-bit PNG).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    z_scale: f64,
    /// Add this to scaled values.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    z_offset: f64,
    /// A raw value that marks a void, besides the format's own nodata.
    #[arg(long, allow_negative_numbers = true)]
    nodata: Option<f64>,
}

impl IngestArgs {
    fn options(&self) -> IngestOptions {
        IngestOptions {
            format: self.format,
            color_encoding: self.color_encoding,
            z_scale: self.z_scale,
            z_offset: self.z_offset,
            nodata: self.nodata,
        }
    }
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
    clusters: Vec<ClusterReport>,
    ingest_time_ms: f64,
    build_time_ms: f64,
    peak_memory_bytes: Option<u64>,
}

/// Peak resident memory of this process (Linux `VmHWM`), if the system tells.
fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn build(args: &BuildArgs) -> Result<(), Error> {
    if !args.dry_run {
        return Err(Error::InvalidArgument(
            "only `build --dry-run` is available: writing a container comes with the container format".into(),
        ));
    }
    let t0 = Instant::now();
    let heightfield = ingest::load(&args.input, &args.ingest.options())?;
    let ingest_time = t0.elapsed();
    let metadata = heightfield.metadata.clone();
    let options = BuildOptions {
        block_size: args.block_size,
        thresholds: match &args.thresholds {
            Some(t) => Thresholds::Explicit(t.clone()),
            None => Thresholds::Ladder,
        },
    };
    let t1 = Instant::now();
    let model = Model::build(heightfield, &options)?;
    let build_time = t1.elapsed();
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
        peak_memory_bytes: peak_memory_bytes(),
    };
    if args.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| Error::InvalidArgument(format!("cannot format the report: {e}")))?;
        println!("{text}");
    } else {
        print_report(&report);
    }
    Ok(())
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
    if let Some(bytes) = r.peak_memory_bytes {
        println!("  peak memory {:.1} MiB", bytes as f64 / (1 << 20) as f64);
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Build(args) => build(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fmrh: error: {e}");
            match e {
                Error::Io { .. } => ExitCode::from(1),
                _ => ExitCode::from(2),
            }
        }
    }
}
