//! `pyfoc.identify`: self-commissioning of a scenario's motor (`pmsm_sim::identify`).

use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{PyfocError, SimulationError};
use crate::simulate::scenario_of;

/// Identifies the motor of `scenario` (a preset name, a TOML path or a dict): Rs, Ld, Lq,
/// psi_f, J and the inverter's voltage error, from standstill and a short I/f spin, with the
/// scenario's inverter and sensing (its speed and load profiles are ignored).
///
/// Returns the report as a dict (`ok`, `identified` with `rs_ohm`, `ld_h`, `lq_h`,
/// `psi_f_wb`, `j_kg_m2`, `inverter_voltage_error_v`; `truth`, `errors_pct`, `steps`,
/// `total_time_s`, `error`, `error_kind`, `failed_step`, `pwm_off_at_end`). A failed
/// identification (open phase, locked rotor, ...) is reported in the dict (`ok` False), not
/// raised. `seed` overrides the scenario's sensor seed. Releases the GIL while it runs.
#[pyfunction]
#[pyo3(signature = (scenario, *, seed = None))]
pub(crate) fn identify<'py>(
    py: Python<'py>,
    scenario: &Bound<'py, PyAny>,
    seed: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let sc = scenario_of(scenario)?;
    let seed = seed
        .map(|s| crate::convert::unsigned(s, "seed"))
        .transpose()?;
    let opts = pmsm_sim::identify::IdentifyOptions {
        seed,
        ..Default::default()
    };
    let report = py
        .detach(|| pmsm_sim::identify::identify(&sc, &opts))
        .map_err(|e| SimulationError::new_err(e.to_string()))?;
    let d = pythonize::pythonize(py, &report)
        .map_err(|e| PyfocError::new_err(e.to_string()))?
        .cast_into::<PyDict>()?;
    Ok(d)
}
