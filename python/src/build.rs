//! Building from Python: `build` (one container), `dataset_build` and `dataset_add`, with
//! the command line's options given as a dict (`block_size`, `thresholds`, `precision`, …,
//! named as the flags are, `-` as `_`) and a progress callback. The GIL is released while
//! fmrh builds; the callback takes it back for each report it hears.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use pyo3::prelude::*;
use pyo3::types::PyDict;

use fmrh::types::{
    ColorEncoding, Format, IngestOptions, Progress, SeamPolicy, Silent, ThinByArea, Thresholds,
    Unit,
};
use fmrh::{CreateOptions, DatasetBuildOptions};

use crate::{to_py, FmrhError, InvalidArgumentError};

/// The options `fmrh build` takes, as the command line's flags give them.
pub struct ModelOptions {
    ingest: IngestOptions,
    create: CreateOptions,
    spacing_m: Option<[f64; 2]>,
}

/// The names `ModelOptions::from_dict` knows, for the message that names an unknown one.
const OPTION_NAMES: &str = "format, color_encoding, z_scale, z_offset, nodata, tile, \
    max_memory, max_samples_per_byte, vertical_datum, block_size, thresholds, precision, \
    page_size, payloads_alone, no_thin, spacing";

fn bad(name: &str, what: &str, value: &Bound<'_, PyAny>) -> PyErr {
    InvalidArgumentError::new_err(format!("option {name}={value}: expected {what}"))
}

fn float(name: &str, v: &Bound<'_, PyAny>) -> PyResult<f64> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(bad(name, "a number", v));
    }
    v.extract::<f64>().map_err(|_| bad(name, "a number", v))
}

fn text(name: &str, v: &Bound<'_, PyAny>) -> PyResult<String> {
    v.extract::<String>().map_err(|_| bad(name, "a string", v))
}

fn flag(name: &str, v: &Bound<'_, PyAny>) -> PyResult<bool> {
    if !v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(bad(name, "True or False", v));
    }
    v.extract::<bool>()
}

fn whole(name: &str, v: &Bound<'_, PyAny>) -> PyResult<u64> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(bad(name, "a whole number >= 0", v));
    }
    v.extract::<u64>()
        .map_err(|_| bad(name, "a whole number >= 0", v))
}

impl ModelOptions {
    /// The options in `dict` (absent: the command line's defaults); an unknown name or a
    /// value of the wrong kind raises `InvalidArgumentError`.
    pub fn from_dict(dict: Option<&Bound<'_, PyDict>>) -> PyResult<ModelOptions> {
        let mut o = ModelOptions {
            ingest: IngestOptions::default(),
            create: CreateOptions::default(),
            spacing_m: None,
        };
        let Some(dict) = dict else {
            return Ok(o);
        };
        for (k, v) in dict.iter() {
            let name: String = k.extract()?;
            let n = name.as_str();
            if v.is_none() {
                continue;
            }
            match n {
                "format" => {
                    let f = text(n, &v)?;
                    o.ingest.format = Some(Format::from_flag(&f).ok_or_else(|| {
                        let all: Vec<_> = Format::ALL.iter().map(|f| f.flag()).collect();
                        bad(n, &format!("one of {}", all.join(", ")), &v)
                    })?);
                }
                "color_encoding" => {
                    let c = text(n, &v)?;
                    o.ingest.color_encoding = Some(
                        ColorEncoding::from_flag(&c)
                            .ok_or_else(|| bad(n, "terrain-rgb or terrarium", &v))?,
                    );
                }
                "z_scale" => o.ingest.z_scale = float(n, &v)?,
                "z_offset" => o.ingest.z_offset = float(n, &v)?,
                "nodata" => o.ingest.nodata = Some(float(n, &v)?),
                "tile" => o.ingest.tile = Some(text(n, &v)?),
                "max_memory" => o.ingest.limits.max_memory = Some(whole(n, &v)?),
                "max_samples_per_byte" => {
                    o.ingest.limits.max_samples_per_byte = Some(float(n, &v)?)
                }
                "vertical_datum" => {
                    let d = text(n, &v)?;
                    o.ingest.vertical_datum = Some(
                        fmrh::types::VerticalDatum::parse(&d)
                            .map_err(InvalidArgumentError::new_err)?,
                    );
                }
                "block_size" => {
                    o.create.block_size = u32::try_from(whole(n, &v)?)
                        .map_err(|_| bad(n, "2^k + 1 from 9 to 1025", &v))?
                }
                "thresholds" => {
                    let t: Vec<f64> = v.extract().map_err(|_| bad(n, "a list of numbers", &v))?;
                    o.create.thresholds = Thresholds::Explicit(t);
                }
                "precision" => o.create.precision = Some(float(n, &v)?),
                "page_size" => {
                    o.create.page_size = Some(
                        u32::try_from(whole(n, &v)?)
                            .map_err(|_| bad(n, "a power of two from 1024 to 65536", &v))?,
                    )
                }
                "payloads_alone" => o.create.payloads_alone = flag(n, &v)?,
                "no_thin" => {
                    o.create.thin = if flag(n, &v)? {
                        ThinByArea::Off
                    } else {
                        ThinByArea::Auto
                    }
                }
                "spacing" => {
                    let s: Vec<f64> = if let Ok(d) = v.extract::<f64>() {
                        vec![d]
                    } else {
                        v.extract()
                            .map_err(|_| bad(n, "metres DX or (DX, DY)", &v))?
                    };
                    let s = match s.as_slice() {
                        [d] => [*d, *d],
                        [dx, dy] => [*dx, *dy],
                        _ => return Err(bad(n, "metres DX or (DX, DY)", &v)),
                    };
                    if !s.iter().all(|d| d.is_finite() && *d > 0.0) {
                        return Err(bad(n, "finite metres > 0", &v));
                    }
                    o.spacing_m = Some(s);
                }
                other => {
                    return Err(InvalidArgumentError::new_err(format!(
                        "unknown option {other:?}; the options are {OPTION_NAMES}"
                    )))
                }
            }
        }
        Ok(o)
    }

