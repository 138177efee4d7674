//! Replay of recorded drives: `pyfoc.read_log` (the CSV format and the MCAP logs of
//! `pmsm_sim::replay`), `Ekf.run(..., dt=...)`'s per-row periods, and `pyfoc.FluxObserver`
//! (the flux + PLL baseline of `ekf_core::flux`). Thin wrappers: the reading, alignment and
//! scaling live in `pmsm_sim::replay`.

use std::sync::{Mutex, PoisonError};

use ekf_core::observer::SkippedCycles;
use ekf_core::saturated::FluxMapObserver;
use ekf_core::{EkfError, Float, FluxEstimate, FluxObserverConfig, PmsmObserver};
use numpy::{PyArray1, PyArrayMethods};
use pmsm_sim::replay::{ReplayError, Scaling};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{contiguous, path_of, record_args, to_vec, vector};
use crate::engine::OutArrays;
use crate::errors::{ConfigError, PyfocError};
use crate::motor::{MAP_POINTS, Motor};
use crate::observer::{OUTPUTS, Observer, Row, Steps, each_observer};
use crate::status::RowStatus;

create_exception!(
    pyfoc,
    LogError,
    PyfocError,
    "A drive log or motor file could not be read; the message names the file (and, for a \
     malformed CSV, the line and column, also in the attributes `file`, `line`, `column`)."
);

/// A reading error as a `pyfoc.LogError` with `file`, `line`, `column` attributes (`None`
/// where they do not apply).
fn log_err(py: Python<'_>, e: ReplayError) -> PyErr {
    let (file, line, column) = match &e {
        ReplayError::Csv {
            file, line, column, ..
        } => (Some(file.clone()), Some(*line), Some(*column)),
        ReplayError::Io { file, .. }
        | ReplayError::Mcap { file, .. }
        | ReplayError::Motor { file, .. } => (Some(file.clone()), None, None),
        ReplayError::Output { path, .. } => (Some(path.clone()), None, None),
        ReplayError::Inconsistent(_) | ReplayError::Config(_) => (None, None, None),
    };
    let err = LogError::new_err(e.to_string());
    let v = err.value(py);
    // Attributes on a fresh exception instance: setting them cannot fail in practice; if it
    // did, the message still carries everything.
    let _ = v.setattr("file", file);
    let _ = v.setattr("line", line);
    let _ = v.setattr("column", column);
    err
}

/// Reads a drive log: the documented CSV (header `t_s, dt_s, u_alpha_v, u_beta_v,
/// i_alpha_a, i_beta_a`, optional `theta_ref_rad`, `omega_ref_rad_s`) or a `pmsm-sim` MCAP
/// log. Returns a dict of numpy arrays in pyfoc's convention: `t`, `dt` (the period that
/// ended at row k), `u_ab` (row k held over `[t_k, t_k+1)`), `i_ab`, `u_prev` (the voltage
/// before row 0) and, when the log has them, `theta_ref`, `omega_ref`. `scaling="power"`:
/// the CSV was logged with the power-invariant Clarke transform (converted). Errors:
/// `pyfoc.LogError` naming file, line and column.
#[pyfunction]
#[pyo3(signature = (path, *, scaling = "amplitude"))]
pub(crate) fn read_log<'py>(
    py: Python<'py>,
    path: &Bound<'py, PyAny>,
    scaling: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let path = path_of(path, "path")?;
    let scaling = Scaling::from_name(scaling).ok_or_else(|| {
        PyValueError::new_err(format!(
            "scaling must be 'amplitude' or 'power', got {scaling:?}"
        ))
    })?;
    let log = py
        .detach(|| pmsm_sim::replay::read_log(&path, scaling))
        .map_err(|e| log_err(py, e))?;
    let d = PyDict::new(py);
    let flat = |v: &[[f64; 2]]| PyArray1::from_slice(py, v.as_flattened()).reshape([v.len(), 2]);
    d.set_item("t", PyArray1::from_slice(py, &log.t_s))?;
    d.set_item("dt", PyArray1::from_slice(py, &log.dt_s))?;
    d.set_item("u_ab", flat(&log.u_ab)?)?;
    d.set_item("i_ab", flat(&log.i_ab)?)?;
    d.set_item("u_prev", PyArray1::from_slice(py, &log.u_prev))?;
    if let Some(v) = &log.theta_ref {
        d.set_item("theta_ref", PyArray1::from_slice(py, v))?;
    }
    if let Some(v) = &log.omega_ref {
        d.set_item("omega_ref", PyArray1::from_slice(py, v))?;
    }
    Ok(d)
}

