//! `pyfoc.tune_qr` and `pyfoc.tune_qr_mcap`: the offline Q/R tuner of `pmsm_sim::tune`.

use numpy::{PyArray1, PyArrayMethods};
use pmsm_sim::tune::{
    AngleTruth, McapTuneReport, RShape, TuneError, TuneOptions, TuneReport, tune_logged_run,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{ensure_memory, fixed, path_of, rows2, to_vec, unsigned, vector};

/// `max_evals` when not given (the CLI's default).
const DEFAULT_MAX_EVALS: usize = 5000;
use crate::errors::{ConfigError, FilterError, PyfocError};
use crate::motor::Motor;

fn to_py(e: TuneError) -> PyErr {
    match e {
        TuneError::Config(_) | TuneError::Option { .. } => ConfigError::new_err(e.to_string()),
        TuneError::NoUsableFilter(_) => FilterError::new_err(e.to_string()),
        TuneError::Log { .. } => PyfocError::new_err(e.to_string()),
        TuneError::LengthMismatch { .. }
        | TuneError::TruthLength { .. }
        | TuneError::TooShort { .. } => PyValueError::new_err(e.to_string()),
    }
}

#[allow(clippy::too_many_arguments)]
fn options(
    skip: Option<&Bound<'_, PyAny>>,
    r_shape: &str,
    max_evals: Option<&Bound<'_, PyAny>>,
    x0: Option<&Bound<'_, PyAny>>,
    discretization: &str,
    min_speed: Option<f64>,
    bound_decades: f64,
) -> PyResult<TuneOptions> {
    let r_shape = match r_shape {
        "full" => RShape::Full,
        "isotropic" => RShape::Isotropic,
        other => {
            return Err(ConfigError::new_err(format!(
                "r_shape must be 'full' or 'isotropic', got {other:?}"
            )));
        }
    };
    let discretization = match discretization {
        "lag_free" => ekf_core::Discretization::LagFree,
        "forward_euler" => ekf_core::Discretization::ForwardEuler,
        other => {
            return Err(ConfigError::new_err(format!(
                "discretization must be 'lag_free' or 'forward_euler', got {other:?}"
            )));
        }
    };
    Ok(TuneOptions {
        skip: skip.map(|o| unsigned::<usize>(o, "skip")).transpose()?,
        r_shape,
        max_evaluations: match max_evals {
            Some(o) => unsigned::<usize>(o, "max_evals")?,
            None => DEFAULT_MAX_EVALS,
        },
        x0: x0
            .map(|o| fixed::<4>(o, "x0"))
            .transpose()?
            .unwrap_or([0.0; 4]),
        discretization,
        min_speed_rad_s: min_speed,
        bound_decades,
        ..TuneOptions::default()
    })
}

/// The report as a dict: the serde layout of `TuneReport`, `q`, `r` as arrays, shortcuts
/// `mean_nis_before`/`mean_nis_after`, and the `toml` snippet.
fn report_dict<'py>(py: Python<'py>, rep: &TuneReport) -> PyResult<Bound<'py, PyDict>> {
    let d = pythonize::pythonize(py, rep)
        .map_err(|e| PyfocError::new_err(e.to_string()))?
        .cast_into::<PyDict>()?;
    let flat = |m: &[f64], n: usize| PyArray1::from_slice(py, m).reshape([n, n]);
    d.set_item("q", flat(rep.q.as_flattened(), 4)?)?;
    d.set_item("r", flat(rep.r.as_flattened(), 2)?)?;
    d.set_item("mean_nis_before", rep.before.mean_nis)?;
    d.set_item("mean_nis_after", rep.after.mean_nis)?;
    d.set_item("toml", rep.toml_snippet())?;
    Ok(d)
}

