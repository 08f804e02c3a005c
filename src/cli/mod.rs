//! The subcommands, one module each, and the few helpers they share: the ingest flags (the
//! command line's mirror of `fmrh::ingest`'s options, so the library knows nothing of clap),
//! the progress bar, JSON output and argument parsers.

pub mod build;
pub mod dataset;
pub mod extract;
pub mod fly;
pub mod info;
pub mod mesh;
pub mod progress;
pub mod recover;
pub mod render;
pub mod replace;
pub mod scan;
pub mod scene;
pub mod serve;
pub mod sidecar;
pub mod verify;

use std::path::Path;

use serde::Serialize;

use fmrh::ingest::{ColorEncoding, Format, IngestOptions};
use fmrh::store::FileSource;
use fmrh::{Error, Store};

/// The input formats, as `--format` names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    /// Raw little-endian `f32` + `.json` sidecar, the form of `../shared/data` (either file).
    F32,
    /// SRTM `.hgt` or `.hgt.gz`: 1201² or 3601² big-endian `i16`, -32768 void.
    Hgt,
    /// GeoTIFF, one band of 8/16/32-bit integers or 32/64-bit floats, GDAL_NODATA honoured.
    Geotiff,
    /// PNG: 8/16-bit grey or grey palette, or Terrain-RGB / Terrarium colour.
    Png,
    /// Baseline JPEG, grey or R=G=B colour (lossy: for throughput tests, not precision).
    Jpeg,
    /// ESRI ASCII grid (`.asc`).
    Asc,
    /// USGS ASCII DEM (`.dem`), 1024-byte records, UTM or geographic profiles.
    UsgsDem,
    /// DTED levels 0–2 (`.dt0`, `.dt1`, `.dt2`).
    Dted,
}

impl From<FormatArg> for Format {
    fn from(f: FormatArg) -> Format {
        match f {
            FormatArg::F32 => Format::F32,
            FormatArg::Hgt => Format::Hgt,
            FormatArg::Geotiff => Format::Geotiff,
            FormatArg::Png => Format::Png,
            FormatArg::Jpeg => Format::Jpeg,
            FormatArg::Asc => Format::Asc,
            FormatArg::UsgsDem => Format::UsgsDem,
            FormatArg::Dted => Format::Dted,
        }
    }
}

/// How an RGB(A) PNG encodes heights, as `--color-encoding` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ColorArg {
    /// Mapbox Terrain-RGB: `h = -10000 + (R·65536 + G·256 + B) · 0.1`.
    TerrainRgb,
    /// Terrarium: `h = R·256 + G + B/256 - 32768`.
    Terrarium,
}

impl From<ColorArg> for ColorEncoding {
    fn from(c: ColorArg) -> ColorEncoding {
        match c {
            ColorArg::TerrainRgb => ColorEncoding::TerrainRgb,
            ColorArg::Terrarium => ColorEncoding::Terrarium,
        }
    }
}

/// How to read an input DEM: the options every command that ingests shares.
#[derive(clap::Args)]
pub struct IngestArgs {
    /// Input format; guessed from the name and contents when absent.
    #[arg(long, value_enum)]
    format: Option<FormatArg>,
    /// How an RGB(A) PNG encodes heights.
    #[arg(long, value_enum)]
    color_encoding: Option<ColorArg>,
    /// Multiply raw values by this (e.g. 0.1 for a decimetre 16-bit PNG).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    z_scale: f64,
    /// Add this to scaled values.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    z_offset: f64,
    /// A raw value that marks a void, besides the format's own nodata.
    #[arg(long, allow_negative_numbers = true)]
    nodata: Option<f64>,
    /// The 1° tile an `.hgt` file holds (e.g. N44W072, its south-west corner), when the
    /// file's name does not say: it places the tile and gives its spacing in metres.
    #[arg(long, value_name = "NAME")]
    tile: Option<String>,
}

impl IngestArgs {
    /// The ingest options these flags give.
    pub fn options(&self) -> IngestOptions {
        IngestOptions {
            format: self.format.map(Format::from),
            color_encoding: self.color_encoding.map(ColorEncoding::from),
            z_scale: self.z_scale,
            z_offset: self.z_offset,
            nodata: self.nodata,
            tile: self.tile.clone(),
        }
    }
}

/// Prints `value` as pretty JSON.
pub fn print_json<T: Serialize>(value: &T) -> Result<(), Error> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::InvalidArgument(format!("cannot format the report: {e}")))?;
    println!("{text}");
    Ok(())
}

/// Opens a container for the read-only commands: positioned reads, the state registered
/// against reuse by writers in other processes (see `Store::open`).
pub fn open(path: &Path) -> Result<Store<FileSource>, Error> {
    Store::open(path)
}

