//! Desktop simulator of a sensorless PMSM drive (first version).
//!
//! A surface PMSM plant in alpha-beta with its mechanics ([`plant`]), a noisy current sensor
//! ([`sensors`]), a **sensored** field-oriented controller that drives the plant through a
//! scenario ([`controller`], [`scenario`]), and the project's EKF observer (`ekf-core`) running
//! alongside, open loop, scored by the metrics of `design.md` section 5 ([`metrics`],
//! [`report`]). [`sim::run`] ties them together, one PWM period at a time, with the timing of
//! `design.md` section 4.
//!
//! Not yet here (each will get its own module): TOML scenarios, MCAP logs, plots, an inverter
//! model (dead time, SVPWM), a computation delay, and closing the loop on the observer with
//! the `foc` crate.
//!
//! ```no_run
//! use pmsm_sim::{metrics::RunMetrics, report, scenario::Scenario, sim};
//!
//! let scenario = Scenario::default_servo();
//! let run = sim::run(&scenario)?;
//! println!("{}", report::table(&RunMetrics::compute(&scenario, &run)));
//! # Ok::<(), pmsm_sim::SimError>(())
//! ```

#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod controller;
mod error;
pub mod metrics;
pub mod plant;
pub mod report;
pub mod scenario;
pub mod sensors;
pub mod sim;

pub use error::SimError;
