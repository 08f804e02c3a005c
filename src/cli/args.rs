//! The command-line arguments several commands share, declared once and `flatten`ed where
//! they are used: how to read a DEM ([`IngestArgs`]), how to build a model and write it
//! ([`ModelArgs`], for `build` and `dataset build|add`), where the camera is and what the view
//! asks ([`CameraArgs`], [`ViewArgs`], for `scene`, `fly`, `render`, `mesh`, `serve`), and
//! the parsers of the values they take. The names and help of `--format` and
//! `--color-encoding` come from `crate::ingest` itself, so the two cannot drift apart.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

use crate::ingest::{ColorEncoding, Format, IngestOptions};
use crate::model::{BuildOptions, Precision, ThinByArea, Thresholds, DEFAULT_BLOCK_SIZE};
use crate::scene::{Camera, Handedness, Mode, SceneOptions, DEFAULT_GAP};
use crate::store::WriteOptions;
use crate::Error;

/// `--format`: the names and one-line help of [`Format::ALL`].
fn format_parser() -> impl TypedValueParser<Value = Format> {
    PossibleValuesParser::new(Format::ALL.map(|f| PossibleValue::new(f.flag()).help(f.about())))
        .try_map(|name: String| {
            Format::from_flag(&name).ok_or_else(|| format!("unknown format {name:?}"))
        })
}

/// `--color-encoding`: the names and one-line help of [`ColorEncoding::ALL`].
fn color_parser() -> impl TypedValueParser<Value = ColorEncoding> {
    PossibleValuesParser::new(
        ColorEncoding::ALL.map(|c| PossibleValue::new(c.flag()).help(c.about())),
    )
    .try_map(|name: String| {
        ColorEncoding::from_flag(&name).ok_or_else(|| format!("unknown encoding {name:?}"))
    })
}

/// How to read an input DEM: the options every command that ingests shares.
#[derive(clap::Args)]
pub struct IngestArgs {
    /// Input format; guessed from the name and contents when absent.
    #[arg(long, value_parser = format_parser())]
    format: Option<Format>,
    /// How an RGB(A) PNG encodes heights.
    #[arg(long, value_parser = color_parser())]
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
    /// The 1° tile an `.hgt` file holds (e.g. N44W072, its south-west corner), when the
    /// file's name does not say: it places the tile and gives its spacing in metres.
    #[arg(long, value_name = "NAME")]
    tile: Option<String>,
    /// The memory a build may take (e.g. 12G, 512M): an input whose grid needs more is
    /// refused before it is read. Default: half of this machine's memory.
    #[arg(long, value_name = "SIZE", value_parser = crate::ingest::limits::parse_size)]
    max_memory: Option<u64>,
    /// The samples a byte of input may declare, past 2^24 samples (default 256; 0: no
    /// ceiling). A header that claims far more than its bytes could be a decompression bomb.
    #[arg(long, value_name = "N")]
    max_samples_per_byte: Option<f64>,
    /// What the heights are above: egm96, egm2008, ellipsoid or unknown. Recorded in the
    /// container (`info` shows it); globe outputs lift EGM96 heights onto the ellipsoid.
    /// Default: the file's vertical CRS (a GeoTIFF's), else EGM96 for SRTM and DTED, else
    /// unknown.
    #[arg(long, value_name = "DATUM", value_parser = crate::geoid::VerticalDatum::parse)]
    vertical_datum: Option<crate::geoid::VerticalDatum>,
}

impl IngestArgs {
    /// The ingest options these flags give.
    pub fn options(&self) -> IngestOptions {
        IngestOptions {
            format: self.format,
            color_encoding: self.color_encoding,
            z_scale: self.z_scale,
            z_offset: self.z_offset,
            nodata: self.nodata,
            tile: self.tile.clone(),
            limits: crate::ingest::IngestLimits {
                max_memory: self.max_memory,
                max_samples_per_byte: self.max_samples_per_byte,
            },
            vertical_datum: self.vertical_datum,
        }
    }
}

