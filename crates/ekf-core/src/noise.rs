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
//! the three reference motors of `docs/design.md` section 6. For the servo motor at 10 kHz,
//! `I_c = 20.6 A` and the default is `R = 1.7e-3 A^2` (sigma 41 mA),
//! `Q = diag(4.2e-4, 4.2e-4, 4.0, 1e-8)`.
//!
//! When the current-sensing noise is known, [`NoiseCovariances::scaled_with_sensor_noise`] sets
//! `R` from it and keeps the ratio `Q_ii / R` of the default.
//!
//! # The rule from the sensing chain ([`NoiseCovariances::from_sensing`])
//!
//! `R` is the variance of what the filter is given: the analogue noise of the current sensor
//! and amplifier (standard deviation `sigma_a`, A) plus the ADC's quantization, uniform over
//! one step of `lsb_a` amperes, whose variance is `lsb_a^2 / 12`:
//!
//! ```text
//! R = (sigma_a^2 + lsb_a^2 / 12) I2          (A^2)
//! Q = the scaled default's Q (model error, speed and angle random walks; above)
//! ```
//!
//! The two errors are independent, so their variances add. Example: a 12-bit ADC over
//! +-25 A (`lsb = 50 A / 4096 = 12.2 mA`) with 20 mA RMS sensor noise gives
//! `R = (0.02^2 + 0.0122^2 / 12) = 4.12e-4 A^2` (sigma 20.3 mA). `Q` keeps its motor-scaled
//! value because it describes the model, not the sensor. [`NoiseCovariances::scaled`] stays the
//! default when the sensing noise is unknown.

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

    /// `Q` of [`scaled`](Self::scaled) and `R = (sensor_sigma_a^2 + adc_lsb_a^2 / 12) I2` from
    /// the sensing chain: the sensor's noise standard deviation (A) and the ADC's step in
    /// amperes (module docs, "The rule from the sensing chain"). A non-finite or absurd value
    /// is refused when the observer is built ([`ObserverConfig::validate`](crate::ObserverConfig::validate)).
    pub fn from_sensing(motor: &MotorParams<T>, ts_s: T, sensor_sigma_a: T, adc_lsb_a: T) -> Self {
        let r = sensor_sigma_a * sensor_sigma_a + adc_lsb_a * adc_lsb_a / to_t(12.0);
        Self {
            q: Self::scaled(motor, ts_s).q,
            r: SMatrix::from_diagonal(&SVector::from([r, r])),
        }
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

#[cfg(test)]
mod tests {
    use super::NoiseCovariances;
    use crate::MotorParams;

    #[test]
    fn from_sensing_adds_quantization_variance() {
        let motor = MotorParams::<f64>::servo();
        let lsb = 50.0 / 4096.0;
        let n = NoiseCovariances::from_sensing(&motor, 1e-4, 0.02, lsb);
        let r = 0.02 * 0.02 + lsb * lsb / 12.0;
        assert!((n.r[(0, 0)] - r).abs() < 1e-15 && (n.r[(1, 1)] - r).abs() < 1e-15);
        assert_eq!(n.r[(0, 1)], 0.0);
        assert!((r - 4.124e-4).abs() < 1e-6, "{r}");
        assert_eq!(n.q, NoiseCovariances::scaled(&motor, 1e-4).q);
        // No ADC step: R is the sensor's variance alone.
        let n0 = NoiseCovariances::from_sensing(&motor, 1e-4, 0.03, 0.0);
        assert!((n0.r[(0, 0)] - 9e-4).abs() < 1e-15);
    }
}
