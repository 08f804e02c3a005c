//! `fmrh._fmrh`: the Python extension behind the `fmrh` package (`python/fmrh/__init__.py`).
//! It holds no algorithm: each method is a call into the fmrh crate's public API (the door,
//! `fmrh::Terrain`), with the GIL released while fmrh reads and decodes, samples handed to
//! numpy without a copy, and fmrh's errors turned into exception classes that keep the
//! CLI's messages (and a corrupt file's invariant).

mod build;
mod distributed;
mod edit;
mod flight;

use std::sync::{Arc, RwLock};

use numpy::{PyArray1, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use fmrh::types::SampleRect;

create_exception!(_fmrh, FmrhError, PyException, "Any error fmrh reports.");
create_exception!(
    _fmrh,
    CorruptError,
    FmrhError,
    "A file breaks one of the format's numbered invariants (`invariant`, e.g. `I-9`)."
);
create_exception!(
    _fmrh,
    BusyError,
    FmrhError,
    "A writer changed the terrain while it was read: read again (the CLI's exit 75)."
);
create_exception!(
    _fmrh,
    InputError,
    FmrhError,
    "An input that is not what it claims, uses an unsupported feature, or is too large."
);
create_exception!(
    _fmrh,
    IoError,
    FmrhError,
    "Reading or writing failed (disk or network)."
);
create_exception!(
    _fmrh,
    InvalidArgumentError,
    FmrhError,
    "An argument fmrh cannot use (a window outside the data, a bad option)."
);

/// fmrh's error as a Python exception of its class, with the same message as the CLI's.
fn to_py(e: fmrh::Error) -> PyErr {
    let message = e.to_string();
    match &e {
        fmrh::Error::Corrupt { invariant, .. } => {
            let err = CorruptError::new_err(message);
            let id = invariant.id();
            Python::attach(|py| {
                let _ = err.value(py).setattr("invariant", id);
            });
            err
        }
        fmrh::Error::Superseded { .. } | fmrh::Error::Changed { .. } => BusyError::new_err(message),
        fmrh::Error::Input { .. }
        | fmrh::Error::Unsupported { .. }
        | fmrh::Error::TooLarge { .. } => InputError::new_err(message),
        fmrh::Error::Io { .. } | fmrh::Error::Poisoned { .. } => IoError::new_err(message),
        fmrh::Error::InvalidArgument(_) => InvalidArgumentError::new_err(message),
        _ => FmrhError::new_err(message),
    }
}

/// `(x, y, z)`.
type Point = (f64, f64, f64);

/// A camera on the globe: latitude, longitude, height, heading, pitch.
type GeoPose = (f64, f64, f64, f64, f64);

/// An open container or dataset.
#[pyclass(module = "fmrh._fmrh", frozen)]
struct Terrain {
    inner: RwLock<Option<Arc<fmrh::Terrain>>>,
    info: fmrh::Info,
    location: String,
}

impl Terrain {
    /// The window `(col_off, row_off, width, height)` as fmrh's inclusive rectangle, checked
    /// against the data (`None`: all of it).
    fn rect(&self, window: Option<(i64, i64, i64, i64)>) -> PyResult<Option<SampleRect>> {
        let Some((c, r, w, h)) = window else {
            return Ok(None);
        };
        if c < 0 || r < 0 || w <= 0 || h <= 0 {
            return Err(InvalidArgumentError::new_err(format!(
                "window ({c}, {r}, {w}, {h}): offsets must be >= 0 and sizes > 0"
            )));
        }
        let (c, r, w, h) = (c as u64, r as u64, w as u64, h as u64);
        if c + w > self.info.width || r + h > self.info.height {
            return Err(InvalidArgumentError::new_err(format!(
                "window ({c}, {r}, {w}, {h}) is outside the data ({} x {} samples)",
                self.info.width, self.info.height
            )));
        }
        Ok(Some(SampleRect {
            col0: c,
            row0: r,
            col1: c + w - 1,
            row1: r + h - 1,
        }))
    }

    /// A flight along `cameras` at `tau` in `mode`, flat or (`globe`) on the globe.
    fn flight(
        &self,
        cameras: Vec<fmrh::Camera>,
        tau: f64,
        mode: &str,
        globe: bool,
    ) -> PyResult<flight::Flight> {
        let options = scene_options(tau, mode)?;
        Ok(flight::Flight::start(
            self.terrain()?,
            cameras,
            options,
            globe,
        ))
    }

    fn terrain(&self) -> PyResult<Arc<fmrh::Terrain>> {
        let inner = self.inner.read().unwrap_or_else(|p| p.into_inner());
        inner
            .clone()
            .ok_or_else(|| FmrhError::new_err(format!("{}: the terrain is closed", self.location)))
    }
}

#[pymethods]
impl Terrain {
    /// `(height, width)`: rows and columns of samples.
    #[getter]
    fn shape(&self) -> (u64, u64) {
        (self.info.height, self.info.width)
    }

    /// The georeference as `(origin_x, origin_y, step_x, step_y, crs)`: sample (0, 0)'s
    /// centre and the steps east and south (`None` when the data has none).
    #[getter]
    fn georeference(&self) -> Option<(f64, f64, f64, f64, Option<String>)> {
        self.info.georeference.as_ref().map(|g| {
            (
                g.origin[0],
                g.origin[1],
                g.step[0],
                g.step[1],
                g.crs.clone(),
            )
        })
    }

    /// What the heights are above: `egm96`, `egm2008`, `ellipsoid` or `unknown`.
    #[getter]
    fn vertical_datum(&self) -> &'static str {
        self.info.vertical_datum.name()
    }

    /// The terrain's description (`fmrh::Info`) as JSON text.
    fn info_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.info).map_err(|e| FmrhError::new_err(e.to_string()))
    }

    /// The samples of the window `(col_off, row_off, width, height)` (or all) as a float32
    /// array of shape `(height, width)`, voids NaN, exactly as stored. The GIL is released
    /// while fmrh reads and decodes.
    #[pyo3(signature = (window=None))]
    fn read<'py>(
        &self,
        py: Python<'py>,
        window: Option<(i64, i64, i64, i64)>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let terrain = self.terrain()?;
        let rect = self.rect(window)?;
        let field = py.detach(move || terrain.read(rect)).map_err(to_py)?;
        array(py, field)
    }

    /// The surface over the window drawn by the coarsest error level within `max_error`
    /// (`fmrh::Terrain::read_within`), as `(heights, max_error, stride)`: `heights` at
    /// every sample of the window, or (`own`) every `stride`-th sample from its first, the
    /// level's own resolution; `max_error` the largest measured error of the blocks drawn.
    #[pyo3(signature = (window, max_error, own=false))]
    fn read_within<'py>(
        &self,
        py: Python<'py>,
        window: Option<(i64, i64, i64, i64)>,
        max_error: f64,
        own: bool,
    ) -> PyResult<(Bound<'py, PyAny>, f64, u64)> {
        let terrain = self.terrain()?;
        let rect = self.rect(window)?;
        let (field, error, stride) = py
            .detach(move || {
                let a = terrain.read_within(rect, max_error)?;
                let field = if own {
                    a.at_stride()?.heights
                } else {
                    a.heights
                };
                Ok::<_, fmrh::Error>((field, a.max_error, a.stride))
            })
            .map_err(to_py)?;
        Ok((array(py, field)?, error, stride))
    }

    /// The blocks a camera at `eye` looking at `target` needs at `tau` pixels of error, each
    /// a dict (its `rect` as `(col0, row0, col1, row1)` inclusive samples, `level`, `tile`,
    /// `error` (measured, height units), `screen_error` (pixels), `stride`, `spacing_m`,
    /// `width`, `height`, `heights` (float32 `(height, width)`, copied from fmrh's decoded
    /// grid). The GIL is released while fmrh selects, reads and decodes.
    #[pyo3(signature = (eye, target, tau=1.0, fov=None, viewport=None, mode="view"))]
    #[allow(clippy::too_many_arguments)]
    fn scene<'py>(
        &self,
        py: Python<'py>,
        eye: (f64, f64, f64),
        target: (f64, f64, f64),
        tau: f64,
        fov: Option<f64>,
        viewport: Option<(u32, u32)>,
        mode: &str,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let terrain = self.terrain()?;
        let camera = camera(eye, target, fov, viewport);
        let options = scene_options(tau, mode)?;
        let scene = py
            .detach(move || terrain.scene(&camera, &options))
            .map_err(to_py)?;
        scene.blocks.iter().map(|b| block_dict(py, b)).collect()
    }

    /// The blocks a camera on the globe needs (`fmrh scene --eye-geo`): at latitude and
    /// longitude `lat`, `lon` (degrees), `height` metres above the WGS 84 ellipsoid,
    /// looking along `heading` (degrees clockwise from north) and `pitch` (degrees above the
    /// horizontal); the data must be geographic. Blocks as `scene` gives them.
    #[pyo3(signature = (lat, lon, height, heading, pitch, tau=1.0, fov=None, viewport=None, mode="view"))]
    #[allow(clippy::too_many_arguments)]
    fn scene_geo<'py>(
        &self,
        py: Python<'py>,
        lat: f64,
        lon: f64,
        height: f64,
        heading: f64,
        pitch: f64,
        tau: f64,
        fov: Option<f64>,
        viewport: Option<(u32, u32)>,
        mode: &str,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let terrain = self.terrain()?;
        let camera = geo_camera((lat, lon, height, heading, pitch), fov, viewport);
        let options = scene_options(tau, mode)?;
        let scene = py
            .detach(move || terrain.scene_on_globe(&camera, &options))
            .map_err(to_py)?;
        scene.blocks.iter().map(|b| block_dict(py, b)).collect()
    }

    /// A flight along `cameras` (each `(eye, target)`), run ahead on a thread of its own
    /// one frame at a time: an iterator of frames (`flight::Flight`).
    #[pyo3(signature = (cameras, tau=1.0, fov=None, viewport=None, mode="view"))]
    fn fly(
        &self,
        cameras: Vec<(Point, Point)>,
        tau: f64,
        fov: Option<f64>,
        viewport: Option<(u32, u32)>,
        mode: &str,
    ) -> PyResult<flight::Flight> {
        let cameras = cameras
            .into_iter()
            .map(|(eye, target)| camera(eye, target, fov, viewport))
            .collect();
        self.flight(cameras, tau, mode, false)
    }

    /// A flight of cameras on the globe (each `(lat, lon, height, heading, pitch)`, as
    /// `scene_geo` takes one).
    #[pyo3(signature = (cameras, tau=1.0, fov=None, viewport=None, mode="view"))]
    fn fly_geo(
        &self,
        cameras: Vec<GeoPose>,
        tau: f64,
        fov: Option<f64>,
        viewport: Option<(u32, u32)>,
        mode: &str,
    ) -> PyResult<flight::Flight> {
        let cameras = cameras
            .into_iter()
            .map(|pose| geo_camera(pose, fov, viewport))
            .collect();
        self.flight(cameras, tau, mode, true)
    }

    /// Checks every numbered invariant (`full`: also recomputes every error and cut) and
    /// returns the report as JSON text: a failed check is in the report, not raised.
    #[pyo3(signature = (full=false))]
    fn verify_json(&self, py: Python<'_>, full: bool) -> PyResult<String> {
        let terrain = self.terrain()?;
        let mode = if full {
            fmrh::types::VerifyMode::Full
        } else {
            fmrh::types::VerifyMode::Fast
        };
        let report = py.detach(move || terrain.verify(mode)).map_err(to_py)?;
        let json = match &report {
            fmrh::Verification::Container(r) => serde_json::to_string(r),
            fmrh::Verification::Dataset(r) => serde_json::to_string(r),
        };
        json.map_err(|e| FmrhError::new_err(e.to_string()))
    }

    /// Starts an edit of this terrain's file or dataset (a local one); while a container's
    /// edit lives, it holds the file's writer lock.
    fn edit(&self, py: Python<'_>) -> PyResult<edit::Edit> {
        let terrain = self.terrain()?;
        let e = py.detach(move || terrain.edit()).map_err(to_py)?;
        Ok(edit::Edit::new(e, self.location.clone()))
    }

    /// Closes the terrain: a later use raises. Reads already running finish.
    fn close(&self) {
        let mut inner = self.inner.write().unwrap_or_else(|p| p.into_inner());
        *inner = None;
    }

    /// Whether `close` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.inner
            .read()
            .unwrap_or_else(|p| p.into_inner())
            .is_none()
    }

    /// Where it was opened from.
    #[getter]
    fn location(&self) -> &str {
        &self.location
    }
}

