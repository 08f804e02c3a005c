//! A heightfield: the grid of heights that every reader produces and the model consumes.
//!
//! Samples are `f32`, row-major, row 0 at the north edge, column 0 at the west edge. A void
//! (nodata) sample is `NaN`; every other sample is finite. Voids are first-class: no reader ever
//! turns nodata into a magic height, and infinite heights are refused. The size limits below
//! are checked by every reader *before* it allocates, so a header that claims an absurd size
//! is an error, not an out-of-memory abort.

use crate::error::{Error, Result};
use crate::geoid::VerticalDatum;

/// The longest side, in samples, that fmrh accepts.
pub const MAX_SIDE: u64 = 1 << 20;

/// The most samples (width × height) that fmrh accepts: 16 GiB of `f32`.
pub const MAX_SAMPLES: u64 = 1 << 32;

/// Where the grid lies in a coordinate reference system.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Georeference {
    /// The coordinate reference system, as the source named it (e.g. `EPSG:4326`).
    pub crs: Option<String>,
    /// CRS coordinates `[x, y]` of the centre of sample (column 0, row 0).
    pub origin: [f64; 2],
    /// CRS units from one column to the next (east) and from one row to the next (south,
    /// hence usually negative for a north-up grid).
    pub step: [f64; 2],
}

/// What is known about a heightfield besides its samples.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Metadata {
    /// Ground distance between samples in metres, `[along a row (east), down a column
    /// (south)]`, when known.
    pub spacing_m: Option<[f64; 2]>,
    /// Georeference, when the source had one.
    pub georeference: Option<Georeference>,
    /// Vertical units, when the source said.
    pub units: Option<String>,
    /// The reader that produced this heightfield (`f32`, `srtm-hgt`, `geotiff`, ...).
    pub source_format: String,
    /// What the heights are above (the geoid, the ellipsoid, or not known): what the
    /// source said (a GeoTIFF's vertical CRS), the reader's convention (SRTM and DTED:
    /// EGM96), or what the user said (`--vertical-datum`).
    pub vertical_datum: VerticalDatum,
}

/// A grid of heights with voids (NaN), row-major from the north-west corner, and what is
/// known of where it lies ([`crate::types::Metadata`]).
///
/// ```
/// use fmrh::types::{Georeference, Metadata};
/// use fmrh::Heightfield;
///
/// # fn main() -> fmrh::Result<()> {
/// let mut dem = Heightfield::new(3, 2, vec![1.0, 2.0, f32::NAN, 4.0, 5.0, 6.0])?;
/// assert_eq!((dem.get(1, 1), dem.get(2, 0), dem.void_count()), (Some(5.0), None, 1));
/// dem.metadata = Metadata {
///     spacing_m: Some([30.0, 30.0]),
///     georeference: Some(Georeference {
///         crs: Some("EPSG:32610".into()),
///         origin: [500_000.0, 5_200_000.0],
///         step: [30.0, -30.0],
///     }),
///     ..Metadata::default()
/// };
/// # Ok(()) }
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Heightfield {
    width: u32,
    height: u32,
    samples: Vec<f32>,
    /// Georeference, spacing, units and provenance.
    pub metadata: Metadata,
}

/// Refuses a `width × height` raster outside fmrh's limits. Readers call this with the sizes a
/// header claims, before allocating anything.
pub fn check_dimensions(width: u64, height: u64) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::InvalidArgument(format!(
            "a heightfield needs at least one sample, got {width} x {height}"
        )));
    }
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(Error::TooLarge {
            what: "heightfield".into(),
            detail: format!("{width} x {height} samples; each side may be at most {MAX_SIDE}"),
        });
    }
    if width * height > MAX_SAMPLES {
        return Err(Error::TooLarge {
            what: "heightfield".into(),
            detail: format!(
                "{width} x {height} = {} samples; at most {MAX_SAMPLES}",
                width * height
            ),
        });
    }
    Ok(())
}

impl Heightfield {
    /// A heightfield from row-major samples (`NaN` = void). Refuses a length that does not
    /// match, sizes beyond the limits, and infinite heights.
    pub fn new(width: u32, height: u32, samples: Vec<f32>) -> Result<Self> {
        check_dimensions(u64::from(width), u64::from(height))?;
        let expected = u64::from(width) * u64::from(height);
        if samples.len() as u64 != expected {
            return Err(Error::InvalidArgument(format!(
                "{width} x {height} heightfield needs {expected} samples, got {}",
                samples.len()
            )));
        }
        if let Some(i) = samples.iter().position(|v| v.is_infinite()) {
            let (x, y) = (i as u64 % u64::from(width), i as u64 / u64::from(width));
            return Err(Error::InvalidArgument(format!(
                "sample at column {x}, row {y} is {}: heights must be finite (NaN marks a void)",
                samples[i]
            )));
        }
        Ok(Heightfield {
            width,
            height,
            samples,
            metadata: Metadata::default(),
        })
    }

    /// A heightfield whose sample at column `x`, row `y` is `f(x, y)`.
    pub fn from_fn(width: u32, height: u32, mut f: impl FnMut(u32, u32) -> f32) -> Result<Self> {
        check_dimensions(u64::from(width), u64::from(height))?;
        let mut samples = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            for x in 0..width {
                samples.push(f(x, y));
            }
        }
        Heightfield::new(width, height, samples)
    }

    /// Samples along a row (east).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Samples down a column (south).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// All samples, row-major, `NaN` for voids.
    pub fn samples(&self) -> &[f32] {
        &self.samples
    }

    /// Gives the samples away (row-major, `NaN` for voids).
    pub fn into_samples(self) -> Vec<f32> {
        self.samples
    }

    /// The height at column `x`, row `y`: `None` for a void or outside the grid.
    pub fn get(&self, x: u32, y: u32) -> Option<f32> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let v = self.samples[y as usize * self.width as usize + x as usize];
        (!v.is_nan()).then_some(v)
    }

    /// How many samples are void.
    pub fn void_count(&self) -> u64 {
        self.samples.iter().filter(|v| v.is_nan()).count() as u64
    }

    /// Attaches metadata.
    pub fn with_metadata(mut self, metadata: Metadata) -> Self {
        self.metadata = metadata;
        self
    }
}