/// How to build a model and write its container: the flags `build`, `dataset build` and
/// `dataset add` share.
#[derive(clap::Args)]
pub struct ModelArgs {
    /// Samples along a block side: 2^k + 1, from 9 to 1025.
    #[arg(long, default_value_t = DEFAULT_BLOCK_SIZE)]
    block_size: u32,
    /// Cluster thresholds in height units, comma-separated (e.g. 0,1,5,20). Default: a √2
    /// ladder from the largest error down, plus 0 (lossless); a dataset's tiles each take
    /// their own.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    thresholds: Option<Vec<f64>>,
    /// Store heights to the step Q (e.g. 0.1): each within Q/2 of the source, plus f32
    /// rounding (bounded by Q/16), a bound every node's error includes, so scenes stay true
    /// to the source. Much smaller files for float DEMs measured to a few centimetres. A
    /// step that changes no height (integer data and --precision 1) is dropped, and the file
    /// is lossless. Default: lossless.
    #[arg(long, value_name = "Q")]
    precision: Option<f64>,
    /// Bytes per page of the container (of each tile): a power of two from 1024 to 65536.
    /// Default: 1024 for data of at most 1024² samples (the two commit slots are two pages,
    /// a large share of a small file), else 4096.
    #[arg(long)]
    page_size: Option<u32>,
    /// Code every payload (physical blocks and grids) alone, not against its parent's grid
    /// where that is smaller: a larger file (1.3–1.4x on the Puget Sound DEMs) whose
    /// payloads decode faster and whose scenes read no ancestor grids.
    #[arg(long, alias = "blocks-alone")]
    payloads_alone: bool,
    /// Keep every node's grid square. By default a longitude-latitude grid's coarse nodes
    /// are thinned by area: near the poles, where a node's samples are much closer east-west
    /// than north-south, it stores every k-th column only (k a power of two), wherever that
    /// does not raise its error (format 6; docs/globe-design.md §4).
    #[arg(long)]
    no_thin: bool,
    /// Ground distance between samples in metres, DX or DX,DY (east, south). Overrides what
    /// the source says; scenes use it to place the terrain in the world.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    spacing: Option<Vec<f64>>,
    #[command(flatten)]
    pub ingest: IngestArgs,
}

impl ModelArgs {
    /// The model's options (the precision as given: `build` drops one that changes nothing).
    pub fn build_options(&self) -> Result<BuildOptions, Error> {
        Ok(BuildOptions {
            block_size: self.block_size,
            thresholds: match &self.thresholds {
                Some(t) => Thresholds::Explicit(t.clone()),
                None => Thresholds::Ladder,
            },
            precision: self.precision.map(Precision::new).transpose()?,
            thin: if self.no_thin {
                ThinByArea::Off
            } else {
                ThinByArea::Auto
            },
        })
    }

    /// The writer's options; `page_size` when `--page-size` is not given (0: by the data's
    /// size).
    pub fn write_options(&self, page_size: u32) -> WriteOptions {
        WriteOptions {
            page_size: self.page_size.unwrap_or(page_size),
            against_parents: !self.payloads_alone,
            ..WriteOptions::default()
        }
    }

    /// `--spacing`, if given.
    pub fn spacing(&self) -> Result<Option<[f64; 2]>, Error> {
        self.spacing.as_deref().map(parse_spacing).transpose()
    }
}

/// The camera options `scene` and `fly` share.
#[derive(clap::Args, Clone)]
pub struct ViewArgs {
    /// Vertical field of view in degrees (strictly between 0 and 180).
    #[arg(long, default_value_t = crate::scene::camera::DEFAULT_FOV_DEG, allow_negative_numbers = true)]
    pub fov: f64,
    /// Viewport in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x768")]
    pub viewport: String,
    /// Tolerance in pixels.
    #[arg(long, allow_negative_numbers = true)]
    pub tau: f64,
    /// uniform: one static bound for the whole view (one cluster); view: each block meets
    /// the tolerance where it is seen.
    #[arg(long, value_enum, default_value = "view")]
    pub mode: ModeArg,
    /// Runs of Hilbert keys separated by at most this many keys are scanned as one.
    #[arg(long, default_value_t = DEFAULT_GAP)]
    pub gap: u64,
    /// Map the file instead of reading it page by page: much faster scheduling. The state
    /// read is registered (Linux), so fmrh writers in other processes leave its pages alone;
    /// where readers cannot register, this falls back to page reads. Other tools must not
    /// modify the file meanwhile. A dataset's tiles are always read page by page.
    #[arg(long)]
    pub mmap: bool,
    /// Ground distance between samples in metres, DX or DX,DY (east, south), where cameras
    /// are placed. Required when the file does not record it (`info` says "spacing
    /// unknown"); `--spacing 1` measures the world in samples. Overrides the file's.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub spacing: Option<Vec<f64>>,
}

