//! The observer's configuration: [`ObserverConfig`], its defaults and its validation.

use nalgebra::{Cholesky, Matrix4, SMatrix, Vector4};

use super::{
    AccelerationFeedforward, BranchCheck, ConsistencyCheck, CovarianceHealth, Discretization,
    InnovationGate, ParameterTracking, SpeedNoiseAdaptation,
};
use crate::ekf::{CovarianceUpdate, all_finite};
use crate::motor::positive;
use crate::{ConfigError, Float, Matrix, MotorParams, NoiseCovariances, Param, to_t};

/// Everything the observer needs; start from [`ObserverConfig::new`] or
/// [`ObserverConfig::seed`] and change fields as needed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObserverConfig<T: Float> {
    /// Motor parameters.
    pub motor: MotorParams<T>,
    /// Sample (PWM) period, seconds.
    pub ts_s: T,
    /// Discretization of the model.
    pub discretization: Discretization,
    /// Process and measurement noise covariances.
    pub noise: NoiseCovariances<T>,
    /// Initial estimate `[i_a, i_b, w_e, theta]`, one period before the first sample.
    pub x0: Vector4<T>,
    /// Initial covariance `P0` (4 x 4).
    pub p0: Matrix4<T>,
    /// Covariance update method of the correction.
    pub covariance_update: CovarianceUpdate,
    /// The status reads [`Status::Uncertain`](super::Status::Uncertain) while the angle's standard deviation
    /// `sqrt(P[3][3])` exceeds this limit, radians. The innovation gate and the branch check
    /// act only while the angle's variance is below this limit ("tracking").
    pub angle_sigma_limit_rad: T,
    /// Wrong-branch (`theta + pi`) detection and recovery; `None` turns it off.
    pub branch_check: Option<BranchCheck<T>>,
    /// Innovation (NIS) gate against measurement glitches; `None` turns it off.
    pub innovation_gate: Option<InnovationGate<T>>,
    /// Covariance health check with self-reset; `None` turns it off.
    pub covariance_health: Option<CovarianceHealth<T>>,
    /// Innovation consistency: the status reads
    /// [`Status::Uncertain`](super::Status::Uncertain) while the recent innovations are far
    /// out of line with the noise seen before (module docs, "Consistency"); `None` turns it
    /// off (the status then reflects the covariance alone).
    pub consistency: Option<ConsistencyCheck<T>>,
    /// Online tracking of `psi_f` and `Rs` (module [`tracking`](super::tracking) docs);
    /// `None` turns it off (the configured values are used as they are).
    pub parameter_tracking: Option<ParameterTracking<T>>,
    /// The delay of the applied voltage behind the `u_prev` given to a step, seconds
    /// (negative: the applied voltage leads it). The prediction turns `u_prev` by
    /// `-w voltage_delay_s` (module docs, "Voltage timing"); 0 (the default) uses it as
    /// given. Within `[-2 Ts, 2 Ts]`.
    pub voltage_delay_s: T,
    /// The inverter's voltage error (dead time, switch drops), V: the voltage lost along a
    /// current aligned with a phase axis, as `foc`'s self-commissioning reports it
    /// (`inverter_voltage_error_v`). The prediction subtracts
    /// `inverter_voltage_v * (sgn(i_a) + sgn(i_b) e^(j 2pi/3) + sgn(i_c) e^(j 4pi/3)) / 2` from
    /// `u_prev`, the signs of the estimated phase currents at mid-period, linear within
    /// `0.02 I_c` of zero (module docs, "Voltage timing"). 0 (the default): none. Within
    /// `[0, 100]` V.
    pub inverter_voltage_v: T,
    /// Speed noise adaptation: `Q_ww` raised while the innovations are larger than a
    /// consistent filter's (module docs, "Speed noise adaptation"); `None` keeps `Q` fixed.
    pub speed_noise_adaptation: Option<SpeedNoiseAdaptation<T>>,
    /// Acceleration feedforward: the speed prediction follows the q current with a gain learnt
    /// online (module docs, "Acceleration feedforward"); `None` (the default): the speed is a
    /// random walk. Opt in with [`AccelerationFeedforward::default_for`] (`pyfoc.Ekf` does by
    /// default, for recorded drives).
    pub acceleration_feedforward: Option<AccelerationFeedforward<T>>,
    /// Host builds: the voltage lead, the inverter's dead-time voltage and `Rs` learnt online
    /// from the samples by a drive observer running alongside and handed to this filter
    /// (module docs of [`crate::calibration`], "Online"); `false` (the default here; `pyfoc.Ekf`
    /// turns it on unless told the voltage timing) keeps the configured ones.
    #[cfg(feature = "std")]
    pub input_calibration: bool,
}

