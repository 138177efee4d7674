//! Errors of a simulation run.

use core::fmt;

use ekf_core::{ConfigError, EkfError};

/// Why a run could not be done.
#[derive(Clone, Debug, PartialEq)]
pub enum SimError {
    /// The scenario is invalid (the message says which field and why).
    Scenario(String),
    /// The observer refused its configuration.
    ObserverConfig(ConfigError),
    /// The observer failed at sample `k`.
    Observer {
        /// Sample index.
        k: usize,
        /// The observer's error.
        error: EkfError,
    },
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Scenario(why) => write!(f, "invalid scenario: {why}"),
            SimError::ObserverConfig(e) => write!(f, "observer configuration refused: {e}"),
            SimError::Observer { k, error } => write!(f, "observer failed at sample {k}: {error}"),
        }
    }
}

impl std::error::Error for SimError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            SimError::Scenario(_) => None,
            SimError::ObserverConfig(e) => Some(e),
            SimError::Observer { error, .. } => Some(error),
        }
    }
}
