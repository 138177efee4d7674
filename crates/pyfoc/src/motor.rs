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