/// A camera at `eye` looking at `target`, with its field of view and viewport if given.
fn camera(
    eye: (f64, f64, f64),
    target: (f64, f64, f64),
    fov: Option<f64>,
    viewport: Option<(u32, u32)>,
) -> fmrh::Camera {
    let camera = fmrh::Camera::looking_at(
        fmrh::glam::DVec3::new(eye.0, eye.1, eye.2),
        fmrh::glam::DVec3::new(target.0, target.1, target.2),
    );
    with_view(camera, fov, viewport)
}

/// `camera` with its field of view and viewport, where given.
fn with_view(
    mut camera: fmrh::Camera,
    fov: Option<f64>,
    viewport: Option<(u32, u32)>,
) -> fmrh::Camera {
    if let Some(f) = fov {
        camera.fov_y_deg = f;
    }
    if let Some((w, h)) = viewport {
        camera.viewport = [w, h];
    }
    camera
}

/// A camera on the globe at `pose`, with its field of view and viewport if given.
fn geo_camera(
    (lat, lon, height, heading, pitch): GeoPose,
    fov: Option<f64>,
    viewport: Option<(u32, u32)>,
) -> fmrh::Camera {
    with_view(
        fmrh::Camera::on_globe(lat, lon, height, heading, pitch),
        fov,
        viewport,
    )
}

