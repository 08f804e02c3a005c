//! Readers: every supported heightfield format in, one [`Heightfield`] out.
//!
//! Each format is a small module with one `read` function. They share three promises:
//!
//! * **Voids are voids.** A format's nodata (SRTM's -32768, GDAL_NODATA, an `.asc`
//!   `NODATA_value`, a transparent pixel, USGS's -32767 and cells outside every profile)
//!   becomes `NaN`, never a magic height.
//! * **Sizes are checked before allocation.** A header is checked against
//!   [`heightfield::check_dimensions`](crate::heightfield::check_dimensions) and against what
//!   the file can actually hold before any buffer is sized from it.
//! * **Malformed input is an error.** Truncated, inconsistent or unsupported input returns
//!   [`Error::Input`] or [`Error::Unsupported`] naming the file. It never panics.
//!
//! Integer-coded formats (grey PNG, JPEG, integer GeoTIFF, `.hgt`) map a raw value `r` to the
//! height `(r · z_scale + z_offset)`, computed in `f64` and rounded once to `f32`. The defaults
//! 1 and 0 leave raw values unchanged.

mod dted;
mod esri_ascii;
mod geotiff;
mod jpeg;
pub mod limits;
mod png;
mod raw_f32;
mod srtm;
mod usgs_dem;
pub mod window;

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};
use crate::geoid::VerticalDatum;
use crate::heightfield::{Georeference, Heightfield, Metadata};
pub use limits::IngestLimits;
pub use window::WindowedRaster;

/// The input formats fmrh reads ([`Format::about`] says what each takes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Raw `f32` with a `.json` sidecar.
    F32,
    /// SRTM `.hgt`.
    Hgt,
    /// GeoTIFF.
    Geotiff,
    /// PNG.
    Png,
    /// Baseline JPEG.
    Jpeg,
    /// ESRI ASCII grid.
    Asc,
    /// USGS ASCII DEM.
    UsgsDem,
    /// DTED.
    Dted,
}

impl Format {
    /// Every format, in the order `--format` lists them.
    pub const ALL: [Format; 8] = [
        Format::F32,
        Format::Hgt,
        Format::Geotiff,
        Format::Png,
        Format::Jpeg,
        Format::Asc,
        Format::UsgsDem,
        Format::Dted,
    ];

    /// The name used in output (a built file's `source_format`).
    pub fn name(self) -> &'static str {
        match self {
            Format::F32 => "f32",
            Format::Hgt => "srtm-hgt",
            Format::Geotiff => "geotiff",
            Format::Png => "png",
            Format::Jpeg => "jpeg",
            Format::Asc => "esri-ascii",
            Format::UsgsDem => "usgs-dem",
            Format::Dted => "dted",
        }
    }

    /// The name the command line's `--format` takes.
    pub fn flag(self) -> &'static str {
        match self {
            Format::F32 => "f32",
            Format::Hgt => "hgt",
            Format::Geotiff => "geotiff",
            Format::Png => "png",
            Format::Jpeg => "jpeg",
            Format::Asc => "asc",
            Format::UsgsDem => "usgs-dem",
            Format::Dted => "dted",
        }
    }

    /// The format `--format NAME` names.
    pub fn from_flag(name: &str) -> Option<Format> {
        Format::ALL.into_iter().find(|f| f.flag() == name)
    }

    /// What it reads, in one line (the command line's help says the same).
    pub fn about(self) -> &'static str {
        match self {
            Format::F32 => {
                "Raw little-endian f32 + .json sidecar, the form of ../shared/data (either file)"
            }
            Format::Hgt => "SRTM .hgt or .hgt.gz: 1201² or 3601² big-endian i16, -32768 void",
            Format::Geotiff => {
                "GeoTIFF, one band of 8/16/32-bit integers or 32/64-bit floats, uncompressed, \
                 deflate, LZW, PackBits or ZSTD, GDAL_NODATA honoured"
            }
            Format::Png => "PNG: 8/16-bit grey or grey palette, or Terrain-RGB / Terrarium colour",
            Format::Jpeg => {
                "Baseline JPEG, grey or R=G=B colour (lossy: for throughput tests, not precision)"
            }
            Format::Asc => "ESRI ASCII grid (.asc), with its .prj",
            Format::UsgsDem => {
                "USGS ASCII DEM (.dem), 1024-byte records, UTM or geographic profiles"
            }
            Format::Dted => {
                "DTED levels 0–2 (.dt0, .dt1, .dt2): WGS 84 grids, signed-magnitude i16"
            }
        }
    }
}

