//! `pyfoc.suite`: the scenario suite of `pmsm-sim` (`pmsm_sim::suite`), as a dict.

use pmsm_sim::suite::{SuiteOptions, run_suite};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{PyfocError, SimulationError};

/// Runs the observer suite: the five reference motors (three surface, two interior) at
/// 10/50/100 % rated speed, a rated load step and starts from unknown angles, with the seed's
/// filter, the flux + PLL baseline and the default EKF side by side (the same as
/// `pmsm-sim suite`).
///
/// Returns the report as a dict (the JSON layout of `pmsm_sim::suite::SuiteReport`: `motors`,
/// `steady`, `transients`, `checks`, ...) plus `markdown` (the tables as printed by the CLI)
/// and `all_pass` (every goal and limit of the default EKF held). `short` halves the
/// simulated time, `seed` seeds the sensor noise, `ideal` turns off noise, ADC, offsets, gain
/// errors and dead time. Releases the GIL while it runs.
#[pyfunction]
#[pyo3(signature = (*, short = false, seed = None, ideal = false))]
pub(crate) fn suite<'py>(
    py: Python<'py>,
    short: bool,
    seed: Option<&Bound<'py, PyAny>>,
    ideal: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let seed = match seed {
        Some(s) => crate::convert::unsigned(s, "seed")?,
        None => 1,
    };
    let opts = SuiteOptions { short, seed, ideal };
    let report = py
        .detach(|| run_suite(&opts))
        .map_err(|e| SimulationError::new_err(e.to_string()))?;
    let d = pythonize::pythonize(py, &report)
        .map_err(|e| PyfocError::new_err(e.to_string()))?
        .cast_into::<PyDict>()?;
    d.set_item("markdown", report.to_markdown())?;
    d.set_item("all_pass", report.all_pass())?;
    Ok(d)
}