    /// A dataset's options: each tile built with these.
    pub fn dataset(self, seam: Option<SeamPolicy>, tile_size: Option<u32>) -> DatasetBuildOptions {
        DatasetBuildOptions {
            read: self.ingest,
            create: self.create,
            seam,
            spacing_m: self.spacing_m,
            tile_size,
        }
    }
}

/// A Python callable `progress(phase, done, total)` as fmrh's progress listener: called when
/// a phase starts and ends, and between at most ten times a second. An exception it raises
/// is kept and raised when the build returns (the build is not interrupted).
struct Callback {
    callback: Py<PyAny>,
    state: Mutex<Phase>,
    error: Mutex<Option<PyErr>>,
}

struct Phase {
    name: String,
    done: u64,
    total: u64,
    told: Instant,
}

impl Callback {
    fn new(callback: Py<PyAny>) -> Arc<Callback> {
        Arc::new(Callback {
            callback,
            state: Mutex::new(Phase {
                name: String::new(),
                done: 0,
                total: 0,
                told: Instant::now(),
            }),
            error: Mutex::new(None),
        })
    }

    fn tell(&self, name: &str, done: u64, total: u64) {
        let mut error = self.error.lock().unwrap_or_else(|p| p.into_inner());
        if error.is_some() {
            return;
        }
        Python::attach(|py| {
            if let Err(e) = self.callback.call1(py, (name, done, total)) {
                *error = Some(e);
            }
        });
    }

    /// The callback's first exception, if it raised.
    fn raised(&self) -> Option<PyErr> {
        self.error.lock().unwrap_or_else(|p| p.into_inner()).take()
    }
}

impl Progress for Callback {
    fn start(&self, phase: &str, total: u64, _unit: Unit) {
        let (name, total) = {
            let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
            *s = Phase {
                name: phase.to_string(),
                done: 0,
                total,
                told: Instant::now(),
            };
            (s.name.clone(), s.total)
        };
        self.tell(&name, 0, total);
    }

    fn advance(&self, n: u64) {
        let due = {
            let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
            s.done = s.done.saturating_add(n);
            (s.told.elapsed() >= Duration::from_millis(100)).then(|| {
                s.told = Instant::now();
                (s.name.clone(), s.done, s.total)
            })
        };
        if let Some((name, done, total)) = due {
            self.tell(&name, done, total);
        }
    }

