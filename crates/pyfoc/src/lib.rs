//! Python bindings (pyo3 + numpy, built with maturin) for the `ekf-core` estimator and the
//! `pmsm-sim` simulator.
//!
//! **Status: not implemented.** This crate is a placeholder in the workspace layout; the
//! bindings are the subject of the pyfoc issue. It exports nothing and nothing tests it.
#![forbid(unsafe_code)]
#![deny(missing_docs)]
