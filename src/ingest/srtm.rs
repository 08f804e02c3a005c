//! SRTM `.hgt` and `.hgt.gz` tiles: a square of big-endian `i16` with no header, -32768 for
//! voids.
//!
//! The side comes from the (decompressed) length: 1201² samples for SRTM3 and 3601² for SRTM1.
//! Any other length is an error. The georeference comes from the name, as in `N44W072.hgt`:
//! that names the tile's south-west corner, and samples are grid-registered, so row 0 lies on
//! latitude 45 and column 0 on longitude -72. The tile name may stand anywhere in the file
//! name (`srtm_N44W072_v3.hgt`); for a file renamed beyond that (`my tile.hgt`) the
//! [`IngestOptions::tile`] option names it. Without either, the tile has no georeference and
//! its spacing is unknown: a degree of longitude depends on the latitude.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use byteorder::{BigEndian, ByteOrder};
use flate2::read::GzDecoder;

use super::{finish, parse_tile_name, read_limited, IngestOptions};
use crate::crs::geographic_spacing;
use crate::error::{Error, Result};
use crate::heightfield::{Georeference, Heightfield, Metadata};

/// SRTM's void value.
pub const SRTM_VOID: i16 = -32768;
const SIDES: [u32; 2] = [1201, 3601];
const MAX_BYTES: u64 = 3601 * 3601 * 2;

/// Reads an `.hgt` or `.hgt.gz` tile.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    let gz = path.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
    let bytes = if gz {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut out = Vec::new();
        GzDecoder::new(file)
            .take(MAX_BYTES + 1)
            .read_to_end(&mut out)
            .map_err(|e| Error::input(path, format!("gzip stream is damaged: {e}")))?;
        out
    } else {
        read_limited(path, MAX_BYTES).map_err(|e| match e {
            Error::Input { .. } => Error::input(
                path,
                "too long for an SRTM tile (1201² or 3601² samples of i16)",
            ),
            other => other,
        })?
    };
    let side = SIDES
        .into_iter()
        .find(|&s| bytes.len() as u64 == u64::from(s) * u64::from(s) * 2)
        .ok_or_else(|| {
            Error::input(
                path,
                format!(
                    "{} bytes is not an SRTM tile: 1201² or 3601² samples of i16 are 2884802 or 25934402 bytes",
                    bytes.len()
                ),
            )
        })?;
    let samples: Vec<f32> = bytes
        .chunks_exact(2)
        .map(|b| match BigEndian::read_i16(b) {
            SRTM_VOID => f32::NAN,
            raw => options.height(f64::from(raw)),
        })
        .collect();
    let mut metadata = Metadata {
        units: Some("metres".into()),
        ..Metadata::default()
    };
    let name = path.file_name().map(|n| n.to_string_lossy());
    let corner = match &options.tile {
        Some(tile) => parse_tile_name(tile),
        None => name.as_deref().and_then(parse_tile_name),
    };
    if let Some((lat, lon)) = corner {
        let step = 1.0 / f64::from(side - 1);
        metadata.georeference = Some(Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [f64::from(lon), f64::from(lat) + 1.0],
            step: [step, -step],
        });
        metadata.spacing_m = Some(geographic_spacing([step, step], f64::from(lat) + 0.5));
    }
    finish(path, side, side, samples, metadata)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_names() {
        assert_eq!(parse_tile_name("N44W072.hgt"), Some((44, -72)));
        assert_eq!(parse_tile_name("s16E166.hgt.gz"), Some((-16, 166)));
        assert_eq!(parse_tile_name("srtm_N44W072_v3.hgt"), Some((44, -72)));
        assert_eq!(parse_tile_name("my N44W072.hgt"), Some((44, -72)));
        assert_eq!(parse_tile_name("tile.hgt"), None);
        assert_eq!(parse_tile_name("N99W072.hgt"), None);
        assert_eq!(parse_tile_name("XN44W072.hgt"), None, "inside a word");
        assert_eq!(parse_tile_name("N44W0721.hgt"), None, "more digits");
        assert_eq!(parse_tile_name("N44W072"), Some((44, -72)));
        assert_eq!(parse_tile_name("é N44W072"), Some((44, -72)));
    }
}
