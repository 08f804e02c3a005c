//! USGS ASCII DEM (`.dem`): fixed 1024-byte records of Fortran-formatted fields.
//!
//! One type A record (the header) is followed by one type B record group per *profile*: a
//! column of elevations running south to north. Each profile starts on a record boundary with
//! a 144-byte header (`I6` row and column ids, `I6` count `m` and `1`, then `D24.15` x, y of
//! its first elevation, local datum and min/max). Then come `m` elevations as `I6`, 146 in the
//! first record and 170 in each record after. A height is `datum + raw · z resolution`.
//!
//! Profiles may start and end at different northings: a quadrangle's footprint is not square
//! in UTM. The grid is the bounding box of all profiles at the header's resolution. Cells no
//! profile reaches are voids, and so are elevations of -32767 (the standard's void fill). Fortran
//! `D` exponents are read as `E`. Every field is read by position with bounds checks, so a
//! damaged file is an error, not a panic.

use std::path::Path;

use super::{finish, read_limited, IngestOptions};
use crate::crs::geographic_spacing;
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Georeference, Heightfield, Metadata, MAX_SIDE};

const RECORD: usize = 1024;
const FIRST_RECORD_ELEVATIONS: usize = 146;
const NEXT_RECORD_ELEVATIONS: usize = 170;
const PROFILE_HEADER: usize = 144;
const VOID: i64 = -32767;
/// A grid may have at most this many cells per elevation the profiles hold (at most 3/4 void).
const MAX_BOX_PER_ELEVATION: u64 = 4;

struct Fields<'a> {
    path: &'a Path,
    bytes: &'a [u8],
}

impl Fields<'_> {
    fn text(&self, at: usize, len: usize, what: &str) -> Result<&str> {
        let raw = self.bytes.get(at..at + len).ok_or_else(|| {
            Error::input(
                self.path,
                format!("truncated: {what} at byte {at} is past the end"),
            )
        })?;
        std::str::from_utf8(raw)
            .map(str::trim)
            .map_err(|_| Error::input(self.path, format!("{what} at byte {at} is not text")))
    }

    fn int(&self, at: usize, len: usize, what: &str) -> Result<i64> {
        let t = self.text(at, len, what)?;
        t.parse().map_err(|_| {
            Error::input(
                self.path,
                format!("{what} at byte {at}: {t:?} is not an integer"),
            )
        })
    }

    fn real(&self, at: usize, len: usize, what: &str) -> Result<f64> {
        let t = self.text(at, len, what)?.replace(['D', 'd'], "E");
        t.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                Error::input(
                    self.path,
                    format!("{what} at byte {at}: {t:?} is not a number"),
                )
            })
    }
}

struct Profile {
    offset: usize,
    column: usize,
    count: usize,
    y: f64,
    datum: f64,
}

fn elevation_offset(profile: usize, k: usize) -> usize {
    if k < FIRST_RECORD_ELEVATIONS {
        profile + PROFILE_HEADER + 6 * k
    } else {
        let rest = k - FIRST_RECORD_ELEVATIONS;
        profile + RECORD * (1 + rest / NEXT_RECORD_ELEVATIONS) + 6 * (rest % NEXT_RECORD_ELEVATIONS)
    }
}

