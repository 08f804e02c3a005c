//! `fmrh dataset`: datasets of many tiles (`format-spec/dataset.md`). `build` makes one from
//! tile DEMs, placed by a layout or by their georeferences; `add` adds a tile. Every other
//! command takes a dataset's directory where it takes a container.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use crate::dataset::{self, DatasetOptions, SeamPolicy, TileInput};
use crate::Error;

#[derive(clap::Subcommand)]
pub enum DatasetCommand {
    /// Build a dataset from tile DEMs: one container per tile and a MANIFEST, in a new
    /// directory that appears only when complete.
    ///
    /// Tiles are placed by --layout (a CSV of `path,col0,row0` lines, offsets in dataset
    /// samples, paths relative to the CSV) or by their georeferences (HGT names, GeoTIFF
    /// geotransforms, sidecars). Neighbours may share one edge row or column, which must
    /// agree sample for sample unless --seam says how to settle it.
    Build(BuildArgs),
    /// Add a tile to a dataset (expansion), or with --replace replace one (a whole file):
    /// placed by --at or by its georeference, its shared edges settled with its neighbours
    /// (the dataset's --seam policy unless given), written complete, then published by one
    /// manifest commit.
    Add(AddArgs),
}

#[derive(clap::Args)]
pub struct AddArgs {
    /// The dataset's directory.
    dir: PathBuf,
    /// The tile DEM. (Its id is not `tile`: `--tile`, the SRTM tile name of the ingest
    /// options, has that one; clap refuses two arguments of one id.)
    #[arg(id = "input", value_name = "TILE")]
    tile: PathBuf,
    /// Where its first sample goes: COL0,ROW0 in dataset samples (default: by its
    /// georeference).
    #[arg(long)]
    at: Option<String>,
    /// How a disagreement on a shared edge is settled (default: the policy the dataset was
    /// built with).
    #[arg(long)]
    seam: Option<SeamPolicy>,
    /// Replace the tile of the same place and size with this one (a whole file), instead of
    /// adding a tile where none is.
    #[arg(long)]
    replace: bool,
    #[command(flatten)]
    tile_options: TileOptions,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// How each tile is built: the model flags `fmrh build` takes too.
#[derive(clap::Args)]
pub struct TileOptions {
    #[command(flatten)]
    model: super::args::ModelArgs,
}

impl TileOptions {
    fn options(&self, seam: SeamPolicy) -> Result<DatasetOptions, Error> {
        Ok(DatasetOptions {
            ingest: self.model.ingest.options(),
            build: self.model.build_options()?,
            // 0: each tile's page size by its size, as `fmrh build` chooses.
            write: self.model.write_options(0),
            seam,
            spacing_m: self.model.spacing()?,
            tile_size: None,
        })
    }
}

#[derive(clap::Args)]
pub struct BuildArgs {
    /// The tile DEMs, placed by their georeferences (or give --layout).
    #[arg(required_unless_present = "layout", conflicts_with = "layout")]
    tiles: Vec<PathBuf>,
    /// A layout: one tile a line, `path,col0,row0`.
    #[arg(long)]
    layout: Option<PathBuf>,
    /// The dataset directory to create (it must not exist).
    #[arg(short, long)]
    output: PathBuf,
    /// How neighbours that disagree on a shared edge are settled: strict (an error naming
    /// both tiles and the first differing sample), first (the tile listed first keeps its
    /// samples) or mean (both take the mean; a void on either side wins).
    #[arg(long, default_value = "strict")]
    seam: SeamPolicy,
    /// Cut every input larger than this many samples a side into tiles of at most this many
    /// (neighbours share an edge row or column). Without it, only an input too large to
    /// build within --max-memory is cut, into tiles of up to 8,193 samples a side that fit
    /// the budget: so a GeoTIFF or .f32 larger than the machine's memory is built in the
    /// memory of one tile.
    #[arg(long, value_name = "SAMPLES")]
    tile_size: Option<u32>,
    #[command(flatten)]
    tile_options: TileOptions,
    /// Quiet: no progress, and no report on success.
    #[arg(long, short)]
    quiet: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

impl DatasetCommand {
    /// Whether the command prints JSON.
    pub fn json(&self) -> bool {
        match self {
            DatasetCommand::Build(a) => a.json,
            DatasetCommand::Add(a) => a.json,
        }
    }
}

/// Runs `fmrh dataset ...`.
pub fn run(command: &DatasetCommand) -> Result<ExitCode, Error> {
    match command {
        DatasetCommand::Build(args) => build(args),
        DatasetCommand::Add(args) => add(args),
    }
}

/// The tiles a layout lists, their paths taken relative to the layout's directory.
fn layout_tiles(layout: &Path) -> Result<Vec<TileInput>, Error> {
    let text = std::fs::read_to_string(layout).map_err(|e| Error::input(layout, e.to_string()))?;
    let lines =
        dataset::placement::parse_layout(&text).map_err(|e| Error::input(layout, e.to_string()))?;
    let base = layout.parent().unwrap_or(Path::new(""));
    Ok(lines
        .into_iter()
        .map(|l| TileInput {
            path: base.join(&l.path),
            at: Some((l.col0, l.row0)),
        })
        .collect())
}

fn build(args: &BuildArgs) -> Result<ExitCode, Error> {
    let inputs = match &args.layout {
        Some(layout) => layout_tiles(layout)?,
        None => args
            .tiles
            .iter()
            .map(|p| TileInput {
                path: p.clone(),
                at: None,
            })
            .collect(),
    };
    let mut options = args.tile_options.options(args.seam)?;
    options.tile_size = args.tile_size;
    let quiet = args.quiet || args.json;
    let bar = (!quiet).then(super::progress::Bar::new);
    let silent = crate::progress::Silent;
    let progress: &dyn crate::progress::Progress = match &bar {
        Some(b) => b,
        None => &silent,
    };
    let t0 = std::time::Instant::now();
    let mut on_tile = |phase: &str, i: usize, n: usize, path: &Path| {
        if let Some(b) = &bar {
            b.spin(&format!("{phase} tile {}/{n}: {}", i + 1, path.display()));
        }
    };
    let summary = dataset::build(&inputs, &args.output, &options, progress, &mut on_tile);
    progress.finish();
    let summary = summary?;
    let seconds = t0.elapsed().as_secs_f64();
    if args.json {
        #[derive(serde::Serialize)]
        struct Report<'a> {
            output: String,
            #[serde(flatten)]
            summary: &'a dataset::DatasetSummary,
            build_time_s: f64,
            peak_memory_bytes: Option<u64>,
        }
        super::print_json(&Report {
            output: args.output.display().to_string(),
            summary: &summary,
            build_time_s: seconds,
            peak_memory_bytes: super::build::peak_memory_bytes(),
        })?;
    } else if !args.quiet {
        println!(
            "{}: {} tiles, {} x {} samples, {} shared edges",
            args.output.display(),
            summary.tiles.len(),
            summary.columns,
            summary.rows,
            summary.shared_edges
        );
        for t in &summary.tiles {
            let r = t.rect;
            println!(
                "  {:<28} {:>10} bytes  columns {}..={}, rows {}..={}{}",
                t.name,
                t.file_length,
                r.col0,
                r.col1,
                r.row0,
                r.row1,
                if t.seam_samples_changed > 0 {
                    format!("  ({} shared-edge samples settled)", t.seam_samples_changed)
                } else {
                    String::new()
                }
            );
        }
        println!(
            "  manifest {} bytes; {} bytes in all; built in {seconds:.1} s",
            summary.manifest_bytes, summary.total_bytes
        );
        if let Some(bytes) = super::build::peak_memory_bytes() {
            println!("  peak memory {:.1} MiB", bytes as f64 / (1 << 20) as f64);
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn add(args: &AddArgs) -> Result<ExitCode, Error> {
    let at = args
        .at
        .as_deref()
        .map(|t| {
            let v: Option<Vec<u64>> = t.split(',').map(|p| p.trim().parse().ok()).collect();
            match v.as_deref() {
                Some([c, r]) => Ok((*c, *r)),
                _ => Err(Error::InvalidArgument(format!(
                    "--at `{t}`: expected COL0,ROW0 (non-negative integers)"
                ))),
            }
        })
        .transpose()?;
    let seam = match args.seam {
        Some(s) => s,
        None => dataset::add::recorded_policy(&dataset::Dataset::open(&args.dir)?),
    };
    let options = args.tile_options.options(seam)?;
    let run = if args.replace {
        dataset::replace_tile
    } else {
        dataset::add
    };
    let (commit, record, shift) = run(
        &args.dir,
        &args.tile,
        at,
        &options,
        &crate::progress::Silent,
    )?;
    let r = record.rect();
    if args.json {
        #[derive(serde::Serialize)]
        struct Report<'a> {
            dataset: String,
            tile: String,
            name: &'a str,
            rect: crate::model::SampleRect,
            /// How far every other tile's dataset coordinates moved (the new tile lies west
            /// or north of the old grid).
            origin_shift: [u64; 2],
            #[serde(flatten)]
            commit: &'a dataset::DatasetCommit,
        }
        super::print_json(&Report {
            dataset: args.dir.display().to_string(),
            tile: args.tile.display().to_string(),
            name: record.name(),
            rect: r,
            origin_shift: [shift.0, shift.1],
            commit: &commit,
        })?;
    } else {
        println!(
            "{} {} to {} as {}: columns {}..={}, rows {}..={} (manifest txn {}; {} neighbours \
             changed to settle shared edges)",
            if args.replace {
                "replaced a tile with"
            } else {
                "added"
            },
            args.tile.display(),
            args.dir.display(),
            record.name(),
            r.col0,
            r.col1,
            r.row0,
            r.row1,
            commit.txn_id,
            commit.tiles.len()
        );
        if shift != (0, 0) {
            println!(
                "  the tile lies west or north of the old grid: every other tile's dataset \
                 coordinates moved by +{} columns, +{} rows",
                shift.0, shift.1
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
