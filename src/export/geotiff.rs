//! A heightfield as a Cloud-Optimized GeoTIFF: one band of 32-bit floats in square tiles,
//! DEFLATE or ZSTD with the floating-point predictor, overviews down to one tile, the
//! georeference as GeoTIFF 1.0 tags, voids as NaN with `GDAL_NODATA` saying so. GIS tools
//! and HTTP range readers open it as they open GDAL's own `-of COG` output.
//!
//! **Layout** (what GDAL's COG driver writes and `validate_cloud_optimized_geotiff.py`
//! checks), in file order:
//!
//! ```text
//! header       "II", 42 and the first IFD's offset (classic TIFF), or "II", 43, 8, 0 and
//!              a u64 offset (BigTIFF, when the file passes 4 GiB)
//! ghost area   "GDAL_STRUCTURAL_METADATA_SIZE=nnnnnn bytes\n" and nnnnnn bytes of
//!              LAYOUT=IFDS_BEFORE_DATA, BLOCK_ORDER=ROW_MAJOR, BLOCK_LEADER=SIZE_AS_UINT4,
//!              BLOCK_TRAILER=LAST_4_BYTES_REPEATED, KNOWN_INCOMPATIBLE_EDITION=NO
//! IFD 0        the full resolution, its out-of-line values after it; then IFD 1, 2, ...
//!              the overviews, each half the size of the one before (rounded up), down
//!              to the first that fits in one tile
//! tiles        the smallest overview's first, the full resolution's last; within each
//!              image row-major; each tile as [size: u32][its bytes][its last 4 bytes]
//! ```
//!
//! so that a reader that fetches the file's first few kilobytes has every IFD, and a
//! reader of one zoom reads one contiguous run of bytes.
//!
//! **Tiles.** 512 × 512 samples (or 256: [`CogOptions::tile`]); edge tiles are filled out
//! by repeating the last column and row, which the predictor turns into zeros. Each tile is
//! coded with TIFF predictor 3 (floating point, TIFF Technical Note 3: each row's samples
//! split into byte planes, most significant first, then differenced byte by byte) and
//! compressed with zlib DEFLATE (TIFF compression 8) or ZSTD (50000, level 9 as GDAL's
//! default). Lossless: the samples read back bit for bit, NaN voids included.
//!
//! **Overviews: nearest sample, and the error each one has.** Overview pixel `(i, j)` of a
//! `w' × h'` overview of a `w × h` image is full-resolution sample `(⌊(i + ½) · w / w'⌋,
//! ⌊(j + ½) · h / h'⌋)`, the sample nearest the overview pixel's centre (GDAL's `NEAREST`):
//! an overview holds only heights the terrain has, never an average that no sample has
//! (which would round off peaks and put heights where there are voids). What it gives up
//! is measured, as fmrh measures every level's error: each overview's largest
//! `|h(x, y) − overview(pixel covering (x, y))|` over the full-resolution samples, in the
//! heights' unit, is written in the file's metadata (`FMRH_OVERVIEW_n_MAX_ERROR`, n from
//! 1 for the largest overview; `gdalinfo` shows it) and returned in [`Written::overviews`].
//!
//! **Where the samples lie.** fmrh's georeference names the *centre* of sample (0, 0)
//! (`heightfield::Georeference`). GeoTIFF's default raster type, `PixelIsArea`, ties the
//! *corner* of pixel (0, 0) to the model, so the tie point is the centre moved back half a
//! step each way; GDAL reports the same geotransform for this file as for a source that tied
//! its centres with `PixelIsPoint`. A north-up grid (east steps positive, south steps
//! negative) is written as `ModelPixelScale` + `ModelTiepoint`; any other as a
//! `ModelTransformation` matrix. A grid with no georeference still gets a geotransform: its
//! spacing in metres (1 when unknown) with sample (0, 0)'s centre at (0, 0) and rows running
//! south, so a GIS tool shows its true size, without a CRS.
//!
//! **The CRS.** An `EPSG:n` name (as the GeoTIFF, SRTM and DTED readers give it, possibly
//! followed by a description) becomes `GeographicTypeGeoKey` or `ProjectedCSTypeGeoKey` with
//! the model type the EPSG registry gives. Any other CRS (a WKT fmrh cannot reduce to a
//! code) is not written into the file, where GeoTIFF 1.0 could only hold it as a citation
//! that GDAL reads as an engineering CRS: [`Written::crs_wkt`] returns it, and the CLI writes
//! it beside the file as GDAL's `.aux.xml` sidecar, which GDAL and QGIS read as the file's
//! CRS. A grid without a CRS gets no key directory: its tie points alone, as GDAL writes such
//! a file.
//!
//! **Voids.** fmrh stores voids, not the source's nodata value: when the samples have any,
//! every image says `GDAL_NODATA = nan`.
//!
//! No I/O beyond the writer it is given (the CLI writes the file atomically).

