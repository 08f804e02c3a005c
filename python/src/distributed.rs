//! A dataset built on many machines, from Python (`fmrh/dask.py` schedules it): the door's
//! `fmrh::distributed` phases, each one call whose arguments and results are bytes and JSON
//! text, so that a scheduler can ship them between processes. The GIL is released while
//! fmrh reads, builds and writes.

use std::collections::HashMap;
use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use fmrh::distributed::{self, Plan, TileScan};
use fmrh::types::{SeamPolicy, Silent};

use crate::build::ModelOptions;
use crate::{to_py, InvalidArgumentError};

/// Reads the DEM at `path` once: `(scan, description)` as bytes, the description (no
/// border lines, a few hundred bytes) being what the planner needs.
#[pyfunction(name = "distributed_scan")]
#[pyo3(signature = (path, options=None))]
pub fn scan<'py>(
    py: Python<'py>,
    path: PathBuf,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>)> {
    let options = ModelOptions::from_dict(options)?.dataset(None, None);
    let scan = py
        .detach(move || distributed::scan_tile(&path, &options))
        .map_err(to_py)?;
    Ok((
        PyBytes::new(py, &scan.to_bytes()),
        PyBytes::new(py, &scan.description().to_bytes()),
    ))
}

/// A DEM to plan: its path, its place from a layout or `None`, its description's bytes.
type Described = (PathBuf, Option<(u64, u64)>, Vec<u8>);

/// Plans the dataset of `tiles` (`(path, (col0, row0) or None, description)`), naming no
/// file as one of `taken`; returns the plan as JSON text.
#[pyfunction(name = "distributed_plan")]
#[pyo3(signature = (tiles, options=None, seam="strict", taken=Vec::new()))]
pub fn plan(
    py: Python<'_>,
    tiles: Vec<Described>,
    options: Option<&Bound<'_, PyDict>>,
    seam: &str,
    taken: Vec<String>,
) -> PyResult<String> {
    let seam: SeamPolicy = seam.parse().map_err(InvalidArgumentError::new_err)?;
    let options = ModelOptions::from_dict(options)?.dataset(Some(seam), None);
    py.detach(move || {
        let planned = tiles
            .into_iter()
            .map(|(p, at, d)| Ok((p, at, TileScan::from_bytes(&d)?)))
            .collect::<fmrh::Result<Vec<_>>>()?;
        Ok(distributed::plan_dataset(&planned, &options, &taken)?.to_json())
    })
    .map_err(to_py)
}

/// Builds tile `index` of the plan (JSON text) from the DEM `path` into the file `out`,
/// given the scans (bytes) of it and its neighbours by index; returns `{"file_length",
/// "seam_samples_changed"}` as JSON text.
#[pyfunction(name = "distributed_build_tile")]
#[pyo3(signature = (plan, index, path, scans, out, options=None))]
pub fn build_tile(
    py: Python<'_>,
    plan: String,
    index: usize,
    path: PathBuf,
    scans: HashMap<usize, Vec<u8>>,
    out: PathBuf,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let options = ModelOptions::from_dict(options)?.dataset(None, None);
    py.detach(move || {
        let plan = Plan::from_json(&plan)?;
        let scans = scans
            .into_iter()
            .map(|(i, b)| Ok((i, TileScan::from_bytes(&b)?)))
            .collect::<fmrh::Result<Vec<_>>>()?;
        let file =
            distributed::build_planned_tile(&plan, index, &path, &scans, &options, &out, &Silent)?;
        Ok(serde_json::json!({
            "file_length": file.file_length,
            "seam_samples_changed": file.seam_samples_changed,
        })
        .to_string())
    })
    .map_err(to_py)
}

/// Publishes the plan's tiles, built under `tiles` (a directory or a URL ending in `/`),
/// by writing the manifest at `manifest`: new, or (`replace`) the next state of the one
/// there. Returns `{"manifest_bytes", "txn_id", "superseded"}` as JSON text.
#[pyfunction(name = "distributed_publish")]
pub fn publish(
    py: Python<'_>,
    plan: String,
    tiles: PathBuf,
    manifest: PathBuf,
    replace: bool,
) -> PyResult<String> {
    py.detach(move || {
        let plan = Plan::from_json(&plan)?;
        let p = distributed::publish_dataset(&plan, &tiles, &manifest, replace)?;
        Ok(serde_json::json!({
            "manifest_bytes": p.manifest_bytes,
            "txn_id": p.txn_id,
            "superseded": p.superseded,
        })
        .to_string())
    })
    .map_err(to_py)
}

/// The tile files a dataset's manifest names (none for a container).
#[pyfunction]
pub fn tile_files(py: Python<'_>, location: PathBuf) -> PyResult<Vec<String>> {
    py.detach(move || fmrh::Terrain::open(&location)?.tile_files())
        .map_err(to_py)
}