    fn finish(&self) {
        let (name, done, total) = {
            let s = self.state.lock().unwrap_or_else(|p| p.into_inner());
            (s.name.clone(), s.done, s.total)
        };
        if !name.is_empty() {
            self.tell(&name, done, total);
        }
    }
}

/// The callback as fmrh's listener, or silence.
fn listener(progress: Option<Py<PyAny>>) -> (Option<Arc<Callback>>, Arc<dyn Progress>) {
    match progress {
        Some(p) => {
            let c = Callback::new(p);
            (Some(c.clone()), c)
        }
        None => (None, Arc::new(Silent)),
    }
}

/// `result` as JSON text, or the callback's exception if it raised.
fn finish<T: serde::Serialize>(
    result: fmrh::Result<T>,
    callback: Option<Arc<Callback>>,
) -> PyResult<String> {
    let value = result.map_err(to_py)?;
    if let Some(e) = callback.and_then(|c| c.raised()) {
        return Err(e);
    }
    serde_json::to_string(&value).map_err(|e| FmrhError::new_err(e.to_string()))
}

/// Builds the container `out` from the DEM `src` (`fmrh build`); returns what was made as
/// JSON text.
#[pyfunction]
#[pyo3(signature = (src, out, options=None, progress=None, overwrite=false))]
pub fn build(
    py: Python<'_>,
    src: PathBuf,
    out: PathBuf,
    options: Option<&Bound<'_, PyDict>>,
    progress: Option<Py<PyAny>>,
    overwrite: bool,
) -> PyResult<String> {
    let mut o = ModelOptions::from_dict(options)?;
    o.create.overwrite = overwrite;
    let (callback, listener) = listener(progress);
    let result = py.detach(move || {
        let mut hf = fmrh::load(&src, &o.ingest)?;
        if let Some(s) = o.spacing_m {
            hf.metadata.spacing_m = Some(s);
        }
        fmrh::create_with_progress(&out, hf, &o.create, listener)
    });
    finish(result, callback)
}

/// Builds the dataset `out` (a new directory) from `tiles`, each `(path, None)` (placed by
/// its georeference) or `(path, (col0, row0))` (every one then); returns the summary as
/// JSON.
#[pyfunction]
#[pyo3(signature = (tiles, out, options=None, seam="strict", tile_size=None, progress=None))]
pub fn dataset_build(
    py: Python<'_>,
    tiles: Vec<(PathBuf, Option<(u64, u64)>)>,
    out: PathBuf,
    options: Option<&Bound<'_, PyDict>>,
    seam: &str,
    tile_size: Option<u32>,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let seam: SeamPolicy = seam.parse().map_err(InvalidArgumentError::new_err)?;
    let options = ModelOptions::from_dict(options)?.dataset(Some(seam), tile_size);
    let (callback, listener) = listener(progress);
    let tell = callback.clone();
    let result = py.detach(move || {
        let mut on_tile = |phase: &str, i: usize, n: usize, _: &std::path::Path| {
            if let Some(c) = &tell {
                c.tell(&format!("{phase} tiles"), i as u64, n as u64);
            }
        };
        fmrh::build_dataset(&tiles, &out, &options, &*listener, &mut on_tile)
    });
    finish(result, callback)
}

/// Adds the tile DEM `src` to the dataset `dir` (`fmrh dataset add`), at `at` or by its
/// georeference, or (`replace`) replaces the tile of its place and size; returns what it
/// did as JSON (`commit`, and `shift`: how far the grid's origin moved).
#[pyfunction]
#[pyo3(signature = (dir, src, at=None, options=None, seam=None, replace=false, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn dataset_add(
    py: Python<'_>,
    dir: PathBuf,
    src: PathBuf,
    at: Option<(u64, u64)>,
    options: Option<&Bound<'_, PyDict>>,
    seam: Option<&str>,
    replace: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let seam: Option<SeamPolicy> = seam
        .map(str::parse)
        .transpose()
        .map_err(InvalidArgumentError::new_err)?;
    let options = ModelOptions::from_dict(options)?.dataset(seam, None);
    let (callback, listener) = listener(progress);
    let result = py.detach(move || fmrh::add_tile(&dir, &src, at, replace, &options, &*listener));
    finish(result, callback)
}