/// The URL `path` names, when it is one (`http://`, `https://`, `s3://`): a remote
/// container or dataset.
pub fn url_of(path: &Path) -> Option<&str> {
    path.to_str().filter(|t| fmrh::store::is_url(t))
}

/// The error for a URL in a build without the `remote` feature.
#[cfg(not(feature = "remote"))]
pub fn no_remote(url: &str) -> Error {
    Error::InvalidArgument(format!(
        "{url}: this fmrh was built without the `remote` feature (HTTP range reads)"
    ))
}

/// Refuses an existing `output` unless `force` (`-`, standard output, always goes).
pub fn check_output(output: &Path, force: bool) -> Result<(), Error> {
    if output != Path::new("-") && !force && output.exists() {
        return Err(Error::InvalidArgument(format!(
            "{} exists; pass --force to replace it",
            output.display()
        )));
    }
    Ok(())
}

/// Writes `bytes` to `output`: standard output for `-`, else atomically (an existing file
/// stays whole until the new one replaces it, and only with `force`).
pub fn write_output(output: &Path, force: bool, bytes: &[u8]) -> Result<(), Error> {
    use std::io::Write;
    if output == Path::new("-") {
        let mut out = std::io::stdout().lock();
        return out
            .write_all(bytes)
            .and_then(|()| out.flush())
            .map_err(|e| Error::io("<stdout>", e));
    }
    fmrh::store::write_atomically(output, force, |w| {
        w.write_all(bytes).map_err(|e| Error::io(output, e))
    })
}

/// Whether `path` names a dataset (a directory with a MANIFEST) rather than a container; a
/// directory without one is an error, not a file to open.
pub fn is_dataset(path: &Path) -> Result<bool, Error> {
    if url_of(path).is_some() {
        // A URL names a dataset when it ends with `/` or `/MANIFEST`.
        return Ok(fmrh::dataset::is_dataset(path));
    }
    if !path.is_dir() {
        return Ok(false);
    }
    if fmrh::dataset::is_dataset(path) {
        return Ok(true);
    }
    Err(Error::input(
        path,
        "a directory without a MANIFEST: not an fmrh dataset (nor a container file)",
    ))
}

/// Parses `a,b,c,d` into four integers.
pub fn parse_quad(text: &str, what: &str) -> Result<[u64; 4], Error> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let values: Option<Vec<u64>> = parts.iter().map(|p| p.parse().ok()).collect();
    match values {
        Some(v) if v.len() == 4 => Ok([v[0], v[1], v[2], v[3]]),
        _ => Err(Error::InvalidArgument(format!(
            "{what} `{text}`: expected four non-negative integers c0,r0,c1,r1"
        ))),
    }
}

/// Parses an inclusive window `c0,r0,c1,r1`.
pub fn parse_window(text: &str) -> Result<fmrh::model::SampleRect, Error> {
    let [col0, row0, col1, row1] = parse_quad(text, "window")?;
    Ok(fmrh::model::SampleRect {
        col0,
        row0,
        col1,
        row1,
    })
}

/// Parses `x,y,z` into a vector of finite numbers.
pub fn parse_vec3(text: &str, what: &str) -> Result<glam::DVec3, Error> {
    let v = parse_list(text, 3, what)?;
    Ok(glam::DVec3::new(v[0], v[1], v[2]))
}

/// Parses `n` comma-separated finite numbers.
pub fn parse_list(text: &str, n: usize, what: &str) -> Result<Vec<f64>, Error> {
    let parts: Option<Vec<f64>> = text.split(',').map(|p| p.trim().parse().ok()).collect();
    match parts {
        Some(v) if v.len() == n && v.iter().all(|x| x.is_finite()) => Ok(v),
        _ => Err(Error::InvalidArgument(format!(
            "{what} `{text}`: expected {n} finite numbers, comma-separated"
        ))),
    }
}

/// Parses a Rust-style range of integers into an inclusive one: `a..b` (b excluded) or
/// `a..=b` (b included). `None` when the range is empty.
pub fn parse_range(text: &str, what: &str) -> Result<Option<(u64, u64)>, Error> {
    let bad = || {
        Error::InvalidArgument(format!(
            "{what} `{text}`: expected A..B (B excluded) or A..=B (B included)"
        ))
    };
    let (a, b, inclusive) = if let Some((a, b)) = text.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = text.split_once("..") {
        (a, b, false)
    } else {
        return Err(bad());
    };
    let a: u64 = a.trim().parse().map_err(|_| bad())?;
    let b: u64 = b.trim().parse().map_err(|_| bad())?;
    let last = if inclusive { Some(b) } else { b.checked_sub(1) };
    Ok(last.filter(|&l| l >= a).map(|l| (a, l)))
}
