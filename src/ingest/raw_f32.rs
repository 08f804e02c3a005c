//! The `.f32` + `.json` pair of `../shared/data`: raw little-endian `f32`, row-major, row 0
//! north, `NaN` for voids, with a JSON sidecar giving at least `width` and `height`.
//!
//! Given either file, the reader finds the other. It first tries the sidecar's `f32_file`, then
//! the same name with the other extension. The `.f32` length must be exactly
//! `width · height · 4`, checked before reading. `spacing_m` and `units` are taken when present,
//! and so is a `georeference` object of the form `fmrh extract` writes (`crs`, `origin`: the
//! centre of sample (0, 0), `step`); a `georeference` of any other shape (the prose of
//! `../shared/data`'s sidecars) is ignored, so those tiles are placed by a layout.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::{finish, read_limited};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Heightfield, Metadata};

/// Sidecars larger than this are not sidecars.
const MAX_SIDECAR_BYTES: u64 = 16 << 20;

#[derive(Deserialize)]
struct Sidecar {
    width: u64,
    height: u64,
    f32_file: Option<String>,
    spacing_m: Option<[f64; 2]>,
    units: Option<String>,
    georeference: Option<serde_json::Value>,
}

/// The georeference of a sidecar, when it is the machine-readable form.
#[derive(Deserialize)]
struct SidecarGeoreference {
    crs: Option<String>,
    origin: [f64; 2],
    step: [f64; 2],
}

fn with_extension(path: &Path, ext: &str) -> PathBuf {
    path.with_extension(ext)
}

/// The pair's header: the `.f32` file, its size (checked against the sidecar's), and the
/// sidecar's metadata (a south-up georeference not yet turned).
pub(super) struct Pair {
    pub f32_path: PathBuf,
    pub width: u64,
    pub height: u64,
    pub metadata: Metadata,
}

/// Finds and checks the pair, given either file, without reading the samples. `whole`: the
/// grid is to be held whole, so it must be within fmrh's limits on a heightfield; otherwise
/// (a reader of windows) each side may be up to 2^32 - 1 samples.
pub(super) fn open(path: &Path, whole: bool) -> Result<Pair> {
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let json_path = if is_json {
        path.to_path_buf()
    } else {
        with_extension(path, "json")
    };
    if !json_path.exists() {
        return Err(Error::input(
            path,
            format!(
                "raw f32 needs its JSON sidecar (width, height), looked for {}",
                json_path.display()
            ),
        ));
    }
    let text = read_limited(&json_path, MAX_SIDECAR_BYTES)?;
    let sidecar: Sidecar = serde_json::from_slice(&text)
        .map_err(|e| Error::input(&json_path, format!("not a valid sidecar: {e}")))?;
    if whole {
        check_dimensions(sidecar.width, sidecar.height)
            .map_err(|e| Error::input(&json_path, e.to_string()))?;
    }
    if sidecar.width == 0
        || sidecar.height == 0
        || sidecar.width > u64::from(u32::MAX)
        || sidecar.height > u64::from(u32::MAX)
    {
        return Err(Error::input(
            &json_path,
            format!(
                "{} x {} samples: each side must be 1 to {}",
                sidecar.width,
                sidecar.height,
                u32::MAX
            ),
        ));
    }
    let f32_path = if is_json {
        match &sidecar.f32_file {
            Some(name) => json_path.with_file_name(name),
            None => with_extension(path, "f32"),
        }
    } else {
        path.to_path_buf()
    };
    let expected = sidecar.width * sidecar.height * 4;
    let len = std::fs::metadata(&f32_path)
        .map_err(|e| Error::io(&f32_path, e))?
        .len();
    if len != expected {
        return Err(Error::input(
            &f32_path,
            format!(
                "{len} bytes, but {} x {} samples of f32 need {expected}",
                sidecar.width, sidecar.height
            ),
        ));
    }
    let georeference = sidecar
        .georeference
        .and_then(|v| serde_json::from_value::<SidecarGeoreference>(v).ok())
        .map(|g| crate::heightfield::Georeference {
            crs: g.crs,
            origin: g.origin,
            step: g.step,
        });
    Ok(Pair {
        f32_path,
        width: sidecar.width,
        height: sidecar.height,
        metadata: Metadata {
            spacing_m: sidecar.spacing_m,
            units: sidecar.units,
            georeference,
            ..Metadata::default()
        },
    })
}

/// Reads `w × h` samples from column `x0`, row `y0` of an `width`-column `.f32` file, a row
/// at a time.
pub(super) fn read_window(
    file: &mut File,
    f32_path: &Path,
    width: u64,
    (x0, y0, w, h): (u64, u64, u64, u64),
) -> Result<Vec<f32>> {
    use std::io::{Seek, SeekFrom};
    let mut samples = Vec::with_capacity((w * h) as usize);
    let mut row = vec![0u8; (w * 4) as usize];
    for y in y0..y0 + h {
        file.seek(SeekFrom::Start((y * width + x0) * 4))
            .and_then(|_| file.read_exact(&mut row))
            .map_err(|e| Error::io(f32_path, e))?;
        samples.extend(
            row.chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
    }
    Ok(samples)
}

/// Reads the pair, given either file.
pub fn read(path: &Path, options: &super::IngestOptions) -> Result<Heightfield> {
    let pair = open(path, true)?;
    let f32_path = pair.f32_path;
    let len = pair.width * pair.height * 4;
    options
        .limits
        .check_declared(&f32_path, pair.width, pair.height, len)?;
    let mut file = File::open(&f32_path).map_err(|e| Error::io(&f32_path, e))?;
    let count = (pair.width * pair.height) as usize;
    let mut samples = Vec::with_capacity(count);
    let mut chunk = vec![0u8; 1 << 20];
    while samples.len() < count {
        let want = ((count - samples.len()) * 4).min(chunk.len());
        file.read_exact(&mut chunk[..want])
            .map_err(|e| Error::io(&f32_path, e))?;
        samples.extend(
            chunk[..want]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
    }
    finish(
        &f32_path,
        pair.width as u32,
        pair.height as u32,
        samples,
        pair.metadata,
    )
}