/// Reads a USGS ASCII DEM.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    // A profile of MAX_SIDE elevations takes under 7 bytes each; MAX_SIDE of them bound the file.
    let bytes = read_limited(path, (MAX_SIDE * MAX_SIDE).saturating_mul(7))?;
    let f = Fields {
        path,
        bytes: &bytes,
    };
    let planimetric = f.int(156, 6, "planimetric reference system")?;
    let zone = f.int(162, 6, "zone")?;
    let ground_units = f.int(528, 6, "ground units")?;
    let elevation_units = f.int(534, 6, "elevation units")?;
    let res = [
        f.real(816, 12, "x resolution")?,
        f.real(828, 12, "y resolution")?,
        f.real(840, 12, "z resolution")?,
    ];
    let columns = f.int(858, 6, "number of profiles")?;
    if res[0] <= 0.0 || res[1] <= 0.0 || res[2] == 0.0 {
        return Err(Error::input(
            path,
            format!("resolution {res:?} must be positive"),
        ));
    }
    if columns < 1 || columns as u64 > MAX_SIDE {
        return Err(Error::input(path, format!("{columns} profiles")));
    }

    // Pass 1: profile headers, for the grid's extent.
    let mut profiles = Vec::with_capacity(columns as usize);
    let mut offset = RECORD;
    let mut x_first = 0.0;
    for p in 0..columns as usize {
        let column = f.int(offset + 6, 6, "profile column")?;
        let count = f.int(offset + 12, 6, "profile length")?;
        if column < 1 || column > columns || count < 0 || count as u64 > MAX_SIDE {
            return Err(Error::input(
                path,
                format!(
                    "profile {} at byte {offset}: column {column}, length {count}",
                    p + 1
                ),
            ));
        }
        let x = f.real(offset + 24, 24, "profile x")?;
        if p == 0 {
            x_first = x;
        }
        let count = count as usize;
        profiles.push(Profile {
            offset,
            column: column as usize - 1,
            count,
            y: f.real(offset + 48, 24, "profile y")?,
            datum: f.real(offset + 72, 24, "profile datum")?,
        });
        let records = if count <= FIRST_RECORD_ELEVATIONS {
            1
        } else {
            1 + (count - FIRST_RECORD_ELEVATIONS).div_ceil(NEXT_RECORD_ELEVATIONS)
        };
        offset += RECORD * records;
        if offset > bytes.len() {
            return Err(Error::input(
                path,
                format!("truncated inside profile {}", p + 1),
            ));
        }
    }
    let with_data = profiles.iter().filter(|p| p.count > 0);
    let bottom = with_data.clone().map(|p| p.y).fold(f64::INFINITY, f64::min);
    let top = with_data
        .map(|p| p.y + (p.count - 1) as f64 * res[1])
        .fold(f64::NEG_INFINITY, f64::max);
    if top.is_nan() || bottom.is_nan() || top < bottom {
        return Err(Error::input(path, "no profile holds an elevation"));
    }
    let rows_f = ((top - bottom) / res[1]).round() + 1.0;
    if rows_f > MAX_SIDE as f64 {
        return Err(Error::input(path, format!("profiles span {rows_f} rows")));
    }
    let (width, height) = (columns as u64, rows_f as u64);
    check_dimensions(width, height).map_err(|e| Error::input(path, e.to_string()))?;
    options
        .limits
        .check_declared(path, width, height, bytes.len() as u64)?;
    // The grid is the profiles' bounding box, sized from their y values: bound it by what the
    // file holds before allocating it. A quadrangle's profiles fill most of their box (a UTM
    // footprint is a slightly rotated rectangle); a box more than MAX_VOID_SHARE void is a
    // damaged or hostile file, not a DEM.
    let elevations: u64 = profiles.iter().map(|p| p.count as u64).sum();
    let cells = width * height;
    if cells > elevations.max(width).saturating_mul(MAX_BOX_PER_ELEVATION) {
        return Err(Error::input(
            path,
            format!(
                "the profiles' y values span {height} rows × {width} columns ({cells} cells), \
                 but they hold {elevations} elevations: the grid would be more than \
                 {}% void",
                100 - 100 / MAX_BOX_PER_ELEVATION
            ),
        ));
    }

    // Pass 2: elevations into the grid, north row first.
    let mut samples = vec![f32::NAN; (width * height) as usize];
    for p in &profiles {
        let first_row = (top - p.y) / res[1];
        if (first_row - first_row.round()).abs() > 1e-6 {
            return Err(Error::input(
                path,
                format!(
                    "profile {} starts at y {} off the common grid",
                    p.column + 1,
                    p.y
                ),
            ));
        }
        let first_row = first_row.round() as i64;
        for k in 0..p.count {
            let raw = f.int(elevation_offset(p.offset, k), 6, "elevation")?;
            let row = first_row - k as i64;
            if row < 0 || row as u64 >= height {
                return Err(Error::input(
                    path,
                    format!("profile {} leaves the grid", p.column + 1),
                ));
            }
            let i = row as usize * width as usize + p.column;
            samples[i] = if raw == VOID {
                f32::NAN
            } else {
                options.height(p.datum + raw as f64 * res[2])
            };
        }
    }

    // The CRS: UTM zones as their EPSG codes by horizontal datum (record A's element 25 at
    // byte 890, blank in old files, which are NAD27), so `info` can give longitude and
    // latitude; geographic profiles count arc-seconds.
    let datum = f.text(890, 6, "horizontal datum").ok().and_then(|t| {
        if t.is_empty() {
            Some(1)
        } else {
            t.parse::<i64>().ok()
        }
    });
    let (crs, spacing_m) = match (planimetric, ground_units) {
        (1, _) if (1..=60).contains(&zone) => {
            let base = match datum {
                Some(1) => Some(26700),
                Some(3) => Some(32600),
                Some(4) => Some(26900),
                _ => None,
            };
            let metres = match ground_units {
                1 => Some(0.3048),
                2 => Some(1.0),
                _ => None,
            };
            (
                Some(base.map_or(format!("UTM zone {zone}"), |b| format!("EPSG:{}", b + zone))),
                metres.map(|m| [res[0] * m, res[1] * m]),
            )
        }
        (0, 3) => {
            let centre_lat = (top + bottom) / 2.0 / 3600.0;
            (
                Some("geographic (arc-seconds)".to_string()),
                Some(geographic_spacing(
                    [res[0] / 3600.0, res[1] / 3600.0],
                    centre_lat,
                )),
            )
        }
        _ => (None, None),
    };
    let metadata = Metadata {
        spacing_m,
        georeference: Some(Georeference {
            crs,
            origin: [x_first, top],
            step: [res[0], -res[1]],
        }),
        units: match elevation_units {
            1 => Some("feet".into()),
            2 => Some("metres".into()),
            _ => None,
        },
        // The datum is the reader's convention, which `ingest` applies.
        ..Metadata::default()
    };
    finish(path, width as u32, height as u32, samples, metadata)
}
