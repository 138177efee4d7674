//! `pyfoc.Ekf`: the PMSM observer of `ekf_core::observer` on numpy arrays. Thin: the
//! configuration's spellings and checks, one step as a dict, and `run`, whose fast path is
//! the [`engine`](crate::engine)'s.

use std::sync::Mutex;

use ekf_core::nalgebra::{Matrix2, Matrix4, Vector4};
use ekf_core::saturated::{FluxOffsetTracking, MapObserver};
use ekf_core::{
    AccelerationFeedforward, CovarianceUpdate, Discretization, EkfError, Float, ObserverConfig,
    PmsmObserver, RsTracking,
};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, RealArray, fixed, record_args, square, to_vec};
use crate::engine;
use crate::errors::{ConfigError, FilterError};
use crate::motor::{MAP_POINTS, Motor};
use crate::observer::{Columns, Filter, OUTPUTS, Observer, Steps, each_observer};
use crate::replay;

/// Extended Kalman filter observer of a PMSM, surface or interior (active-flux model when
/// `ld != lq`; states `i_alpha, i_beta, omega_e, theta`).
///
/// `Ekf(motor, ts, *, q=None, r=None, x0=None, p0=None, discretization="lag_free",
/// dtype="float64", covariance_update="joseph", tracking="default", voltage_delay_s=0.0,
/// inverter_voltage_v=0.0, acceleration_feedforward=None, saturating=False,
/// input_calibration=None)`. Unset, `acceleration_feedforward` and `input_calibration` are on
/// for a constant-parameter motor (a recorded drive's defaults; the calibration off when the
/// voltage timing is told), off on a flux map; both `False` is the filter foc runs. With the
/// calibration on, the first `run` of a new filter primes it with its own rows (`prime`: the
/// voltage delay a copy's calibration handed over last over the record, and the innovation
/// level its status check learnt, are this filter's from row 0; told the `Rs` the copy ended
/// with where that matters), and the thermal link of its `Rs` tracking takes the windows'
/// `(psi_f, Rs)` as its reference once they have told `Rs` by themselves (ekf-core's
/// `ParameterTracking::link_follows_data`).
///
/// Thread safety: the filter sits behind a lock that is taken with the GIL released, so
/// calls on one `Ekf` from several threads are serialized (each completes, in some order)
/// while other Python threads keep running.
#[pyclass(frozen, module = "pyfoc")]
pub(crate) struct Ekf {
    inner: Mutex<Filter>,
    /// Sample time, s.
    #[pyo3(get)]
    ts: f64,
    /// Precision of the filter, `"float64"` or `"float32"`.
    #[pyo3(get)]
    dtype: &'static str,
    /// Whether the acceleration feedforward is on (as given, or the default).
    #[pyo3(get)]
    acceleration_feedforward: bool,
    /// Whether the online input calibration is on (as given, or the default).
    #[pyo3(get)]
    input_calibration: bool,
}

impl Ekf {
    /// Runs `f` on the filter with the GIL released and the lock held
    /// ([`Filter::with`]).
    pub(crate) fn with<R: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Filter) -> R + Send,
    ) -> R {
        Filter::with(&self.inner, py, f)
    }

    /// Primes the online input calibration with a record's rows ([`Observer::prime`]) when
    /// the calibration is on and, with `only_fresh`, the filter has filtered no row yet;
    /// either way a record with rows leaves the filter not fresh. Returns the voltage delay
    /// set (s), `None` when nothing was set.
    fn prime_rows(
        &self,
        py: Python<'_>,
        (u, i, n): (&RealArray<'_>, &RealArray<'_>, usize),
        u_prev: Option<[f64; 2]>,
        dt: Option<&[f64]>,
        only_fresh: bool,
    ) -> PyResult<Option<f64>> {
        if n == 0 {
            return Ok(None);
        }
        let wanted = self.input_calibration && (!only_fresh || self.with(py, |f| f.fresh));
        if !wanted {
            self.with(py, |f| f.fresh = false);
            return Ok(None);
        }
        convert::ensure_memory(n as u128 * 32, "the record")?;
        let (u, i) = (to_vec(u, "u_ab")?, to_vec(i, "i_ab")?);
        Ok(self.with(py, move |f| {
            let primed = if !only_fresh || f.fresh {
                f.observer.prime(u_prev.unwrap_or(f.u_last), &u, &i, dt)
            } else {
                None
            };
            f.fresh = false;
            primed
        }))
    }
}