/// The `dt=` argument of a `run`: `(n,)`, every value finite and `> 0`; ValueError naming
/// `dt` otherwise.
pub(crate) fn periods(obj: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f64>> {
    let arr = vector(obj, "dt", Some(n))?;
    let v = to_vec(&arr, "dt")?;
    if let Some(k) = v.iter().position(|d| !(d.is_finite() && *d > 0.0)) {
        return Err(PyValueError::new_err(format!(
            "dt[{k}] = {}: every period must be finite and > 0 s",
            v[k]
        )));
    }
    Ok(v)
}

/// The `dt=` argument of a function on a record's arrays ([`periods`]; `ts` on every row when
/// absent) and the time stamps it gives, from 0: `(dt_s, t_s)`.
fn periods_and_times(
    dt: Option<&Bound<'_, PyAny>>,
    n: usize,
    ts: f64,
) -> PyResult<(Vec<f64>, Vec<f64>)> {
    let dt_s = match dt {
        Some(d) => periods(d, n)?,
        None => vec![ts; n],
    };
    let t_s = dt_s
        .iter()
        .scan(0.0, |t, d| {
            let now = *t;
            *t += d;
            Some(now)
        })
        .collect();
    Ok((dt_s, t_s))
}

/// One step with the period that ended at this row.
#[inline]
fn step_row_dt<T: Float + Into<f64>, O: Steps<T>>(
    o: &mut O,
    u: [f64; 2],
    i: [f64; 2],
    dt: f64,
) -> Row {
    let c = |v: f64| T::from_subset(&v);
    let (values, status) = match o.step_dt(u.map(c), i.map(c), c(dt)) {
        Ok(e) => (crate::observer::outputs(&e), RowStatus::of(e.status)),
        Err(_) => (crate::observer::outputs(&o.estimate()), RowStatus::Rejected),
    };
    Row {
        values: values.map(Into::into),
        status,
    }
}

impl Observer {
    /// `run` with per-row periods: a plain loop (row `k` predicts with `u[k-1]`, `prev` for
    /// row 0, over `dt[k]`); returns the rows and the last row's voltage. A refused row (a
    /// voltage or current the filter refuses: not finite, or implausible) is a skipped cycle
    /// (`ekf_core::observer::SkippedCycles`): its period joins the next row's, and its outputs
    /// are the estimate with the angle advanced to its time.
    pub(crate) fn run_dt(
        &mut self,
        mut prev: [f64; 2],
        u: &[f64],
        i: &[f64],
        dt: &[f64],
    ) -> (Vec<Row>, [f64; 2]) {
        let mut rows = Vec::with_capacity(dt.len());
        let mut skipped = SkippedCycles::default();
        for ((uk, ik), &d) in u.chunks_exact(2).zip(i.chunks_exact(2)).zip(dt) {
            let ik = [ik[0], ik[1]];
            let row = skipped.step(d, |d| {
                let row = each_observer!(&mut *self, o => step_row_dt(o, prev, ik, d));
                if row.status == RowStatus::Rejected {
                    Err(row)
                } else {
                    Ok(row)
                }
            });
            rows.push(row.unwrap_or_else(|mut row| {
                row.values[0] = skipped.advance(row.values[0], row.values[1]);
                row
            }));
            prev = [uk[0], uk[1]];
        }
        (rows, prev)
    }

    /// Primes the online input calibration with the record `run` is about to filter
    /// (`PmsmObserver::prime_input_calibration`: a copy runs over the rows, its last handed-over
    /// voltage timing is set here). Row `k` predicts with `u[k-1]` (`prev` for row 0), over
    /// `dt[k]` or `ts`. Returns the delay set (s); nothing happens (`None`) on a flux map, with
    /// the calibration off, or when the copy handed over no other delay.
    pub(crate) fn prime(
        &mut self,
        prev: [f64; 2],
        u: &[f64],
        i: &[f64],
        dt: Option<&[f64]>,
    ) -> Option<f64> {
        fn go<T: Float>(
            o: &mut PmsmObserver<T>,
            prev: [f64; 2],
            u: &[f64],
            i: &[f64],
            dt: Option<&[f64]>,
        ) -> Option<f64> {
            let c = |v: f64| T::from_subset(&v);
            let ts = o.model().ts();
            let rows = i.chunks_exact(2).enumerate().map(|(k, ik)| {
                let p = if k == 0 {
                    prev
                } else {
                    [u[2 * k - 2], u[2 * k - 1]]
                };
                let d = dt.map_or(ts, |d| c(d[k]));
                ([c(p[0]), c(p[1])], [c(ik[0]), c(ik[1])], d)
            });
            o.prime_input_calibration(rows)
                .map(|d| d.to_subset().unwrap_or(f64::NAN))
        }
        match self {
            Observer::F64(o) => go(o, prev, u, i, dt),
            Observer::F32(o) => go(o, prev, u, i, dt),
            Observer::MapF64(_) | Observer::MapF32(_) => None,
        }
    }
}

/// `Ekf.run`'s outputs from rows: into a caller's `out` arrays (returned), or fresh arrays.
pub(crate) fn rows_to_dict<'py>(
    py: Python<'py>,
    rows: &[Row],
    given: Option<(OutArrays<'py>, Bound<'py, PyDict>)>,
) -> PyResult<Bound<'py, PyDict>> {
    match given {
        Some(((values, status), d)) => {
            for (k, a) in values.iter().enumerate() {
                let mut rw = a.readwrite();
                let s = contiguous(rw.as_slice_mut())?;
                for (dst, r) in s.iter_mut().zip(rows) {
                    *dst = r.values[k];
                }
            }
            let mut rw = status.readwrite();
            let s = contiguous(rw.as_slice_mut())?;
            for (dst, r) in s.iter_mut().zip(rows) {
                *dst = r.status as i8;
            }
            Ok(d)
        }
        None => {
            let d = PyDict::new(py);
            for (k, name) in OUTPUTS.iter().enumerate() {
                let col: Vec<f64> = rows.iter().map(|r| r.values[k]).collect();
                d.set_item(name, PyArray1::from_vec(py, col))?;
            }
            let st: Vec<i8> = rows.iter().map(|r| r.status as i8).collect();
            d.set_item("status", PyArray1::from_vec(py, st))?;
            Ok(d)
        }
    }
}

