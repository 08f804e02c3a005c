//! GeoTIFF: one band of integers (8/16/32-bit, signed or not) or floats (32/64-bit).
//!
//! Voids are `NaN` samples and samples equal to the `GDAL_NODATA` tag (tag 42113, ASCII). The
//! georeference comes from `ModelPixelScale` (33550) and `ModelTiepoint` (33922). The
//! `GeoKeyDirectory` (34735) supplies the EPSG code and whether a pixel is an area (the tie
//! point is a corner, the default) or a point (the tie point is a sample centre). Decoding
//! (strips, tiles, compression) is the `tiff` crate's, bounded by its limits.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

use super::{finish, geographic_spacing, IngestOptions};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Georeference, Heightfield, Metadata, MAX_SAMPLES};

/// GeoKey: 1 = geographic, 2 = projected model.
const GT_MODEL_TYPE: u16 = 1024;
/// GeoKey: 1 = pixel is area, 2 = pixel is point.
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;
/// GeoKey ProjLinearUnitsGeoKey: the unit of a projected CRS's coordinates (an EPSG unit code).
const PROJ_LINEAR_UNITS: u16 = 3076;

/// Metres per unit of the EPSG linear unit `code`, for the units projected CRSs use.
fn metres_per_unit(code: u16) -> Option<f64> {
    Some(match code {
        9001 => 1.0,             // metre
        9002 => 0.3048,          // international foot
        9003 => 1200.0 / 3937.0, // US survey foot
        9005 => 0.304_797_265_4, // Clarke's foot
        9030 => 1852.0,          // nautical mile
        9036 => 1000.0,          // kilometre
        9093 => 1609.344,        // statute mile
        _ => return None,
    })
}

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

/// Reads a single-band GeoTIFF.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut limits = Limits::default();
    limits.decoding_buffer_size = usize::try_from(MAX_SAMPLES * 8).unwrap_or(usize::MAX);
    let mut dec = Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits);
    let (width, height) = dec.dimensions().map_err(|e| tiff_error(path, e))?;
    check_dimensions(u64::from(width), u64::from(height))
        .map_err(|e| Error::input(path, e.to_string()))?;
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
    let image = dec.read_image().map_err(|e| tiff_error(path, e))?;

    let convert = |raw: f64| -> f32 {
        if raw.is_nan() || nodata == Some(raw) {
            f32::NAN
        } else {
            options.height(raw)
        }
    };
    let samples: Vec<f32> = match image {
        DecodingResult::U8(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::I8(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::U16(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::I16(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::U32(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::I32(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::F32(v) => v.into_iter().map(|r| convert(f64::from(r))).collect(),
        DecodingResult::F64(v) => v.into_iter().map(convert).collect(),
        other => {
            return Err(Error::unsupported(
                path,
                format!(
                    "sample type {}: fmrh reads 8/16/32-bit integers and 32/64-bit floats",
                    sample_type_name(&other)
                ),
            ))
        }
    };
    if samples.len() as u64 != u64::from(width) * u64::from(height) {
        return Err(Error::unsupported(
            path,
            "more than one sample per pixel: a heightfield GeoTIFF has one band",
        ));
    }
    finish(path, width, height, samples, metadata)
}

/// The strips (or tiles) must lie inside the file, and for an uncompressed image they must hold
/// every sample. The decoder would otherwise pad a short image silently.
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
    let have: u64 = counts.iter().fold(0u64, |a, &c| a.saturating_add(c));
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
    let (Ok(scale), Ok(tie)) = (
        dec.get_tag_f64_vec(Tag::ModelPixelScaleTag),
        dec.get_tag_f64_vec(Tag::ModelTiepointTag),
    ) else {
        return Ok(metadata);
    };
    if scale.len() < 2 || tie.len() < 6 || scale[0] <= 0.0 || scale[1] <= 0.0 {
        return Err(Error::input(
            path,
            "malformed ModelPixelScale or ModelTiepoint tag",
        ));
    }
    let keys = dec
        .get_tag_u16_vec(Tag::GeoKeyDirectoryTag)
        .unwrap_or_default();
    let key = |id: u16| -> Option<u16> {
        keys.get(4..)?
            .chunks_exact(4)
            .find(|k| k[0] == id && k[1] == 0)
            .map(|k| k[3])
    };
    // Pixel-is-area: the tie point is the corner of pixel (i, j), half a pixel from its centre.
    let half = if key(GT_RASTER_TYPE) == Some(2) {
        0.0
    } else {
        0.5
    };
    let origin = [
        tie[3] + (half - tie[0]) * scale[0],
        tie[4] - (half - tie[1]) * scale[1],
    ];
    let step = [scale[0], -scale[1]];
    let (crs, geographic) = match (key(PROJECTED_CS_TYPE), key(GEOGRAPHIC_TYPE)) {
        (Some(code), _) if code != 32767 => (Some(format!("EPSG:{code}")), false),
        (_, Some(code)) if code != 32767 => (Some(format!("EPSG:{code}")), true),
        _ => (None, key(GT_MODEL_TYPE) == Some(2)),
    };
    metadata.spacing_m = if geographic {
        let centre_lat = origin[1] + step[1] * f64::from(height - 1) / 2.0;
        Some(geographic_spacing([scale[0], scale[1]], centre_lat))
    } else {
        // A projected CRS's coordinates are in its linear unit: feet and US survey feet are
        // common (state plane systems). Without the key, metres (the GeoTIFF default); with
        // a unit this reader does not know, the spacing is left unknown, never guessed.
        match key(PROJ_LINEAR_UNITS) {
            None => Some([scale[0], scale[1]]),
            Some(unit) => metres_per_unit(unit).map(|m| [scale[0] * m, scale[1] * m]),
        }
    };
    metadata.georeference = Some(Georeference { crs, origin, step });
    Ok(metadata)
}
