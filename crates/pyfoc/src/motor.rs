//! `pyfoc.Motor`: the motor parameters (SI), surface or interior.

use ekf_core::{Float, MotorKind, MotorParams};
use pyo3::prelude::*;

use crate::errors::ConfigError;

/// Motor parameters (SI): `Motor(rs, ls, psi_f, pole_pairs, *, ld=None, lq=None)`.
///
/// `ls` is the inductance of a surface PMSM (`Ld = Lq = ls`); `ld` / `lq` override it per
/// axis for an interior PMSM (`ls` may then be `None`, and reads back as `(ld + lq) / 2`).
#[pyclass(frozen, skip_from_py_object, module = "pyfoc")]
#[derive(Clone, Copy)]
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
        format!(
            "Motor(rs={}, ls={}, psi_f={}, pole_pairs={}, ld={}, lq={})",
            self.rs, self.ls, self.psi_f, self.pole_pairs, self.ld, self.lq
        )
    }
}

impl Motor {
    pub(crate) fn params<T: Float>(&self) -> MotorParams<T> {
        MotorParams::salient_from_f64(self.rs, self.ld, self.lq, self.psi_f, self.pole_pairs)
    }
}