use std::io::Write;

use rayon::prelude::*;

use crate::crs::{Crs, CrsKind};
use crate::error::{Error, Result};
use crate::geoid::VerticalDatum;
use crate::heightfield::Heightfield;

/// GeoKey ids (GeoTIFF 1.0 §6.3) and values this writer uses.
mod key {
    pub const GT_MODEL_TYPE: u16 = 1024;
    pub const GT_RASTER_TYPE: u16 = 1025;
    pub const GEOGRAPHIC_TYPE: u16 = 2048;
    pub const PROJECTED_CS_TYPE: u16 = 3072;
    pub const VERTICAL_CS_TYPE: u16 = 4096;
    pub const MODEL_PROJECTED: u16 = 1;
    pub const MODEL_GEOGRAPHIC: u16 = 2;
    pub const RASTER_PIXEL_IS_AREA: u16 = 1;
}

/// TIFF tags this writer uses (TIFF 6.0, GeoTIFF 1.0, GDAL's private tags).
mod tag {
    pub const NEW_SUBFILE_TYPE: u16 = 254;
    pub const IMAGE_WIDTH: u16 = 256;
    pub const IMAGE_LENGTH: u16 = 257;
    pub const BITS_PER_SAMPLE: u16 = 258;
    pub const COMPRESSION: u16 = 259;
    pub const PHOTOMETRIC: u16 = 262;
    pub const SAMPLES_PER_PIXEL: u16 = 277;
    pub const PLANAR_CONFIGURATION: u16 = 284;
    pub const PREDICTOR: u16 = 317;
    pub const TILE_WIDTH: u16 = 322;
    pub const TILE_LENGTH: u16 = 323;
    pub const TILE_OFFSETS: u16 = 324;
    pub const TILE_BYTE_COUNTS: u16 = 325;
    pub const SAMPLE_FORMAT: u16 = 339;
    pub const MODEL_PIXEL_SCALE: u16 = 33550;
    pub const MODEL_TIEPOINT: u16 = 33922;
    pub const MODEL_TRANSFORMATION: u16 = 34264;
    pub const GEO_KEY_DIRECTORY: u16 = 34735;
    pub const GDAL_METADATA: u16 = 42112;
    pub const GDAL_NODATA: u16 = 42113;
}

/// TIFF field types.
mod kind {
    pub const ASCII: u16 = 2;
    pub const SHORT: u16 = 3;
    pub const LONG: u16 = 4;
    pub const DOUBLE: u16 = 12;
    pub const LONG8: u16 = 16;
}

/// TIFF compression codes.
const COMPRESSION_DEFLATE: u16 = 8;
const COMPRESSION_ZSTD: u16 = 50000;
/// TIFF predictor 3: floating point.
const PREDICTOR_FLOATING_POINT: u16 = 3;
/// ZSTD's level: GDAL's default for COMPRESS=ZSTD.
const ZSTD_LEVEL: i32 = 9;

/// The compressions [`write()`] offers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TiffCompression {
    /// zlib DEFLATE (TIFF compression 8): every TIFF reader has it.
    #[default]
    Deflate,
    /// ZSTD (TIFF compression 50000): smaller and faster to decode; GDAL ≥ 2.3 and most
    /// COG readers have it.
    Zstd,
}