impl<T: Float> ObserverConfig<T> {
    /// The project default: [`Discretization::LagFree`], [`NoiseCovariances::scaled`], Joseph
    /// update, `x0 = 0` (rotor angle and speed unknown), [`default_p0`], and the three
    /// safeguards on: [`BranchCheck::default_for`], [`InnovationGate::default`],
    /// [`CovarianceHealth::default`]; and online tracking of `psi_f` and `Rs`
    /// ([`ParameterTracking::default_for`]).
    pub fn new(motor: MotorParams<T>, ts_s: T) -> Self {
        Self {
            motor,
            ts_s,
            discretization: Discretization::LagFree,
            noise: NoiseCovariances::scaled(&motor, ts_s),
            x0: Vector4::zeros(),
            p0: default_p0(&motor, ts_s),
            covariance_update: CovarianceUpdate::Joseph,
            angle_sigma_limit_rad: to_t(0.2),
            branch_check: Some(BranchCheck::default_for(ts_s)),
            innovation_gate: Some(InnovationGate::default()),
            covariance_health: Some(CovarianceHealth::default()),
            consistency: Some(ConsistencyCheck::default_for(ts_s)),
            parameter_tracking: Some(ParameterTracking::default_for(ts_s)),
            speed_noise_adaptation: Some(SpeedNoiseAdaptation::default()),
            voltage_delay_s: T::zero(),
            inverter_voltage_v: T::zero(),
            acceleration_feedforward: None,
            #[cfg(feature = "std")]
            input_calibration: false,
        }
    }

    /// The project default ([`new`](Self::new)) for an interior motor whose q axis saturates
    /// under load (a PM-assisted synchronous reluctance machine, a strongly saturating
    /// interior PM motor), told the small-signal constants a low-current commissioning
    /// measures: the model's `Lq` is [`saturating_lq`] (the midpoint of the told `Ld` and
    /// `Lq`) instead of the told `Lq`; `Q` and `P0` follow from that model. A surface motor
    /// (`Ld == Lq`) and an inverse-salient one (`Lq < Ld`) get [`new`](Self::new) itself.
    ///
    /// Why (module docs of [`observer`](super), "Saturating motors told their small-signal
    /// constants"): the observer's angle is that of the active flux
    /// `psi - Lq i`; an `Lq` off by `dLq` turns it by about `dLq i_q / psi_a` at steady state,
    /// and there nothing tells the angle from `Lq` apart. Under load the q axis saturates and
    /// its chord inductance falls from the small-signal `Lq` toward `Ld`; the midpoint halves
    /// the worst error over that range. The price on a motor that does not saturate: at rated
    /// `i_q` an angle bias of `(Lq - Ld) i_q / (2 psi_a)`, so it is a choice, not the default.
    pub fn saturating(motor: MotorParams<T>, ts_s: T) -> Self {
        let mut m = motor;
        m.lq_h = saturating_lq(&motor);
        Self::new(m, ts_s)
    }

    /// The seed's filter: [`Discretization::ForwardEuler`], [`NoiseCovariances::seed`] and the
    /// standard covariance update (seed step 6, made symmetric); `x0`, `P0` as in
    /// [`new`](Self::new); no branch check, no innovation gate, no covariance health check,
    /// no parameter tracking.
    pub fn seed(motor: MotorParams<T>, ts_s: T) -> Self {
        Self {
            discretization: Discretization::ForwardEuler,
            noise: NoiseCovariances::seed(),
            covariance_update: CovarianceUpdate::StandardSymmetrized,
            branch_check: None,
            innovation_gate: None,
            covariance_health: None,
            consistency: None,
            parameter_tracking: None,
            speed_noise_adaptation: None,
            acceleration_feedforward: None,
            ..Self::new(motor, ts_s)
        }
    }