/// `--mode`.
#[derive(clap::ValueEnum, Clone, Copy)]
pub enum ModeArg {
    /// One cluster for the whole view.
    Uniform,
    /// View-dependent.
    View,
}

impl ViewArgs {
    /// The viewport as `[width, height]`.
    pub fn viewport(&self) -> Result<[u32; 2], Error> {
        let bad = || {
            Error::InvalidArgument(format!(
                "viewport `{}`: expected WIDTHxHEIGHT in pixels, e.g. 1024x768",
                self.viewport
            ))
        };
        let (w, h) = self.viewport.split_once(['x', 'X']).ok_or_else(bad)?;
        Ok([
            w.trim().parse().map_err(|_| bad())?,
            h.trim().parse().map_err(|_| bad())?,
        ])
    }

    /// The spacing to place `file`'s terrain with: `--spacing`, else the file's own; an error
    /// when neither is known, since a camera in metres over samples of unknown size sees the
    /// wrong terrain.
    pub fn spacing<S: crate::store::Source>(
        &self,
        store: &crate::store::Store<S>,
        file: &std::path::Path,
    ) -> Result<Option<[f64; 2]>, Error> {
        if let Some(s) = &self.spacing {
            return parse_spacing(s).map(Some);
        }
        if store.header().metadata.spacing_m.is_none() {
            return Err(Error::InvalidArgument(format!(
                "{}: the distance between samples is unknown (its source did not say), so a \
                 camera in metres cannot be placed; give --spacing DX[,DY] in metres \
                 (--spacing 1 measures the world in samples), or rebuild with --spacing",
                file.display()
            )));
        }
        Ok(None)
    }

    /// The scene options (without a window).
    /// The spacing `--spacing` gives, if any (a dataset knows its own otherwise).
    pub fn given_spacing(&self) -> Result<Option<[f64; 2]>, Error> {
        self.spacing.as_deref().map(parse_spacing).transpose()
    }

    /// An error when `--spacing` is given for a camera on the globe, where the
    /// georeference places the samples and a flat spacing means nothing.
    pub fn flat_spacing_only(&self, globe: bool) -> Result<(), Error> {
        if globe && self.spacing.is_some() {
            return Err(Error::InvalidArgument(
                "--spacing sets the flat frame's spacing; on the globe (--eye-geo, --globe, \
                 --geo) the georeference places the samples: drop one of them"
                    .into(),
            ));
        }
        Ok(())
    }

    /// [`ViewArgs::options`] restricted to `window` (the `--window` text), if given.
    pub fn options_in(&self, window: Option<&str>) -> Result<SceneOptions, Error> {
        let mut options = self.options();
        options.window = window.map(parse_window).transpose()?;
        Ok(options)
    }

    pub fn options(&self) -> SceneOptions {
        SceneOptions {
            tau: self.tau,
            mode: match self.mode {
                ModeArg::Uniform => Mode::Uniform,
                ModeArg::View => Mode::View,
            },
            window: None,
            gap: self.gap,
        }
    }
}

/// Where the camera is and where it looks, in the world frame.
#[derive(clap::Args, Clone)]
pub struct CameraArgs {
    /// Eye position x,y,z in metres (x = col * dx east, y = row * dy south, z height; with
    /// --globe, Earth-centred Earth-fixed metres).
    #[arg(
        long,
        allow_hyphen_values = true,
        required_unless_present = "eye_geo",
        conflicts_with = "eye_geo"
    )]
    eye: Option<String>,
    /// The point looked at, x,y,z (the frame of --eye).
    #[arg(
        long,
        allow_hyphen_values = true,
        required_unless_present = "eye_geo",
        conflicts_with = "eye_geo"
    )]
    target: Option<String>,
    /// Up direction on screen, x,y,z.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "eye_geo")]
    up: Option<String>,
    /// --eye, --target and --up in Earth-centred Earth-fixed metres (WGS 84), the terrain
    /// on the ellipsoid: for geographic grids (latitude and longitude).
    #[arg(long)]
    globe: bool,
    /// The eye on the globe: latitude and longitude in degrees and height above the
    /// ellipsoid in metres (implies --globe; look with --look).
    #[arg(long, allow_hyphen_values = true, value_name = "LAT,LON,H")]
    eye_geo: Option<String>,
    /// With --eye-geo: heading in degrees clockwise from north and pitch in degrees above
    /// the horizontal (-90 straight down) [default: 0,-30].
    #[arg(long, allow_hyphen_values = true, value_name = "HEADING,PITCH")]
    look: Option<String>,
}