/// The flux observer with PLL (`ekf_core::FluxObserver`, the usual tuning: observer gain and
/// PLL bandwidth `0.1 / ts`): the baseline the EKF is compared against. On a motor given by a
/// flux map, the flux observer on the map's active flux (`ekf_core::saturated::FluxMapObserver`).
/// `FluxObserver(motor, ts)`; `ConfigError` for invalid parameters.
#[pyclass(frozen, module = "pyfoc")]
pub(crate) struct FluxObserver {
    inner: Mutex<FluxInner>,
    /// Sample time, s.
    #[pyo3(get)]
    ts: f64,
}

struct FluxInner {
    obs: Flux,
    u_last: [f64; 2],
}

/// The flux observer on constant parameters or on a motor's flux map.
// One per `FluxObserver`, behind its lock.
#[allow(clippy::large_enum_variant)]
enum Flux {
    Plain(ekf_core::FluxObserver<f64>),
    Map(Box<FluxMapObserver<f64, MAP_POINTS>>),
}

impl Flux {
    fn step(&mut self, u: [f64; 2], i: [f64; 2]) -> Result<FluxEstimate<f64>, EkfError> {
        match self {
            Flux::Plain(o) => o.step(u, i),
            Flux::Map(o) => o.step(u, i),
        }
    }

