//! `pyfoc.DriveObserver`: the drive observer of `ekf_core::drive` (an EKF for recorded drives
//! with the acceleration, the voltage lead, the resistance error and the dead-time voltage as
//! states) on numpy arrays. Thin: the same alignment and validation as `Ekf.run` and
//! `FluxObserver.run`; the method is documented in `ekf_core::drive`.

use std::sync::{Mutex, PoisonError};

use ekf_core::{DriveConfig, DriveEstimate, DriveObserver as Inner, RecordCalibration};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{record_args, to_vec};
use crate::errors::ConfigError;
use crate::motor::Motor;
use crate::replay::periods;
use crate::status::RowStatus;

/// The float columns of `DriveObserver.run`, in this order.
const DRIVE_OUTPUTS: [&str; 10] = [
    "theta",
    "omega",
    "omega_mech",
    "i_alpha",
    "i_beta",
    "nis",
    "accel",
    "voltage_lead",
    "rs",
    "dead_time",
];

/// An estimate's values in the order of [`DRIVE_OUTPUTS`].
fn values(e: &DriveEstimate<f64>) -> [f64; DRIVE_OUTPUTS.len()] {
    [
        e.theta_rad,
        e.omega_e_rad_s,
        e.omega_mech_rad_s,
        e.i_alpha_a,
        e.i_beta_a,
        e.nis,
        e.accel_rad_s2,
        e.voltage_lead_s,
        e.rs_ohm,
        e.dead_time_v,
    ]
}

/// The drive observer (`ekf_core::DriveObserver` with `DriveConfig::new(motor, ts)`): an EKF
/// for recorded drives that also estimates the acceleration, the lead of the applied voltage
/// over the logged one, the resistance error and the inverter's dead-time voltage.
/// `DriveObserver(motor, ts)`; `ConfigError` for invalid parameters.
#[pyclass(frozen, module = "pyfoc")]
pub(crate) struct DriveObserver {
    inner: Mutex<DriveInner>,
    /// Sample time, s.
    #[pyo3(get)]
    ts: f64,
}

struct DriveInner {
    obs: Inner<f64>,
    /// The record's calibration from every accepted row so far (`calibration()`).
    cal: RecordCalibration<f64>,
    /// Voltage that predicts the first row of the next `run`.
    u_last: [f64; 2],
}

impl DriveObserver {
    /// Runs `f` on the observer with the GIL released and the lock held (its steps commit
    /// whole, so a poisoned lock is taken over).
    fn with<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut DriveInner) -> R + Send) -> R {
        py.detach(|| {
            let mut guard = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
            f(&mut guard)
        })
    }
}

#[pymethods]
impl DriveObserver {
    #[new]
    fn new(motor: &Motor, ts: f64) -> PyResult<Self> {
        let cfg = DriveConfig::new(motor.params::<f64>(), ts);
        let obs = Inner::new(&cfg).map_err(|e| ConfigError::new_err(e.to_string()))?;
        Ok(Self {
            inner: Mutex::new(DriveInner {
                obs,
                cal: RecordCalibration::new(),
                u_last: [0.0; 2],
            }),
            ts,
        })
    }

    /// Runs the observer over a record (same timing as `Ekf.run`); returns a dict of `(N,)`
    /// float64 arrays `theta`, `omega`, `omega_mech`, `i_alpha`, `i_beta`, `nis`, `accel`
    /// (electrical, rad/s^2), `voltage_lead` (s), `rs` (ohm, in use), `dead_time` (V) and an
    /// int8 array `status` (`Status.TRACKING` when the observer tracks, else `UNCERTAIN`;
    /// `REJECTED` for a refused row, whose outputs repeat the current estimate and whose
    /// state is kept). Continues from the current state; row 0 predicts with `u_prev` if
    /// given, else the last row of the previous `run` (zero for a new observer). `dt`: `(N,)`
    /// periods that ended at each row (finite, > 0; a period above 64 `ts` is a REJECTED
    /// row); without it every period is `ts`. The GIL is released while the observer runs.
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
        let dt = dt.map(|d| periods(d, n)).transpose()?;
        // Input copies (32 bytes a row), the columns (80) and the status (1).
        crate::convert::ensure_memory(n as u128 * 113, "run")?;
        let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
        let (cols, st) = self.with(py, move |g| {
            let mut prev = u_prev.unwrap_or(g.u_last);
            let mut cols: [Vec<f64>; DRIVE_OUTPUTS.len()] = std::array::from_fn(|_| vec![0.0; n]);
            let mut st = vec![0i8; n];
            for (k, (uk, ik)) in u.chunks_exact(2).zip(i.chunks_exact(2)).enumerate() {
                let ik = [ik[0], ik[1]];
                let r = match &dt {
                    Some(d) => g.obs.step_dt(prev, ik, d[k]),
                    None => g.obs.step(prev, ik),
                };
                let (e, s) = match r {
                    Ok(e) if e.tracking => (e, RowStatus::Tracking),
                    Ok(e) => (e, RowStatus::Uncertain),
                    Err(_) => (g.obs.estimate(), RowStatus::Rejected),
                };
                if s != RowStatus::Rejected {
                    g.cal.push(&e);
                }
                for (c, v) in cols.iter_mut().zip(values(&e)) {
                    c[k] = v;
                }
                st[k] = s as i8;
                prev = [uk[0], uk[1]];
            }
            g.u_last = prev;
            (cols, st)
        });
        let d = PyDict::new(py);
        for (name, c) in DRIVE_OUTPUTS.into_iter().zip(cols) {
            d.set_item(name, PyArray1::from_vec(py, c))?;
        }
        d.set_item("status", PyArray1::from_vec(py, st))?;
        Ok(d)
    }

    /// State `[i_alpha, i_beta, omega_e, theta, accel, voltage_lead, d_rs, dead_time]` as a
    /// `(8,)` float64 array (a copy).
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let x: Vec<f64> = self.with(py, |g| g.obs.state().iter().copied().collect());
        PyArray1::from_vec(py, x)
    }

    /// State covariance as an `(8, 8)` float64 array (a copy).
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self.with(py, |g| {
            let p = g.obs.covariance();
            (0..p.nrows())
                .map(|r| (0..p.ncols()).map(|c| p[(r, c)]).collect())
                .collect()
        });
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// The record's input errors from every row run so far (module `ekf_core::calibration`:
    /// the estimates of the rows where the observer tracked, weighted by the speed squared),
    /// as the default `Ekf` takes them: a dict with `voltage_delay_s` (minus the lead of the
    /// applied voltage over the logged one, s), `rs_ohm`, `inverter_voltage_v` and `samples`
    /// (rows averaged); `None` before a tracked row. The second pass: `Ekf(Motor(rs_ohm, ...),
    /// ts, voltage_delay_s=..., inverter_voltage_v=..., acceleration_feedforward=True)`.
    fn calibration<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(c) = self.with(py, |g| g.cal.result()) else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("voltage_delay_s", -c.voltage_lead_s)?;
        d.set_item("rs_ohm", c.rs_ohm)?;
        d.set_item("inverter_voltage_v", c.dead_time_v)?;
        d.set_item("samples", c.samples)?;
        Ok(Some(d))
    }

    fn __repr__(&self) -> String {
        format!("DriveObserver(ts={})", self.ts)
    }
}
