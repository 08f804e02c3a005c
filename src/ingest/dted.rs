//! DTED (Digital Terrain Elevation Data, MIL-PRF-89020B) levels 0, 1 and 2: `.dt0`, `.dt1`,
//! `.dt2`.
//!
//! A file is three fixed headers, then one record per longitude line:
//!
//! ```text
//! UHL  80 bytes   "UHL1", origin longitude and latitude (DDDMMSSH), longitude and
//!                 latitude intervals (tenths of arc-seconds), counts of longitude lines
//!                 (bytes 47..51) and of points per line (51..55)
//! DSI  648 bytes  "DSI", data set identification
//! ACC  2700 bytes "ACC", accuracy
//! per longitude line, west to east:
//!      0xAA, block count (3 bytes), longitude count (2), latitude count (2),
//!      points south to north (2 bytes each, big-endian signed magnitude),
//!      checksum (4 bytes: the sum of the record's other bytes)
//! ```
//!
//! Samples are grid-registered: the origin (the south-west corner) is a sample. Heights are
//! metres above mean sea level; -32767 (0xFFFF in signed magnitude) is a void. The checksum of
//! every record is verified: a mismatch is a damaged file. The CRS is WGS 84 (EPSG:4326).

use std::path::Path;

use super::{finish, read_limited, IngestOptions};
use crate::crs::geographic_spacing;
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Georeference, Heightfield, Metadata};

const UHL_LEN: usize = 80;
const DSI_LEN: usize = 648;
const ACC_LEN: usize = 2700;
const HEADERS_LEN: usize = UHL_LEN + DSI_LEN + ACC_LEN;
/// The sentinel that opens every data record.
const RECORD_SENTINEL: u8 = 0xAA;
/// Record bytes besides the points: sentinel, block count, two counts, checksum.
const RECORD_OVERHEAD: usize = 8 + 4;
/// DTED's void: -32767.
const VOID: i32 = -32767;
/// The longest side any DTED level has (level 2: one arc-second, 3601 points).
const MAX_POINTS: usize = 3601;