/// Proposes Q and R for the observer from a record by maximizing the innovation
/// likelihood (`pmsm_sim::tune`). `u_ab`, `i_ab`: `(N, 2)` (row k of `u_ab` held over
/// `[t_k, t_k+1)`); `theta_true` (and `omega_true`), `(N,)`, add the angle error of the
/// default and the tuned filter. Returns a dict (see the stub, python/pyfoc/__init__.pyi). Releases the GIL.
#[pyfunction]
#[pyo3(signature = (motor, ts, u_ab, i_ab, *, theta_true = None, omega_true = None, skip = None,
    r_shape = "full", max_evals = None, x0 = None, discretization = "lag_free",
    min_speed = None, bound_decades = 3.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn tune_qr<'py>(
    py: Python<'py>,
    motor: &Motor,
    ts: f64,
    u_ab: &Bound<'py, PyAny>,
    i_ab: &Bound<'py, PyAny>,
    theta_true: Option<&Bound<'py, PyAny>>,
    omega_true: Option<&Bound<'py, PyAny>>,
    skip: Option<&Bound<'py, PyAny>>,
    r_shape: &str,
    max_evals: Option<&Bound<'py, PyAny>>,
    x0: Option<&Bound<'py, PyAny>>,
    discretization: &str,
    min_speed: Option<f64>,
    bound_decades: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = options(
        skip,
        r_shape,
        max_evals,
        x0,
        discretization,
        min_speed,
        bound_decades,
    )?;
    let u = rows2(u_ab, "u_ab")?;
    let i = rows2(i_ab, "i_ab")?;
    let th = theta_true
        .map(|o| vector(o, "theta_true", None))
        .transpose()?;
    let w = omega_true
        .map(|o| vector(o, "omega_true", None))
        .transpose()?;
    if w.is_some() && th.is_none() {
        return Err(PyValueError::new_err("omega_true needs theta_true"));
    }
    // The copies of the inputs, probed at once.
    let len =
        |a: &Option<crate::convert::RealArray<'_>>| a.as_ref().map_or(0, |a| a.as_array().len());
    let values = u.as_array().len() + i.as_array().len() + len(&th) + len(&w);
    ensure_memory(8 * values as u128, "tune_qr")?;
    let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
    let th = th.map(|a| to_vec(&a, "theta_true")).transpose()?;
    let w = w.map(|a| to_vec(&a, "omega_true")).transpose()?;
    let params = motor.params::<f64>();
    let rep = py
        .detach(|| {
            let (u, _) = u.as_chunks::<2>();
            let (i, _) = i.as_chunks::<2>();
            let truth = th.as_deref().map(|t| AngleTruth {
                theta_rad: t,
                omega_rad_s: w.as_deref(),
            });
            pmsm_sim::tune::tune_qr(&params, ts, u, i, truth, &opts)
        })
        .map_err(to_py)?;
    report_dict(py, &rep)
}

/// `tune_qr` on a `pmsm-sim` MCAP log (protobuf or JSON): motor and Ts from its scenario,
/// the true angle from the log, the angle-error window above 5 % of rated speed unless
/// `min_speed` says otherwise. The dict adds `scenario`, `periods`, `sensor_r` (the R the
/// scenario's sensor produces), `replay_matches_log` and `replay_max_diff_rad`. Releases the
/// GIL.
#[pyfunction]
#[pyo3(signature = (path, *, skip = None, r_shape = "full", max_evals = None, x0 = None,
    discretization = "lag_free", min_speed = None, bound_decades = 3.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn tune_qr_mcap<'py>(
    py: Python<'py>,
    path: &Bound<'py, PyAny>,
    skip: Option<&Bound<'py, PyAny>>,
    r_shape: &str,
    max_evals: Option<&Bound<'py, PyAny>>,
    x0: Option<&Bound<'py, PyAny>>,
    discretization: &str,
    min_speed: Option<f64>,
    bound_decades: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let path = path_of(path, "path")?;
    let opts = options(
        skip,
        r_shape,
        max_evals,
        x0,
        discretization,
        min_speed,
        bound_decades,
    )?;
    let m: McapTuneReport = py
        .detach(|| {
            let run = pmsm_sim::tune::LoggedRun::read(&path)?;
            tune_logged_run(&run, &opts)
        })
        .map_err(to_py)?;
    let d = report_dict(py, &m.report)?;
    d.set_item("scenario", &m.scenario)?;
    d.set_item("periods", m.periods)?;
    d.set_item(
        "sensor_r",
        PyArray1::from_slice(py, m.sensor_r.as_flattened()).reshape([2, 2])?,
    )?;
    d.set_item("replay_matches_log", m.replay_matches_log)?;
    d.set_item("replay_max_diff_rad", m.replay_max_diff_rad)?;
    d.set_item("min_speed_rad_s", m.min_speed_rad_s)?;
    Ok(d)
}
