//! GeoTIFF: one band of integers (8/16/32-bit, signed or not) or floats (32/64-bit).
//!
//! Voids are `NaN` samples and samples equal to the `GDAL_NODATA` tag (tag 42113, ASCII). The
//! georeference comes from `ModelPixelScale` (33550) and `ModelTiepoint` (33922). The
//! `GeoKeyDirectory` (34735) supplies the EPSG code and whether a pixel is an area (the tie
//! point is a corner, the default) or a point (the tie point is a sample centre). Decoding
//! (strips, tiles, compression) is the `tiff` crate's, bounded by its limits, one strip or
//! tile at a time into the grid of heights.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{ChunkType, Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

use super::{finish, IngestOptions};
use crate::crs::{Crs, CrsKind};
use crate::error::{Error, Result};
use crate::geoid::VerticalDatum;
use crate::heightfield::{check_dimensions, Georeference, Heightfield, Metadata, MAX_SAMPLES};

/// GeoKey GTModelTypeGeoKey: 1 = projected, 2 = geographic, 3 = geocentric.
const GT_MODEL_TYPE: u16 = 1024;
const MODEL_PROJECTED: u16 = 1;
const MODEL_GEOGRAPHIC: u16 = 2;
/// GeoKey value: user-defined (the parameters follow in other keys).
const USER_DEFINED: u16 = 32767;
/// GeoKey: 1 = pixel is area, 2 = pixel is point.
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;
/// GeoKey ProjLinearUnitsGeoKey: the unit of a projected CRS's coordinates (an EPSG unit code).
const PROJ_LINEAR_UNITS: u16 = 3076;
/// GeoKey ProjLinearUnitSizeGeoKey: metres per unit of a user-defined linear unit (a double).
const PROJ_LINEAR_UNIT_SIZE: u16 = 3077;
/// GeoKey VerticalCSTypeGeoKey: the heights' vertical CRS, an EPSG code (5773 EGM96 height,
/// 3855 EGM2008 height, ...).
const VERTICAL_CS_TYPE: u16 = 4096;

fn tiff_error(path: &Path, e: tiff::TiffError) -> Error {
    match e {
        tiff::TiffError::UnsupportedError(u) => Error::unsupported(path, u.to_string()),
        tiff::TiffError::IoError(io) => {
            Error::input(path, format!("truncated or unreadable: {io}"))
        }
        tiff::TiffError::LimitsExceeded => Error::TooLarge {
            what: path.display().to_string(),
            detail: "the TIFF needs more memory than fmrh allows".into(),
        },
        other => Error::input(path, other.to_string()),
    }
}

/// A GeoTIFF whose header has been read and checked: any window of it can be decoded, one
/// strip or tile at a time, without the rest.
pub(super) struct Tiff {
    path: std::path::PathBuf,
    dec: Decoder<BufReader<File>>,
    /// Columns and rows, as stored.
    pub width: u32,
    pub height: u32,
    nodata: Option<f64>,
    /// The georeference as stored (a south-up grid is not yet turned).
    pub metadata: Metadata,
}

/// Opens a single-band GeoTIFF and checks its header. `whole`: the whole grid is to be held,
/// so it is checked against the memory budget and fmrh's limits on a heightfield; otherwise
/// (a reader of windows) only against the proportion of samples to bytes and TIFF's own
/// limits, and each window is the caller's to bound.
pub(super) fn open(path: &Path, options: &IngestOptions, whole: bool) -> Result<Tiff> {
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    check_first_ifd(path, &mut file, file_len)?;
    std::io::Seek::rewind(&mut file).map_err(|e| Error::io(path, e))?;
    let mut limits = Limits::default();
    limits.decoding_buffer_size = usize::try_from(MAX_SAMPLES * 8).unwrap_or(usize::MAX);
    let mut dec = Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits);
    let (width, height) = dec.dimensions().map_err(|e| tiff_error(path, e))?;
    if whole {
        check_dimensions(u64::from(width), u64::from(height))
            .map_err(|e| Error::input(path, e.to_string()))?;
        options
            .limits
            .check_declared(path, u64::from(width), u64::from(height), file_len)?;
    } else {
        if width == 0 || height == 0 {
            return Err(Error::input(path, format!("{width} x {height} samples")));
        }
        options
            .limits
            .check_proportion(path, u64::from(width), u64::from(height), file_len)?;
    }
    match dec.colortype().map_err(|e| tiff_error(path, e))? {
        ColorType::Gray(_) => {}
        other => {
            return Err(Error::unsupported(
                path,
                format!("colour type {other:?}: a heightfield GeoTIFF has one grey band"),
            ))
        }
    }
    let nodata: Option<f64> = match dec.get_tag_ascii_string(Tag::GdalNodata) {
        Ok(s) => Some(
            s.trim_matches(|c: char| c == '\0' || c.is_whitespace())
                .parse()
                .map_err(|_| Error::input(path, format!("GDAL_NODATA {s:?} is not a number")))?,
        ),
        Err(_) => None,
    };
    check_data_extent(path, &mut dec, width, height, file_len)?;
    let metadata = georeference(path, &mut dec, height)?;
    Ok(Tiff {
        path: path.to_path_buf(),
        dec,
        width,
        height,
        nodata,
        metadata,
    })
}

