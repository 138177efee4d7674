//! `pyfoc.Status`: the status of an output row, a Python `IntEnum` built at import.

use ekf_core::Status;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyDict;

/// The status of an output row: the members of the Python `IntEnum` `pyfoc.Status`, whose
/// values are the codes of `Ekf.run`'s int8 `status` array.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[repr(i8)]
pub(crate) enum RowStatus {
    /// The angle's standard deviation is below its limit.
    Tracking = 0,
    /// The filter ran but the angle is not trustworthy (not converged, standstill).
    Uncertain = 1,
    /// The sample was rejected (a non-finite voltage or current, or an implausible voltage:
    /// ekf-core's `EkfError::ImplausibleInput`); the state was kept.
    Rejected = 2,
}

impl RowStatus {
    /// Every member with its Python name, in value order.
    const MEMBERS: [(&'static str, RowStatus); 3] = [
        ("TRACKING", RowStatus::Tracking),
        ("UNCERTAIN", RowStatus::Uncertain),
        ("REJECTED", RowStatus::Rejected),
    ];

    /// The observer's status of an accepted sample.
    pub(crate) fn of(s: Status) -> Self {
        match s {
            Status::Tracking => RowStatus::Tracking,
            Status::Uncertain => RowStatus::Uncertain,
        }
    }

    /// `pyfoc.Status(self)`.
    pub(crate) fn to_py(self, py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
        static STATUS: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
        STATUS.import(py, "pyfoc", "Status")?.call1((self as i8,))
    }

    /// The `IntEnum` class `pyfoc.Status`.
    pub(crate) fn py_class(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
        let members: Vec<(&str, i8)> = Self::MEMBERS.iter().map(|&(n, s)| (n, s as i8)).collect();
        let kw = PyDict::new(py);
        kw.set_item("module", "pyfoc")?;
        let cls = py
            .import("enum")?
            .getattr("IntEnum")?
            .call(("Status", members), Some(&kw))?;
        cls.setattr(
            "__doc__",
            "Status of an estimate: the value of each row of `Ekf.run(...)[\"status\"]` (int8) \
             and the `status` of `Ekf.step`. TRACKING: the angle's standard deviation is below \
             its limit; UNCERTAIN: the filter ran but the angle is not trustworthy yet (not \
             converged, or near standstill); REJECTED: the step was refused and the state kept (a \
             voltage or current that is not finite, beyond anything a drive applies or a motor \
             carries (a corrupted sample), or so large that the step's arithmetic overflows; a \
             singular innovation covariance; with dt, a period not in (0, 64 ts]).",
        )?;
        Ok(cls)
    }
}
