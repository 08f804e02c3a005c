//! ESRI ASCII grid (`.asc`): a short `key value` header, then `nrows` rows of `ncols` numbers,
//! north row first.
//!
//! Header keys (any case, any order): `ncols`, `nrows`, `xllcorner` or `xllcenter`,
//! `yllcorner` or `yllcenter`, `cellsize` (or `dx` and `dy`), and an optional `NODATA_value`. A
//! value equal to `NODATA_value` is a void. The header's size is checked against the file before
//! allocating: every value needs at least two bytes (a digit and a separator).
//!
//! The grid's CRS comes from a `.prj` beside it (same name), as GDAL reads it: WKT, or the
//! older ESRI `Projection` / `Units` / `Zone` / `Datum` lines. Without one, the CRS and so the
//! ground spacing are unknown: the cell size alone does not say metres, feet or degrees.

use std::path::Path;

use super::{finish, read_limited, IngestOptions};
use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::format::MAX_STRING_LEN;
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
    options
        .limits
        .check_declared(path, ncols, nrows, bytes.len() as u64)?;
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
    let prj = read_prj(path)?;
    if let (Some(x), Some(y)) = (xll, yll) {
        let half = if centre { 0.0 } else { 0.5 };
        let origin = [x + half * sx, y + (nrows as f64 - 1.0 + half) * sy];
        if let Some((_, crs)) = &prj {
            let centre_lat = origin[1] - sy * (nrows as f64 - 1.0) / 2.0;
            metadata.spacing_m = crs.spacing([sx, sy], centre_lat);
        }
        metadata.georeference = Some(Georeference {
            crs: prj.map(|(name, _)| name),
            origin,
            step: [sx, -sy],
        });
    }
    finish(path, ncols as u32, nrows as u32, samples, metadata)
}

/// The CRS of the `.prj` beside `path`, if there is one: the name to record (`EPSG:n`, or the
/// WKT itself) and what it says. A `.prj` that is there but says nothing fmrh can read is an
/// error, not a silent fallback.
fn read_prj(path: &Path) -> Result<Option<(String, Crs)>> {
    let Some(prj) = ["prj", "PRJ"]
        .iter()
        .map(|ext| path.with_extension(ext))
        .find(|p| p.is_file())
    else {
        return Ok(None);
    };
    let bytes = read_limited(&prj, 64 * 1024)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|_| Error::input(&prj, "not a text file"))?
        .trim()
        .trim_start_matches('\u{feff}');
    let crs = if text.contains('[') {
        Crs::from_wkt(text).map_err(|e| Error::input(&prj, e))?
    } else {
        esri_prj(text).ok_or_else(|| {
            Error::input(
                &prj,
                "neither WKT nor ESRI Projection/Units lines fmrh understands",
            )
        })?
    };
    let name = match crs.epsg {
        Some(code) => format!("EPSG:{code}"),
        None if text.len() <= MAX_STRING_LEN as usize => text.to_string(),
        None => {
            return Err(Error::input(
                &prj,
                format!("WKT of {} bytes; at most {MAX_STRING_LEN}", text.len()),
            ))
        }
    };
    Ok(Some((name, crs)))
}

/// The older ESRI `.prj`: `Projection GEOGRAPHIC` or `Projection UTM` with `Zone`, `Datum`,
/// `Units` lines (as ArcInfo wrote them).
fn esri_prj(text: &str) -> Option<Crs> {
    let field = |key: &str| {
        text.lines().find_map(|l| {
            let mut it = l.split_whitespace();
            it.next()
                .filter(|k| k.eq_ignore_ascii_case(key))
                .and(it.next())
                .map(str::to_ascii_uppercase)
        })
    };
    let units = field("Units");
    match field("Projection")?.as_str() {
        "GEOGRAPHIC" => matches!(units.as_deref(), None | Some("DD"))
            .then(|| Crs::from_epsg(4326))
            .flatten(),
        "UTM" => {
            let zone: i32 = field("Zone")?.parse().ok()?;
            let base = match field("Datum").as_deref() {
                Some("NAD27") => 26700,
                Some("NAD83") => 26900,
                Some("WGS84") if zone > 0 => 32600,
                Some("WGS84") => 32700,
                _ => return None,
            };
            let crs = Crs::from_epsg(base + zone.unsigned_abs())?;
            match units.as_deref() {
                None | Some("METERS") => Some(crs),
                _ => None,
            }
        }
        _ => None,
    }
}