/// How [`write()`] writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CogOptions {
    /// The tiles' compression.
    pub compression: TiffCompression,
    /// The tiles' side in samples: 256 or 512.
    pub tile: u32,
    /// Write BigTIFF even when the file would fit classic TIFF's 4 GiB (for tests).
    pub force_bigtiff: bool,
}

impl Default for CogOptions {
    fn default() -> CogOptions {
        CogOptions {
            compression: TiffCompression::Deflate,
            tile: 512,
            force_bigtiff: false,
        }
    }
}

/// One overview [`write()`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Overview {
    /// Its size in pixels.
    pub width: u32,
    /// Its size in pixels.
    pub height: u32,
    /// Its largest difference from the full-resolution samples it covers (both not void),
    /// in the heights' unit.
    pub max_error: f64,
}

/// What [`write()`] wrote, for the caller to report.
#[derive(Clone, Debug, PartialEq)]
pub struct Written {
    /// The EPSG code written as the CRS, if any.
    pub epsg: Option<u32>,
    /// A CRS that is not an EPSG code: not in the file; the caller keeps it beside it.
    pub crs_wkt: Option<String>,
    /// Void samples (NaN in the file).
    pub voids: u64,
    /// The overviews, largest first.
    pub overviews: Vec<Overview>,
    /// Whether the file is BigTIFF.
    pub bigtiff: bool,
}

/// The EPSG code an `EPSG:n` name gives, ignoring a description after the number.
pub fn epsg_code(name: &str) -> Option<u32> {
    let rest = name.trim();
    let rest = rest
        .strip_prefix("EPSG:")
        .or_else(|| rest.strip_prefix("epsg:"))?;
    let digits: String = rest
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok().filter(|&c| c > 0 && c < 65535)
}

/// GDAL's PAM sidecar (`FILE.aux.xml`) holding `wkt` as the CRS of the file beside it.
pub fn aux_xml(wkt: &str) -> String {
    let escaped = wkt
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;");
    format!(
        "<PAMDataset>\n  <SRS dataAxisToSRSAxisMapping=\"1,2\">{escaped}</SRS>\n</PAMDataset>\n"
    )
}

/// One image of the file: the full resolution or an overview.
struct Level {
    width: u32,
    height: u32,
    /// Compressed tiles, row-major.
    tiles: Vec<Vec<u8>>,
}

/// Writes `hf` to `out` as a Cloud-Optimized GeoTIFF.
pub fn write<W: Write>(hf: &Heightfield, options: &CogOptions, mut out: W) -> Result<Written> {
    if options.tile != 256 && options.tile != 512 {
        return Err(Error::InvalidArgument(format!(
            "a tile side of {}: it must be 256 or 512",
            options.tile
        )));
    }
    let (w, h) = (hf.width(), hf.height());
    let samples = hf.samples();
    let voids = samples.iter().filter(|v| v.is_nan()).count() as u64;
    // The overviews' sizes, down to the first that fits in one tile.
    let mut sizes = vec![(w, h)];
    while let Some(&(ow, oh)) = sizes.last() {
        if ow <= options.tile && oh <= options.tile {
            break;
        }
        sizes.push((ow.div_ceil(2), oh.div_ceil(2)));
    }
    let mut overviews = Vec::new();
    let mut levels = vec![Level {
        width: w,
        height: h,
        tiles: tiles_of(samples, w, h, options)?,
    }];
    for &(ow, oh) in &sizes[1..] {
        let ovr = overview(samples, w, h, ow, oh);
        overviews.push(Overview {
            width: ow,
            height: oh,
            max_error: overview_error(samples, w, h, &ovr, ow, oh),
        });
        levels.push(Level {
            width: ow,
            height: oh,
            tiles: tiles_of(&ovr, ow, oh, options)?,
        });
    }
    let mut written = Written {
        epsg: None,
        crs_wkt: None,
        voids,
        overviews,
        bigtiff: false,
    };
    let geo = geo_fields(hf, &mut written);
    let metadata = gdal_metadata(&written.overviews);
    let mut bytes = layout(&levels, &geo, &metadata, voids > 0, options, false)?;
    if bytes.is_none() || options.force_bigtiff {
        bytes = layout(&levels, &geo, &metadata, voids > 0, options, true)?;
        written.bigtiff = true;
    }
    let bytes = bytes.ok_or_else(|| {
        Error::InvalidArgument("the GeoTIFF would pass BigTIFF's 16 EiB".into())
    })?;
    out.write_all(&bytes)
        .map_err(|e| Error::io("<GeoTIFF output>", e))?;
    Ok(written)
}