    /// Checks every field; the observer's constructor calls it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.motor.validate()?;
        positive(self.ts_s, Param::Ts)?;
        if !(self.ts_s >= to_t::<T>(MIN_TS_S) && self.ts_s <= to_t::<T>(MAX_TS_S)) {
            return Err(ConfigError::OutOfRange(Param::Ts));
        }
        positive(self.angle_sigma_limit_rad, Param::AngleSigmaLimit)?;
        check_psd(&self.noise.q, Matrix::Q)?;
        check_psd(&self.noise.r, Matrix::R)?;
        // S = H P H^T + R must stay invertible whatever P becomes: R positive definite.
        let r = &self.noise.r;
        // (R is finite here: `check_psd` refused NaN and infinities.)
        if r[(0, 0)] <= T::zero() || r[(0, 0)] * r[(1, 1)] - r[(0, 1)] * r[(1, 0)] <= T::zero() {
            return Err(ConfigError::NotPositiveDefinite(Matrix::R));
        }
        check_psd(&self.p0, Matrix::P0)?;
        // Forward Euler's current pole `1 - Rs Ts / Ls` must lie inside the unit circle.
        if self.discretization == Discretization::ForwardEuler
            && self.motor.rs_ohm * self.ts_s >= to_t::<T>(2.0) * self.motor.lq_h
        {
            return Err(ConfigError::TooLargeForTs(Param::Rs));
        }
        if !all_finite(&self.x0) {
            return Err(ConfigError::NonFiniteInitialState);
        }
        if let Some(b) = &self.branch_check {
            positive(b.threshold_rad, Param::BranchThreshold)?;
            non_negative(b.min_speed_rad_s, Param::BranchMinSpeed)?;
            non_negative(b.allowance, Param::BranchAllowance)?;
            non_negative(b.flip_angle_sigma_rad, Param::BranchFlipSigma)?;
        }
        if let Some(g) = &self.innovation_gate {
            positive(g.nis_threshold, Param::GateNisThreshold)?;
            positive(g.settled_nis, Param::GateSettledNis)?;
        }
        if let Some(c) = &self.consistency {
            c.validate()?;
        }
        if let Some(f) = &self.acceleration_feedforward {
            f.validate()?;
        }
        if let Some(a) = &self.speed_noise_adaptation {
            a.validate()?;
        }
        let two_ts = self.ts_s + self.ts_s;
        if !self.voltage_delay_s.is_finite() {
            return Err(ConfigError::NonFinite(Param::VoltageDelay));
        }
        if !(self.voltage_delay_s >= -two_ts && self.voltage_delay_s <= two_ts) {
            return Err(ConfigError::OutOfRange(Param::VoltageDelay));
        }
        if !self.inverter_voltage_v.is_finite() {
            return Err(ConfigError::NonFinite(Param::InverterVoltage));
        }
        if !(self.inverter_voltage_v >= T::zero() && self.inverter_voltage_v <= to_t(100.0)) {
            return Err(ConfigError::OutOfRange(Param::InverterVoltage));
        }
        if let Some(t) = &self.parameter_tracking {
            t.validate_for(self.motor.psi_f_wb, self.motor.rs_ohm, self.ts_s)?;
        }
        if let Some(h) = &self.covariance_health {
            positive(h.trace_factor, Param::HealthTraceFactor)?;
            positive(h.current_factor, Param::HealthCurrentFactor)?;
            positive(h.max_w_ts_rad, Param::HealthMaxSpeed)?;
            positive(h.divergence_nis, Param::HealthDivergenceNis)?;
            // P0 is finite and positive semi-definite here, so its trace is finite and >= 0.
            if self.p0.trace() <= T::zero() {
                return Err(ConfigError::ZeroInitialCovarianceTrace);
            }
            // The bound itself must be finite, or an overflowing P would pass it.
            if !(h.trace_factor * self.p0.trace()).is_finite() {
                return Err(ConfigError::TooLargeInitialCovariance);
            }
        }
        Ok(())
    }
}

