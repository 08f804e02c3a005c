//! Editing from Python: an `Edit` collects replacements (`replace`), then `commit` writes
//! them all in one transaction or `rollback` drops them; nothing is written before the
//! commit. The Python wrapper makes it a context manager (commit on a clean exit, rollback
//! on an exception).

use std::sync::Mutex;

use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::{to_py, FmrhError, InvalidArgumentError};

/// An edit in progress (`Terrain.edit()`).
#[pyclass(module = "fmrh._fmrh", frozen)]
pub struct Edit {
    inner: Mutex<Option<fmrh::Edit>>,
    location: String,
}

impl Edit {
    pub fn new(edit: fmrh::Edit, location: String) -> Edit {
        Edit {
            inner: Mutex::new(Some(edit)),
            location,
        }
    }

    fn take(&self) -> PyResult<fmrh::Edit> {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .ok_or_else(|| self.ended())
    }

    fn ended(&self) -> PyErr {
        FmrhError::new_err(format!(
            "{}: the edit has ended (committed or rolled back)",
            self.location
        ))
    }
}

#[pymethods]
impl Edit {
    /// Replaces samples with `heights` (a 2-D float32 array; NaN makes a void), its
    /// north-west sample at column `col`, row `row`. Nothing is written until `commit`.
    fn replace(&self, col: i64, row: i64, heights: &Bound<'_, PyAny>) -> PyResult<()> {
        if col < 0 || row < 0 {
            return Err(InvalidArgumentError::new_err(format!(
                "replace at column {col}, row {row}: the place must be >= 0"
            )));
        }
        let array: PyReadonlyArray2<'_, f32> = heights.extract().map_err(|_| {
            InvalidArgumentError::new_err(
                "replace: heights must be a 2-D numpy array of float32 (rows, columns)",
            )
        })?;
        let shape = array.shape();
        let (h, w) = (shape[0], shape[1]);
        let (Ok(w32), Ok(h32)) = (u32::try_from(w), u32::try_from(h)) else {
            return Err(InvalidArgumentError::new_err(format!(
                "replace: a {h} x {w} patch is too large"
            )));
        };
        if w == 0 || h == 0 {
            return Err(InvalidArgumentError::new_err(format!(
                "replace: a {h} x {w} patch holds no sample"
            )));
        }
        let samples: Vec<f32> = match array.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => array.as_array().iter().copied().collect(),
        };
        let patch = fmrh::Heightfield::new(w32, h32, samples).map_err(to_py)?;
        let mut inner = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        let edit = inner.as_mut().ok_or_else(|| self.ended())?;
        edit.replace(col as u64, row as u64, patch).map_err(to_py)
    }

    /// Writes every replacement in one commit and returns what it did as JSON text
    /// (`txn_id`, `files`, `blocks`, `grids`). The GIL is released while fmrh writes.
    fn commit(&self, py: Python<'_>) -> PyResult<String> {
        let edit = self.take()?;
        let committed = py.detach(move || edit.commit()).map_err(to_py)?;
        serde_json::to_string(&committed).map_err(|e| FmrhError::new_err(e.to_string()))
    }

    /// Drops every replacement: nothing was written, and nothing is.
    fn rollback(&self) -> PyResult<()> {
        drop(self.take()?);
        Ok(())
    }

    /// Whether it was committed or rolled back.
    #[getter]
    fn ended_(&self) -> bool {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .is_none()
    }
}