    fn estimate(&self) -> FluxEstimate<f64> {
        match self {
            Flux::Plain(o) => o.estimate(),
            Flux::Map(o) => o.estimate(),
        }
    }
}

#[pymethods]
impl FluxObserver {
    #[new]
    fn new(motor: &Motor, ts: f64) -> PyResult<Self> {
        let cfg = FluxObserverConfig::new(motor.params::<f64>(), ts);
        let cfg_err = |e: ekf_core::ConfigError| ConfigError::new_err(e.to_string());
        let obs = match &motor.map {
            None => Flux::Plain(ekf_core::FluxObserver::new(&cfg).map_err(cfg_err)?),
            Some(t) => {
                let map = t.map::<f64>().map_err(ConfigError::new_err)?;
                Flux::Map(Box::new(FluxMapObserver::new(&cfg, map).map_err(cfg_err)?))
            }
        };
        Ok(Self {
            inner: Mutex::new(FluxInner {
                obs,
                u_last: [0.0; 2],
            }),
            ts,
        })
    }

    /// Runs the observer over a record (same timing as `Ekf.run`); returns a dict of `(N,)`
    /// float64 arrays `theta`, `omega`, `omega_mech` and an int8 array `status`
    /// (`Status.UNCERTAIN` on every accepted row: the baseline has no confidence measure, so it
    /// never claims `TRACKING`;
    /// `Status.REJECTED` for a non-finite row, whose outputs repeat the previous estimate).
    /// Continues from the current state; row 0 predicts with `u_prev` if given, else the
    /// last row of the previous `run` (zero for a new observer). `dt`: `(N,)` periods that
    /// ended at each row, validated (finite, > 0); the baseline steps with its fixed `ts`.
    #[pyo3(signature = (u_ab, i_ab, *, u_prev = None, dt = None))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        u_ab: &Bound<'py, PyAny>,
        i_ab: &Bound<'py, PyAny>,
        u_prev: Option<&Bound<'py, PyAny>>,
        dt: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (u, i, n, u_prev) = record_args(u_ab, i_ab, u_prev)?;
        if let Some(dt) = dt {
            periods(dt, n)?;
        }
        crate::convert::ensure_memory(n as u128 * 64, "run")?;
        let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
        let out = py.detach(|| {
            let mut g = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
            let mut prev = u_prev.unwrap_or(g.u_last);
            let mut cols = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
            let mut st = vec![0i8; n];
            for (k, (uk, ik)) in u.chunks_exact(2).zip(i.chunks_exact(2)).enumerate() {
                let (e, s) = match g.obs.step(prev, [ik[0], ik[1]]) {
                    Ok(e) => (e, RowStatus::Uncertain),
                    Err(_) => (g.obs.estimate(), RowStatus::Rejected),
                };
                cols[0][k] = e.theta_rad;
                cols[1][k] = e.omega_e_rad_s;
                cols[2][k] = e.omega_mech_rad_s;
                st[k] = s as i8;
                prev = [uk[0], uk[1]];
            }
            g.u_last = prev;
            (cols, st)
        });
        let (cols, st) = out;
        let d = PyDict::new(py);
        for (name, c) in ["theta", "omega", "omega_mech"].into_iter().zip(cols) {
            d.set_item(name, PyArray1::from_vec(py, c))?;
        }
        d.set_item("status", PyArray1::from_vec(py, st))?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!("FluxObserver(ts={})", self.ts)
    }
}