/// Reads a single-band GeoTIFF.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    let mut tiff = open(path, options, true)?;
    let (width, height) = (tiff.width, tiff.height);
    let samples = tiff.read_window(0, 0, width, height, options)?;
    finish(path, width, height, samples, tiff.metadata)
}

impl Tiff {
    /// The `w × h` samples from column `x0`, row `y0` (as stored), decoded one strip or tile
    /// at a time into the grid of `f32` heights: only the chunks the window touches are read,
    /// and the window is the only allocation its size. (A whole-image decode first held every
    /// sample in its stored type as well: for 16-bit integers 6 bytes a sample at the peak, 4
    /// now. `fmrh build` of Puget Sound 4k as a tiled 16-bit GeoTIFF peaked at 105 MB, now
    /// 76 MB.) Each chunk's decoded length is checked against the size its place in the image
    /// declares, and the chunks' count against the image's size.
    pub(super) fn read_window(
        &mut self,
        x0: u32,
        y0: u32,
        w: u32,
        h: u32,
        options: &IngestOptions,
    ) -> Result<Vec<f32>> {
        let path = self.path.as_path();
        let (width, height) = (self.width, self.height);
        if w == 0
            || h == 0
            || u64::from(x0) + u64::from(w) > u64::from(width)
            || u64::from(y0) + u64::from(h) > u64::from(height)
        {
            return Err(Error::InvalidArgument(format!(
                "window of {w} x {h} samples at column {x0}, row {y0} of a {width} x {height} \
                 image"
            )));
        }
        let nodata = self.nodata;
        let convert = |raw: f64| -> f32 {
            if raw.is_nan() || nodata == Some(raw) {
                f32::NAN
            } else {
                options.height(raw)
            }
        };
        let dec = &mut self.dec;
        let (cw, ch) = dec.chunk_dimensions();
        if cw == 0 || ch == 0 {
            return Err(Error::input(path, format!("{cw} x {ch} strips or tiles")));
        }
        let count = match dec.get_chunk_type() {
            ChunkType::Strip => dec.strip_count(),
            ChunkType::Tile => dec.tile_count(),
        }
        .map_err(|e| tiff_error(path, e))?;
        let (across, down) = (width.div_ceil(cw), height.div_ceil(ch));
        if u64::from(count) != u64::from(across) * u64::from(down) {
            return Err(Error::input(
                path,
                format!(
                    "{count} strips or tiles of {cw} x {ch} samples for a {width} x {height} \
                     image (it needs {})",
                    u64::from(across) * u64::from(down)
                ),
            ));
        }
        let (ww, wh) = (w as usize, h as usize);
        let mut samples = vec![f32::NAN; ww * wh];
        // The chunks the window touches, row by row of chunks.
        for cy in y0 / ch..=(y0 + (h - 1)) / ch {
            for cx in x0 / cw..=(x0 + (w - 1)) / cw {
                let index = cy * across + cx;
                let chunk = dec.read_chunk(index).map_err(|e| tiff_error(path, e))?;
                let (cx0, cy0) = (cx * cw, cy * ch);
                // The data in this chunk: clipped at the image's right and bottom edges.
                let (dw, dh) = (cw.min(width - cx0) as usize, ch.min(height - cy0) as usize);
                let values = chunk_values(path, chunk)?;
                // A chunk decodes to its data (dw x dh) or, for an edge tile, to the whole
                // padded tile (cw x ch); any other length is not what the file declares.
                let stride = match values.len() {
                    n if n == dw * dh => dw,
                    n if n == cw as usize * ch as usize => cw as usize,
                    n => {
                        return Err(Error::input(
                            path,
                            format!(
                                "strip or tile {index} decodes to {n} samples, not the {dw} x \
                                 {dh} it declares (more than one band?)"
                            ),
                        ))
                    }
                };
                // The part of the chunk inside the window, in image coordinates.
                let (ix0, ix1) = (cx0.max(x0), (cx0 + dw as u32).min(x0 + w));
                let (iy0, iy1) = (cy0.max(y0), (cy0 + dh as u32).min(y0 + h));
                let n = (ix1 - ix0) as usize;
                for y in iy0..iy1 {
                    let from = (y - cy0) as usize * stride + (ix0 - cx0) as usize;
                    let to = (y - y0) as usize * ww + (ix0 - x0) as usize;
                    for (out, &v) in samples[to..to + n].iter_mut().zip(&values[from..from + n]) {
                        *out = convert(v);
                    }
                }
            }
        }
        Ok(samples)
    }
}

