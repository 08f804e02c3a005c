//! A heightfield as a GeoTIFF: one band of 32-bit floats, DEFLATE-compressed strips, the
//! georeference as GeoTIFF 1.0 tags, voids as NaN with `GDAL_NODATA` saying so.
//!
//! **Where the samples lie.** fmrh's georeference names the *centre* of sample (0, 0)
//! (`heightfield::Georeference`). GeoTIFF's default raster type, `PixelIsArea`, ties the
//! *corner* of pixel (0, 0) to the model, so the tie point is the centre moved back half a
//! step each way; GDAL reports the same geotransform for this file as for a source that tied
//! its centres with `PixelIsPoint`. A north-up grid (east steps positive, south steps
//! negative) is written as `ModelPixelScale` + `ModelTiepoint`; any other as a
//! `ModelTransformation` matrix.
//!
//! **The CRS.** An `EPSG:n` name (as the GeoTIFF, SRTM and DTED readers give it, possibly
//! followed by a description) becomes `GeographicTypeGeoKey` or `ProjectedCSTypeGeoKey` with
//! the model type the EPSG registry gives. A name fmrh cannot reduce to a code (a WKT, free
//! text) is kept as `GTCitationGeoKey` only, with no CRS keys, and [`Written::crs_kept`] says
//! so: a reader then sees the geotransform and the text, not a CRS. A grid without a CRS
//! name gets no key directory: its tie points alone, as GDAL writes such a file.
//!
//! **Voids.** fmrh stores voids, not the source's nodata value: when the samples have any,
//! the file says `GDAL_NODATA = nan`.
//!
//! No I/O beyond the writer it is given (the CLI writes the file atomically).

use std::io::{Seek, Write};

use tiff::encoder::{colortype, compression::DeflateLevel, Compression, TiffEncoder};
use tiff::tags::Tag;

use crate::crs::{Crs, CrsKind};
use crate::error::{Error, Result};
use crate::heightfield::Heightfield;

/// GeoKey ids (GeoTIFF 1.0 §6.3) and values this writer uses.
mod key {
    pub const GT_MODEL_TYPE: u16 = 1024;
    pub const GT_RASTER_TYPE: u16 = 1025;
    pub const GT_CITATION: u16 = 1026;
    pub const GEOGRAPHIC_TYPE: u16 = 2048;
    pub const PROJECTED_CS_TYPE: u16 = 3072;
    pub const MODEL_PROJECTED: u16 = 1;
    pub const MODEL_GEOGRAPHIC: u16 = 2;
    pub const RASTER_PIXEL_IS_AREA: u16 = 1;
    /// `GeoAsciiParamsTag`: where an ASCII key's value lies.
    pub const ASCII_PARAMS: u16 = 34737;
}

/// Tag ids the `tiff` crate has no names for.
const MODEL_TRANSFORMATION: u16 = 34264;

/// Rows per strip: strips of about 256 KiB at 16,384 columns, fewer rows when wider.
const STRIP_BYTES: u64 = 256 << 10;

/// What [`write()`] wrote, for the caller to report.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Written {
    /// The EPSG code written as the CRS, if any.
    pub epsg: Option<u32>,
    /// A CRS name that could not be written as a code, kept as the citation only.
    pub crs_kept: Option<String>,
    /// Void samples (NaN in the file).
    pub voids: u64,
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