/// What an [`Ekf`]'s constructor was given, checked for shape (the observer's configuration
/// checks the values).
struct Settings {
    q: Option<[[f64; 4]; 4]>,
    r: Option<[[f64; 2]; 2]>,
    x0: Option<[f64; 4]>,
    p0: Option<[[f64; 4]; 4]>,
    disc: Discretization,
    update: CovarianceUpdate,
    tracking: Tracking,
    voltage_delay_s: f64,
    inverter_voltage_v: f64,
    feedforward: bool,
    saturating: bool,
    input_calibration: bool,
}

/// The observer of `motor` in precision `T`: on constant parameters, or on the motor's flux
/// map (`map`, as `Observer::MapF64` / `MapF32` take it).
fn build<T: Float, O>(
    motor: &Motor,
    ts: f64,
    s: &Settings,
    plain: impl FnOnce(PmsmObserver<T>) -> O,
    map: impl FnOnce(Box<MapObserver<T, MAP_POINTS>>) -> O,
) -> PyResult<O> {
    let cfg_err = |e: ekf_core::ConfigError| ConfigError::new_err(e.to_string());
    let conv = |v: f64| T::from_subset(&v);
    let table = motor.map.as_ref();
    let flux_map = table
        .map(|t| t.map::<T>())
        .transpose()
        .map_err(ConfigError::new_err)?;
    let mut cfg = match &flux_map {
        None if s.saturating => ObserverConfig::saturating(motor.params::<T>(), conv(ts)),
        None => ObserverConfig::new(motor.params::<T>(), conv(ts)),
        Some(_) if s.saturating => {
            return Err(ConfigError::new_err(
                "saturating is for a motor told its small-signal constants; on a flux map the \
                 map is the model: leave it False",
            ));
        }
        Some(m) => {
            let p = motor.params::<T>();
            MapObserver::default_config(m, p.rs_ohm, p.pole_pairs, conv(ts))
        }
    };
    cfg.voltage_delay_s = conv(s.voltage_delay_s);
    cfg.inverter_voltage_v = conv(s.inverter_voltage_v);
    if s.feedforward {
        if flux_map.is_some() {
            return Err(ConfigError::new_err(
                "acceleration_feedforward is not available on a flux map: leave it unset or False",
            ));
        }
        cfg.acceleration_feedforward =
            Some(AccelerationFeedforward::default_for(&cfg.motor, cfg.ts_s));
    }
    cfg.discretization = s.disc;
    if s.input_calibration {
        if flux_map.is_some() {
            return Err(ConfigError::new_err(
                "input_calibration is not available on a flux map: leave it unset or False",
            ));
        }
        cfg.input_calibration = true;
        // A recorded drive's defaults: the thermal link's reference follows the windows.
        if let Some(t) = &mut cfg.parameter_tracking {
            t.link_follows_data = true;
        }
    }
    cfg.covariance_update = s.update;
    match s.tracking {
        Tracking::Default => {}
        Tracking::Flux => {
            if let Some(t) = &mut cfg.parameter_tracking {
                t.rs = RsTracking::Fixed;
            }
        }
        Tracking::Off => cfg.parameter_tracking = None,
    }
    if let Some(q) = s.q {
        cfg.noise.q = Matrix4::from_fn(|i, j| conv(q[i][j]));
    }
    if let Some(r) = s.r {
        cfg.noise.r = Matrix2::from_fn(|i, j| conv(r[i][j]));
    }
    if let Some(x0) = s.x0 {
        cfg.x0 = Vector4::from_fn(|i, _| conv(x0[i]));
    }
    if let Some(p0) = s.p0 {
        cfg.p0 = Matrix4::from_fn(|i, j| conv(p0[i][j]));
    }
    match flux_map {
        None => PmsmObserver::new(&cfg).map(plain).map_err(cfg_err),
        Some(m) => {
            cfg.parameter_tracking = None;
            let mut o = MapObserver::new(&cfg, m).map_err(cfg_err)?;
            if matches!(s.tracking, Tracking::Flux) {
                o.set_flux_offset_tracking(Some(FluxOffsetTracking::new()))
                    .map_err(cfg_err)?;
            }
            Ok(map(Box::new(o)))
        }
    }
}

/// Online parameter tracking of an [`Ekf`] (`tracking=` argument).
#[derive(Clone, Copy)]
enum Tracking {
    /// `"default"`: the flux tracked, `Rs` by the split filter with the thermal link; on a
    /// flux map, the map as it is.
    Default,
    /// `"flux"`: the flux tracked, `Rs` fixed; on a flux map, the map's `psi_d` offset learnt
    /// online (`FluxOffsetTracking::new`).
    Flux,
    /// `"off"`: the configured parameters as they are.
    Off,
}