/// Overview `ow × oh` of the `w × h` samples: each pixel the sample nearest its centre.
fn overview(samples: &[f32], w: u32, h: u32, ow: u32, oh: u32) -> Vec<f32> {
    let pick = |i: u32, n: u32, on: u32| -> usize {
        ((((u64::from(i) * 2 + 1) * u64::from(n)) / (2 * u64::from(on))) as usize)
            .min(n as usize - 1)
    };
    let cols: Vec<usize> = (0..ow).map(|i| pick(i, w, ow)).collect();
    let mut out = Vec::with_capacity(ow as usize * oh as usize);
    for j in 0..oh {
        let row = pick(j, h, oh) * w as usize;
        out.extend(cols.iter().map(|&c| samples[row + c]));
    }
    out
}

/// The largest `|sample − overview pixel covering it|` over samples and pixels both not
/// void: full-resolution sample `x` lies in overview pixel `⌊(x + ½) · ow / w⌋`.
fn overview_error(samples: &[f32], w: u32, h: u32, ovr: &[f32], ow: u32, oh: u32) -> f64 {
    let cover = |x: u32, n: u32, on: u32| -> usize {
        ((((u64::from(x) * 2 + 1) * u64::from(on)) / (2 * u64::from(n))) as usize)
            .min(on as usize - 1)
    };
    let cols: Vec<usize> = (0..w).map(|x| cover(x, w, ow)).collect();
    (0..h)
        .into_par_iter()
        .map(|y| {
            let orow = &ovr[cover(y, h, oh) * ow as usize..][..ow as usize];
            let row = &samples[y as usize * w as usize..][..w as usize];
            row.iter()
                .zip(&cols)
                .map(|(&v, &c)| {
                    let o = orow[c];
                    if v.is_nan() || o.is_nan() {
                        0.0
                    } else {
                        (f64::from(v) - f64::from(o)).abs()
                    }
                })
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
}

/// The `w × h` samples cut into tiles, each coded and compressed, row-major.
fn tiles_of(samples: &[f32], w: u32, h: u32, options: &CogOptions) -> Result<Vec<Vec<u8>>> {
    let t = options.tile;
    let (across, down) = (w.div_ceil(t), h.div_ceil(t));
    (0..across * down)
        .into_par_iter()
        .map(|k| {
            let (tx, ty) = (k % across, k / across);
            let mut raw = Vec::with_capacity((t * t * 4) as usize);
            let mut row = vec![0u8; (t * 4) as usize];
            for r in 0..t {
                // Past the image's edge: the last row and column again.
                let y = (ty * t + r).min(h - 1) as usize;
                let line = &samples[y * w as usize..][..w as usize];
                let values: Vec<f32> = (0..t)
                    .map(|c| line[(tx * t + c).min(w - 1) as usize])
                    .collect();
                predict_row(&values, &mut row);
                raw.extend_from_slice(&row);
            }
            compress(&raw, options.compression)
        })
        .collect()
}

/// TIFF predictor 3 on one row: the samples' bytes as planes, most significant first, then
/// each byte minus the one before it (wrapping).
pub fn predict_row(values: &[f32], out: &mut [u8]) {
    let n = values.len();
    for (i, v) in values.iter().enumerate() {
        for (b, byte) in v.to_be_bytes().into_iter().enumerate() {
            out[b * n + i] = byte;
        }
    }
    for k in (1..4 * n).rev() {
        out[k] = out[k].wrapping_sub(out[k - 1]);
    }
}

/// `raw` compressed as the TIFF compression says.
fn compress(raw: &[u8], compression: TiffCompression) -> Result<Vec<u8>> {
    let failed = |e: std::io::Error| Error::InvalidArgument(format!("GeoTIFF: compressing: {e}"));
    match compression {
        TiffCompression::Deflate => {
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
            z.write_all(raw).map_err(failed)?;
            z.finish().map_err(failed)
        }
        TiffCompression::Zstd => zstd::bulk::compress(raw, ZSTD_LEVEL).map_err(failed),
    }
}

/// One IFD entry: its tag, type, count and value bytes (little-endian).
struct Field {
    tag: u16,
    kind: u16,
    count: u64,
    value: Vec<u8>,
}

impl Field {
    fn shorts(tag: u16, v: &[u16]) -> Field {
        Field {
            tag,
            kind: kind::SHORT,
            count: v.len() as u64,
            value: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn longs(tag: u16, v: &[u32]) -> Field {
        Field {
            tag,
            kind: kind::LONG,
            count: v.len() as u64,
            value: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn doubles(tag: u16, v: &[f64]) -> Field {
        Field {
            tag,
            kind: kind::DOUBLE,
            count: v.len() as u64,
            value: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn ascii(tag: u16, text: &str) -> Field {
        let mut value = text.as_bytes().to_vec();
        value.push(0);
        Field {
            tag,
            kind: kind::ASCII,
            count: value.len() as u64,
            value,
        }
    }

    /// Offsets: LONG in classic TIFF, LONG8 in BigTIFF (`None` when one passes a LONG).
    fn offsets(tag: u16, v: &[u64], big: bool) -> Option<Field> {
        if big {
            return Some(Field {
                tag,
                kind: kind::LONG8,
                count: v.len() as u64,
                value: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            });
        }
        let longs: Option<Vec<u32>> = v.iter().map(|&x| u32::try_from(x).ok()).collect();
        Some(Field::longs(tag, &longs?))
    }
}

/// The georeference's fields (main image only), and what became of the CRS in `written`.
fn geo_fields(hf: &Heightfield, written: &mut Written) -> Vec<Field> {
    let mut fields = Vec::new();
    let (origin, step) = match &hf.metadata.georeference {
        Some(g) => (g.origin, g.step),
        None => {
            // Sample (0, 0)'s centre at (0, 0), rows running south, in metres when known.
            let [dx, dy] = hf
                .metadata
                .spacing_m
                .filter(|s| s.iter().all(|v| v.is_finite() && *v > 0.0))
                .unwrap_or([1.0, 1.0]);
            ([0.0, 0.0], [dx, -dy])
        }
    };
    // The corner of pixel (0, 0): the centre of sample (0, 0) moved back half a step.
    let x0 = origin[0] - 0.5 * step[0];
    let y0 = origin[1] - 0.5 * step[1];
    if step[0] > 0.0 && step[1] < 0.0 {
        fields.push(Field::doubles(tag::MODEL_PIXEL_SCALE, &[step[0], -step[1], 0.0]));
        fields.push(Field::doubles(tag::MODEL_TIEPOINT, &[0.0, 0.0, 0.0, x0, y0, 0.0]));
    } else {
        #[rustfmt::skip]
        let m = [
            step[0], 0.0, 0.0, x0,
            0.0, step[1], 0.0, y0,
            0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
        ];
        fields.push(Field::doubles(tag::MODEL_TRANSFORMATION, &m));
    }
    let Some(name) = hf.metadata.georeference.as_ref().and_then(|g| g.crs.as_ref()) else {
        // Without a CRS, no key directory at all: GDAL would read one without a model type
        // as an engineering CRS, where the source had none.
        return fields;
    };
    let code = epsg_code(name);
    let model = match (code, code.and_then(Crs::from_epsg).map(|c| c.kind)) {
        (Some(c), Some(CrsKind::Geographic)) => Some((key::MODEL_GEOGRAPHIC, key::GEOGRAPHIC_TYPE, c)),
        (Some(c), Some(CrsKind::Projected { .. })) => {
            Some((key::MODEL_PROJECTED, key::PROJECTED_CS_TYPE, c))
        }
        _ => None,
    };
    match model {
        Some((model, key_id, c)) => {
            let mut keys = vec![
                [key::GT_MODEL_TYPE, 0, 1, model],
                [key::GT_RASTER_TYPE, 0, 1, key::RASTER_PIXEL_IS_AREA],
                [key_id, 0, 1, c as u16],
            ];
            // The heights' vertical CRS, when it is a geoid's (EPSG 5773 EGM96 height,
            // 3855 EGM2008 height): GDAL reads the pair as a compound CRS.
            let vertical = match hf.metadata.vertical_datum {
                VerticalDatum::Egm96 => Some(5773),
                VerticalDatum::Egm2008 => Some(3855),
                VerticalDatum::Ellipsoid | VerticalDatum::Unknown => None,
            };
            if let Some(v) = vertical {
                keys.push([key::VERTICAL_CS_TYPE, 0, 1, v]);
            }
            let mut directory: Vec<u16> = vec![1, 1, 0, keys.len() as u16];
            directory.extend(keys.iter().flatten());
            fields.push(Field::shorts(tag::GEO_KEY_DIRECTORY, &directory));
            written.epsg = Some(c);
        }
        None => written.crs_wkt = Some(name.clone()),
    }
    fields
}

/// GDAL's metadata of the main image: how the overviews were made and their errors.
fn gdal_metadata(overviews: &[Overview]) -> String {
    let mut xml = String::from("<GDALMetadata>\n");
    xml.push_str(
        "  <Item name=\"OVERVIEW_RESAMPLING\">NEAREST</Item>\n",
    );
    for (i, o) in overviews.iter().enumerate() {
        xml.push_str(&format!(
            "  <Item name=\"FMRH_OVERVIEW_{}_MAX_ERROR\">{}</Item>\n",
            i + 1,
            o.max_error
        ));
    }
    xml.push_str("</GDALMetadata>");
    xml
}

/// What the ghost area holds after its first line.
const GHOST: &str = "LAYOUT=IFDS_BEFORE_DATA\nBLOCK_ORDER=ROW_MAJOR\nBLOCK_LEADER=SIZE_AS_UINT4\n\
                     BLOCK_TRAILER=LAST_4_BYTES_REPEATED\nKNOWN_INCOMPATIBLE_EDITION=NO\n ";

/// The whole file, classic TIFF or BigTIFF; `None` when classic TIFF cannot hold it.
fn layout(
    levels: &[Level],
    geo: &[Field],
    metadata: &str,
    has_voids: bool,
    options: &CogOptions,
    big: bool,
) -> Result<Option<Vec<u8>>> {
    let (entry, count_size, next_size, inline) = if big { (20, 8, 8, 8) } else { (12, 2, 4, 4) };
    let mut file: Vec<u8> = Vec::new();
    if big {
        file.extend_from_slice(b"II");
        file.extend_from_slice(&43u16.to_le_bytes());
        file.extend_from_slice(&8u16.to_le_bytes());
        file.extend_from_slice(&0u16.to_le_bytes());
        file.extend_from_slice(&0u64.to_le_bytes());
    } else {
        file.extend_from_slice(b"II");
        file.extend_from_slice(&42u16.to_le_bytes());
        file.extend_from_slice(&0u32.to_le_bytes());
    }
    let ghost = format!(
        "GDAL_STRUCTURAL_METADATA_SIZE={:06} bytes\n{GHOST}",
        GHOST.len()
    );
    file.extend_from_slice(ghost.as_bytes());
    if file.len() % 2 == 1 {
        file.push(0);
    }
    // The IFDs' fields, tile offsets left at zero for now: their sizes do not depend on the
    // values, so the tiles' offsets follow from the IFDs' sizes.
    let fields_of = |level: usize, offsets: &[u64]| -> Option<Vec<Field>> {
        let l = &levels[level];
        let t = options.tile;
        let mut f = vec![
            Field::longs(tag::NEW_SUBFILE_TYPE, &[u32::from(level > 0)]),
            Field::longs(tag::IMAGE_WIDTH, &[l.width]),
            Field::longs(tag::IMAGE_LENGTH, &[l.height]),
            Field::shorts(tag::BITS_PER_SAMPLE, &[32]),
            Field::shorts(
                tag::COMPRESSION,
                &[match options.compression {
                    TiffCompression::Deflate => COMPRESSION_DEFLATE,
                    TiffCompression::Zstd => COMPRESSION_ZSTD,
                }],
            ),
            Field::shorts(tag::PHOTOMETRIC, &[1]),
            Field::shorts(tag::SAMPLES_PER_PIXEL, &[1]),
            Field::shorts(tag::PLANAR_CONFIGURATION, &[1]),
            Field::shorts(tag::PREDICTOR, &[PREDICTOR_FLOATING_POINT]),
            Field::longs(tag::TILE_WIDTH, &[t]),
            Field::longs(tag::TILE_LENGTH, &[t]),
            Field::offsets(tag::TILE_OFFSETS, offsets, big)?,
            Field::longs(
                tag::TILE_BYTE_COUNTS,
                &l.tiles.iter().map(|b| b.len() as u32).collect::<Vec<_>>(),
            ),
            Field::shorts(tag::SAMPLE_FORMAT, &[3]),
        ];
        if level == 0 {
            for g in geo {
                f.push(Field {
                    tag: g.tag,
                    kind: g.kind,
                    count: g.count,
                    value: g.value.clone(),
                });
            }
            f.push(Field::ascii(tag::GDAL_METADATA, metadata));
        }
        if has_voids {
            f.push(Field::ascii(tag::GDAL_NODATA, "nan"));
        }
        f.sort_by_key(|x| x.tag);
        Some(f)
    };
    let ifd_size = |fields: &[Field]| -> u64 {
        let out_of_line: u64 = fields
            .iter()
            .filter(|f| f.value.len() > inline)
            .map(|f| f.value.len().next_multiple_of(2) as u64)
            .sum();
        (count_size + fields.len() * entry + next_size) as u64 + out_of_line
    };
    // Where each IFD starts, and where the tiles start.
    let mut ifd_at = Vec::with_capacity(levels.len());
    let mut at = file.len() as u64;
    for (i, l) in levels.iter().enumerate() {
        ifd_at.push(at);
        let zeros = vec![0u64; l.tiles.len()];
        at += ifd_size(&fields_of(i, &zeros).ok_or_else(|| bug("no fields"))?);
    }
    // The tiles, smallest overview first, each as [size][bytes][last 4 bytes].
    let mut offsets: Vec<Vec<u64>> = vec![Vec::new(); levels.len()];
    for (i, l) in levels.iter().enumerate().rev() {
        for t in &l.tiles {
            offsets[i].push(at + 4);
            at += 4 + t.len() as u64 + 4;
        }
    }
    if !big && at > u64::from(u32::MAX) {
        return Ok(None);
    }
    for (i, &start) in ifd_at.iter().enumerate() {
        debug_assert_eq!(file.len() as u64, start);
        let fields = fields_of(i, &offsets[i]).ok_or_else(|| bug("offsets past 4 GiB"))?;
        let next = ifd_at.get(i + 1).copied().unwrap_or(0);
        let mut extra_at = start + (count_size + fields.len() * entry + next_size) as u64;
        let mut extra = Vec::new();
        if big {
            file.extend_from_slice(&(fields.len() as u64).to_le_bytes());
        } else {
            file.extend_from_slice(&(fields.len() as u16).to_le_bytes());
        }
        for f in &fields {
            file.extend_from_slice(&f.tag.to_le_bytes());
            file.extend_from_slice(&f.kind.to_le_bytes());
            if big {
                file.extend_from_slice(&f.count.to_le_bytes());
            } else {
                file.extend_from_slice(&(f.count as u32).to_le_bytes());
            }
            let mut slot = vec![0u8; inline];
            if f.value.len() <= inline {
                slot[..f.value.len()].copy_from_slice(&f.value);
            } else {
                if big {
                    slot.copy_from_slice(&extra_at.to_le_bytes());
                } else {
                    slot.copy_from_slice(&(extra_at as u32).to_le_bytes());
                }
                extra.extend_from_slice(&f.value);
                if f.value.len() % 2 == 1 {
                    extra.push(0);
                }
                extra_at += f.value.len().next_multiple_of(2) as u64;
            }
            file.extend_from_slice(&slot);
        }
        if big {
            file.extend_from_slice(&next.to_le_bytes());
        } else {
            file.extend_from_slice(&(next as u32).to_le_bytes());
        }
        file.extend_from_slice(&extra);
    }
    // The header's pointer to the first IFD.
    if big {
        file[8..16].copy_from_slice(&ifd_at[0].to_le_bytes());
    } else {
        file[4..8].copy_from_slice(&(ifd_at[0] as u32).to_le_bytes());
    }
    for l in levels.iter().rev() {
        for t in &l.tiles {
            file.extend_from_slice(&(t.len() as u32).to_le_bytes());
            file.extend_from_slice(t);
            file.extend_from_slice(&t[t.len().saturating_sub(4)..]);
        }
    }
    debug_assert_eq!(file.len() as u64, at);
    Ok(Some(file))
}

/// An internal inconsistency of the writer (never the input's fault).
fn bug(what: &str) -> Error {
    Error::InvalidArgument(format!("GeoTIFF writer: {what}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsg_codes_come_from_names_with_or_without_a_description() {
        assert_eq!(epsg_code("EPSG:4326"), Some(4326));
        assert_eq!(
            epsg_code("EPSG:4326 (WGS84 geographic), heights EGM96 geoid"),
            Some(4326)
        );
        assert_eq!(epsg_code("epsg: 32610"), Some(32610));
        assert_eq!(epsg_code("UTM zone 10N"), None);
        assert_eq!(epsg_code("EPSG:"), None);
        assert_eq!(epsg_code("EPSG:0"), None);
        assert_eq!(epsg_code("EPSG:99999999999"), None);
    }

    /// Predictor 3 by hand on two samples: planes [3f 40 | 80 00 | 00 00 | 00 00] for
    /// 1.0 = 3f800000 and 2.0 = 40000000, then differenced.
    #[test]
    fn the_floating_point_predictor_splits_bytes_into_planes_and_differences_them() {
        let mut out = [0u8; 8];
        predict_row(&[1.0, 2.0], &mut out);
        let planes: [u8; 8] = [0x3f, 0x40, 0x80, 0x00, 0x00, 0x00, 0x00, 0x00];
        let mut want = planes;
        for k in (1..8).rev() {
            want[k] = planes[k].wrapping_sub(planes[k - 1]);
        }
        assert_eq!(out, want);
        assert_eq!(out, [0x3f, 0x01, 0x40, 0x80, 0x00, 0x00, 0x00, 0x00]);
    }

    #[test]
    fn an_overview_takes_the_sample_nearest_each_pixels_centre() {
        // 5 samples to 3: pixel centres at 5/6, 15/6, 25/6 samples: samples 0, 2, 4.
        let row: Vec<f32> = (0..5).map(|v| v as f32).collect();
        assert_eq!(overview(&row, 5, 1, 3, 1), vec![0.0, 2.0, 4.0]);
        // 4 to 2: centres at 1 and 3: samples 1 and 3 (GDAL's NEAREST).
        assert_eq!(overview(&row[..4], 4, 1, 2, 1), vec![1.0, 3.0]);
        // Its error: 0 1 2 3 against 1 1 3 3.
        assert_eq!(overview_error(&row[..4], 4, 1, &[1.0, 3.0], 2, 1), 1.0);
    }
}