/// Reads a DTED file.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    let max_len = HEADERS_LEN + MAX_POINTS * (RECORD_OVERHEAD + 2 * MAX_POINTS);
    let bytes = read_limited(path, max_len as u64)?;
    let uhl = bytes
        .get(..UHL_LEN)
        .filter(|h| h.starts_with(b"UHL"))
        .ok_or_else(|| Error::input(path, "no DTED user header label (UHL) at the start"))?;
    let text = |at: usize, len: usize, what: &str| -> Result<&str> {
        std::str::from_utf8(&uhl[at..at + len])
            .map(str::trim)
            .map_err(|_| Error::input(path, format!("UHL {what} is not text")))
    };
    let number = |at: usize, len: usize, what: &str| -> Result<u32> {
        let t = text(at, len, what)?;
        t.parse()
            .map_err(|_| Error::input(path, format!("UHL {what} {t:?} is not a number")))
    };
    let lon0 = angle(text(4, 8, "origin longitude")?, 3, b'E', b'W')
        .ok_or_else(|| Error::input(path, "UHL origin longitude is not DDDMMSSH"))?;
    let lat0 = angle(text(12, 8, "origin latitude")?, 3, b'N', b'S')
        .ok_or_else(|| Error::input(path, "UHL origin latitude is not DDDMMSSH"))?;
    let lon_interval = number(20, 4, "longitude interval")?;
    let lat_interval = number(24, 4, "latitude interval")?;
    let columns = number(47, 4, "number of longitude lines")? as usize;
    let rows = number(51, 4, "number of latitude points")? as usize;
    if lon_interval == 0 || lat_interval == 0 {
        return Err(Error::input(path, "UHL gives a zero interval"));
    }
    if columns > MAX_POINTS || rows > MAX_POINTS {
        return Err(Error::input(
            path,
            format!("{columns} × {rows} points: DTED has at most {MAX_POINTS} a side"),
        ));
    }
    check_dimensions(columns as u64, rows as u64).map_err(|e| Error::input(path, e.to_string()))?;
    options
        .limits
        .check_declared(path, columns as u64, rows as u64, bytes.len() as u64)?;
    if bytes.get(UHL_LEN..UHL_LEN + 3) != Some(b"DSI")
        || bytes.get(UHL_LEN + DSI_LEN..UHL_LEN + DSI_LEN + 3) != Some(b"ACC")
    {
        return Err(Error::input(
            path,
            "DSI or ACC header missing after the UHL",
        ));
    }
    let record_len = RECORD_OVERHEAD + 2 * rows;
    let needed = HEADERS_LEN + columns * record_len;
    if bytes.len() < needed {
        return Err(Error::input(
            path,
            format!(
                "truncated: {columns} records of {record_len} bytes need {needed} bytes, the file has {}",
                bytes.len()
            ),
        ));
    }
    let mut samples = vec![f32::NAN; columns * rows];
    for (col, record) in bytes[HEADERS_LEN..needed]
        .chunks_exact(record_len)
        .enumerate()
    {
        if record[0] != RECORD_SENTINEL {
            return Err(Error::input(
                path,
                format!("record {col} does not start with the 0xAA sentinel"),
            ));
        }
        let (body, sum) = record.split_at(record_len - 4);
        let stored = u32::from_be_bytes([sum[0], sum[1], sum[2], sum[3]]);
        let computed = body.iter().map(|&b| u32::from(b)).sum::<u32>();
        if stored != computed {
            return Err(Error::input(
                path,
                format!("record {col}: checksum {stored} but the bytes sum to {computed}"),
            ));
        }
        for (k, point) in body[8..].chunks_exact(2).enumerate() {
            let raw = u16::from_be_bytes([point[0], point[1]]);
            let magnitude = i32::from(raw & 0x7FFF);
            let value = if raw & 0x8000 != 0 {
                -magnitude
            } else {
                magnitude
            };
            // Points run south to north; row 0 is the north edge.
            let row = rows - 1 - k;
            samples[row * columns + col] = if value == VOID {
                f32::NAN
            } else {
                options.height(f64::from(value))
            };
        }
    }
    let step = [
        f64::from(lon_interval) / 36_000.0,
        f64::from(lat_interval) / 36_000.0,
    ];
    let north = lat0 + step[1] * (rows - 1) as f64;
    let metadata = Metadata {
        spacing_m: Some(geographic_spacing(step, (lat0 + north) / 2.0)),
        georeference: Some(Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [lon0, north],
            step: [step[0], -step[1]],
        }),
        units: Some("metres".into()),
        // The datum is the reader's convention, which `ingest` applies.
        ..Metadata::default()
    };
    finish(path, columns as u32, rows as u32, samples, metadata)
}

/// Degrees of a `DDDMMSSH` (or `DDMMSSH` with `degree_digits` 2) angle: hemisphere letter
/// `positive` or `negative` last.
fn angle(text: &str, degree_digits: usize, positive: u8, negative: u8) -> Option<f64> {
    let b = text.as_bytes();
    if b.len() != degree_digits + 5 {
        return None;
    }
    let (digits, hemisphere) = b.split_at(degree_digits + 4);
    if !digits.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let n = |r: std::ops::Range<usize>| {
        digits[r]
            .iter()
            .fold(0u32, |a, &c| a * 10 + u32::from(c - b'0'))
    };
    let (d, m, s) = (
        n(0..degree_digits),
        n(degree_digits..degree_digits + 2),
        n(degree_digits + 2..degree_digits + 4),
    );
    if m >= 60 || s >= 60 || d > 180 {
        return None;
    }
    let value = f64::from(d) + f64::from(m) / 60.0 + f64::from(s) / 3600.0;
    match hemisphere[0].to_ascii_uppercase() {
        h if h == positive => Some(value),
        h if h == negative => Some(-value),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles() {
        assert_eq!(angle("0660000W", 3, b'E', b'W'), Some(-66.0));
        assert_eq!(angle("0453000S", 3, b'N', b'S'), Some(-45.5));
        assert_eq!(angle("0070030E", 3, b'E', b'W'), Some(7.0 + 30.0 / 3600.0));
        assert_eq!(angle("0660000X", 3, b'E', b'W'), None);
        assert_eq!(angle("0666000W", 3, b'E', b'W'), None);
        assert_eq!(angle("066000W", 3, b'E', b'W'), None);
        assert_eq!(angle("0é60000W", 3, b'E', b'W'), None);
    }
}
