//! The raster output of `extract` and `scene --reconstruct`: `.f32` + `.json`, the form of
//! `../shared/data`, so `fmrh build` reads it back and anyone can diff it against a source;
//! or a GeoTIFF (`crate::export::geotiff`) that GIS tools open as they are.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::heightfield::Heightfield;
use crate::model::SampleRect;
use crate::store::Store;
use crate::store::{write_atomically, Source as StoreSource};
use crate::Error;

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
    /// The container's storage precision (format 2.1): the samples are the stored ones,
    /// each within 9/16 of it of the original source; absent when stored bit for bit.
    #[serde(skip_serializing_if = "Option::is_none")]
    storage_precision: Option<f64>,
}

/// The raster formats `extract` and `scene --reconstruct` write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RasterFormat {
    /// Raw little-endian f32 with a `.json` sidecar (what `../shared/data` holds).
    F32,
    /// A Cloud-Optimized GeoTIFF: f32 in 512² tiles, DEFLATE or ZSTD with the
    /// floating-point predictor, overviews, the georeference and CRS as GeoTIFF tags (a CRS
    /// that is not an EPSG code in a `.tif.aux.xml` beside it), voids as NaN.
    #[value(alias = "cog", alias = "tiff")]
    Tif,
}

impl RasterFormat {
    /// The format an output name implies: `.tif` and `.tiff` are GeoTIFFs.
    fn of(output: &Path) -> RasterFormat {
        let ext = output
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("tif" | "tiff") => RasterFormat::Tif,
            _ => RasterFormat::F32,
        }
    }
}

/// The compressions of a GeoTIFF output (`--compress`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum TifCompression {
    /// zlib DEFLATE: every TIFF reader has it.
    #[default]
    Deflate,
    /// ZSTD: smaller and faster to decode; GDAL ≥ 2.3 and most COG readers have it.
    Zstd,
}

/// How a GeoTIFF output is written: `--compress` and `--tile`.
#[derive(clap::Args, Clone, Copy, Debug)]
pub struct TifArgs {
    /// A GeoTIFF output's compression (with the floating-point predictor).
    #[arg(long, value_enum, default_value_t = TifCompression::Deflate)]
    compress: TifCompression,
    /// A GeoTIFF output's tile side in samples: 256 or 512.
    #[arg(long, default_value_t = 512)]
    tile: u32,
}

impl TifArgs {
    /// The writer's options.
    pub fn options(&self) -> crate::export::geotiff::CogOptions {
        crate::export::geotiff::CogOptions {
            compression: match self.compress {
                TifCompression::Deflate => crate::export::geotiff::TiffCompression::Deflate,
                TifCompression::Zstd => crate::export::geotiff::TiffCompression::Zstd,
            },
            tile: self.tile,
            force_bigtiff: false,
        }
    }
}

/// Where a raster goes (a `.f32` and its sidecar, or a GeoTIFF and, when its CRS is not an
/// EPSG code, GDAL's `.aux.xml` beside it), checked before any work is done.
pub struct RasterOutput {
    f32_path: PathBuf,
    /// The `.json` sidecar of a `.f32`, or the `.tif.aux.xml` of a GeoTIFF.
    json_path: PathBuf,
    format: RasterFormat,
    force: bool,
    cog: crate::export::geotiff::CogOptions,
    /// No message on success.
    quiet: bool,
}

impl RasterOutput {
    /// `format`, or the one the name implies. Refuses a `.json` output name, and existing
    /// files unless `force`. `-` is standard output: the raw samples only (a sidecar has
    /// nowhere to go; its size line goes to standard error), or the whole GeoTIFF.
    pub fn new(
        output: &Path,
        format: Option<RasterFormat>,
        force: bool,
    ) -> Result<RasterOutput, Error> {
        let format = format.unwrap_or_else(|| RasterFormat::of(output));
        let cog = crate::export::geotiff::CogOptions::default();
        if output == Path::new("-") {
            return Ok(RasterOutput {
                f32_path: output.to_path_buf(),
                json_path: PathBuf::new(),
                format,
                force,
                cog,
                quiet: false,
            });
        }
        if format == RasterFormat::Tif {
            // GDAL's sidecar: it may be written (a CRS that is not an EPSG code), and a stale
            // one would give the new file an old CRS, so it is an output too.
            let mut aux = output.as_os_str().to_owned();
            aux.push(".aux.xml");
            let aux = PathBuf::from(aux);
            for p in [output, &aux] {
                super::check_output(p, force)?;
            }
            return Ok(RasterOutput {
                f32_path: output.to_path_buf(),
                json_path: aux,
                format,
                force,
                cog,
                quiet: false,
            });
        }
        if output.extension().is_some_and(|e| e == "json") {
            return Err(Error::InvalidArgument(
                "the output is the .f32 file; its .json sidecar is written beside it".into(),
            ));
        }
        let json_path = output.with_extension("json");
        for p in [output, &json_path] {
            super::check_output(p, force)?;
        }
        Ok(RasterOutput {
            f32_path: output.to_path_buf(),
            json_path,
            format,
            force,
            cog,
            quiet: false,
        })
    }

    /// The same output, with no message on success.
    pub fn quietly(self, quiet: bool) -> RasterOutput {
        RasterOutput { quiet, ..self }
    }

    /// The same output, a GeoTIFF written as `tif` says.
    pub fn with_tif(self, tif: &TifArgs) -> RasterOutput {
        RasterOutput {
            cog: tif.options(),
            ..self
        }
    }