/// How the colour channels of an 8-bit RGB(A) PNG encode height.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorEncoding {
    /// Mapbox Terrain-RGB: `h = -10000 + (R·65536 + G·256 + B) · 0.1`.
    TerrainRgb,
    /// Terrarium: `h = R·256 + G + B/256 - 32768`.
    Terrarium,
}

impl ColorEncoding {
    /// Every encoding, in the order `--color-encoding` lists them.
    pub const ALL: [ColorEncoding; 2] = [ColorEncoding::TerrainRgb, ColorEncoding::Terrarium];

    /// The name the command line's `--color-encoding` takes.
    pub fn flag(self) -> &'static str {
        match self {
            ColorEncoding::TerrainRgb => "terrain-rgb",
            ColorEncoding::Terrarium => "terrarium",
        }
    }

    /// The encoding `--color-encoding NAME` names.
    pub fn from_flag(name: &str) -> Option<ColorEncoding> {
        ColorEncoding::ALL.into_iter().find(|c| c.flag() == name)
    }

    /// Its formula, in one line.
    pub fn about(self) -> &'static str {
        match self {
            ColorEncoding::TerrainRgb => {
                "Mapbox Terrain-RGB: h = -10000 + (R·65536 + G·256 + B) · 0.1"
            }
            ColorEncoding::Terrarium => "Terrarium: h = R·256 + G + B/256 - 32768",
        }
    }
}

/// Options that say how to read an input.
#[derive(Clone, Debug, PartialEq)]
pub struct IngestOptions {
    /// The format; detected from the file name and contents when `None`.
    pub format: Option<Format>,
    /// How an RGB(A) PNG encodes heights; required for such files.
    pub color_encoding: Option<ColorEncoding>,
    /// Multiplier applied to raw values (see the module docs).
    pub z_scale: f64,
    /// Offset added after scaling.
    pub z_offset: f64,
    /// A raw value that marks a void, in addition to the format's own.
    pub nodata: Option<f64>,
    /// The 1° tile an `.hgt` holds, named as SRTM names it (`N44W072`: the south-west
    /// corner), for a file whose name does not say.
    pub tile: Option<String>,
    /// What a file may declare before it is believed: the memory a build may take and the
    /// samples a byte of input may claim ([`IngestLimits`]).
    pub limits: IngestLimits,
    /// What the heights are above, overriding what the source says (a GeoTIFF's vertical
    /// CRS) and the reader's convention (SRTM and DTED: EGM96; the others: unknown).
    pub vertical_datum: Option<VerticalDatum>,
}

impl Default for IngestOptions {
    fn default() -> Self {
        IngestOptions {
            format: None,
            color_encoding: None,
            z_scale: 1.0,
            z_offset: 0.0,
            nodata: None,
            tile: None,
            limits: IngestLimits::default(),
            vertical_datum: None,
        }
    }
}

impl IngestOptions {
    /// The height of raw value `raw`, or `NaN` if `raw` is the user's nodata value.
    #[inline]
    fn height(&self, raw: f64) -> f32 {
        if self.nodata == Some(raw) {
            return f32::NAN;
        }
        (raw * self.z_scale + self.z_offset) as f32
    }

    fn check(&self) -> Result<()> {
        if !self.z_scale.is_finite() || self.z_scale == 0.0 || !self.z_offset.is_finite() {
            return Err(Error::InvalidArgument(format!(
                "z-scale {} and z-offset {} must be finite, and the scale non-zero",
                self.z_scale, self.z_offset
            )));
        }
        if self
            .limits
            .max_samples_per_byte
            .is_some_and(|r| r.is_nan() || r < 0.0)
        {
            return Err(Error::InvalidArgument(
                "max-samples-per-byte must be a number >= 0 (0: no ceiling)".into(),
            ));
        }
        if self.nodata.is_some_and(f64::is_nan) {
            return Err(Error::InvalidArgument("nodata must be a number".into()));
        }
        if let Some(tile) = &self.tile {
            if parse_tile_name(tile).is_none_or(|_| tile.trim().len() != 7) {
                return Err(Error::InvalidArgument(format!(
                    "tile {tile:?}: expected a 1° tile name such as N44W072 or S16E166"
                )));
            }
        }
        Ok(())
    }
}

