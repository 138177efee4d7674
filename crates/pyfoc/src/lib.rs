//! Python bindings for the `ekf-core` observer and the `pmsm-sim` simulator.
//!
//! Thin by design: wrapper types and conversions only; every algorithm lives in the Rust
//! crates. Arrays in and out follow the project's timing convention: row `k` of `u_ab` is the
//! voltage held over `[t_k, t_k+1)`, row `k` of `i_ab` the currents sampled at `t_k`, and row
//! `k` of the output the estimate at `t_k` (predicted with `u_ab[k-1]`, corrected with
//! `i_ab[k]`).
#![forbid(unsafe_code)]
#![deny(missing_docs)]

use ekf_core::nalgebra::{Matrix2, Matrix4, Vector4};
use ekf_core::{
    CovarianceUpdate, Discretization, EkfError, Estimate, Float, MotorParams, ObserverConfig,
    PmsmObserver, Status,
};
use std::sync::{Mutex, PoisonError};

use numpy::{PyArray1, PyArray2};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyModule};

mod convert;
mod identify;
mod simulate;
mod suite;
mod tune;

use convert::{pair, rows2, square, try_vec, vec4};

create_exception!(
    pyfoc,
    PyfocError,
    PyValueError,
    "Base class of pyfoc's errors (a ValueError)."
);
create_exception!(
    pyfoc,
    ConfigError,
    PyfocError,
    "Invalid motor or filter parameters; the message gives the reason."
);
create_exception!(
    pyfoc,
    SimulationError,
    PyfocError,
    "The simulator could not run the scenario (e.g. its controller could not be built)."
);
create_exception!(
    pyfoc,
    FilterError,
    PyfocError,
    "A filter operation was refused (e.g. a non-finite reset); the filter is unchanged."
);

/// Row status in `Ekf.run` output: the angle's standard deviation is below its limit.
const STATUS_TRACKING: i8 = 0;
/// Row status: the filter ran but the angle is not trustworthy (not converged, standstill).
const STATUS_UNCERTAIN: i8 = 1;
/// Row status: the sample was rejected (non-finite voltage or current); the state was kept.
const STATUS_REJECTED: i8 = 2;

/// Motor parameters (SI): `Motor(rs, ls, psi_f, pole_pairs, *, ld=None, lq=None)`.
#[pyclass(frozen, module = "pyfoc")]
#[derive(Clone, Copy)]
struct Motor {
    #[pyo3(get)]
    rs: f64,
    #[pyo3(get)]
    ls: f64,
    #[pyo3(get)]
    psi_f: f64,
    #[pyo3(get)]
    pole_pairs: u32,
    #[pyo3(get)]
    ld: f64,
    #[pyo3(get)]
    lq: f64,
}

#[pymethods]
impl Motor {
    #[new]
    #[pyo3(signature = (rs, ls, psi_f, pole_pairs, *, ld = None, lq = None))]
    fn new(
        rs: f64,
        ls: f64,
        psi_f: f64,
        pole_pairs: i64,
        ld: Option<f64>,
        lq: Option<f64>,
    ) -> PyResult<Self> {
        let pole_pairs = u32::try_from(pole_pairs).map_err(|_| {
            ConfigError::new_err(format!("pole_pairs must be >= 1, got {pole_pairs}"))
        })?;
        let m = Self {
            rs,
            ls,
            psi_f,
            pole_pairs,
            ld: ld.unwrap_or(ls),
            lq: lq.unwrap_or(ls),
        };
        m.params::<f64>()
            .validate()
            .map_err(|e| ConfigError::new_err(e.to_string()))?;
        for (name, v) in [("ld", m.ld), ("lq", m.lq)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::new_err(format!(
                    "{name} must be positive and finite, got {v}"
                )));
            }
        }
        Ok(m)
    }

    fn __repr__(&self) -> String {
        format!(
            "Motor(rs={}, ls={}, psi_f={}, pole_pairs={}, ld={}, lq={})",
            self.rs, self.ls, self.psi_f, self.pole_pairs, self.ld, self.lq
        )
    }
}

impl Motor {
    fn params<T: Float>(&self) -> MotorParams<T> {
        MotorParams::from_f64(self.rs, self.ls, self.psi_f, self.pole_pairs)
    }
}

/// The observer in the precision the user chose.
#[derive(Clone)]
// One per `Ekf` object, behind its lock; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
enum Observer {
    F64(PmsmObserver<f64>),
    F32(PmsmObserver<f32>),
}

/// One output row in f64 with its status code.
#[derive(Clone, Copy)]
struct Row {
    theta: f64,
    omega: f64,
    omega_mech: f64,
    i_alpha: f64,
    i_beta: f64,
    nis: f64,
    status: i8,
}