/// A decoded chunk's values as `f64` (every supported sample type converts exactly).
fn chunk_values(path: &Path, chunk: DecodingResult) -> Result<Vec<f64>> {
    Ok(match chunk {
        DecodingResult::U8(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I8(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F64(v) => v,
        other => {
            return Err(Error::unsupported(
                path,
                format!(
                    "sample type {}: fmrh reads 8/16/32-bit integers and 32/64-bit floats",
                    sample_type_name(&other)
                ),
            ))
        }
    })
}

/// The strips (or tiles) must lie inside the file, and for an uncompressed image they must hold
/// every sample. The decoder would otherwise pad a short image silently.
/// Every entry of the first IFD declares values that fit in the file. The `tiff` crate sizes
/// a tag's value vector from its declared count before it reads it (0.11: a GeoKeyDirectory
/// of 926 M shorts in a 705-byte file asked for 29.6 GB and aborted; found by the `ingest`
/// fuzz target), so the counts are checked here first, from the bytes.
fn check_first_ifd(path: &Path, file: &mut File, file_len: u64) -> Result<()> {
    use std::io::{Read, Seek, SeekFrom};
    let mut read = |at: u64, n: usize| -> Result<Option<Vec<u8>>> {
        if at.saturating_add(n as u64) > file_len {
            return Ok(None);
        }
        let mut b = vec![0u8; n];
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut b))
            .map_err(|e| Error::io(path, e))?;
        Ok(Some(b))
    };
    // Anything malformed here is the crate's to refuse with its own words.
    let Some(head) = read(0, 16.min(file_len as usize))? else {
        return Ok(());
    };
    let le = match head.get(..2) {
        Some(b"II") => true,
        Some(b"MM") => false,
        _ => return Ok(()),
    };
    let uint = |b: &[u8]| -> u64 {
        let mut v = [0u8; 8];
        if le {
            v[..b.len()].copy_from_slice(b);
            u64::from_le_bytes(v)
        } else {
            v[8 - b.len()..].copy_from_slice(b);
            u64::from_be_bytes(v)
        }
    };
    let (big, ifd) = match (head.get(2..4).map(uint), head.len()) {
        (Some(42), n) if n >= 8 => (false, uint(&head[4..8])),
        (Some(43), 16) => (true, uint(&head[8..16])),
        _ => return Ok(()),
    };
    let (count_len, entry_len) = if big { (8, 20) } else { (2, 12) };
    let Some(count) = read(ifd, count_len)?.map(|b| uint(&b)) else {
        return Ok(());
    };
    let entries_end = (count as u128) * (entry_len as u128) + (ifd + count_len as u64) as u128;
    if entries_end > u128::from(file_len) {
        return Err(Error::input(
            path,
            format!("the first IFD declares {count} entries, past the end of the {file_len}-byte file"),
        ));
    }
    let Some(entries) = read(ifd + count_len as u64, (count as usize) * entry_len)? else {
        return Ok(());
    };
    for e in entries.chunks_exact(entry_len) {
        let (tag, kind) = (uint(&e[0..2]), uint(&e[2..4]));
        let n = if big { uint(&e[4..12]) } else { uint(&e[4..8]) };
        let size: u64 = match kind {
            1 | 2 | 6 | 7 => 1,
            3 | 8 => 2,
            4 | 9 | 11 | 13 => 4,
            5 | 10 | 12 | 16 | 17 | 18 => 8,
            _ => continue,
        };
        if n.checked_mul(size).is_none_or(|bytes| bytes > file_len) {
            return Err(Error::input(
                path,
                format!(
                    "tag {tag} declares {n} values of {size} bytes, more than the whole \
                     {file_len}-byte file"
                ),
            ));
        }
    }
    Ok(())
}