/// Writes `hf` to `out` as a GeoTIFF.
pub fn write<W: Write + Seek>(hf: &Heightfield, out: W) -> Result<Written> {
    let tiff_error = |e: tiff::TiffError| Error::InvalidArgument(format!("GeoTIFF: {e}"));
    let mut encoder = TiffEncoder::new(out)
        .map_err(tiff_error)?
        .with_compression(Compression::Deflate(DeflateLevel::Balanced));
    let (w, h) = (hf.width(), hf.height());
    let mut image = encoder
        .new_image::<colortype::Gray32Float>(w, h)
        .map_err(tiff_error)?;
    let rows = u32::try_from((STRIP_BYTES / (4 * u64::from(w.max(1)))).max(1)).unwrap_or(1);
    image.rows_per_strip(rows).map_err(tiff_error)?;
    let samples = hf.samples();
    let voids = samples.iter().filter(|v| v.is_nan()).count() as u64;
    let mut written = Written {
        epsg: None,
        crs_kept: None,
        voids,
    };
    let dir = image.encoder();
    if let Some(g) = &hf.metadata.georeference {
        // The corner of pixel (0, 0): the centre of sample (0, 0) moved back half a step.
        let x0 = g.origin[0] - 0.5 * g.step[0];
        let y0 = g.origin[1] - 0.5 * g.step[1];
        if g.step[0] > 0.0 && g.step[1] < 0.0 {
            dir.write_tag(Tag::ModelPixelScaleTag, &[g.step[0], -g.step[1], 0.0][..])
                .map_err(tiff_error)?;
            dir.write_tag(Tag::ModelTiepointTag, &[0.0, 0.0, 0.0, x0, y0, 0.0][..])
                .map_err(tiff_error)?;
        } else {
            #[rustfmt::skip]
            let m = [
                g.step[0], 0.0, 0.0, x0,
                0.0, g.step[1], 0.0, y0,
                0.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 0.0, 1.0,
            ];
            dir.write_tag(Tag::Unknown(MODEL_TRANSFORMATION), &m[..])
                .map_err(tiff_error)?;
        }
        let mut keys: Vec<[u16; 4]> = vec![[key::GT_RASTER_TYPE, 0, 1, key::RASTER_PIXEL_IS_AREA]];
        let mut ascii = String::new();
        let code = g.crs.as_deref().and_then(epsg_code);
        let crs = code.and_then(Crs::from_epsg);
        match (code, crs.map(|c| c.kind)) {
            (Some(c), Some(CrsKind::Geographic)) => {
                keys.push([key::GT_MODEL_TYPE, 0, 1, key::MODEL_GEOGRAPHIC]);
                keys.push([key::GEOGRAPHIC_TYPE, 0, 1, c as u16]);
                written.epsg = Some(c);
            }
            (Some(c), Some(CrsKind::Projected { .. })) => {
                keys.push([key::GT_MODEL_TYPE, 0, 1, key::MODEL_PROJECTED]);
                keys.push([key::PROJECTED_CS_TYPE, 0, 1, c as u16]);
                written.epsg = Some(c);
            }
            _ => {
                if let Some(name) = &g.crs {
                    // GeoTIFF ASCII values end with '|', which the text must not hold.
                    let text: String = name.chars().filter(|&c| c != '|').collect();
                    let count = u16::try_from(text.len() + 1).unwrap_or(u16::MAX);
                    keys.push([key::GT_CITATION, key::ASCII_PARAMS, count, 0]);
                    ascii.push_str(&text);
                    ascii.push('|');
                    written.crs_kept = Some(name.clone());
                }
            }
        }
        // Without a CRS, no key directory at all: GDAL would read one without a model type
        // as an engineering CRS, where the source had none.
        if g.crs.is_some() {
            keys.sort_unstable_by_key(|k| k[0]);
            let mut directory: Vec<u16> = vec![1, 1, 0, keys.len() as u16];
            directory.extend(keys.iter().flatten());
            dir.write_tag(Tag::GeoKeyDirectoryTag, &directory[..])
                .map_err(tiff_error)?;
        }
        if !ascii.is_empty() {
            dir.write_tag(Tag::GeoAsciiParamsTag, ascii.as_str())
                .map_err(tiff_error)?;
        }
    }
    if voids > 0 {
        dir.write_tag(Tag::GdalNodata, "nan").map_err(tiff_error)?;
    }
    image.write_data(samples).map_err(tiff_error)?;
    Ok(written)
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
}
