//! Errors of the simulator.

use ekf_core::ConfigError;
use thiserror::Error;

/// A scenario field whose value is refused, and why.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("{field}: {problem}")]
pub struct FieldError {
    /// Dotted path of the field, e.g. `inverter.dead_time_s`.
    pub field: String,
    /// What is wrong with it.
    pub problem: String,
}

impl FieldError {
    /// A field error.
    pub fn new(field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            problem: problem.into(),
        }
    }
}

/// Why the simulator could not do what it was asked.
#[derive(Debug, Error)]
pub enum SimError {
    /// A scenario file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A scenario is malformed, incomplete or physically invalid.
    #[error("{file}: {field}: {problem}")]
    Scenario {
        /// The file (or `preset NAME` for a built-in scenario).
        file: String,
        /// Dotted path of the offending field (`-` when the file as a whole is unreadable).
        field: String,
        /// What is wrong.
        problem: String,
    },
    /// No built-in scenario has this name.
    #[error("no built-in scenario named {name:?} (known: {known})")]
    UnknownPreset {
        /// The name asked for.
        name: String,
        /// The known names, comma separated.
        known: String,
    },
    /// The observer refused its configuration.
    #[error("observer configuration refused: {0}")]
    ObserverConfig(#[from] ConfigError),
    /// The simulation stopped before its end (non-finite state, observer failure, log
    /// failure); the outputs written so far are complete and readable.
    #[error("run stopped at t = {t_s} s: {reason}")]
    Stopped {
        /// Simulated time of the stop, s.
        t_s: f64,
        /// What happened.
        reason: String,
    },
    /// Writing an output file failed.
    #[error("{path}: {message}")]
    Output {
        /// The file.
        path: String,
        /// What failed.
        message: String,
    },
}

/// `x` as a TOML float, shortest round-trip: plain decimals (`2.875`, `0.001`, `1.0`) from
/// 1e-4 to 1e16, exponent form outside (`1.5e-9`); never Rust's `2.875000e0`. The numbers of
/// error messages and of tune's proposals.
pub fn plain(x: f64) -> String {
    let a = x.abs();
    let s = if a == 0.0 || (1e-4..1e16).contains(&a) || !a.is_finite() {
        format!("{x}")
    } else {
        format!("{x:e}")
    };
    if x.is_finite() && !s.contains(['.', 'e']) {
        format!("{s}.0")
    } else {
        s
    }
}
