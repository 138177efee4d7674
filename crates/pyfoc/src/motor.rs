//! `pyfoc.Motor`: the motor parameters (SI), surface or interior, or a saturating motor's
//! flux map.

use std::sync::Arc;

use ekf_core::{Float, FluxMap, MotorKind, MotorParams};
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;

use crate::convert::{real_array, to_vec};
use crate::errors::ConfigError;

/// Largest number of grid points per axis of a flux map.
pub(crate) const MAP_POINTS: usize = 32;

/// A flux map as given (`Motor.from_flux_map`): ascending axes (A) and row-major fluxes (Wb).
pub(crate) struct MapTable {
    pub(crate) i_d: Vec<f64>,
    pub(crate) i_q: Vec<f64>,
    pub(crate) psi_d: Vec<f64>,
    pub(crate) psi_q: Vec<f64>,
}

impl MapTable {
    /// The interpolating map in the filter's precision (checked when the motor was made).
    pub(crate) fn map<T: Float>(&self) -> Result<FluxMap<T, MAP_POINTS>, String> {
        let c = |v: &[f64]| v.iter().map(|x| T::from_subset(x)).collect::<Vec<T>>();
        FluxMap::new(
            &c(&self.i_d),
            &c(&self.i_q),
            &c(&self.psi_d),
            &c(&self.psi_q),
        )
        .map_err(|e| format!("flux map: {e}"))
    }
}

/// Motor parameters (SI): `Motor(rs, ls, psi_f, pole_pairs, *, ld=None, lq=None)`.
///
/// `ls` is the inductance of a surface PMSM (`Ld = Lq = ls`); `ld` / `lq` override it per
/// axis for an interior PMSM (`ls` may then be `None`, and reads back as `(ld + lq) / 2`).
#[pyclass(frozen, skip_from_py_object, module = "pyfoc")]
#[derive(Clone)]
pub(crate) struct Motor {
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
    /// The flux map of a saturating motor (`from_flux_map`); `ld`, `lq`, `psi_f` are then its
    /// small-signal values at zero current.
    pub(crate) map: Option<Arc<MapTable>>,
}

#[pymethods]
impl Motor {
    #[new]
    #[pyo3(signature = (rs, ls, psi_f, pole_pairs, *, ld = None, lq = None))]
    fn new(
        rs: f64,
        ls: Option<f64>,
        psi_f: f64,
        pole_pairs: i64,
        ld: Option<f64>,
        lq: Option<f64>,
    ) -> PyResult<Self> {
        let pole_pairs = u32::try_from(pole_pairs).map_err(|_| {
            ConfigError::new_err(format!("pole_pairs must be >= 1, got {pole_pairs}"))
        })?;
        let (ld, lq) = match (ld.or(ls), lq.or(ls)) {
            (Some(ld), Some(lq)) => (ld, lq),
            _ => {
                return Err(ConfigError::new_err(
                    "give ls (surface PMSM) or both ld and lq (interior PMSM)",
                ));
            }
        };
        let m = Self {
            rs,
            ls: ls.unwrap_or(0.5 * (ld + lq)),
            psi_f,
            pole_pairs,
            ld,
            lq,
            map: None,
        };
        if !(m.ls.is_finite() && m.ls > 0.0) {
            return Err(ConfigError::new_err(format!(
                "ls must be positive and finite, got {}",
                m.ls
            )));
        }
        m.params::<f64>()
            .validate()
            .map_err(|e| ConfigError::new_err(e.to_string()))?;
        Ok(m)
    }