    /// Writes `hf` (the container's samples `window`) and its sidecar, each atomically.
    pub fn write<S: StoreSource>(
        &self,
        hf: &Heightfield,
        window: SampleRect,
        kind: &'static str,
        container: &Path,
        store: &Store<S>,
    ) -> Result<(), Error> {
        self.write_from(
            hf,
            window,
            Source {
                kind,
                container: container.display().to_string(),
                txn_id: store.txn_id(),
                original_format: store.header().metadata.source_format.clone(),
                storage_precision: store.header().precision.map(|p| p.step()),
            },
        )
    }

    /// Writes `hf` (the dataset's samples `window`, in dataset coordinates) and its sidecar.
    /// The sidecar's `source.txn_id` is the manifest's.
    pub fn write_dataset(
        &self,
        hf: &Heightfield,
        window: SampleRect,
        dir: &Path,
        txn_id: u64,
    ) -> Result<(), Error> {
        self.write_from(
            hf,
            window,
            Source {
                kind: "fmrh extract",
                container: dir.display().to_string(),
                txn_id,
                original_format: "fmrh-dataset".into(),
                storage_precision: None,
            },
        )
    }

    fn write_from(
        &self,
        hf: &Heightfield,
        window: SampleRect,
        source: Source,
    ) -> Result<(), Error> {
        if self.format == RasterFormat::Tif {
            return self.write_tif(hf);
        }
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
        let file_name = self
            .f32_path
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
            source,
        };
        let json = serde_json::to_vec_pretty(&sidecar)
            .map_err(|e| Error::InvalidArgument(format!("cannot format the sidecar: {e}")))?;
        let mut raw = Vec::with_capacity(samples.len() * 4);
        for v in samples {
            raw.extend_from_slice(&v.to_le_bytes());
        }
        if self.f32_path == Path::new("-") {
            let mut out = std::io::stdout().lock();
            out.write_all(&raw)
                .and_then(|()| out.flush())
                .map_err(|e| Error::io("<stdout>", e))?;
            if self.quiet {
                return Ok(());
            }
            eprintln!(
                "fmrh: wrote {} x {} samples ({} void) to standard output as raw little-endian \
                 f32, row-major",
                hf.width(),
                hf.height(),
                samples.len() as u64 - valid
            );
            return Ok(());
        }
        for (path, bytes) in [(&self.f32_path, &raw), (&self.json_path, &json)] {
            write_atomically(path, self.force, |w| {
                w.write_all(bytes).map_err(|e| Error::io(path, e))
            })?;
        }
        if self.quiet {
            return Ok(());
        }
        eprintln!(
            "fmrh: wrote {} x {} samples ({} void) to {} and {}",
            hf.width(),
            hf.height(),
            samples.len() as u64 - valid,
            self.f32_path.display(),
            self.json_path.display()
        );
        Ok(())
    }

    /// Writes `hf` as a Cloud-Optimized GeoTIFF, atomically (or to standard output), and
    /// its CRS in GDAL's `.aux.xml` beside it when that is not an EPSG code (a stale sidecar
    /// is removed: it would give the new file an old CRS). The two files are written one
    /// after the other, the sidecar first.
    fn write_tif(&self, hf: &Heightfield) -> Result<(), Error> {
        let mut bytes = Vec::new();
        let written = crate::export::geotiff::write(hf, &self.cog, &mut bytes)?;
        let path = &self.f32_path;
        let stdout = path == Path::new("-");
        let mut sidecar = String::new();
        if let Some(wkt) = &written.crs_wkt {
            if stdout {
                eprintln!(
                    "fmrh: the CRS {wkt:?} is not an EPSG code and has no sidecar to go to on \
                     standard output: the GeoTIFF has the geotransform without a CRS"
                );
            } else {
                let aux = crate::export::geotiff::aux_xml(wkt);
                write_atomically(&self.json_path, self.force, |w| {
                    w.write_all(aux.as_bytes())
                        .map_err(|e| Error::io(&self.json_path, e))
                })?;
                sidecar = format!(
                    ", its CRS (not an EPSG code) in {}",
                    self.json_path.display()
                );
            }
        } else if !stdout && self.json_path.exists() {
            std::fs::remove_file(&self.json_path).map_err(|e| Error::io(&self.json_path, e))?;
        }
        if stdout {
            let mut out = std::io::stdout().lock();
            out.write_all(&bytes)
                .and_then(|()| out.flush())
                .map_err(|e| Error::io("<stdout>", e))?;
        } else {
            write_atomically(path, self.force, |w| {
                w.write_all(&bytes).map_err(|e| Error::io(path, e))
            })?;
        }
        let overviews: Vec<String> = written
            .overviews
            .iter()
            .map(|o| format!("{}x{} (max error {:.3})", o.width, o.height, o.max_error))
            .collect();
        if self.quiet {
            return Ok(());
        }
        eprintln!(
            "fmrh: wrote {} x {} samples ({} void) to {} as a Cloud-Optimized GeoTIFF{}{}, \
             {} tiles of {}, {}{}",
            hf.width(),
            hf.height(),
            written.voids,
            if stdout {
                "standard output".to_string()
            } else {
                path.display().to_string()
            },
            if written.bigtiff { " (BigTIFF)" } else { "" },
            written
                .epsg
                .map(|c| format!(" (EPSG:{c})"))
                .unwrap_or_default(),
            match self.cog.compression {
                crate::export::geotiff::TiffCompression::Deflate => "DEFLATE",
                crate::export::geotiff::TiffCompression::Zstd => "ZSTD",
            },
            self.cog.tile,
            if overviews.is_empty() {
                "no overview (one tile)".to_string()
            } else {
                format!("nearest-sample overviews {}", overviews.join(", "))
            },
            sidecar
        );
        Ok(())
    }
}
