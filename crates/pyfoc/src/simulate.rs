//! `pyfoc.simulate`: the drive simulator from Python.

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{ensure_memory, nesting_within, path_of};
use crate::errors::{ConfigError, SimulationError};

/// Bytes per period of a recorded run: the trace's sample and the output columns (about 45
/// doubles).
fn bytes_per_period() -> u128 {
    core::mem::size_of::<pmsm_sim::sim::Sample>() as u128 + 45 * 8
}

/// Reads a scenario: a preset name, a path to a TOML file, or a dict with the TOML layout.
pub(crate) fn scenario_of(obj: &Bound<'_, PyAny>) -> PyResult<pmsm_sim::scenario::Scenario> {
    use pmsm_sim::scenario::Scenario;
    let py = obj.py();
    let err = |e: pmsm_sim::SimError| ConfigError::new_err(e.to_string());
    if obj.is_instance_of::<PyDict>() {
        // Deserialization recurses with the data (internally tagged enums buffer whole
        // values): a recursive or absurdly deep dict is refused before it can exhaust the stack.
        nesting_within(obj, 32, "scenario dict")?;
        // Errors name the key path as for a TOML file ("scenario dict: motor.pole_pairs:
        // expected a whole number >= 0, got the string \"four\"").
        let mut de = pythonize::Depythonizer::from_object(obj);
        return Scenario::from_deserializer(&mut de, "scenario dict").map_err(err);
    }
    let text: String = py
        .import("os")?
        .call_method1("fspath", (obj,))
        .and_then(|p| p.extract())
        .map_err(|_| {
            PyTypeError::new_err(
                "scenario: expected a preset name, a str or os.PathLike path, or a dict",
            )
        })?;
    if Scenario::preset_text(&text).is_some() {
        return Scenario::preset(&text).map_err(err);
    }
    let path = std::path::Path::new(&text);
    if path.exists() {
        return Scenario::from_file(path).map_err(err);
    }
    Err(ConfigError::new_err(format!(
        "scenario {text:?} is neither a preset nor an existing file"
    )))
}

/// Columns of a simulation trace.
fn trace_dict<'py>(
    py: Python<'py>,
    out: &pmsm_sim::sim::RunOutput,
) -> PyResult<Bound<'py, PyDict>> {
    let s = &out.trace.samples;
    let d = PyDict::new(py);
    let col = |f: &dyn Fn(&pmsm_sim::sim::Sample) -> f64| s.iter().map(f).collect::<Vec<f64>>();
    let put = |name: &str, v: Vec<f64>| d.set_item(name, PyArray1::from_vec(py, v));
    // (N, w) columns, built flat and reshaped (no per-row allocation).
    let put2 =
        |name: &str, f: &dyn Fn(&pmsm_sim::sim::Sample) -> Vec<f64>, w: usize| -> PyResult<()> {
            let flat: Vec<f64> = s.iter().flat_map(f).collect();
            let arr = PyArray1::from_vec(py, flat).reshape([s.len(), w])?;
            d.set_item(name, arr)
        };
    put("t", col(&|x| x.t_s))?;
    put("theta", col(&|x| x.truth.theta_e_rad))?;
    put("omega", col(&|x| x.truth.omega_e_rad_s))?;
    put("speed_rpm", col(&|x| x.truth.speed_rpm))?;
    put("torque", col(&|x| x.truth.torque_nm))?;
    put("load_torque", col(&|x| x.truth.load_torque_nm))?;
    put("speed_ref_rpm", col(&|x| x.control.speed_ref_rpm))?;
    put2("i_ab", &|x| x.truth.i_ab_a.to_vec(), 2)?;
    put2("i_dq", &|x| x.truth.i_dq_a.to_vec(), 2)?;
    put2("i_ab_meas", &|x| x.measured.i_ab_a.to_vec(), 2)?;
    put2("u_ab", &|x| x.inverter.u_ab_v.to_vec(), 2)?;
    put2("duties", &|x| x.inverter.duties.to_vec(), 3)?;
    put("theta_est", col(&|x| x.observer.theta_e_rad))?;
    put("omega_est", col(&|x| x.observer.omega_e_rad_s))?;
    put("angle_error_deg", col(&|x| x.observer.angle_error_deg))?;
    put("nis", col(&|x| x.observer.nis))?;
    put2("p_diag", &|x| x.observer.p_diag.to_vec(), 4)?;
    if s.iter().any(|x| x.controller_observer.is_some()) {
        let nan = f64::NAN;
        put(
            "controller_theta_est",
            col(&|x| x.controller_observer.map_or(nan, |o| o.theta_e_rad)),
        )?;
        put(
            "controller_omega_est",
            col(&|x| x.controller_observer.map_or(nan, |o| o.omega_e_rad_s)),
        )?;
    }
    if s.iter().any(|x| x.seed_filter.is_some()) {
        let nan = f64::NAN;
        put(
            "seed_theta_est",
            col(&|x| x.seed_filter.map_or(nan, |o| o.theta_e_rad)),
        )?;
    }
    Ok(d)
}