#[pymethods]
impl Ekf {
    #[new]
    #[pyo3(signature = (motor, ts, *, q = None, r = None, x0 = None, p0 = None,
        discretization = "lag_free", dtype = "float64", covariance_update = "joseph",
        tracking = "default", voltage_delay_s = 0.0, inverter_voltage_v = 0.0,
        acceleration_feedforward = None, saturating = false, input_calibration = None))]
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
        tracking: &str,
        voltage_delay_s: f64,
        inverter_voltage_v: f64,
        acceleration_feedforward: Option<bool>,
        saturating: bool,
        input_calibration: Option<bool>,
    ) -> PyResult<Self> {
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
        let tracking = match tracking {
            "default" => Tracking::Default,
            "flux" => Tracking::Flux,
            "off" => Tracking::Off,
            other => {
                return Err(ConfigError::new_err(format!(
                    "tracking must be 'default', 'flux' or 'off', got {other:?}"
                )));
            }
        };
        let q = q.map(|o| square::<4>(o, "q")).transpose()?;
        let r = r.map(|o| square::<2>(o, "r")).transpose()?;
        let p0 = p0.map(|o| square::<4>(o, "p0")).transpose()?;
        let x0 = x0.map(|o| fixed::<4>(o, "x0")).transpose()?;
        // The defaults (unset): both on for a constant-parameter motor, the calibration off
        // when the voltage timing was told; both off on a flux map.
        let constant = motor.map.is_none();
        let timing_told = voltage_delay_s != 0.0 || inverter_voltage_v != 0.0;
        let feedforward = acceleration_feedforward.unwrap_or(constant);
        let input_calibration = input_calibration.unwrap_or(constant && !timing_told);
        let settings = Settings {
            q,
            r,
            x0,
            p0,
            disc,
            update,
            tracking,
            voltage_delay_s,
            inverter_voltage_v,
            feedforward,
            saturating,
            input_calibration,
        };
        let (observer, dtype) = match dtype {
            "float64" => (
                build(motor, ts, &settings, Observer::F64, Observer::MapF64)?,
                "float64",
            ),
            "float32" => (
                build(motor, ts, &settings, Observer::F32, Observer::MapF32)?,
                "float32",
            ),
            other => {
                return Err(ConfigError::new_err(format!(
                    "dtype must be 'float64' or 'float32', got {other:?}"
                )));
            }
        };
        Ok(Self {
            inner: Mutex::new(Filter {
                observer,
                u_last: [0.0, 0.0],
                fresh: true,
            }),
            ts,
            dtype,
            acceleration_feedforward: feedforward,
            input_calibration,
        })
    }

    /// Runs the filter over a record; returns a dict of `(N,)` float64 arrays `theta`, `omega`,
    /// `omega_mech`, `i_alpha`, `i_beta`, `nis`, `psi_f`, `rs`, `winding_temperature` (the
    /// tracked parameters) and an int8 array `status` (the values of
    /// `pyfoc.Status`). Continues from the filter's current state: row 0
    /// predicts with `u_prev` if given, else with the last row of the previous `run` (zero
    /// for a new filter). The GIL is released while the filter runs.
    ///
    /// `out`: a dict holding those ten arrays (e.g. the dict a previous `run` of the same
    /// length returned), written in place and returned, so that a record filtered in chunks
    /// allocates nothing per chunk (fresh output memory is the largest cost of `run` after
    /// the steps). Each array must be one-dimensional of length N, C-contiguous, writable, of
    /// the dtype above, and not shared with another output; no other thread may use them
    /// during the call. A bad `out` raises before the filter moves.
    ///
    /// `dt`: an `(N,)` array of the period that ended at each row, s (each finite and > 0,
    /// else ValueError naming `dt`), for logs with irregular periods (skipped cycles); the
    /// rows then run in a plain loop. Without it every period is `ts`.
    ///
    /// The first run of a new filter with the input calibration on primes it with its rows
    /// (`prime`).
    #[pyo3(signature = (u_ab, i_ab, *, u_prev = None, dt = None, out = None))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        u_ab: &Bound<'py, PyAny>,
        i_ab: &Bound<'py, PyAny>,
        u_prev: Option<&Bound<'py, PyAny>>,
        dt: Option<&Bound<'py, PyAny>>,
        out: Option<Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (u, i, n, u_prev) = record_args(u_ab, i_ab, u_prev)?;
        let dt = dt.map(|dt| replay::periods(dt, n)).transpose()?;
        let given = out
            .map(|d| engine::out_arrays(&d, n).map(|a| (a, d)))
            .transpose()?;
        // The run's memory (the per-row loop's, or the block engine's as it probes it),
        // checked before the priming moves anything.
        let row_bytes = match (&dt, &given) {
            (Some(_), _) => 40 + Columns::ROW_BYTES,
            (None, Some(_)) => 32,
            (None, None) => 32 + Columns::ROW_BYTES,
        };
        convert::ensure_memory(n as u128 * row_bytes, "run")?;
        // The first run of a new filter primes the online input calibration with its record
        // (the class docs); any run with rows ends the filter's fresh state.
        self.prime_rows(py, (&u, &i, n), u_prev, dt.as_deref(), true)?;
        if let Some(dt) = dt {
            // Per-row periods: a separate, plain loop (`replay::run_dt`); the optimized
            // path below is left as it is.
            let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
            let rows = self.with(py, move |inner| {
                let prev = u_prev.unwrap_or(inner.u_last);
                let (rows, last) = inner.observer.run_dt(prev, &u, &i, &dt);
                inner.u_last = last;
                rows
            });
            return replay::rows_to_dict(py, &rows, given);
        }
        engine::run(py, &self.inner, &u, &i, n, u_prev, given)
    }

    /// Primes the online input calibration with a whole record before filtering it in chunks:
    /// a copy of the filter runs over the rows (`u_ab`, `i_ab`, `u_prev`, `dt` as `run` takes
    /// them) and the voltage delay its calibration handed over last, with the innovation level
    /// its status check learnt, is set on this filter (the class docs); where the copy ends with
    /// an `Rs` that matters for the record, the filter is first built again told that `Rs`
    /// (`ekf_core::calibration`, "Told by the record"). The first `run` of a
    /// new filter does this with its own rows; after `prime` (or any `run` or `step`) it does
    /// not, so `prime(u, i)` then `run` on chunks of `u`, `i` gives what one `run(u, i)` gives.
    /// Returns the delay set as `voltage_delay_s` (s; minus the lead of the applied voltage),
    /// or None when no delay was set (the calibration off or a flux map: nothing set; no
    /// hand-over on the record).
    #[pyo3(signature = (u_ab, i_ab, *, u_prev = None, dt = None))]
    fn prime<'py>(
        &self,
        py: Python<'py>,
        u_ab: &Bound<'py, PyAny>,
        i_ab: &Bound<'py, PyAny>,
        u_prev: Option<&Bound<'py, PyAny>>,
        dt: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Option<f64>> {
        let (u, i, n, u_prev) = record_args(u_ab, i_ab, u_prev)?;
        let dt = dt.map(|dt| replay::periods(dt, n)).transpose()?;
        self.prime_rows(py, (&u, &i, n), u_prev, dt.as_deref(), false)
    }

    /// `omega_mech`, `i_alpha`, `i_beta`, `nis`, `psi_f`, `rs`, `winding_temperature`) and
    /// `status`, a `pyfoc.Status`
    /// (`REJECTED` for a refused sample: not finite, implausible (a corrupted sample), or so
    /// large that the step overflows; the state is then unchanged).
    /// Does not change the voltage `run` uses for its next first row.
    fn step<'py>(
        &self,
        py: Python<'py>,
        u_prev: &Bound<'py, PyAny>,
        i: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = fixed::<2>(u_prev, "u_prev")?;
        let i = fixed::<2>(i, "i")?;
        let r = self.with(py, |inner| {
            inner.fresh = false;
            inner.observer.step(u, i)
        });
        let out = PyDict::new(py);
        for (name, v) in OUTPUTS.iter().zip(r.values) {
            out.set_item(name, v)?;
        }
        out.set_item("status", r.status.to_py(py)?)?;
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

    /// Replaces state (length 4) and covariance (4 x 4). `FilterError` and nothing changed
    /// when either is not finite; `ConfigError` and nothing changed when `p` fails the
    /// constructor's check of `p0` (symmetric positive semi-definite, entries <= 1e18).
    fn reset(&self, py: Python<'_>, x: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let x = fixed::<4>(x, "x")?;
        let p = square::<4>(p, "p")?;
        if p.iter().flatten().all(|v| v.is_finite()) {
            ekf_core::observer::check_covariance(&Matrix4::from_fn(|i, j| p[i][j]))
                .map_err(|e| ConfigError::new_err(format!("p: {e}")))?;
        }
        fn go<T: Float, O: Steps<T>>(
            o: &mut O,
            x: [f64; 4],
            p: [[f64; 4]; 4],
        ) -> Result<(), EkfError> {
            let c = |v: f64| T::from_subset(&v);
            o.reset(
                Vector4::from_fn(|i, _| c(x[i])),
                Matrix4::from_fn(|i, j| c(p[i][j])),
            )
        }
        let res = self.with(
            py,
            |inner| each_observer!(&mut inner.observer, o => go(o, x, p)),
        );
        res.map_err(|e| FilterError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!("Ekf(ts={}, dtype={:?})", self.ts, self.dtype)
    }
}