fn check_data_extent<R: std::io::Read + std::io::Seek>(
    path: &Path,
    dec: &mut Decoder<R>,
    width: u32,
    height: u32,
    file_len: u64,
) -> Result<()> {
    let mut tags = |a: Tag, b: Tag| -> Vec<u64> {
        match dec.find_tag_unsigned_vec::<u64>(a) {
            Ok(Some(v)) => v,
            _ => dec
                .find_tag_unsigned_vec::<u64>(b)
                .ok()
                .flatten()
                .unwrap_or_default(),
        }
    };
    let offsets = tags(Tag::StripOffsets, Tag::TileOffsets);
    let counts = tags(Tag::StripByteCounts, Tag::TileByteCounts);
    if offsets.len() != counts.len() {
        return Err(Error::input(
            path,
            "strip offsets and byte counts differ in number",
        ));
    }
    for (&o, &c) in offsets.iter().zip(&counts) {
        if o.checked_add(c).is_none_or(|end| end > file_len) {
            return Err(Error::input(
                path,
                format!(
                    "image data at bytes {o}..{} lies past the end of the {file_len}-byte file",
                    o.saturating_add(c)
                ),
            ));
        }
    }
    let compression: u16 = dec
        .find_tag_unsigned(Tag::Compression)
        .ok()
        .flatten()
        .unwrap_or(1);
    let bits: u64 = dec
        .find_tag_unsigned_vec::<u64>(Tag::BitsPerSample)
        .ok()
        .flatten()
        .map(|v| v.iter().sum())
        .unwrap_or(1);
    // The bytes the strips or tiles cover, each byte once: a file whose tile offsets all
    // point at one small stream (a decompression bomb) holds only that stream.
    let mut spans: Vec<(u64, u64)> = offsets
        .iter()
        .zip(&counts)
        .map(|(&o, &c)| (o, o.saturating_add(c)))
        .collect();
    spans.sort_unstable();
    let (mut have, mut reach) = (0u64, 0u64);
    for (start, end) in spans {
        let from = start.max(reach);
        if end > from {
            have = have.saturating_add(end - from);
            reach = end;
        }
    }
    let need = (u64::from(width) * bits).div_ceil(8) * u64::from(height);
    // The most bytes each codec can make of one stored byte: a header that claims more than
    // its data could decode to is refused before the image buffer is sized from it.
    let (codec, ratio) = match compression {
        1 => ("uncompressed", 1),
        // Deflate's ceiling is 1032:1 (a 258-byte match per 2 bits, RFC 1951).
        8 | 32946 => ("deflate", 1032),
        // LZW with 12-bit codes emits at most ~3,800 bytes per code of 12 bits.
        5 => ("LZW", 2600),
        // PackBits: at most 128 bytes from a 2-byte run.
        32773 => ("PackBits", 64),
        // ZSTD: an RLE block makes up to 128 KiB from 4 bytes.
        50000 => ("ZSTD", 32_768),
        _ => return Ok(()),
    };
    if have.saturating_mul(ratio) < need {
        return Err(Error::input(
            path,
            format!(
                "{codec} image data is {have} bytes, which cannot hold the {need} bytes the \
                 image needs"
            ),
        ));
    }
    Ok(())
}

fn sample_type_name(r: &DecodingResult) -> &'static str {
    match r {
        DecodingResult::U64(_) => "u64",
        DecodingResult::I64(_) => "i64",
        DecodingResult::F16(_) => "f16",
        _ => "other",
    }
}

