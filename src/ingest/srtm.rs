//! SRTM `.hgt` and `.hgt.gz` tiles: a square of big-endian `i16` with no header, -32768 for
//! voids.
//!
//! The side comes from the (decompressed) length: 1201² samples for SRTM3 and 3601² for SRTM1.
//! Any other length is an error. The georeference comes from the name, as in `N44W072.hgt`:
//! that names the tile's south-west corner, and samples are grid-registered, so row 0 lies on
//! latitude 45 and column 0 on longitude -72. A name that does not parse leaves the tile without
//! a georeference.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use byteorder::{BigEndian, ByteOrder};
use flate2::read::GzDecoder;

use super::{finish, geographic_spacing, read_limited, IngestOptions};
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
    if let Some((lat, lon)) = parse_tile_name(path) {
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

/// `(south latitude, west longitude)` from a name like `N44W072...` or `s16e166...`.
fn parse_tile_name(path: &Path) -> Option<(i32, i32)> {
    let name = path.file_name()?.to_str()?.as_bytes();
    if name.len() < 7 {
        return None;
    }
    let digits = |b: &[u8]| -> Option<i32> {
        b.iter().try_fold(0i32, |acc, &c| {
            c.is_ascii_digit().then(|| acc * 10 + i32::from(c - b'0'))
        })
    };
    let lat = digits(&name[1..3])?;
    let lon = digits(&name[4..7])?;
    let lat = match name[0].to_ascii_uppercase() {
        b'N' => lat,
        b'S' => -lat,
        _ => return None,
    };
    let lon = match name[3].to_ascii_uppercase() {
        b'E' => lon,
        b'W' => -lon,
        _ => return None,
    };
    ((-90..90).contains(&lat) && (-180..180).contains(&lon)).then_some((lat, lon))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_names() {
        assert_eq!(parse_tile_name(Path::new("N44W072.hgt")), Some((44, -72)));
        assert_eq!(
            parse_tile_name(Path::new("/x/s16E166.hgt.gz")),
            Some((-16, 166))
        );
        assert_eq!(parse_tile_name(Path::new("tile.hgt")), None);
        assert_eq!(parse_tile_name(Path::new("N99W072.hgt")), None);
    }
}