/// Reads the heightfield at `path`.
pub fn load(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    options.check()?;
    let format = match options.format {
        Some(f) => f,
        None => detect(path)?,
    };
    let mut hf = match format {
        Format::F32 => raw_f32::read(path, options)?,
        Format::Hgt => srtm::read(path, options)?,
        Format::Geotiff => geotiff::read(path, options)?,
        Format::Png => png::read(path, options)?,
        Format::Jpeg => jpeg::read(path, options)?,
        Format::Asc => esri_ascii::read(path, options)?,
        Format::UsgsDem => usgs_dem::read(path, options)?,
        Format::Dted => dted::read(path, options)?,
    };
    settle_source(&mut hf.metadata, format, options);
    Ok(hf)
}

/// Names the reader in `metadata` and settles what its heights are above: the user's word,
/// else what the file said, else the reader's convention.
fn settle_source(metadata: &mut Metadata, format: Format, options: &IngestOptions) {
    metadata.source_format = format.name().to_string();
    metadata.vertical_datum = match options.vertical_datum {
        Some(datum) => datum,
        None if metadata.vertical_datum != VerticalDatum::Unknown => metadata.vertical_datum,
        None => VerticalDatum::of_source_format(format.name()),
    };
}

/// Guesses the format from the file name, then from the first bytes.
pub fn detect(path: &Path) -> Result<Format> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let by_name = [
        (".f32", Format::F32),
        (".json", Format::F32),
        (".hgt", Format::Hgt),
        (".hgt.gz", Format::Hgt),
        (".tif", Format::Geotiff),
        (".tiff", Format::Geotiff),
        (".png", Format::Png),
        (".jpg", Format::Jpeg),
        (".jpeg", Format::Jpeg),
        (".asc", Format::Asc),
        (".dem", Format::UsgsDem),
        (".dt0", Format::Dted),
        (".dt1", Format::Dted),
        (".dt2", Format::Dted),
    ];
    if let Some(&(_, f)) = by_name.iter().find(|(ext, _)| name.ends_with(ext)) {
        return Ok(f);
    }
    let mut head = [0u8; 8];
    let n = File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .map_err(|e| Error::io(path, e))?;
    let head = &head[..n];
    if head.starts_with(b"\x89PNG") {
        Ok(Format::Png)
    } else if head.starts_with(b"II*\0") || head.starts_with(b"MM\0*") {
        Ok(Format::Geotiff)
    } else if head.starts_with(&[0xFF, 0xD8]) {
        Ok(Format::Jpeg)
    } else if head.starts_with(b"UHL1") {
        Ok(Format::Dted)
    } else {
        Err(Error::input(
            path,
            "cannot tell the format from the name or contents; give --format",
        ))
    }
}

/// `(south latitude, west longitude)` of the 1° tile named in `name` as SRTM names it
/// (`N44W072`, `s16E166`), wherever it stands, as long as it is not part of a longer word or
/// number.
pub fn parse_tile_name(name: &str) -> Option<(i32, i32)> {
    let b = name.as_bytes();
    let digits = |b: &[u8]| -> Option<i32> {
        b.iter().try_fold(0i32, |acc, &c| {
            c.is_ascii_digit().then(|| acc * 10 + i32::from(c - b'0'))
        })
    };
    (0..b.len().saturating_sub(6)).find_map(|i| {
        if i > 0 && b[i - 1].is_ascii_alphanumeric() {
            return None;
        }
        if b.get(i + 7).is_some_and(u8::is_ascii_digit) {
            return None;
        }
        let lat = digits(&b[i + 1..i + 3])?;
        let lon = digits(&b[i + 4..i + 7])?;
        let lat = match b[i].to_ascii_uppercase() {
            b'N' => lat,
            b'S' => -lat,
            _ => return None,
        };
        let lon = match b[i + 3].to_ascii_uppercase() {
            b'E' => lon,
            b'W' => -lon,
            _ => return None,
        };
        ((-90..90).contains(&lat) && (-180..180).contains(&lon)).then_some((lat, lon))
    })
}