/// `Ok` when `v` is finite and not negative.
pub(super) fn non_negative<T: Float>(v: T, param: Param) -> Result<(), ConfigError> {
    if !v.is_finite() {
        Err(ConfigError::NonFinite(param))
    } else if v < T::zero() {
        Err(ConfigError::NotPositive(param))
    } else {
        Ok(())
    }
}

/// The q-axis inductance [`ObserverConfig::saturating`] gives the model, henry: for an
/// interior motor (`Lq > Ld`) the midpoint `(Ld + Lq) / 2` of the small-signal values (the
/// minimax choice when the q axis's chord inductance under load may lie anywhere between
/// `Ld` and the small-signal `Lq`); otherwise `Lq` as told.
pub fn saturating_lq<T: Float>(motor: &MotorParams<T>) -> T {
    if motor.lq_h > motor.ld_h {
        (motor.ld_h + motor.lq_h) * to_t::<T>(0.5)
    } else {
        motor.lq_h
    }
}

/// Default initial covariance: `diag((0.1 I_c)^2, (0.1 I_c)^2, (0.05 / Ts)^2, pi^2)`, i.e. the
/// currents roughly known, the speed unknown up to `0.05` rad per sample, the angle unknown.
pub fn default_p0<T: Float>(motor: &MotorParams<T>, ts_s: T) -> Matrix4<T> {
    let si = motor.characteristic_current_a() * to_t(0.1);
    let sw = to_t::<T>(0.05) / ts_s;
    let pi = T::pi();
    Matrix4::from_diagonal(&Vector4::new(si * si, si * si, sw * sw, pi * pi))
}

/// Shortest accepted sample time, s (10 MHz).
pub const MIN_TS_S: f64 = 1e-7;
/// Longest accepted sample time, s (1 Hz).
pub const MAX_TS_S: f64 = 1.0;
/// Largest accepted entry of `Q`, `R`, `P0` and of a covariance given to a reset: no sensor
/// or model error is that large, and beyond it the filter's `f32` arithmetic would overflow
/// (products of two entries stay below `f32::MAX`).
pub const MAX_COVARIANCE_ENTRY: f64 = 1e18;

/// The check a configuration applies to `P0` (finite, symmetric to rounding, positive
/// semi-definite, no entry above [`MAX_COVARIANCE_ENTRY`]), for a covariance a caller is
/// about to give [`PmsmObserver::reset`](super::PmsmObserver::reset) (which checks only that
/// it is finite: the health check of the next step catches a covariance that goes bad in
/// the filter's own arithmetic).
pub fn check_covariance<T: Float>(p: &Matrix4<T>) -> Result<(), ConfigError> {
    check_psd(p, Matrix::P0)
}

/// Symmetric (to rounding) and positive semi-definite: `m + delta I` has a Cholesky factor for
/// `delta = 1e3 eps max|m_ij|`, i.e. no eigenvalue below `-delta`; and no entry above
/// [`MAX_COVARIANCE_ENTRY`].
fn check_psd<T: Float, const N: usize>(
    m: &SMatrix<T, N, N>,
    which: Matrix,
) -> Result<(), ConfigError> {
    if !all_finite(m) {
        return Err(ConfigError::NonFiniteMatrix(which));
    }
    let scale = m.iter().fold(T::zero(), |acc, v| acc.max(v.abs()));
    if scale > to_t::<T>(MAX_COVARIANCE_ENTRY) {
        return Err(ConfigError::TooLargeMatrix(which));
    }
    if scale == T::zero() {
        return Ok(());
    }
    let tol = T::default_epsilon() * to_t(1e3) * scale;
    if (m - m.transpose()).iter().any(|d| d.abs() > tol) {
        return Err(ConfigError::NotSymmetric(which));
    }
    let shifted = m + SMatrix::<T, N, N>::identity() * tol;
    if Cholesky::new(shifted).is_none() {
        return Err(ConfigError::NotPositiveSemiDefinite(which));
    }
    Ok(())
}
