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
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyModule};

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
#[pyclass(module = "pyfoc")]
struct Ekf {
    observer: Observer,
    /// Voltage used to predict the first row of the next `run`.
    u_last: [f64; 2],
    ts: f64,
    dtype: &'static str,
}

/// Reads a config matrix given as an `n x n` array or a length-`n` diagonal.
fn square<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[[f64; N]; N]> {
    let a = float_array(obj, name)?;
    let shape = a.shape().to_vec();
    let v: Vec<f64> = a.to_vec()?;
    match shape.as_slice() {
        [n] if *n == N => Ok(core::array::from_fn(|r| {
            core::array::from_fn(|c| if r == c { v[r] } else { 0.0 })
        })),
        [n, m] if *n == N && *m == N => Ok(core::array::from_fn(|r| {
            core::array::from_fn(|c| v[r * N + c])
        })),
        _ => Err(PyValueError::new_err(format!(
            "{name}: expected a ({N}, {N}) matrix or a length-{N} diagonal, got shape {shape:?}"
        ))),
    }
}

/// `numpy.ascontiguousarray(obj, dtype=float64)` for real numeric input; TypeError otherwise.
fn float_array<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let arr = np
        .call_method1("asarray", (obj,))
        .map_err(|e| PyTypeError::new_err(format!("{name}: not convertible to an array: {e}")))?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "f" | "i" | "u") {
        let dtype = arr.getattr("dtype")?.str()?.to_string();
        return Err(PyTypeError::new_err(format!(
            "{name}: expected a real numeric array, got dtype {dtype}"
        )));
    }
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", np.getattr("float64")?)?;
    let arr = np.call_method("ascontiguousarray", (arr,), Some(&kwargs))?;
    Ok(arr.cast_into::<numpy::PyArrayDyn<f64>>()?)
}

/// An `(N, 2)` float array, flattened row-major (copied, so the GIL can be released safely);
/// ValueError naming the argument for another shape.
fn rows2(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let a = float_array(obj, name)?;
    let shape = a.shape().to_vec();
    if shape.len() != 2 || shape[1] != 2 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape (N, 2), got {shape:?}"
        )));
    }
    Ok(a.to_vec()?)
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
    fn with_capacity(n: usize) -> Self {
        Self {
            theta: Vec::with_capacity(n),
            omega: Vec::with_capacity(n),
            omega_mech: Vec::with_capacity(n),
            i_alpha: Vec::with_capacity(n),
            i_beta: Vec::with_capacity(n),
            nis: Vec::with_capacity(n),
            status: Vec::with_capacity(n),
        }
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

/// A length-2 vector.
fn pair(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 2]> {
    let a = float_array(obj, name)?;
    let v: Vec<f64> = a.to_vec()?;
    match v.as_slice() {
        [a, b] => Ok([*a, *b]),
        _ => Err(PyValueError::new_err(format!(
            "{name}: expected 2 values, got shape {:?}",
            a.shape()
        ))),
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
        let x0 = match x0 {
            None => None,
            Some(o) => {
                let v: Vec<f64> = float_array(o, "x0")?.to_vec()?;
                Some(<[f64; 4]>::try_from(v.as_slice()).map_err(|_| {
                    PyValueError::new_err(format!("x0: expected 4 values, got {}", v.len()))
                })?)
            }
        };
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
            observer,
            u_last: [0.0, 0.0],
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
        &mut self,
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
        if let Some(p) = u_prev {
            self.u_last = pair(p, "u_prev")?;
        }
        let first = self.u_last;
        let observer = &mut self.observer;
        let (cols, last) = py.detach(|| {
            let mut cols = Columns::with_capacity(u.len() / 2);
            let mut prev = first;
            for (uk, ik) in u.chunks_exact(2).zip(i.chunks_exact(2)) {
                cols.push(&observer.step(prev, [ik[0], ik[1]]));
                prev = [uk[0], uk[1]];
            }
            (cols, prev)
        });
        self.u_last = last;
        cols.into_dict(py)
    }

    /// One sample: predicts with `u_prev` (voltage held over the previous period), corrects
    /// with `i` (currents sampled now). Returns a dict of floats (`theta`, `omega`,
    /// `omega_mech`, `i_alpha`, `i_beta`, `nis`) and `status` (`"tracking"`, `"uncertain"`,
    /// or `"rejected"` for a non-finite sample, in which case the state is unchanged).
    /// Does not change the voltage `run` uses for its next first row.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        u_prev: &Bound<'py, PyAny>,
        i: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = pair(u_prev, "u_prev")?;
        let i = pair(i, "i")?;
        let r = self.observer.step(u, i);
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
        PyArray1::from_slice(py, &self.observer.state())
    }

    /// State covariance as a `(4, 4)` float64 array.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self
            .observer
            .covariance()
            .iter()
            .map(|r| r.to_vec())
            .collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// Voltage `[u_alpha, u_beta]` that predicts the first row of the next `run`.
    #[getter]
    fn u_last<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.u_last)
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
    fn reset(&mut self, x: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let xv: Vec<f64> = float_array(x, "x")?.to_vec()?;
        let x = <[f64; 4]>::try_from(xv.as_slice()).map_err(|_| {
            PyValueError::new_err(format!("x: expected 4 values, got {}", xv.len()))
        })?;
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
        let res = match &mut self.observer {
            Observer::F64(o) => go(o, x, p),
            Observer::F32(o) => go(o, x, p),
        };
        res.map_err(|e| FilterError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!("Ekf(ts={}, dtype={:?})", self.ts, self.dtype)
    }
}