/// Reads at most `limit` bytes of `path`; more is an error (the caller's size check failed).
/// Checks the grid `path` declares against the limits, by the file's size on disk.
fn check_declared(path: &Path, options: &IngestOptions, width: u64, height: u64) -> Result<()> {
    let len = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    options.limits.check_declared(path, width, height, len)
}

fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len > limit {
        return Err(Error::input(
            path,
            format!("file is {len} bytes, more than the {limit} this format can need"),
        ));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(limit)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// Builds the heightfield, turning a rejected sample (an infinite height) into an input error
/// that names the file.
fn finish(
    path: &Path,
    width: u32,
    height: u32,
    mut samples: Vec<f32>,
    mut metadata: Metadata,
) -> Result<Heightfield> {
    check_metadata(path, &metadata)?;
    if let Some(g) = &mut metadata.georeference {
        north_up(g, &mut samples, width as usize, height as usize);
    }
    Heightfield::new(width, height, samples)
        .map(|hf| hf.with_metadata(metadata))
        .map_err(|e| match e {
            Error::InvalidArgument(reason) => Error::input(path, reason),
            other => other,
        })
}

/// Turns a south-up grid (rows running north, `step[1] > 0`) or an east-to-west one
/// (`step[0] < 0`) into fmrh's orientation, row 0 north and column 0 west, by reversing the
/// rows or the columns, and moves the georeference's origin to the new first sample.
fn north_up(g: &mut Georeference, samples: &mut [f32], width: usize, height: usize) {
    if width == 0 || samples.len() != width * height {
        return; // Heightfield::new refuses it
    }
    let [flip_columns, flip_rows] = north_up_georeference(g, width as u64, height as u64);
    flip(samples, width, flip_columns, flip_rows);
}

/// Moves `g` to the north-up orientation of a `width × height` grid (as [`north_up`] does);
/// says whether the columns and the rows are to be reversed.
fn north_up_georeference(g: &mut Georeference, width: u64, height: u64) -> [bool; 2] {
    let flip_rows = g.step[1] > 0.0;
    if flip_rows {
        g.origin[1] += g.step[1] * height.saturating_sub(1) as f64;
        g.step[1] = -g.step[1];
    }
    let flip_columns = g.step[0] < 0.0;
    if flip_columns {
        g.origin[0] += g.step[0] * width.saturating_sub(1) as f64;
        g.step[0] = -g.step[0];
    }
    [flip_columns, flip_rows]
}

/// Reverses the columns and/or the rows of a row-major `width`-column grid.
fn flip(samples: &mut [f32], width: usize, columns: bool, rows: bool) {
    if width == 0 {
        return;
    }
    let height = samples.len() / width;
    if rows {
        for y in 0..height / 2 {
            let (top, bottom) = samples.split_at_mut((height - 1 - y) * width);
            top[y * width..(y + 1) * width].swap_with_slice(&mut bottom[..width]);
        }
    }
    if columns {
        for row in samples.chunks_exact_mut(width) {
            row.reverse();
        }
    }
}

/// Checks what a reader found about the grid's geometry: a spacing must be finite and
/// positive (a negative or zero cell size is a damaged header, and scenes would divide by
/// it), a georeference finite with non-zero steps.
fn check_metadata(path: &Path, metadata: &Metadata) -> Result<()> {
    if let Some(s) = metadata.spacing_m {
        if !s.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(Error::input(
                path,
                format!(
                    "sample spacing {} × {} m: it must be finite and positive",
                    s[0], s[1]
                ),
            ));
        }
    }
    if let Some(g) = &metadata.georeference {
        let finite = g.origin.iter().chain(&g.step).all(|v| v.is_finite());
        if !finite || g.step.contains(&0.0) {
            return Err(Error::input(
                path,
                format!(
                    "georeference origin {:?}, step {:?}: it must be finite, the steps non-zero",
                    g.origin, g.step
                ),
            ));
        }
    }
    Ok(())
}
