//! Making a container through the door: from heights in memory ([`create`]) or from a DEM
//! file in any format fmrh reads ([`build`]), written atomically.

use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

use super::ErrorLevel;
use crate::error::Result;
use crate::heightfield::Heightfield;
use crate::ingest::IngestOptions;
use crate::model::{BuildOptions, Model, Precision, ThinByArea, Thresholds, DEFAULT_BLOCK_SIZE};
use crate::progress::{Progress, Silent};
use crate::store::{write_file, WriteOptions};

/// How [`create`] and [`build`] make a container.
///
/// ```
/// use fmrh::types::Thresholds;
/// use fmrh::CreateOptions;
///
/// // Blocks of 129 samples, heights kept to 1 cm, and three error levels: 20 m, 5 m and
/// // 1 cm (no level can be finer than the storage bound of 9/16 cm).
/// let options = CreateOptions {
///     block_size: 129,
///     thresholds: Thresholds::Explicit(vec![20.0, 5.0, 0.01]),
///     precision: Some(0.01),
///     ..CreateOptions::default()
/// };
/// # let dir = tempfile::tempdir().unwrap();
/// # let dem = fmrh::Heightfield::from_fn(300, 300, |x, y| (x as f32 * 0.013).sin() * 300.0 + y as f32 * 0.0007)?;
/// let created = fmrh::create(&dir.path().join("levels.fmrh"), dem, &options)?;
/// assert_eq!(created.error_levels.len(), 3);
/// # Ok::<(), fmrh::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct CreateOptions {
    /// Samples along a block side: `2^k + 1`, 9 to 1025 (65 by default).
    pub block_size: u32,
    /// The error levels' thresholds: a √2 ladder from the coarsest error down to 0 (the
    /// default), or given ones.
    pub thresholds: Thresholds,
    /// Store heights to this step `Q` instead of bit for bit: each within `Q/2` of its source
    /// plus the `f32` rounding, a bound (`9Q/16`) every error includes. `None`: lossless.
    pub precision: Option<f64>,
    /// Thin a longitude-latitude grid's coarse nodes east-west by their true area where
    /// that costs no error (format 6; the default, [`ThinByArea::Auto`]).
    pub thin: ThinByArea,
    /// Bytes per page (a power of two, 1024 to 65536); `None`: 1024 for at most 1024²
    /// samples, else 4096.
    pub page_size: Option<u32>,
    /// Code every payload alone rather than against its parent's grid where that is smaller:
    /// a larger file (1.3–1.4×) whose scenes decode no ancestor.
    pub payloads_alone: bool,
    /// Replace an existing file (atomically: it stays whole until the new one is complete)
    /// instead of refusing.
    pub overwrite: bool,
}

impl Default for CreateOptions {
    fn default() -> Self {
        CreateOptions {
            block_size: DEFAULT_BLOCK_SIZE,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: ThinByArea::Auto,
            page_size: None,
            payloads_alone: false,
            overwrite: false,
        }
    }
}

/// What [`create`] and [`build`] made.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Created {
    /// Bytes of the file.
    pub file_length: u64,
    /// Bytes per page.
    pub page_size: u32,
    /// The coarsest level's measured error.
    pub max_error: f64,
    /// The error levels, by threshold ascending (the finest first).
    pub error_levels: Vec<ErrorLevel>,
}

/// Creates the container at `path` from `heightfield`: cut into blocks, every node's error
/// measured, the error levels built, and the file written so that it appears complete or
/// not at all (written beside `path`, synced, renamed).
///
/// ```
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("dome.fmrh");
/// let dome = fmrh::Heightfield::from_fn(200, 150, |x, y| {
///     let (dx, dy) = (x as f32 - 100.0, y as f32 - 75.0);
///     (4000.0 - dx * dx - dy * dy).max(0.0) * 0.05
/// })?;
/// let created = fmrh::create(&path, dome, &fmrh::CreateOptions::default())?;
/// assert_eq!(created.file_length, std::fs::metadata(&path).unwrap().len());
/// # Ok(()) }
/// ```
pub fn create(path: &Path, heightfield: Heightfield, options: &CreateOptions) -> Result<Created> {
    create_with_progress(path, heightfield, options, Arc::new(Silent))
}

/// [`create`], telling `progress` how each phase advances (the model's levels measured,
/// then the payload bytes written; [`types::Progress`](crate::types::Progress)).
pub fn create_with_progress(
    path: &Path,
    heightfield: Heightfield,
    options: &CreateOptions,
    progress: Arc<dyn Progress>,
) -> Result<Created> {
    let metadata = heightfield.metadata.clone();
    let samples = u64::from(heightfield.width()) * u64::from(heightfield.height());
    let model = Model::build_with_progress(
        heightfield,
        &BuildOptions {
            block_size: options.block_size,
            thresholds: options.thresholds.clone(),
            precision: options.precision.map(Precision::new).transpose()?,
            thin: options.thin,
        },
        &*progress,
    )?;
    let write = WriteOptions {
        page_size: options
            .page_size
            .unwrap_or_else(|| crate::format::page_size_for(samples)),
        against_parents: !options.payloads_alone,
        progress,
        ..WriteOptions::default()
    };
    let summary = write_file(&model, &metadata, path, &write, options.overwrite)?;
    Ok(Created {
        file_length: summary.file_length,
        page_size: summary.page_size,
        max_error: model.max_error(),
        error_levels: model
            .clusters()
            .iter()
            .map(|c| ErrorLevel {
                threshold: c.threshold,
                max_error: c.max_error,
                blocks: c.nodes.len() as u64,
            })
            .collect(),
    })
}

/// Reads the DEM at `input` into memory, as [`build`] reads it (`read` says how: its
/// format, scale, nodata, and the memory it may take): to change its heights or metadata
/// (a spacing, a CRS) before [`create`].
pub fn load(input: &Path, read: &IngestOptions) -> Result<Heightfield> {
    crate::ingest::load(input, read)
}

/// Reads the DEM at `input` (GeoTIFF, SRTM `.hgt`, PNG, ASCII grids, DTED, USGS DEM, JPEG, or
/// raw `f32` with a sidecar; `read` says how: its format, scale, nodata) and creates the
/// container at `output` from it, as [`create`] does.
///
/// ```
/// use fmrh::types::IngestOptions;
///
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// let asc = dir.path().join("tiny.asc");
/// std::fs::write(
///     &asc,
///     "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 10\nNODATA_value -9999\n\
///      1 2 3\n4 -9999 6\n",
/// ).unwrap();
/// let out = dir.path().join("tiny.fmrh");
/// fmrh::build(&asc, &out, &IngestOptions::default(), &fmrh::CreateOptions::default())?;
/// let samples = fmrh::Terrain::open(&out)?.read(None)?;
/// assert_eq!(samples.get(0, 1), Some(4.0));
/// assert_eq!(samples.get(1, 1), None); // the nodata sample is a void
/// # Ok(()) }
/// ```
pub fn build(
    input: &Path,
    output: &Path,
    read: &IngestOptions,
    options: &CreateOptions,
) -> Result<Created> {
    create(output, crate::ingest::load(input, read)?, options)
}