/// The record's back-EMF per unit speed against the motor's flux linkage, from a run's own
/// angle and status (`pmsm_sim::replay::flux_check`, whose module docs give the method):
/// `u_ab`, `i_ab` (N, 2) in `Ekf.run`'s convention (row k predicts with `u_ab[k-1]`), `theta`
/// and `status` (N,) as `Ekf.run` returns them, `dt` (N,) the period that ended at each row
/// (default `ts`). Returns a dict (`blocks`, `flux_wb`, `told_wb`, `ratio`, `off`: more than
/// 10 % from the told flux), or `None` when no block of light load, steady speed and status
/// `TRACKING` is found. ValueError naming the argument for a wrong shape or value.
#[pyfunction]
#[pyo3(signature = (motor, ts, u_ab, i_ab, theta, status, *, dt = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn flux_check<'py>(
    py: Python<'py>,
    motor: &Motor,
    ts: f64,
    u_ab: &Bound<'py, PyAny>,
    i_ab: &Bound<'py, PyAny>,
    theta: &Bound<'py, PyAny>,
    status: &Bound<'py, PyAny>,
    dt: Option<&Bound<'py, PyAny>>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    use pmsm_sim::replay::{DriveLog, ObserverTrace, ReplayMotor, ReplayStatus};
    if !(ts.is_finite() && ts > 0.0) {
        return Err(PyValueError::new_err(format!(
            "ts = {ts}: must be finite and > 0 s"
        )));
    }
    let (u, i, n, _) = record_args(u_ab, i_ab, None)?;
    // The copies below: u_ab, i_ab twice (flat, then as pairs), theta, status, dt, t.
    crate::convert::ensure_memory(n as u128 * 104, "flux_check")?;
    let pairs = |a: &crate::convert::RealArray<'_>, name: &str| -> PyResult<Vec<[f64; 2]>> {
        let flat = to_vec(a, name)?;
        Ok(flat.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
    };
    let u_ab = pairs(&u, "u_ab")?;
    let i_ab = pairs(&i, "i_ab")?;
    let theta = to_vec(&vector(theta, "theta", Some(n))?, "theta")?;
    let codes = to_vec(&vector(status, "status", Some(n))?, "status")?;
    let status = codes
        .iter()
        .enumerate()
        .map(|(k, &c)| match c {
            0.0 => Ok(ReplayStatus::Tracking),
            1.0 => Ok(ReplayStatus::Uncertain),
            2.0 => Ok(ReplayStatus::Rejected),
            _ => Err(PyValueError::new_err(format!(
                "status[{k}] = {c}: expected a pyfoc.Status code (0, 1 or 2)"
            ))),
        })
        .collect::<PyResult<Vec<_>>>()?;
    let (dt_s, t_s) = periods_and_times(dt, n, ts)?;
    let log = DriveLog {
        t_s,
        dt_s,
        u_ab,
        i_ab,
        u_prev: [0.0; 2],
        theta_ref: None,
        omega_ref: None,
    };
    let trace = ObserverTrace {
        theta,
        status,
        ..ObserverTrace::default()
    };
    let m = ReplayMotor {
        params: motor.params(),
        ts_s: ts,
        voltage_delay_s: 0.0,
        inverter_voltage_v: 0.0,
    };
    let Some(f) = py.detach(|| pmsm_sim::replay::flux_check(&log, &m, &trace)) else {
        return Ok(None);
    };
    let d = PyDict::new(py);
    d.set_item("blocks", f.blocks)?;
    d.set_item("flux_wb", f.flux_wb)?;
    d.set_item("told_wb", f.told_wb)?;
    d.set_item("ratio", f.ratio)?;
    d.set_item("off", f.off())?;
    Ok(Some(d))
}

