//! Process and measurement noise covariances `Q` (4 x 4) and `R` (2 x 2) of the PMSM observer.
//!
//! # Why the seed's numbers do not carry over
//!
//! The seed's `Q = diag(0.01, 0.01, 10, 0.01)`, `R = diag(0.1, 0.1)` are SI numbers for one motor
//! and one sample time ([`NoiseCovariances::seed`]). On a motor with a ten times smaller
//! inductance or flux, or at another `Ts`, the same numbers mean something else entirely.
//!
//! # The scaling rule of the default ([`NoiseCovariances::scaled`])
//!
//! Write the currents in units of the characteristic current `I_c = psi_f / Ls` and the speed
//! in radians per sample, `w' = w_e Ts`. The forward-Euler current equation becomes
//!
//! ```text
//! i'_{k+1} = (1 - Rs Ts / Ls) i'_k + (Ts / psi_f) u_k + w'_k [sin th_k, -cos th_k]
//! ```
//!
//! so in these units every motor looks alike: the back-EMF moves the current by exactly `w'`
//! per sample, and the only motor-dependent numbers left are `Rs Ts / Ls` and `w'`. The default
//! therefore fixes the noise in these normalized units, and converts back to SI:
//!
//! ```text
//! R      = (sigma_z  I_c)^2  I2        sigma_z  = 2.0e-3  (sensor noise, fraction of I_c)
//! Q_ii   = (sigma_i  I_c)^2            sigma_i  = 1.0e-3  (current model error per sample)
//! Q_ww   = (sigma_w / Ts)^2            sigma_w  = 2.0e-4  (speed random walk, rad/sample per sample)
//! Q_thth =  sigma_th^2                 sigma_th = 1.0e-4  (angle random walk, rad per sample)
//! ```
//!
//! With the same normalized numbers the filter's gains, bandwidths and accuracy depend only on
//! `w_e Ts` and `Rs Ts / Ls`, not on the size of the motor; the tests run the same default on
//! the three reference motors of `design.md` section 6. For the servo motor at 10 kHz,
//! `I_c = 20.6 A` and the default is `R = 1.7e-3 A^2` (sigma 41 mA),
//! `Q = diag(4.2e-4, 4.2e-4, 4.0, 1e-8)`.
//!
//! When the current-sensing noise is known, [`NoiseCovariances::scaled_with_sensor_noise`] sets
//! `R` from it and keeps the ratio `Q_ii / R` of the default.

use nalgebra::{SMatrix, SVector};

use crate::{Float, MotorParams, to_t};

/// Normalized sensor noise standard deviation, fraction of `I_c` (see the module docs).
pub const SIGMA_Z_NORM: f64 = 2.0e-3;
/// Normalized current process noise standard deviation per sample, fraction of `I_c`.
pub const SIGMA_I_NORM: f64 = 1.0e-3;
/// Normalized speed random walk, `w_e Ts` radians per sample, per sample.
pub const SIGMA_W_NORM: f64 = 2.0e-4;
/// Angle random walk, radians per sample.
pub const SIGMA_TH: f64 = 1.0e-4;

/// Process noise `Q` (4 x 4, state order `[i_a, i_b, w_e, theta]`) and measurement noise `R`
/// (2 x 2, `[i_a, i_b]`), SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseCovariances<T: Float> {
    /// Process noise covariance `Q` (4 x 4): A^2, A^2, (rad/s)^2, rad^2 per sample.
    pub q: SMatrix<T, 4, 4>,
    /// Measurement noise covariance `R` (2 x 2), A^2.
    pub r: SMatrix<T, 2, 2>,
}

impl<T: Float> NoiseCovariances<T> {
    /// Diagonal `Q = diag(q)` and `R = diag(r)`.
    pub fn from_diagonals(q: [T; 4], r: [T; 2]) -> Self {
        Self {
            q: SMatrix::from_diagonal(&SVector::from(q)),
            r: SMatrix::from_diagonal(&SVector::from(r)),
        }
    }

    /// The seed's tuning, `Q = diag(0.01, 0.01, 10, 0.01)`, `R = diag(0.1, 0.1)`, in SI units
    /// whatever the motor and `Ts` (seed section "EKF tuning").
    pub fn seed() -> Self {
        Self::from_diagonals(
            [to_t(0.01), to_t(0.01), to_t(10.0), to_t(0.01)],
            [to_t(0.1), to_t(0.1)],
        )
    }

    /// The default, scaled from the motor and the sample time (module docs give the rule).
    pub fn scaled(motor: &MotorParams<T>, ts_s: T) -> Self {
        let ic = motor.characteristic_current_a();
        Self::scaled_with_sensor_noise(ts_s, ic * to_t(SIGMA_Z_NORM))
    }

    /// As [`scaled`](Self::scaled), with `R = sigma_a^2 I2` from a known current-sensing noise
    /// standard deviation `sigma_a` (ampere); `Q_ii` keeps its default ratio to `R`.
    pub fn scaled_with_sensor_noise(ts_s: T, sigma_a: T) -> Self {
        let ratio: T = to_t(SIGMA_I_NORM / SIGMA_Z_NORM);
        let r = sigma_a * sigma_a;
        let qi = r * ratio * ratio;
        let sw = to_t::<T>(SIGMA_W_NORM) / ts_s;
        let sth: T = to_t(SIGMA_TH);
        Self::from_diagonals([qi, qi, sw * sw, sth * sth], [r, r])
    }
}
