//! Field-oriented control for a PMSM around the `ekf-core` observer, `no_std`, for Cortex-M4F.
//!
//! **Status:** only the reference-frame transforms exist so far ([`transforms`]); current and
//! speed loops, SVPWM, start-up and faults are the subject of the foc issue and are not here yet.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod transforms;

pub use transforms::{Abc, AlphaBeta, Dq};
