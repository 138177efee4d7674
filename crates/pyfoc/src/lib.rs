//! Python bindings for the `ekf-core` observer and the `pmsm-sim` simulator.
//!
//! Thin by design: wrapper types and conversions only; every algorithm lives in the Rust
//! crates. Arrays in and out follow the project's timing convention: row `k` of `u_ab` is the
//! voltage held over `[t_k, t_k+1)`, row `k` of `i_ab` the currents sampled at `t_k`, and row
//! `k` of the output the estimate at `t_k` (predicted with `u_ab[k-1]`, corrected with
//! `i_ab[k]`).
#![forbid(unsafe_code)]
#![deny(missing_docs)]
//!
//! `lib.rs` registers the module; each Python class has its file: `Motor` (`motor.rs`),
//! `Ekf` (`ekf.rs`), `FluxObserver` (`replay.rs`, with `read_log`), `DriveObserver`
//! (`drive.rs`), `Status` (`status.rs`); the exceptions are in `errors.rs`. The fast path of
//! `Ekf.run` (buffer pool, 2-thread pipeline, page-mapping thread) is `engine`; the rows
//! themselves are `observer`'s.

use pyo3::prelude::*;

mod bench;
mod convert;
mod drive;
mod ekf;
mod engine;
mod errors;
mod identify;
mod motor;
mod observer;
mod replay;
mod simulate;
mod status;
mod suite;
mod sweep;
mod tune;

use errors::{ConfigError, FilterError, PyfocError, SimulationError};
use status::RowStatus;

/// `pyfoc`: the sensorless PMSM observer of `ekf-core` on numpy arrays.
#[pymodule]
fn pyfoc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<motor::Motor>()?;
    m.add_class::<ekf::Ekf>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(tune::tune_qr, m)?)?;
    m.add_function(wrap_pyfunction!(tune::tune_qr_mcap, m)?)?;
    m.add_function(wrap_pyfunction!(suite::suite, m)?)?;
    m.add_function(wrap_pyfunction!(sweep::sweep_plan, m)?)?;
    m.add_function(wrap_pyfunction!(sweep::sweep_run, m)?)?;
    m.add_function(wrap_pyfunction!(identify::identify, m)?)?;
    m.add_function(wrap_pyfunction!(engine::clear_buffer_pool, m)?)?;
    m.add_function(wrap_pyfunction!(replay::read_log, m)?)?;
    m.add_function(wrap_pyfunction!(replay::flux_check, m)?)?;
    m.add_function(wrap_pyfunction!(replay::speed_bands, m)?)?;
    m.add_class::<replay::FluxObserver>()?;
    m.add_class::<drive::DriveObserver>()?;
    m.add("LogError", py.get_type::<replay::LogError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("PyfocError", py.get_type::<PyfocError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("FilterError", py.get_type::<FilterError>())?;
    m.add("Status", RowStatus::py_class(py)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    bench::add_to(m)?;
    Ok(())
}