/// Reads a scenario: a preset name, a path to a TOML file, or a dict with the TOML layout.
fn scenario_of(obj: &Bound<'_, PyAny>) -> PyResult<pmsm_sim::scenario::Scenario> {
    use pmsm_sim::scenario::Scenario;
    let py = obj.py();
    let err = |e: pmsm_sim::SimError| ConfigError::new_err(e.to_string());
    if obj.is_instance_of::<PyDict>() {
        let text: String = py
            .import("json")?
            .call_method1("dumps", (obj,))?
            .extract()?;
        let sc: Scenario = serde_json::from_str(&text)
            .map_err(|e| ConfigError::new_err(format!("scenario dict: {e}")))?;
        sc.validate()
            .map_err(|e| ConfigError::new_err(format!("scenario dict: {e}")))?;
        return Ok(sc);
    }
    let text: String = py
        .import("os")?
        .call_method1("fspath", (obj,))
        .and_then(|p| p.extract())
        .map_err(|_| PyTypeError::new_err("scenario: expected a preset name, a path or a dict"))?;
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
    let put2 =
        |name: &str, f: &dyn Fn(&pmsm_sim::sim::Sample) -> Vec<f64>, w: usize| -> PyResult<()> {
            let rows: Vec<Vec<f64>> = s.iter().map(f).collect();
            let arr = if rows.is_empty() {
                PyArray2::zeros(py, [0, w], false)
            } else {
                PyArray2::from_vec2(py, &rows)?
            };
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
/// The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (scenario = None, *, duration = None, seed = None))]
fn simulate<'py>(
    py: Python<'py>,
    scenario: Option<&Bound<'py, PyAny>>,
    duration: Option<f64>,
    seed: Option<u64>,
) -> PyResult<Bound<'py, PyDict>> {
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
        sc.seed = s;
    }
    let out = py
        .detach(|| {
            pmsm_sim::sim::run_with(
                &sc,
                pmsm_sim::sim::RunOptions {
                    record_trace: true,
                    ..Default::default()
                },
            )
        })
        .map_err(|e| match e {
            pmsm_sim::SimError::Scenario { .. } => ConfigError::new_err(e.to_string()),
            other => SimulationError::new_err(other.to_string()),
        })?;
    let d = trace_dict(py, &out)?;
    let metrics = serde_json::to_string(&out.metrics)
        .map_err(|e| SimulationError::new_err(format!("metrics: {e}")))?;
    d.set_item(
        "metrics",
        py.import("json")?.call_method1("loads", (metrics,))?,
    )?;
    d.set_item("completed", out.end.is_completed())?;
    d.set_item("scenario", sc.name.clone())?;
    Ok(d)
}

/// `pyfoc`: the sensorless PMSM observer of `ekf-core` on numpy arrays.
#[pymodule]
fn pyfoc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Motor>()?;
    m.add_class::<Ekf>()?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
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
