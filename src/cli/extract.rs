//! `fmrh extract`: full-resolution samples out of a container, bit for bit as stored, in the
//! `.f32` + `.json` form of `../shared/data` (so `fmrh build` reads them back).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use serde::Serialize;

use fmrh::model::SampleRect;
use fmrh::store::write_atomically;
use fmrh::Error;

#[derive(clap::Args)]
pub struct ExtractArgs {
    /// The container.
    file: PathBuf,
    /// The window, inclusive sample coordinates `c0,r0,c1,r1` (default: the whole dataset).
    #[arg(long)]
    window: Option<String>,
    /// The `.f32` to write; its `.json` sidecar goes beside it.
    #[arg(short, long)]
    output: PathBuf,
    /// Replace existing output files.
    #[arg(long)]
    force: bool,
}

/// The sidecar, with the keys `../shared/data/README.md` promises.
#[derive(Serialize)]
struct Sidecar {
    width: u32,
    height: u32,
    f32_file: String,
    f32_layout: &'static str,
    nodata_in_f32: &'static str,
    nodata_count: u64,
    min: Option<f32>,
    max: Option<f32>,
    mean: Option<f64>,
    units: Option<String>,
    spacing_m: Option<[f64; 2]>,
    georeference: Option<Geo>,
    /// `[c0, r0, c1, r1]` of the container's samples, inclusive.
    window: [u64; 4],
    source: Source,
}

#[derive(Serialize)]
struct Geo {
    crs: Option<String>,
    /// CRS coordinates of the centre of the window's sample (0, 0).
    origin: [f64; 2],
    step: [f64; 2],
}

#[derive(Serialize)]
struct Source {
    kind: &'static str,
    container: String,
    txn_id: u64,
    original_format: String,
}

/// Runs `fmrh extract`.
pub fn run(args: &ExtractArgs) -> Result<ExitCode, Error> {
    let store = super::open(&args.file)?;
    let data = store.domain().data_rect();
    let window = match &args.window {
        Some(text) => {
            let [c0, r0, c1, r1] = super::parse_quad(text, "window")?;
            SampleRect {
                col0: c0,
                row0: r0,
                col1: c1,
                row1: r1,
            }
        }
        None => data,
    };
    let json_path = args.output.with_extension("json");
    if args.output.extension().is_some_and(|e| e == "json") {
        return Err(Error::InvalidArgument(
            "the output is the .f32 file; its .json sidecar is written beside it".into(),
        ));
    }
    for p in [&args.output, &json_path] {
        if !args.force && p.exists() {
            return Err(Error::InvalidArgument(format!(
                "{} exists; pass --force to replace it",
                p.display()
            )));
        }
    }
    let hf = store.read_window(window)?;
    let samples = hf.samples();
    let (mut min, mut max, mut sum, mut valid) = (f32::INFINITY, f32::NEG_INFINITY, 0f64, 0u64);
    for &v in samples {
        if !v.is_nan() {
            min = min.min(v);
            max = max.max(v);
            sum += f64::from(v);
            valid += 1;
        }
    }
    let meta = &hf.metadata;
    let file_name = args
        .output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let sidecar = Sidecar {
        width: hf.width(),
        height: hf.height(),
        f32_file: file_name,
        f32_layout: "raw little-endian float32, row-major, width*height values, no header",
        nodata_in_f32: "NaN",
        nodata_count: samples.len() as u64 - valid,
        min: (valid > 0).then_some(min),
        max: (valid > 0).then_some(max),
        mean: (valid > 0).then(|| sum / valid as f64),
        units: meta.units.clone(),
        spacing_m: meta.spacing_m,
        georeference: meta.georeference.as_ref().map(|g| Geo {
            crs: g.crs.clone(),
            origin: g.origin,
            step: g.step,
        }),
        window: [window.col0, window.row0, window.col1, window.row1],
        source: Source {
            kind: "fmrh extract",
            container: args.file.display().to_string(),
            txn_id: store.txn_id(),
            original_format: store.header().metadata.source_format.clone(),
        },
    };
    let json = serde_json::to_vec_pretty(&sidecar)
        .map_err(|e| Error::InvalidArgument(format!("cannot format the sidecar: {e}")))?;
    let mut raw = Vec::with_capacity(samples.len() * 4);
    for v in samples {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    for (path, bytes) in [(&args.output, &raw), (&json_path, &json)] {
        write_atomically(path, args.force, |w| {
            w.write_all(bytes).map_err(|e| Error::io(path, e))
        })?;
    }
    eprintln!(
        "fmrh: wrote {} x {} samples ({} void) to {} and {}",
        hf.width(),
        hf.height(),
        samples.len() as u64 - valid,
        args.output.display(),
        json_path.display()
    );
    Ok(ExitCode::SUCCESS)
}