impl CameraArgs {
    /// The camera, with `view`'s field of view and viewport.
    pub fn camera(&self, view: &ViewArgs) -> Result<Camera, Error> {
        if self.look.is_some() && self.eye_geo.is_none() {
            return Err(Error::InvalidArgument(
                "--look takes a heading and pitch for --eye-geo; give --eye-geo too".into(),
            ));
        }
        let (eye, target, up) = match &self.eye_geo {
            Some(geo) => {
                let [lat, lon, h] = parse_vec3(geo, "--eye-geo")?.to_array();
                let look = parse_list(self.look.as_deref().unwrap_or("0,-30"), 2, "--look")?;
                if !(-90.0..=90.0).contains(&lat) {
                    return Err(Error::InvalidArgument(format!(
                        "--eye-geo: latitude {lat} is not within -90..=90"
                    )));
                }
                crate::globe::look(lat, lon, h, look[0], look[1])
            }
            None => {
                let need = |v: &Option<String>, name: &str| {
                    v.as_deref()
                        .ok_or_else(|| Error::InvalidArgument(format!("{name} is required")))
                        .and_then(|s| parse_vec3(s, name))
                };
                let up = match &self.up {
                    Some(u) => parse_vec3(u, "--up")?,
                    None => glam::DVec3::Z,
                };
                (
                    need(&self.eye, "--eye")?,
                    need(&self.target, "--target")?,
                    up,
                )
            }
        };
        let handedness = if self.globe || self.eye_geo.is_some() {
            Handedness::Right
        } else {
            Handedness::Left
        };
        Ok(Camera {
            eye,
            target,
            up,
            fov_y_deg: view.fov,
            viewport: view.viewport()?,
            handedness,
        })
    }

    /// Whether the camera is on the globe (ECEF), not in the flat frame.
    pub fn globe(&self) -> bool {
        self.globe || self.eye_geo.is_some()
    }

    /// An error unless the camera is in the flat frame: `what` does not work on the globe
    /// yet.
    pub fn flat_only(&self, what: &str) -> Result<(), Error> {
        if self.globe() {
            return Err(Error::InvalidArgument(format!(
                "{what} takes flat-frame cameras only so far (no --globe or --eye-geo)"
            )));
        }
        Ok(())
    }
}

/// Refinement past the data, as `--refine` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RefineArg {
    /// Seed 004's fractal nodes: noise seeded by the block's key, amplitude from its
    /// roughness, each depth's error half the one above.
    Fractal,
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
pub fn parse_window(text: &str) -> Result<crate::model::SampleRect, Error> {
    let [col0, row0, col1, row1] = parse_quad(text, "window")?;
    Ok(crate::model::SampleRect {
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
/// `a..=b` (b included). An empty or reversed range is an error: nothing to scan is a mistake.
pub fn parse_range(text: &str, what: &str) -> Result<(u64, u64), Error> {
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
    match last.filter(|&l| l >= a) {
        Some(l) => Ok((a, l)),
        // Nothing to scan is a mistake in the range, not an empty answer.
        None if b < a => Err(Error::InvalidArgument(format!(
            "{what} `{text}`: the range is reversed ({b} is below {a})"
        ))),
        None => Err(Error::InvalidArgument(format!(
            "{what} `{text}`: the range is empty ({b} is excluded); A..=B includes B"
        ))),
    }
}

/// `--spacing`: one or two finite positive distances.
pub fn parse_spacing(values: &[f64]) -> Result<[f64; 2], Error> {
    let ok = |v: f64| v.is_finite() && v > 0.0;
    match values {
        [d] if ok(*d) => Ok([*d, *d]),
        [dx, dy] if ok(*dx) && ok(*dy) => Ok([*dx, *dy]),
        _ => Err(Error::InvalidArgument(format!(
            "--spacing {values:?}: expected DX or DX,DY, finite metres > 0"
        ))),
    }
}