/// A run's angle error by speed band and direction, fitted to a d-axis voltage the model
/// lacks and a timing (`pmsm_sim::replay::speed_bands`, whose module docs give the method):
/// `theta`, `theta_ref` (N,) electrical angles (rad), `omega_ref` (N,) the reference speed
/// (rad/s el.), `psi_f` the flux linkage the observer was told (Wb), `dt` (N,) the period
/// that ended at each row (default `ts`). Scored as `pmsm-sim replay` scores: rows with
/// `|omega_ref|` at least 10 % of its largest, 20 ms after each period longer than 1.35 `ts`
/// left out, the error's circular mean removed, rows more than 45 deg off left out. Returns a
/// dict (`offset_deg`, `bands`: a list of dicts, `fit`: a dict or `None`), or `None` with
/// fewer than 16 rows to use. ValueError naming the argument for a wrong shape or value.
#[pyfunction]
#[pyo3(signature = (ts, theta, theta_ref, omega_ref, psi_f, *, dt = None))]
pub(crate) fn speed_bands<'py>(
    py: Python<'py>,
    ts: f64,
    theta: &Bound<'py, PyAny>,
    theta_ref: &Bound<'py, PyAny>,
    omega_ref: &Bound<'py, PyAny>,
    psi_f: f64,
    dt: Option<&Bound<'py, PyAny>>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    use pmsm_sim::replay::{DriveLog, ReplayStatus};
    if !(ts.is_finite() && ts > 0.0) {
        return Err(PyValueError::new_err(format!(
            "ts = {ts}: must be finite and > 0 s"
        )));
    }
    if !(psi_f.is_finite() && psi_f > 0.0) {
        return Err(PyValueError::new_err(format!(
            "psi_f = {psi_f}: must be finite and > 0 Wb"
        )));
    }
    let theta = to_vec(&vector(theta, "theta", None)?, "theta")?;
    let n = theta.len();
    // The copies below: theta_ref, omega_ref, dt, t, the (unused) voltages and currents, the
    // statuses, the mask, the errors and the samples kept.
    crate::convert::ensure_memory(n as u128 * 120, "speed_bands")?;
    let theta_ref = to_vec(&vector(theta_ref, "theta_ref", Some(n))?, "theta_ref")?;
    let omega_ref = to_vec(&vector(omega_ref, "omega_ref", Some(n))?, "omega_ref")?;
    let (dt_s, t_s) = periods_and_times(dt, n, ts)?;
    let log = DriveLog {
        t_s,
        u_ab: vec![[0.0; 2]; n],
        i_ab: vec![[0.0; 2]; n],
        dt_s,
        u_prev: [0.0; 2],
        theta_ref: Some(theta_ref),
        omega_ref: Some(omega_ref),
    };
    let result = py.detach(|| {
        let status = vec![ReplayStatus::Tracking; n];
        let score = pmsm_sim::replay::score(&log, ts, &theta, &status)?;
        let offset = score.offset_deg.to_radians();
        pmsm_sim::replay::speed_bands(&log, ts, &theta, offset, psi_f).map(|b| (score, b))
    });
    let Some((score, b)) = result else {
        return Ok(None);
    };
    let d = PyDict::new(py);
    d.set_item("offset_deg", score.offset_deg)?;
    let bands = pyo3::types::PyList::empty(py);
    for x in &b.bands {
        let e = PyDict::new(py);
        e.set_item("from_share", x.from_share)?;
        e.set_item("to_share", x.to_share)?;
        e.set_item("forward", x.forward)?;
        e.set_item("samples", x.samples)?;
        e.set_item("speed_rad_s", x.speed_rad_s)?;
        e.set_item("mean_deg", x.mean_deg)?;
        e.set_item("rms_deg", x.rms_deg)?;
        bands.append(e)?;
    }
    d.set_item("bands", bands)?;
    match b.fit {
        Some(f) => {
            let e = PyDict::new(py);
            e.set_item("constant_deg", f.constant_deg)?;
            e.set_item("d_voltage_v", f.d_voltage_v)?;
            e.set_item("delay_s", f.delay_s)?;
            e.set_item("residual_rms_deg", f.residual_rms_deg)?;
            d.set_item("fit", e)?;
        }
        None => d.set_item("fit", py.None())?,
    }
    Ok(Some(d))
}