fn row_of<T: Float + Into<f64>>(e: &Estimate<T>, status: i8) -> Row {
    Row {
        theta: e.theta_rad.into(),
        omega: e.omega_e_rad_s.into(),
        omega_mech: e.omega_mech_rad_s.into(),
        i_alpha: e.i_alpha_a.into(),
        i_beta: e.i_beta_a.into(),
        nis: e.nis.into(),
        status,
    }
}

fn status_code(s: Status) -> i8 {
    match s {
        Status::Tracking => STATUS_TRACKING,
        Status::Uncertain => STATUS_UNCERTAIN,
    }
}

impl Observer {
    /// One step; a refused sample yields the unchanged estimate with the rejected status.
    fn step(&mut self, u: [f64; 2], i: [f64; 2]) -> Row {
        fn go<T: Float + Into<f64>>(o: &mut PmsmObserver<T>, u: [T; 2], i: [T; 2]) -> Row {
            match o.step(u, i) {
                Ok(e) => row_of(&e, status_code(e.status)),
                Err(_) => row_of(&o.estimate(), STATUS_REJECTED),
            }
        }
        match self {
            Observer::F64(o) => go(o, u, i),
            Observer::F32(o) => go(o, u.map(|v| v as f32), i.map(|v| v as f32)),
        }
    }

    fn state(&self) -> [f64; 4] {
        match self {
            Observer::F64(o) => (*o.state()).into(),
            Observer::F32(o) => o.state().map(f64::from).into(),
        }
    }

    fn covariance(&self) -> [[f64; 4]; 4] {
        let m: Matrix4<f64> = match self {
            Observer::F64(o) => o.covariance(),
            Observer::F32(o) => o.covariance().map(f64::from),
        };
        core::array::from_fn(|r| core::array::from_fn(|c| m[(r, c)]))
    }
}

/// Extended Kalman filter observer of a surface PMSM (states `i_alpha, i_beta, omega_e, theta`).
///
/// `Ekf(motor, ts, *, q=None, r=None, x0=None, p0=None, discretization="lag_free",
/// dtype="float64", covariance_update="joseph")`.
///
/// Thread safety: the filter sits behind a lock that is taken with the GIL released, so
/// calls on one `Ekf` from several threads are serialized (each completes, in some order)
/// while other Python threads keep running.
#[pyclass(frozen, module = "pyfoc")]
struct Ekf {
    inner: Mutex<EkfInner>,
    ts: f64,
    dtype: &'static str,
}

/// The mutable part of an [`Ekf`].
struct EkfInner {
    observer: Observer,
    /// Voltage used to predict the first row of the next `run`.
    u_last: [f64; 2],
}

impl Ekf {
    /// Runs `f` on the filter with the GIL released and the lock held (a panic in another
    /// call cannot leave the filter half-updated: its steps commit whole, so a poisoned lock
    /// is taken over).
    fn with<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut EkfInner) -> R + Send) -> R {
        py.detach(|| {
            let mut guard = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
            f(&mut guard)
        })
    }
}

/// Output columns of `run`.
struct Columns {
    theta: Vec<f64>,
    omega: Vec<f64>,
    omega_mech: Vec<f64>,
    i_alpha: Vec<f64>,
    i_beta: Vec<f64>,
    nis: Vec<f64>,
    status: Vec<i8>,
}

impl Columns {
    /// Room for `n` rows, or MemoryError.
    fn with_capacity(n: usize) -> PyResult<Self> {
        let v = || try_vec::<f64>(n, "run output");
        Ok(Self {
            theta: v()?,
            omega: v()?,
            omega_mech: v()?,
            i_alpha: v()?,
            i_beta: v()?,
            nis: v()?,
            status: try_vec::<i8>(n, "run output")?,
        })
    }

    fn push(&mut self, r: &Row) {
        self.theta.push(r.theta);
        self.omega.push(r.omega);
        self.omega_mech.push(r.omega_mech);
        self.i_alpha.push(r.i_alpha);
        self.i_beta.push(r.i_beta);
        self.nis.push(r.nis);
        self.status.push(r.status);
    }

    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let out = PyDict::new(py);
        out.set_item("theta", PyArray1::from_vec(py, self.theta))?;
        out.set_item("omega", PyArray1::from_vec(py, self.omega))?;
        out.set_item("omega_mech", PyArray1::from_vec(py, self.omega_mech))?;
        out.set_item("i_alpha", PyArray1::from_vec(py, self.i_alpha))?;
        out.set_item("i_beta", PyArray1::from_vec(py, self.i_beta))?;
        out.set_item("nis", PyArray1::from_vec(py, self.nis))?;
        out.set_item("status", PyArray1::from_vec(py, self.status))?;
        Ok(out)
    }
}

