//! `fmrh extract`: full-resolution samples out of a container, bit for bit as stored, in the
//! `.f32` + `.json` form of `../shared/data` (so `fmrh build` reads them back) or as a
//! Cloud-Optimized GeoTIFF.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::Error;

#[derive(clap::Args)]
pub struct ExtractArgs {
    /// The container, or a dataset's directory (the window is then in dataset samples;
    /// samples where no tile lies are voids).
    file: PathBuf,
    /// The window, inclusive sample coordinates `c0,r0,c1,r1` (default: the whole dataset).
    #[arg(long)]
    window: Option<String>,
    /// The file to write: a `.f32` (its `.json` sidecar goes beside it), or a GeoTIFF
    /// (`.tif`, `.tiff`, or --format tif). `-`: standard output.
    #[arg(short, long)]
    output: PathBuf,
    /// The output's format (default: from its name; `.f32` otherwise). `tif` (or `cog`)
    /// is a Cloud-Optimized GeoTIFF.
    #[arg(long, value_enum)]
    format: Option<super::sidecar::RasterFormat>,
    #[command(flatten)]
    tif: super::sidecar::TifArgs,
    /// Replace existing output files.
    #[arg(long)]
    force: bool,
    /// Quiet: no progress bar, and no message on success.
    #[arg(long, short)]
    quiet: bool,
}

/// Runs `fmrh extract`.
pub fn run(args: &ExtractArgs) -> Result<ExitCode, Error> {
    if super::is_dataset(&args.file)? {
        let ds = crate::dataset::Dataset::open(&args.file)?;
        let window = match &args.window {
            Some(text) => super::args::parse_window(text)?,
            None => ds.grid(),
        };
        let out = super::sidecar::RasterOutput::new(&args.output, args.format, args.force)?
            .with_tif(&args.tif)
            .quietly(args.quiet);
        let hf = ds.read_window(window)?;
        out.write_dataset(&hf, window, &args.file, ds.txn_id())?;
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        return extract(args, &crate::store::Store::open_url(url)?);
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    extract(args, &super::open(&args.file)?)
}

/// Extracts from `store`.
fn extract<S: crate::store::Source>(
    args: &ExtractArgs,
    store: &crate::store::Store<S>,
) -> Result<ExitCode, Error> {
    let data = store.domain().data_rect();
    let window = match &args.window {
        Some(text) => super::args::parse_window(text)?,
        None => data,
    };
    let out = super::sidecar::RasterOutput::new(&args.output, args.format, args.force)?
        .with_tif(&args.tif)
        .quietly(args.quiet);
    let hf = if args.quiet {
        store.read_window(window)?
    } else {
        store.read_window_with_progress(window, &super::progress::Bar::new())?
    };
    out.write(&hf, window, "fmrh extract", &args.file, store)?;
    Ok(ExitCode::SUCCESS)
}