/// Scene options at `tau` in `mode` (`view` or `uniform`).
fn scene_options(tau: f64, mode: &str) -> PyResult<fmrh::SceneOptions> {
    let mut options = fmrh::SceneOptions::new(tau);
    options.mode = match mode {
        "view" => fmrh::types::Mode::View,
        "uniform" => fmrh::types::Mode::Uniform,
        other => {
            return Err(InvalidArgumentError::new_err(format!(
                "mode `{other}`: expected view or uniform"
            )))
        }
    };
    Ok(options)
}

/// A decoded block as a dict: `rect` (`(col0, row0, col1, row1)`, inclusive), `level`,
/// `tile`, `error`, `screen_error`, `stride`, `spacing_m`, `width`, `height`, `heights`.
fn block_dict<'py>(py: Python<'py>, b: &fmrh::Block) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("rect", (b.rect.col0, b.rect.row0, b.rect.col1, b.rect.row1))?;
    d.set_item("level", b.level)?;
    d.set_item("tile", b.tile)?;
    d.set_item("error", b.error)?;
    d.set_item("screen_error", b.screen_error)?;
    d.set_item("stride", b.stride)?;
    d.set_item("spacing_m", b.spacing_m.map(|[x, y]| (x, y)))?;
    d.set_item("width", b.width)?;
    d.set_item("height", b.height)?;
    let heights =
        PyArray1::from_slice(py, &b.heights).reshape([b.height as usize, b.width as usize])?;
    d.set_item("heights", heights)?;
    Ok(d)
}