    /// Motor from datasheet values (`ekf_core::catalog::datasheet` states the conventions):
    /// line-to-line resistance and inductance of a star winding (halved to per phase), and
    /// the flux from `kv_rpm_per_v` (rpm per volt of line-to-line peak back-EMF) or
    /// `kt_nm_per_a` (N m per peak phase ampere): exactly one of the two.
    #[staticmethod]
    #[pyo3(signature = (*, pole_pairs, r_ll, l_ll = None, kv_rpm_per_v = None, kt_nm_per_a = None, ld_ll = None, lq_ll = None))]
    #[allow(clippy::too_many_arguments)]
    fn from_datasheet(
        pole_pairs: i64,
        r_ll: f64,
        l_ll: Option<f64>,
        kv_rpm_per_v: Option<f64>,
        kt_nm_per_a: Option<f64>,
        ld_ll: Option<f64>,
        lq_ll: Option<f64>,
    ) -> PyResult<Self> {
        use ekf_core::catalog::datasheet;
        let pp = u32::try_from(pole_pairs)
            .ok()
            .filter(|&p| p >= 1)
            .ok_or_else(|| {
                ConfigError::new_err(format!("pole_pairs must be >= 1, got {pole_pairs}"))
            })?;
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(ConfigError::new_err(format!(
                    "{name} must be positive and finite, got {v}"
                )))
            }
        };
        let psi_f = match (kv_rpm_per_v, kt_nm_per_a) {
            (Some(kv), None) => datasheet::psi_f_from_kv(positive("kv_rpm_per_v", kv)?, pp),
            (None, Some(kt)) => datasheet::psi_f_from_kt(positive("kt_nm_per_a", kt)?, pp),
            _ => {
                return Err(ConfigError::new_err(
                    "give exactly one of kv_rpm_per_v and kt_nm_per_a",
                ));
            }
        };
        let (ld, lq) = match (l_ll, ld_ll, lq_ll) {
            (Some(l), None, None) => {
                let l = datasheet::phase_from_line_to_line(positive("l_ll", l)?);
                (l, l)
            }
            (None, Some(d), Some(q)) => (
                datasheet::phase_from_line_to_line(positive("ld_ll", d)?),
                datasheet::phase_from_line_to_line(positive("lq_ll", q)?),
            ),
            _ => {
                return Err(ConfigError::new_err(
                    "give l_ll (surface motor) or both ld_ll and lq_ll (interior motor)",
                ));
            }
        };
        let rs = datasheet::phase_from_line_to_line(positive("r_ll", r_ll)?);
        Self::new(rs, None, psi_f, i64::from(pp), Some(ld), Some(lq))
    }

    /// A saturating motor from its flux maps: `psi_d(i_d, i_q)` and `psi_q(i_d, i_q)` on a
    /// current grid. `i_d` of shape `(n_d,)` and `i_q` of shape `(n_q,)` ascending, A;
    /// `psi_d` and `psi_q` of shape `(n_d, n_q)`, Wb (`psi[a, b]` at `(i_d[a], i_q[b])`),
    /// magnet flux included in `psi_d`. At most 32 points per axis. Refused with `ConfigError`
    /// naming the problem: wrong shapes, non-finite values, axes not ascending, `psi_d` not
    /// rising with `i_d` or `psi_q` with `i_q`, an incremental inductance matrix that is not
    /// positive definite at a node. `ld`, `lq`, `psi_f` read back the small-signal values at
    /// zero current. `Ekf` on this motor runs the observer on the map (no parameter
    /// tracking: the map is the model); `FluxObserver` the flux observer on the map.
    #[staticmethod]
    #[pyo3(signature = (rs, pole_pairs, i_d, i_q, psi_d, psi_q))]
    fn from_flux_map(
        rs: f64,
        pole_pairs: i64,
        i_d: &Bound<'_, PyAny>,
        i_q: &Bound<'_, PyAny>,
        psi_d: &Bound<'_, PyAny>,
        psi_q: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let axis = |obj: &Bound<'_, PyAny>, name: &str| -> PyResult<Vec<f64>> {
            let a = real_array(obj, name)?;
            if a.shape().len() != 1 {
                return Err(ConfigError::new_err(format!(
                    "{name} must have shape (n,), got {:?}",
                    a.shape()
                )));
            }
            to_vec(&a, name)
        };
        let (i_d, i_q) = (axis(i_d, "i_d")?, axis(i_q, "i_q")?);
        for (name, v) in [("i_d", &i_d), ("i_q", &i_q)] {
            if v.len() > MAP_POINTS {
                return Err(ConfigError::new_err(format!(
                    "flux map too large: {name} has {} points, at most {MAP_POINTS}",
                    v.len()
                )));
            }
        }
        let grid = |obj: &Bound<'_, PyAny>, name: &str| -> PyResult<Vec<f64>> {
            let a = real_array(obj, name)?;
            if a.shape() != [i_d.len(), i_q.len()] {
                return Err(ConfigError::new_err(format!(
                    "{name} must have shape (len(i_d), len(i_q)) = ({}, {}), got {:?}",
                    i_d.len(),
                    i_q.len(),
                    a.shape()
                )));
            }
            to_vec(&a, name)
        };
        let table = MapTable {
            psi_d: grid(psi_d, "psi_d")?,
            psi_q: grid(psi_q, "psi_q")?,
            i_d,
            i_q,
        };
        let map = table.map::<f64>().map_err(ConfigError::new_err)?;
        let pp = u32::try_from(pole_pairs).unwrap_or(0);
        let small = ekf_core::saturated::small_signal(&map, rs, pp);
        let mut m = Self::new(
            rs,
            None,
            small.psi_f_wb,
            pole_pairs,
            Some(small.ld_h),
            Some(small.lq_h),
        )?;
        m.map = Some(Arc::new(table));
        Ok(m)
    }

    /// Whether the motor is given by a flux map (`from_flux_map`).
    #[getter]
    fn has_flux_map(&self) -> bool {
        self.map.is_some()
    }

    /// `"surface"`, `"interior"` (Lq > Ld) or `"inverse_salient"` (Lq < Ld: accepted, but
    /// check that Ld and Lq are not swapped).
    #[getter]
    fn kind(&self) -> &'static str {
        match self.params::<f64>().kind() {
            MotorKind::Surface => "surface",
            MotorKind::Interior => "interior",
            MotorKind::InverseSalient => "inverse_salient",
        }
    }

    fn __repr__(&self) -> String {
        match &self.map {
            None => format!(
                "Motor(rs={}, ls={}, psi_f={}, pole_pairs={}, ld={}, lq={})",
                self.rs, self.ls, self.psi_f, self.pole_pairs, self.ld, self.lq
            ),
            Some(t) => format!(
                "Motor.from_flux_map(rs={}, pole_pairs={}, {} x {} grid; small-signal ld={}, \
                 lq={}, psi_f={})",
                self.rs,
                self.pole_pairs,
                t.i_d.len(),
                t.i_q.len(),
                self.ld,
                self.lq,
                self.psi_f
            ),
        }
    }
}

impl Motor {
    pub(crate) fn params<T: Float>(&self) -> MotorParams<T> {
        MotorParams::salient_from_f64(self.rs, self.ld, self.lq, self.psi_f, self.pole_pairs)
    }
}
