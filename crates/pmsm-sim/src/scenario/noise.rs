//! `[observer_noise]`: the noise covariances of the simulator's `ekf-core` observer (the
//! table's "EKF f64 (sim)"), in exactly the form `pmsm-sim tune` prints, so that its proposal
//! can be pasted into a scenario file.
//!
//! | key | meaning | used |
//! |---|---|---|
//! | `q` | process noise `Q` (4 x 4: A^2, A^2, (rad/s)^2, rad^2 per sample) | yes: `ObserverConfig::noise.q` |
//! | `r` | measurement noise `R` (2 x 2, alpha-beta, A^2) | yes: `ObserverConfig::noise.r` |
//! | `sigma_z`, `rho_z`, `sigma_i`, `sigma_w`, `sigma_th` | the same proposal in `ekf_core::noise`'s normalized units | no: a record of the tuner's result, accepted and kept |
//!
//! Without the table the observer keeps `ObserverConfig::new`'s noise (scaled to the motor).
//! `q` and `r` are checked as the observer checks them (symmetric, positive semi-definite,
//! `R` positive definite, entries at most 1e18); the reference filter and `foc`'s own
//! observer keep their noise.

use ekf_core::nalgebra::{Matrix2, Matrix4};
use ekf_core::noise::NoiseCovariances;
use serde::{Deserialize, Serialize};

/// `[observer_noise]` (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObserverNoise {
    /// Process noise covariance `Q` (4 x 4), rows.
    pub q: [[f64; 4]; 4],
    /// Measurement noise covariance `R` (2 x 2), A^2, rows.
    pub r: [[f64; 2]; 2],
    /// Normalized measurement sigmas (alpha, beta); a record, not used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_z: Option<[f64; 2]>,
    /// Normalized measurement correlation; a record, not used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rho_z: Option<f64>,
    /// Normalized current process sigma; a record, not used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_i: Option<f64>,
    /// Normalized speed process sigma; a record, not used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_w: Option<f64>,
    /// Angle process sigma; a record, not used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_th: Option<f64>,
}

impl ObserverNoise {
    /// `Q` and `R` as the observer takes them.
    pub fn covariances(&self) -> NoiseCovariances<f64> {
        NoiseCovariances {
            q: Matrix4::from_fn(|r, c| self.q[r][c]),
            r: Matrix2::from_fn(|r, c| self.r[r][c]),
        }
    }
}