#[allow(clippy::too_many_arguments)]
fn build<T: Float>(
    motor: &Motor,
    ts: f64,
    q: Option<[[f64; 4]; 4]>,
    r: Option<[[f64; 2]; 2]>,
    x0: Option<[f64; 4]>,
    p0: Option<[[f64; 4]; 4]>,
    disc: Discretization,
    update: CovarianceUpdate,
) -> Result<PmsmObserver<T>, ekf_core::ConfigError> {
    let conv = |v: f64| T::from_subset(&v);
    let mut cfg = ObserverConfig::new(motor.params::<T>(), conv(ts));
    cfg.discretization = disc;
    cfg.covariance_update = update;
    if let Some(q) = q {
        cfg.noise.q = Matrix4::from_fn(|i, j| conv(q[i][j]));
    }
    if let Some(r) = r {
        cfg.noise.r = Matrix2::from_fn(|i, j| conv(r[i][j]));
    }
    if let Some(x0) = x0 {
        cfg.x0 = Vector4::from_fn(|i, _| conv(x0[i]));
    }
    if let Some(p0) = p0 {
        cfg.p0 = Matrix4::from_fn(|i, j| conv(p0[i][j]));
    }
    PmsmObserver::new(&cfg)
}

#[pymethods]
impl Ekf {
    #[new]
    #[pyo3(signature = (motor, ts, *, q = None, r = None, x0 = None, p0 = None,
        discretization = "lag_free", dtype = "float64", covariance_update = "joseph"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        motor: &Motor,
        ts: f64,
        q: Option<&Bound<'_, PyAny>>,
        r: Option<&Bound<'_, PyAny>>,
        x0: Option<&Bound<'_, PyAny>>,
        p0: Option<&Bound<'_, PyAny>>,
        discretization: &str,
        dtype: &str,
        covariance_update: &str,
    ) -> PyResult<Self> {
        if motor.ld != motor.lq {
            return Err(ConfigError::new_err(format!(
                "the observer models a surface PMSM (ld == lq); got ld={} lq={}",
                motor.ld, motor.lq
            )));
        }
        let disc = match discretization {
            "lag_free" => Discretization::LagFree,
            "forward_euler" => Discretization::ForwardEuler,
            other => {
                return Err(ConfigError::new_err(format!(
                    "discretization must be 'lag_free' or 'forward_euler', got {other:?}"
                )));
            }
        };
        let update = match covariance_update {
            "joseph" => CovarianceUpdate::Joseph,
            "standard" => CovarianceUpdate::StandardSymmetrized,
            other => {
                return Err(ConfigError::new_err(format!(
                    "covariance_update must be 'joseph' or 'standard', got {other:?}"
                )));
            }
        };
        let q = q.map(|o| square::<4>(o, "q")).transpose()?;
        let r = r.map(|o| square::<2>(o, "r")).transpose()?;
        let p0 = p0.map(|o| square::<4>(o, "p0")).transpose()?;
        let x0 = x0.map(|o| vec4(o, "x0")).transpose()?;
        let cfg_err = |e: ekf_core::ConfigError| ConfigError::new_err(e.to_string());
        let (observer, dtype) = match dtype {
            "float64" => (
                Observer::F64(build(motor, ts, q, r, x0, p0, disc, update).map_err(cfg_err)?),
                "float64",
            ),
            "float32" => (
                Observer::F32(build(motor, ts, q, r, x0, p0, disc, update).map_err(cfg_err)?),
                "float32",
            ),
            other => {
                return Err(ConfigError::new_err(format!(
                    "dtype must be 'float64' or 'float32', got {other:?}"
                )));
            }
        };
        Ok(Self {
            inner: Mutex::new(EkfInner {
                observer,
                u_last: [0.0, 0.0],
            }),
            ts,
            dtype,
        })
    }

    /// Runs the filter over a record; returns a dict of `(N,)` float64 arrays `theta`, `omega`,
    /// `omega_mech`, `i_alpha`, `i_beta`, `nis` and an int8 array `status` (0 tracking,
    /// 1 uncertain, 2 rejected sample). Continues from the filter's current state: row 0
    /// predicts with `u_prev` if given, else with the last row of the previous `run` (zero
    /// for a new filter). The GIL is released while the filter runs.
    #[pyo3(signature = (u_ab, i_ab, *, u_prev = None))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        u_ab: &Bound<'py, PyAny>,
        i_ab: &Bound<'py, PyAny>,
        u_prev: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = rows2(u_ab, "u_ab")?;
        let i = rows2(i_ab, "i_ab")?;
        if u.len() != i.len() {
            return Err(PyValueError::new_err(format!(
                "u_ab and i_ab must have the same length, got {} and {}",
                u.len() / 2,
                i.len() / 2
            )));
        }
        let u_prev = u_prev.map(|p| pair(p, "u_prev")).transpose()?;
        convert::check_memory((u.len() / 2) as u128 * 49, "run output")?;
        let mut cols = Columns::with_capacity(u.len() / 2)?;
        let cols = self.with(py, move |inner| {
            let mut prev = u_prev.unwrap_or(inner.u_last);
            for (uk, ik) in u.chunks_exact(2).zip(i.chunks_exact(2)) {
                cols.push(&inner.observer.step(prev, [ik[0], ik[1]]));
                prev = [uk[0], uk[1]];
            }
            inner.u_last = prev;
            cols
        });
        cols.into_dict(py)
    }

    /// One sample: predicts with `u_prev` (voltage held over the previous period), corrects
    /// with `i` (currents sampled now). Returns a dict of floats (`theta`, `omega`,
    /// `omega_mech`, `i_alpha`, `i_beta`, `nis`) and `status` (`"tracking"`, `"uncertain"`,
    /// or `"rejected"` for a non-finite sample, in which case the state is unchanged).
    /// Does not change the voltage `run` uses for its next first row.
    fn step<'py>(
        &self,
        py: Python<'py>,
        u_prev: &Bound<'py, PyAny>,
        i: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = pair(u_prev, "u_prev")?;
        let i = pair(i, "i")?;
        let r = self.with(py, |inner| inner.observer.step(u, i));
        let out = PyDict::new(py);
        out.set_item("theta", r.theta)?;
        out.set_item("omega", r.omega)?;
        out.set_item("omega_mech", r.omega_mech)?;
        out.set_item("i_alpha", r.i_alpha)?;
        out.set_item("i_beta", r.i_beta)?;
        out.set_item("nis", r.nis)?;
        let status = match r.status {
            STATUS_TRACKING => "tracking",
            STATUS_UNCERTAIN => "uncertain",
            _ => "rejected",
        };
        out.set_item("status", status)?;
        Ok(out)
    }

    /// State `[i_alpha, i_beta, omega_e, theta]` as a `(4,)` float64 array.
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let x = self.with(py, |inner| inner.observer.state());
        PyArray1::from_slice(py, &x)
    }

    /// State covariance as a `(4, 4)` float64 array.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let p = self.with(py, |inner| inner.observer.covariance());
        let rows: Vec<Vec<f64>> = p.iter().map(|r| r.to_vec()).collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// Voltage `[u_alpha, u_beta]` that predicts the first row of the next `run`.
    #[getter]
    fn u_last<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let u = self.with(py, |inner| inner.u_last);
        PyArray1::from_slice(py, &u)
    }

    /// Sample time, s.
    #[getter]
    fn ts(&self) -> f64 {
        self.ts
    }

    /// Precision of the filter, `"float64"` or `"float32"`.
    #[getter]
    fn dtype(&self) -> &'static str {
        self.dtype
    }

    /// Replaces state (length 4) and covariance (4 x 4). `FilterError` and nothing changed
    /// when either is not finite.
    fn reset(&self, py: Python<'_>, x: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let x = vec4(x, "x")?;
        let p = square::<4>(p, "p")?;
        fn go<T: Float>(
            o: &mut PmsmObserver<T>,
            x: [f64; 4],
            p: [[f64; 4]; 4],
        ) -> Result<(), EkfError> {
            let c = |v: f64| T::from_subset(&v);
            o.reset(
                Vector4::from_fn(|i, _| c(x[i])),
                Matrix4::from_fn(|i, j| c(p[i][j])),
            )
        }
        let res = self.with(py, |inner| match &mut inner.observer {
            Observer::F64(o) => go(o, x, p),
            Observer::F32(o) => go(o, x, p),
        });
        res.map_err(|e| FilterError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!("Ekf(ts={}, dtype={:?})", self.ts, self.dtype)
    }
}

/// `pyfoc`: the sensorless PMSM observer of `ekf-core` on numpy arrays.
#[pymodule]
fn pyfoc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Motor>()?;
    m.add_class::<Ekf>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(tune::tune_qr, m)?)?;
    m.add_function(wrap_pyfunction!(tune::tune_qr_mcap, m)?)?;
    m.add_function(wrap_pyfunction!(suite::suite, m)?)?;
    m.add_function(wrap_pyfunction!(identify::identify, m)?)?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("PyfocError", py.get_type::<PyfocError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("FilterError", py.get_type::<FilterError>())?;
    m.add("STATUS_TRACKING", STATUS_TRACKING)?;
    m.add("STATUS_UNCERTAIN", STATUS_UNCERTAIN)?;
    m.add("STATUS_REJECTED", STATUS_REJECTED)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