/// Runs the simulator (closed loop, the scenario's controller, the observer alongside) and
/// returns a dict of arrays aligned on the PWM period (`t`, true `theta`/`omega`, `i_ab`,
/// measured `i_ab_meas`, applied `u_ab`, `duties`, the observer's `theta_est`/`omega_est`/
/// `angle_error_deg`/`nis`/`p_diag`, ...) plus `metrics` (dict, as `pmsm-sim --json`) and
/// `completed` (False when the run stopped early; the arrays then hold what was simulated).
/// With `mcap`, the run is also logged to that file (as `pmsm-sim run` does), its time
/// stamps from `log_time`: `"wall"` (the wall-clock time at the start plus the simulated
/// time, the default) or `"zero"` (the simulated time alone); anything else: ConfigError.
/// MemoryError, before anything runs, when the trace would not fit in memory. The GIL is
/// released while it runs.
#[pyfunction]
#[pyo3(signature = (scenario = None, *, duration = None, seed = None, mcap = None, log_time = "wall"))]
pub(crate) fn simulate<'py>(
    py: Python<'py>,
    scenario: Option<&Bound<'py, PyAny>>,
    duration: Option<f64>,
    seed: Option<&Bound<'py, PyAny>>,
    mcap: Option<&Bound<'py, PyAny>>,
    log_time: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let log_time = match log_time {
        "wall" => pmsm_sim::mcap_log::LogTime::Wall,
        "zero" => pmsm_sim::mcap_log::LogTime::Zero,
        other => {
            return Err(ConfigError::new_err(format!(
                "log_time must be \"wall\" or \"zero\", got {other:?}"
            )));
        }
    };
    let mut sc = match scenario {
        Some(obj) => scenario_of(obj)?,
        None => pmsm_sim::scenario::Scenario::preset("default")
            .map_err(|e| ConfigError::new_err(e.to_string()))?,
    };
    if let Some(d) = duration {
        if !(d.is_finite() && d > 0.0) {
            return Err(ConfigError::new_err(format!(
                "duration must be positive, got {d}"
            )));
        }
        sc = sc.with_duration(d);
    }
    if let Some(s) = seed {
        sc.seed = crate::convert::unsigned(s, "seed")?;
    }
    sc.validate()
        .map_err(|e| ConfigError::new_err(format!("{}: {e}", sc.name)))?;
    let mcap_path = mcap.map(|m| path_of(m, "mcap")).transpose()?;
    let periods = sc.periods();
    // MemoryError rather than an abort inside the simulator when the trace cannot fit.
    ensure_memory(
        periods as u128 * bytes_per_period(),
        &format!("simulating {periods} periods with a trace"),
    )?;
    let mut log = match &mcap_path {
        Some(p) => Some(
            pmsm_sim::mcap_log::McapLog::create(
                p,
                &sc,
                pmsm_sim::mcap_log::LogOptions {
                    start_time_unix_ns: log_time.start_time_unix_ns(),
                    ..pmsm_sim::mcap_log::LogOptions::default()
                },
            )
            .map_err(|e| SimulationError::new_err(e.to_string()))?,
        ),
        None => None,
    };
    let out = py
        .detach(|| {
            let mut sinks: Vec<&mut dyn pmsm_sim::sim::SampleSink> = Vec::new();
            if let Some(l) = log.as_mut() {
                sinks.push(l);
            }
            let out = pmsm_sim::sim::run_with(
                &sc,
                pmsm_sim::sim::RunOptions {
                    record_trace: true,
                    sinks,
                    ..Default::default()
                },
            )?;
            if let Some(mut l) = log.take() {
                if let Some(t) = out.end.stop_time_s() {
                    l.event(t, "error", &out.end.describe())?;
                }
                l.finish(Some(&out.metrics))?;
            }
            Ok(out)
        })
        .map_err(|e: pmsm_sim::SimError| match e {
            pmsm_sim::SimError::Scenario { .. } => ConfigError::new_err(e.to_string()),
            other => SimulationError::new_err(other.to_string()),
        })?;
    let d = trace_dict(py, &out)?;
    let metrics = pythonize::pythonize(py, &out.metrics)
        .map_err(|e| SimulationError::new_err(format!("metrics: {e}")))?;
    d.set_item("metrics", metrics)?;
    d.set_item("completed", out.end.is_completed())?;
    d.set_item("scenario", sc.name.clone())?;
    Ok(d)
}
