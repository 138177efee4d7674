//! The output arrays of `run`: a caller's `out` dict, checked, or fresh arrays.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::observer::OUTPUTS;

/// `run`'s output arrays: the [`OUTPUTS`] columns and the status codes.
pub(crate) type OutArrays<'py> = (
    [Bound<'py, PyArray1<f64>>; OUTPUTS.len()],
    Bound<'py, PyArray1<i8>>,
);

/// `run`'s outputs: a caller's arrays (and their dict), or fresh ones (the float columns as
/// the rows of one array, and the status codes; `true` when taken from the [`pool`], whose
/// arrays may be longer than the run: their first `N` values are the output).
pub(super) enum Outs<'py> {
    /// A caller's arrays and their dict.
    Given(OutArrays<'py>, Bound<'py, PyDict>),
    /// Fresh arrays: the float columns as rows, the status codes, reused from the pool.
    Fresh(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<i8>>, bool),
}

/// The output arrays of `run` in a caller's `out` dict, checked: each present, of its dtype,
/// one-dimensional of length `n`, C-contiguous, writable, and no two overlapping (all of
/// them are borrowed for writing at once here, which rust-numpy refuses for overlapping
/// arrays and for read-only ones).
pub(crate) fn out_arrays<'py>(d: &Bound<'py, PyDict>, n: usize) -> PyResult<OutArrays<'py>> {
    fn get<'py, T: numpy::Element>(
        d: &Bound<'py, PyDict>,
        name: &str,
        dtype: &str,
        n: usize,
    ) -> PyResult<Bound<'py, PyArray1<T>>> {
        let item = d
            .get_item(name)?
            .ok_or_else(|| PyValueError::new_err(format!("out has no array {name:?}")))?;
        let a = item.cast_into::<PyArray1<T>>().map_err(|_| {
            PyValueError::new_err(format!(
                "out[{name:?}] must be a one-dimensional {dtype} numpy array"
            ))
        })?;
        if a.len() != n {
            return Err(PyValueError::new_err(format!(
                "out[{name:?}] must have length {n} (the rows of u_ab), got {}",
                a.len()
            )));
        }
        if !a.is_c_contiguous() {
            return Err(PyValueError::new_err(format!(
                "out[{name:?}] must be C-contiguous"
            )));
        }
        Ok(a)
    }
    let mut values = Vec::with_capacity(OUTPUTS.len());
    for name in OUTPUTS {
        values.push(get::<f64>(d, name, "float64", n)?);
    }
    let status = get::<i8>(d, "status", "int8", n)?;
    let values: [Bound<'py, PyArray1<f64>>; OUTPUTS.len()] = values
        .try_into()
        .map_err(|_| PyValueError::new_err("out: internal count of arrays"))?;
    {
        let mut borrows = Vec::with_capacity(OUTPUTS.len());
        for (name, a) in OUTPUTS.iter().zip(&values) {
            borrows.push(a.try_readwrite().map_err(|e| {
                PyValueError::new_err(format!(
                    "out[{name:?}] cannot be written ({e}): read-only, or overlapping another output or an input"
                ))
            })?);
        }
        status.try_readwrite().map_err(|e| {
            PyValueError::new_err(format!(
                "out[\"status\"] cannot be written ({e}): read-only, or overlapping another output or an input"
            ))
        })?;
    }
    Ok((values, status))
}