fn georeference<R: std::io::Read + std::io::Seek>(
    path: &Path,
    dec: &mut Decoder<R>,
    height: u32,
) -> Result<Metadata> {
    let mut metadata = Metadata::default();
    let keys = dec
        .get_tag_u16_vec(Tag::GeoKeyDirectoryTag)
        .unwrap_or_default();
    let doubles = dec
        .get_tag_f64_vec(Tag::GeoDoubleParamsTag)
        .unwrap_or_default();
    let entry = |id: u16| keys.get(4..)?.chunks_exact(4).find(|k| k[0] == id);
    // A SHORT key is stored in the directory itself (location 0).
    let key = |id: u16| entry(id).filter(|k| k[1] == 0).map(|k| k[3]);
    // A DOUBLE key points into GeoDoubleParams.
    let double_key = |id: u16| {
        entry(id)
            .filter(|k| k[1] == Tag::GeoDoubleParamsTag.to_u16())
            .and_then(|k| doubles.get(usize::from(k[3])).copied())
    };
    // What the heights are above, when the file says (a code fmrh does not know: unknown).
    metadata.vertical_datum = key(VERTICAL_CS_TYPE)
        .filter(|&c| c != 0 && c != USER_DEFINED)
        .map_or(VerticalDatum::Unknown, |c| VerticalDatum::of_epsg(u32::from(c)));
    // Pixel-is-area: the tie point is the corner of pixel (i, j), half a pixel from its centre.
    let half = if key(GT_RASTER_TYPE) == Some(2) {
        0.0
    } else {
        0.5
    };
    // The affine map from (column, row) of a pixel's corner (or centre, pixel-is-point) to CRS
    // coordinates: either a scale and a tie point, or a full 4×4 ModelTransformation.
    let (origin, step) = match (
        dec.get_tag_f64_vec(Tag::ModelPixelScaleTag),
        dec.get_tag_f64_vec(Tag::ModelTiepointTag),
        dec.get_tag_f64_vec(Tag::ModelTransformationTag),
    ) {
        (Ok(scale), Ok(tie), _) => {
            let ok = |v: f64| v.is_finite() && v != 0.0;
            if scale.len() < 2 || tie.len() < 6 || !ok(scale[0]) || !ok(scale[1]) {
                return Err(Error::input(
                    path,
                    "malformed ModelPixelScale or ModelTiepoint tag",
                ));
            }
            // y = tie_y - (j - tie_j) · scale_y: a negative scale_y is a south-up grid.
            let step = [scale[0], -scale[1]];
            let origin = [
                tie[3] + (half - tie[0]) * step[0],
                tie[4] + (half - tie[1]) * step[1],
            ];
            (origin, step)
        }
        (_, _, Ok(m)) => {
            if m.len() < 16 {
                return Err(Error::input(path, "malformed ModelTransformation tag"));
            }
            // x = m0·i + m1·j + m3, y = m4·i + m5·j + m7.
            if m[1] != 0.0 || m[4] != 0.0 {
                return Err(Error::unsupported(
                    path,
                    format!(
                        "the grid is rotated or sheared (ModelTransformation terms {} and {}); \
                         fmrh stores grids whose rows run east-west: resample it first, \
                         e.g. with gdalwarp",
                        m[1], m[4]
                    ),
                ));
            }
            let step = [m[0], m[5]];
            if !step.iter().all(|v| v.is_finite() && *v != 0.0) {
                return Err(Error::input(path, "malformed ModelTransformation tag"));
            }
            ([m[3] + half * step[0], m[7] + half * step[1]], step)
        }
        _ => return Ok(metadata),
    };
    let model_type = key(GT_MODEL_TYPE);
    let code = |k: u16| key(k).filter(|&c| c != 0 && c != USER_DEFINED);
    let (name, crs) = match (code(PROJECTED_CS_TYPE), code(GEOGRAPHIC_TYPE)) {
        (Some(c), _) => (Some(format!("EPSG:{c}")), Crs::from_epsg(u32::from(c))),
        (None, Some(c)) if model_type != Some(MODEL_PROJECTED) => {
            (Some(format!("EPSG:{c}")), Crs::from_epsg(u32::from(c)))
        }
        _ => (None, None),
    };
    // What the coordinates are: the CRS's kind from its code when the registry knows it,
    // else the model type key; a projected unit from ProjLinearUnits (an EPSG unit code, or
    // user-defined with its size in metres), else from the registry. Nothing known leaves the
    // spacing unknown, never guessed.
    let kind = match (crs.as_ref().map(|c| c.kind), model_type) {
        (Some(kind), _) => kind,
        (None, Some(MODEL_GEOGRAPHIC)) => CrsKind::Geographic,
        (None, Some(MODEL_PROJECTED)) => CrsKind::Projected {
            metres_per_unit: None,
        },
        _ => CrsKind::Other,
    };
    // The key, when present, decides (even when it names a unit fmrh does not know).
    let linear_unit = match key(PROJ_LINEAR_UNITS) {
        Some(USER_DEFINED) => Some(double_key(PROJ_LINEAR_UNIT_SIZE)),
        Some(unit) => Some(crate::crs::epsg_linear_unit(u32::from(unit))),
        None => None,
    };
    let kind = match kind {
        CrsKind::Projected { metres_per_unit } => CrsKind::Projected {
            metres_per_unit: linear_unit.unwrap_or(metres_per_unit),
        },
        other => other,
    };
    let centre_lat = origin[1] + step[1] * f64::from(height - 1) / 2.0;
    metadata.spacing_m = kind.spacing(step, centre_lat);
    metadata.georeference = Some(Georeference {
        crs: name,
        origin,
        step,
    });
    Ok(metadata)
}
