//! `pyfoc._bench`: hooks for the benchmarks in `crates/pyfoc/bench` (private: not part of the
//! API, free to change).

use ekf_core::Float;
use numpy::PyUntypedArrayMethods;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::convert::{rows2, to_vec};
use crate::ekf::Ekf;
use crate::observer::{Steps, each_observer};

/// Seconds that the observer's own steps take over the rows of `u_ab`, `i_ab` (the loop of
/// `Ekf.run` without its inputs' checks, copies and output columns), on a copy of `ekf`'s
/// filter (its state is not changed).
#[pyfunction]
fn time_steps(
    py: Python<'_>,
    ekf: &Ekf,
    u_ab: &Bound<'_, PyAny>,
    i_ab: &Bound<'_, PyAny>,
) -> PyResult<f64> {
    let (u, i) = (rows2(u_ab, "u_ab")?, rows2(i_ab, "i_ab")?);
    if u.shape()[0] != i.shape()[0] {
        return Err(PyValueError::new_err(
            "u_ab and i_ab must have the same length",
        ));
    }
    let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
    let mut obs = ekf.with(py, |inner| inner.observer.clone());
    Ok(py.detach(move || {
        fn go<T: Float + Into<f64>, O: Steps<T>>(o: &mut O, u: &[f64], i: &[f64]) -> f64 {
            let c = |v: f64| T::from_subset(&v);
            let mut prev = [c(0.0); 2];
            let mut acc = 0.0;
            let t0 = std::time::Instant::now();
            for (uk, ik) in u.chunks_exact(2).zip(i.chunks_exact(2)) {
                if let Ok(e) = o.step(prev, [c(ik[0]), c(ik[1])]) {
                    acc += e.theta_rad.into();
                }
                prev = [c(uk[0]), c(uk[1])];
            }
            let dt = t0.elapsed().as_secs_f64();
            std::hint::black_box(acc);
            dt
        }
        each_observer!(&mut obs, o => go(o, &u, &i))
    }))
}

/// The submodule `_bench`, imported as `from pyfoc._bench import time_steps` (registered in
/// `sys.modules`; an attribute of the native module only, so neither in `pyfoc.__all__` nor
/// re-exported by the package).
pub(crate) fn add_to(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    let sub = PyModule::new(py, "_bench")?;
    sub.add_function(wrap_pyfunction!(time_steps, &sub)?)?;
    m.setattr("_bench", &sub)?;
    py.import("sys")?
        .getattr("modules")?
        .set_item("pyfoc._bench", &sub)?;
    Ok(())
}
