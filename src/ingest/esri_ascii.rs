//! ESRI ASCII grid (`.asc`): a short `key value` header, then `nrows` rows of `ncols` numbers,
//! north row first.
//!
//! Header keys (any case, any order): `ncols`, `nrows`, `xllcorner` or `xllcenter`,
//! `yllcorner` or `yllcenter`, `cellsize` (or `dx` and `dy`), and an optional `NODATA_value`. A
//! value equal to `NODATA_value` is a void. The header's size is checked against the file before
//! allocating: every value needs at least two bytes (a digit and a separator).

use std::path::Path;

use super::{finish, read_limited, IngestOptions};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Georeference, Heightfield, Metadata, MAX_SAMPLES};

/// Reads an ESRI ASCII grid.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    // Longest plausible file: every value 40 characters.
    let bytes = read_limited(path, MAX_SAMPLES.saturating_mul(40))?;
    let text = std::str::from_utf8(&bytes).map_err(|_| Error::input(path, "not a text file"))?;
    let mut tokens = text.split_ascii_whitespace().peekable();

    let (mut ncols, mut nrows) = (None, None);
    let (mut xll, mut yll, mut centre) = (None, None, false);
    let (mut cellsize, mut dx, mut dy, mut nodata) = (None, None, None, None);
    while let Some(&tok) = tokens.peek() {
        if !tok.starts_with(|c: char| c.is_ascii_alphabetic()) {
            break;
        }
        let key = tok.to_ascii_lowercase();
        tokens.next();
        let value = tokens
            .next()
            .ok_or_else(|| Error::input(path, format!("header key {tok} has no value")))?;
        let num = |v: &str| -> Result<f64> {
            v.parse::<f64>()
                .ok()
                .filter(|f| f.is_finite())
                .ok_or_else(|| Error::input(path, format!("header {key}: {v:?} is not a number")))
        };
        match key.as_str() {
            "ncols" => {
                ncols = Some(
                    value
                        .parse::<u64>()
                        .map_err(|_| Error::input(path, format!("ncols {value:?}")))?,
                )
            }
            "nrows" => {
                nrows = Some(
                    value
                        .parse::<u64>()
                        .map_err(|_| Error::input(path, format!("nrows {value:?}")))?,
                )
            }
            "xllcorner" => xll = Some(num(value)?),
            "xllcenter" => (xll, centre) = (Some(num(value)?), true),
            "yllcorner" => yll = Some(num(value)?),
            "yllcenter" => (yll, centre) = (Some(num(value)?), true),
            "cellsize" => cellsize = Some(num(value)?),
            "dx" => dx = Some(num(value)?),
            "dy" => dy = Some(num(value)?),
            "nodata_value" => nodata = Some(num(value)?),
            _ => return Err(Error::input(path, format!("unknown header key {tok:?}"))),
        }
    }
    let (Some(ncols), Some(nrows)) = (ncols, nrows) else {
        return Err(Error::input(path, "header must give ncols and nrows"));
    };
    check_dimensions(ncols, nrows).map_err(|e| Error::input(path, e.to_string()))?;
    if ncols * nrows > bytes.len() as u64 / 2 + 1 {
        return Err(Error::input(
            path,
            format!(
                "header says {ncols} x {nrows} values, but the file is only {} bytes",
                bytes.len()
            ),
        ));
    }
    let count = (ncols * nrows) as usize;
    let mut samples = Vec::with_capacity(count);
    for tok in tokens {
        if samples.len() == count {
            return Err(Error::input(
                path,
                format!("more than the {count} values the header announces"),
            ));
        }
        let v: f64 = tok.parse().map_err(|_| {
            Error::input(
                path,
                format!("value {} ({tok:?}) is not a number", samples.len()),
            )
        })?;
        samples.push(if Some(v) == nodata || v.is_nan() {
            f32::NAN
        } else {
            options.height(v)
        });
    }
    if samples.len() != count {
        return Err(Error::input(
            path,
            format!(
                "truncated: {} values of the {count} the header announces",
                samples.len()
            ),
        ));
    }

    let (sx, sy) = match (cellsize, dx, dy) {
        (Some(c), _, _) => (c, c),
        (None, Some(x), Some(y)) => (x, y),
        _ => {
            return Err(Error::input(
                path,
                "header must give cellsize (or dx and dy)",
            ))
        }
    };
    if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
        return Err(Error::input(
            path,
            format!("cell size {sx} × {sy}: it must be finite and positive"),
        ));
    }
    let mut metadata = Metadata::default();
    if let (Some(x), Some(y)) = (xll, yll) {
        let half = if centre { 0.0 } else { 0.5 };
        metadata.georeference = Some(Georeference {
            crs: None,
            origin: [x + half * sx, y + (nrows as f64 - 1.0 + half) * sy],
            step: [sx, -sy],
        });
    }
    finish(path, ncols as u32, nrows as u32, samples, metadata)
}
