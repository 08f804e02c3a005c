//! A raster read one window at a time: how a raster larger than the memory budget is built
//! (issue 39, point 2).
//!
//! [`WindowedRaster::open`] reads only the header; [`WindowedRaster::read`] decodes one window
//! of samples into a [`Heightfield`] of its own, whose georeference is the window's. What it
//! holds is the window and one strip or tile of the source, never the whole grid:
//!
//! * **GeoTIFF**: only the strips or tiles the window touches are decoded, each checked as a
//!   whole read checks it. A tiled file reads each tile once for the windows of a dataset
//!   build (twice: scan, then build); a striped file decodes a strip once per window it
//!   crosses, so a window `n` columns wide of a striped file costs a full strip each time.
//!   Large rasters are tiled (a COG is), so that cost is documented rather than cached.
//! * **`.f32`**: each row of the window is one seek and one read.
//! * **Every other format** (SRTM, DTED, PNG, JPEG, ASCII grids) is small by nature or cannot
//!   be read by parts ([`streams`] says which do): it is loaded whole, under the budget, as
//!   `fmrh build` loads it.
//!
//! Windows are in fmrh's orientation (row 0 north, column 0 west) whatever the file stores: a
//! south-up or east-to-west source is read from the mirrored place and turned, so that the
//! windows of a raster put back together are exactly what [`super::load`] reads.

use std::fs::File;
use std::path::{Path, PathBuf};

use super::{detect, flip, geotiff, north_up_georeference, raw_f32, Format, IngestOptions};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Heightfield, Metadata};
use crate::ingest::limits::BUILD_BYTES_PER_SAMPLE;
use crate::model::SampleRect;

/// Where the samples come from.
enum Source {
    Tiff(Box<geotiff::Tiff>),
    F32 { file: File, path: PathBuf },
}

/// Whether rasters of `format` are read by windows.
pub fn streams(format: Format) -> bool {
    matches!(format, Format::Geotiff | Format::F32)
}

/// A raster whose header has been read, read by windows.
pub struct WindowedRaster {
    path: PathBuf,
    options: IngestOptions,
    width: u64,
    height: u64,
    /// The whole raster's metadata, north up.
    metadata: Metadata,
    /// Whether the source's columns (east to west) and rows (south up) are reversed.
    flip: [bool; 2],
    source: Source,
}

impl WindowedRaster {
    /// Opens `path` for windowed reading: a GeoTIFF's or `.f32`'s header only (its sides may
    /// be up to 2^32 - 1 samples, its samples in proportion to its bytes); any other format is
    /// refused ([`streams`]).
    pub fn open(path: &Path, options: &IngestOptions) -> Result<WindowedRaster> {
        options.check()?;
        let format = match options.format {
            Some(f) => f,
            None => detect(path)?,
        };
        let (width, height, mut metadata, source) = match format {
            Format::Geotiff => {
                let tiff = geotiff::open(path, options, false)?;
                let (w, h) = (u64::from(tiff.width), u64::from(tiff.height));
                let metadata = tiff.metadata.clone();
                (w, h, metadata, Source::Tiff(Box::new(tiff)))
            }
            Format::F32 => {
                let pair = raw_f32::open(path, false)?;
                let len = pair.width * pair.height * 4;
                options
                    .limits
                    .check_proportion(&pair.f32_path, pair.width, pair.height, len)?;
                let file = File::open(&pair.f32_path).map_err(|e| Error::io(&pair.f32_path, e))?;
                (
                    pair.width,
                    pair.height,
                    pair.metadata,
                    Source::F32 {
                        file,
                        path: pair.f32_path,
                    },
                )
            }
            other => {
                return Err(Error::unsupported(
                    path,
                    format!(
                        "{} is read whole, not by windows (only a GeoTIFF or .f32 is)",
                        other.name()
                    ),
                ))
            }
        };
        let flip = match &mut metadata.georeference {
            Some(g) => north_up_georeference(g, width, height),
            None => [false, false],
        };
        super::check_metadata(path, &metadata)?;
        super::settle_source(&mut metadata, format, options);
        Ok(WindowedRaster {
            path: path.to_path_buf(),
            options: options.clone(),
            width,
            height,
            metadata,
            flip,
            source,
        })
    }

    /// Columns of the whole raster.
    pub fn width(&self) -> u64 {
        self.width
    }

    /// Rows of the whole raster.
    pub fn height(&self) -> u64 {
        self.height
    }

    /// The samples of `window` (in the raster's north-up samples) as a heightfield of their
    /// own, georeferenced where the window lies. The window must fit in the raster, in fmrh's
    /// limits on a heightfield and in the memory budget (a build takes
    /// [`BUILD_BYTES_PER_SAMPLE`] bytes a sample).
    pub fn read(&mut self, window: SampleRect) -> Result<Heightfield> {
        let SampleRect {
            col0,
            row0,
            col1,
            row1,
        } = window;
        if col1 < col0 || row1 < row0 || col1 >= self.width || row1 >= self.height {
            return Err(Error::InvalidArgument(format!(
                "window columns {col0}..={col1}, rows {row0}..={row1} of a {} x {} raster",
                self.width, self.height
            )));
        }
        let (w, h) = (col1 - col0 + 1, row1 - row0 + 1);
        check_dimensions(w, h).map_err(|e| Error::input(&self.path, e.to_string()))?;
        if !self.options.limits.holds(w * h) {
            return Err(Error::TooLarge {
                what: self.path.display().to_string(),
                detail: format!(
                    "a window of {w} x {h} samples needs about {} bytes to build, more than \
                     the memory budget of {} bytes: raise --max-memory, or give a smaller \
                     --tile-size",
                    w * h * BUILD_BYTES_PER_SAMPLE,
                    self.options.limits.budget()
                ),
            });
        }
        // The same window in the source's own orientation.
        let [flip_columns, flip_rows] = self.flip;
        let x0 = if flip_columns {
            self.width - 1 - col1
        } else {
            col0
        };
        let y0 = if flip_rows {
            self.height - 1 - row1
        } else {
            row0
        };
        let mut samples = match &mut self.source {
            Source::Tiff(tiff) => {
                // Every side and offset here is below the TIFF's u32 sides.
                tiff.read_window(x0 as u32, y0 as u32, w as u32, h as u32, &self.options)?
            }
            // Raw heights, as a whole read takes them.
            Source::F32 { file, path } => {
                raw_f32::read_window(file, path, self.width, (x0, y0, w, h))?
            }
        };
        flip(&mut samples, w as usize, flip_columns, flip_rows);
        let mut metadata = self.metadata.clone();
        if let Some(g) = &mut metadata.georeference {
            g.origin[0] += col0 as f64 * g.step[0];
            g.origin[1] += row0 as f64 * g.step[1];
        }
        Heightfield::new(w as u32, h as u32, samples)
            .map(|hf| hf.with_metadata(metadata))
            .map_err(|e| match e {
                Error::InvalidArgument(reason) => Error::input(&self.path, reason),
                other => other,
            })
    }
}