/// A heightfield's samples as a float32 array of shape `(height, width)`, without a copy
/// (the samples' buffer becomes the array's).
fn array(py: Python<'_>, field: fmrh::Heightfield) -> PyResult<Bound<'_, PyAny>> {
    let (w, h) = (field.width() as usize, field.height() as usize);
    let flat = PyArray1::from_vec(py, field.into_samples());
    Ok(flat.reshape([h, w])?.into_any())
}

/// Opens a container file, a dataset directory, or either by `http(s)://` or `s3://` URL.
#[pyfunction]
fn open(py: Python<'_>, location: std::path::PathBuf) -> PyResult<Terrain> {
    let shown = location.display().to_string();
    let (terrain, info) = py
        .detach(move || {
            let t = fmrh::Terrain::open(&location)?;
            let info = t.info()?;
            Ok::<_, fmrh::Error>((t, info))
        })
        .map_err(to_py)?;
    Ok(Terrain {
        inner: RwLock::new(Some(Arc::new(terrain))),
        info,
        location: shown,
    })
}

/// The crate's format version, `(major, minor)`.
#[pyfunction]
fn format_version() -> (u16, u16) {
    (fmrh::raw::FORMAT_MAJOR, fmrh::raw::FORMAT_MINOR)
}

#[pymodule]
fn _fmrh(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_function(wrap_pyfunction!(open, m)?)?;
    m.add_function(wrap_pyfunction!(format_version, m)?)?;
    m.add_function(wrap_pyfunction!(build::build, m)?)?;
    m.add_function(wrap_pyfunction!(build::dataset_build, m)?)?;
    m.add_function(wrap_pyfunction!(build::dataset_add, m)?)?;
    for f in [
        wrap_pyfunction!(distributed::scan, m)?,
        wrap_pyfunction!(distributed::plan, m)?,
        wrap_pyfunction!(distributed::build_tile, m)?,
        wrap_pyfunction!(distributed::publish, m)?,
        wrap_pyfunction!(distributed::tile_files, m)?,
    ] {
        m.add_function(f)?;
    }
    m.add_class::<Terrain>()?;
    m.add_class::<edit::Edit>()?;
    m.add_class::<flight::Flight>()?;
    // Each exception names `fmrh` as its module, where the package exports it: so it
    // pickles by reference (a Dask worker's error arrives as the same class) and prints as
    // `fmrh.CorruptError`.
    for (name, class) in [
        ("FmrhError", py.get_type::<FmrhError>()),
        ("CorruptError", py.get_type::<CorruptError>()),
        ("BusyError", py.get_type::<BusyError>()),
        ("InputError", py.get_type::<InputError>()),
        ("IoError", py.get_type::<IoError>()),
        (
            "InvalidArgumentError",
            py.get_type::<InvalidArgumentError>(),
        ),
    ] {
        class.setattr("__module__", "fmrh")?;
        m.add(name, class)?;
    }
    Ok(())
}
