//! The native half of `pyfoc.sweep` (the Python half, in `python/pyfoc/_sweep.py`, hands the
//! runs to an executor and builds the DataFrame): the plan of `pmsm_sim::analysis::sweep`
//! expanded into runs, and one run's flattened metrics with the GIL released.

use pmsm_sim::analysis::sweep::{Cell, Plan, run_toml};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

use crate::errors::ConfigError;
use crate::simulate::scenario_of;

/// A TOML value as a Python object (int, float, str, bool, list, dict).
fn py_of_toml<'py>(py: Python<'py>, v: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    pythonize::pythonize(py, v).map_err(|e| ConfigError::new_err(format!("value {v}: {e}")))
}

/// A cell as a Python object (None, bool, int, float, str).
fn py_of_cell<'py>(py: Python<'py>, c: &Cell) -> PyResult<Bound<'py, PyAny>> {
    Ok(match c {
        Cell::Null => py.None().into_bound(py),
        Cell::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Cell::Int(i) => i.into_pyobject(py)?.into_any(),
        Cell::Float(f) => f.into_pyobject(py)?.into_any(),
        Cell::Text(s) => s.into_pyobject(py)?.into_any(),
    })
}

/// `(paths, runs)`: the varied paths (sorted) and, per run, `(index, values, seed, toml)` with
/// `values` the varied values in the paths' order and `toml` the run's scenario. ConfigError
/// naming the path for a malformed `vary`, the scenario's errors as `pyfoc.simulate`'s.
#[pyfunction]
#[pyo3(name = "_sweep_plan")]
pub(crate) fn sweep_plan<'py>(
    py: Python<'py>,
    scenario: &Bound<'py, PyAny>,
    vary: &Bound<'py, PyDict>,
    n: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyTuple>> {
    let sc = scenario_of(scenario)?;
    let mut items = Vec::with_capacity(vary.len());
    for (k, v) in vary.iter() {
        let path: String = k.extract().map_err(|_| {
            PyTypeError::new_err(format!("vary: keys are dotted paths (str), got {k}"))
        })?;
        crate::convert::nesting_within(&v, 8, &format!("vary[{path:?}]"))?;
        let value: toml::Value = pythonize::depythonize(&v)
            .map_err(|e| ConfigError::new_err(format!("vary.{path}: not a scenario value: {e}")))?;
        items.push((path, value));
    }
    let plan = Plan::new(&sc, &items, n, seed).map_err(ConfigError::new_err)?;
    let runs = py
        .detach(|| plan.runs())
        .map_err(|e| ConfigError::new_err(e.to_string()))?;
    let out = PyList::empty(py);
    for r in &runs {
        let values = PyList::empty(py);
        for (_, v) in &r.values {
            values.append(py_of_toml(py, v)?)?;
        }
        out.append((r.index, values, r.seed, r.toml.as_str()))?;
    }
    (plan.paths(), out).into_pyobject(py)
}

/// One run of a sweep: `(metrics, error)`, `metrics` a list of `(dotted name, value)` (empty
/// after an error), `error` None or why the run could not run. The GIL is released while it
/// runs.
#[pyfunction]
#[pyo3(name = "_sweep_run")]
pub(crate) fn sweep_run<'py>(
    py: Python<'py>,
    index: usize,
    toml: &str,
) -> PyResult<Bound<'py, PyTuple>> {
    let origin = format!("sweep run {index}");
    let result = py.detach(|| run_toml(toml, &origin, None));
    let metrics = PyList::empty(py);
    let error = match result {
        Ok(cells) => {
            for (k, c) in &cells {
                metrics.append((k.as_str(), py_of_cell(py, c)?))?;
            }
            None
        }
        Err(e) => Some(e),
    };
    (metrics, error).into_pyobject(py)
}
