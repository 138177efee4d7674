//! The validation of a [`FocConfig`]: [`FocConfig::validate`] checks every field (finite,
//! positive, in range, consistent with the others) and names the first bad one in a
//! [`ConfigError`]. Every duration must also fit the `u32` tick counters (at most `1e9`
//! periods).

use core::f32::consts::PI;
use core::fmt;

use super::FocConfig;
use crate::transforms::FRAC_1_SQRT_3;

impl FocConfig {
    /// Checks every field (no panics; the first problem found is returned).
    pub fn validate(&self) -> Result<(), ConfigError> {
        use Field as F;
        self.motor.validate().map_err(ConfigError::Observer)?;
        self.observer.validate().map_err(ConfigError::Observer)?;
        if self.observer.motor != self.motor || self.observer.ts_s != self.ts_s {
            return Err(ConfigError::ObserverMismatch);
        }
        positive(self.ts_s, F::Ts)?;
        in_range(self.angle_advance_periods, 0.0, 4.0, F::AngleAdvance)?;
        positive(self.current_bw_rad_s, F::CurrentBandwidth)?;
        if !(self.current_pi_gains().is_valid() && self.current_pi_gains_d().is_valid()) {
            return Err(ConfigError::OutOfRange(F::CurrentGains));
        }
        positive(self.speed_bw_rad_s, F::SpeedBandwidth)?;
        positive(self.inertia_kg_m2, F::Inertia)?;
        if !self.speed_pi_gains().is_valid() {
            return Err(ConfigError::OutOfRange(F::SpeedGains));
        }
        if self.speed_divider == 0 {
            return Err(ConfigError::NotPositive(F::SpeedDivider));
        }
        positive(self.current_limit_a, F::CurrentLimit)?;
        positive(self.over_current_a, F::OverCurrent)?;
        if self.over_current_a <= self.current_limit_a {
            return Err(ConfigError::OutOfRange(F::OverCurrent));
        }
        positive(self.u_dc_min_v, F::UdcMin)?;
        positive(self.u_dc_max_v, F::UdcMax)?;
        if self.u_dc_max_v <= self.u_dc_min_v {
            return Err(ConfigError::OutOfRange(F::UdcMax));
        }
        positive(self.max_speed_rad_s, F::MaxSpeed)?;
        positive(self.speed_slew_rad_s2, F::SpeedSlew)?;
        in_range(
            self.max_modulation,
            1e-3,
            2.0 * FRAC_1_SQRT_3,
            F::MaxModulation,
        )?;
        in_range(self.dead_time_s, 0.0, f32::MAX, F::DeadTime)?;
        if self.dead_time_s >= 0.5 * self.ts_s {
            return Err(ConfigError::OutOfRange(F::DeadTime));
        }
        positive(self.dead_time_band(), F::DeadTimeBand)?;
        let fw = &self.field_weakening;
        // Built without the `field-weakening` feature: refused by its first field.
        if fw.enabled && !cfg!(feature = "field-weakening") {
            return Err(ConfigError::OutOfRange(F::FwVoltageMargin));
        }
        in_range(fw.voltage_margin, 0.5, 1.0, F::FwVoltageMargin)?;
        positive(fw.bandwidth_rad_s, F::FwBandwidth)?;
        if fw.bandwidth_rad_s > self.current_bw_rad_s {
            return Err(ConfigError::OutOfRange(F::FwBandwidth));
        }
        positive(self.max_negative_id(), F::FwMaxNegativeId)?;
        if self.max_negative_id() > self.current_limit_a {
            return Err(ConfigError::OutOfRange(F::FwMaxNegativeId));
        }
        #[cfg(feature = "flux-map")]
        if let Some(m) = &self.flux_map {
            let k = m.mtpa.torque_constant_nm_a() / self.torque_constant_nm_a();
            if !(k - 1.0).abs().le(&1e-4) {
                return Err(ConfigError::OutOfRange(F::FluxMap));
            }
        }
        #[cfg(feature = "d-excitation")]
        if let Some(x) = &self.d_excitation {
            positive(x.amplitude_a, F::DExcitation)?;
            if x.amplitude_a > self.current_limit_a
                || x.half_period_ticks < 2
                || !(x.min_speed_rad_s >= 0.0 && x.min_speed_rad_s.is_finite())
            {
                return Err(ConfigError::OutOfRange(F::DExcitation));
            }
        }
        let s = &self.startup;
        positive(s.align_current_a, F::AlignCurrent)?;
        if s.align_current_a > self.current_limit_a {
            return Err(ConfigError::OutOfRange(F::AlignCurrent));
        }
        in_range(s.align_time_s, 0.0, 60.0, F::AlignTime)?;
        in_range(s.align_angle_rad, -2.0 * PI, 2.0 * PI, F::AlignAngle)?;
        positive(s.if_current_a, F::IfCurrent)?;
        if s.if_current_a > self.current_limit_a {
            return Err(ConfigError::OutOfRange(F::IfCurrent));
        }
        positive(s.accel_rad_s2, F::Accel)?;
        positive(s.handover_speed_rad_s, F::HandoverSpeed)?;
        if s.handover_speed_rad_s >= self.max_speed_rad_s {
            return Err(ConfigError::OutOfRange(F::HandoverSpeed));
        }
        in_range(s.blend_time_s, 0.0, 60.0, F::BlendTime)?;
        in_range(s.exit_speed_ratio, 0.01, 0.99, F::ExitSpeedRatio)?;
        positive(s.acquire_timeout_s, F::AcquireTimeout)?;
        in_range(s.damping_ratio, 0.0, 5.0, F::DampingRatio)?;
        in_range(s.kick_speed_ratio, 0.0, 1.0, F::KickSpeedRatio)?;
        let h = &self.health;
        positive(h.window_s, F::HealthWindow)?;
        if h.window_s < self.ts_s {
            return Err(ConfigError::OutOfRange(F::HealthWindow));
        }
        positive(h.nis_limit, F::NisLimit)?;
        positive(h.speed_tolerance, F::SpeedTolerance)?;
        in_range(h.lock_angle_rad, 0.5 * PI, PI, F::LockAngle)?;
        positive(h.lost_time_s, F::LostTime)?;
        positive(h.lock_time_s, F::LockTime)?;
        positive(h.stall_time_s, F::StallTime)?;
        let [lo, hi] = h.flux_range;
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(ConfigError::NonFinite(F::FluxRange));
        }
        if !(lo > 0.0 && lo < 1.0 && hi > 1.0) {
            return Err(ConfigError::OutOfRange(F::FluxRange));
        }
        let step = self.max_current_step();
        if step.is_nan() {
            return Err(ConfigError::NonFinite(F::MaxCurrentStep));
        } else if step <= 0.0 {
            return Err(ConfigError::NotPositive(F::MaxCurrentStep));
        }
        if self.samples.missing_trip_ticks == 0 {
            return Err(ConfigError::NotPositive(F::MissingTripTicks));
        }
        if self.samples.over_current_trip_ticks == 0 {
            return Err(ConfigError::NotPositive(F::OverCurrentTripTicks));
        }
        in_range(self.samples.stuck_angle_rad, 0.0, 1.0e6, F::StuckAngle)?;
        // Every duration must fit the u32 tick counters.
        let longest = s
            .align_time_s
            .max(s.blend_time_s)
            .max(s.acquire_timeout_s)
            .max(h.lost_time_s)
            .max(h.lock_time_s)
            .max(h.stall_time_s);
        if longest / self.ts_s > 1.0e9 {
            return Err(ConfigError::OutOfRange(F::Ts));
        }
        Ok(())
    }
}

fn positive(v: f32, field: Field) -> Result<(), ConfigError> {
    if !v.is_finite() {
        Err(ConfigError::NonFinite(field))
    } else if v <= 0.0 {
        Err(ConfigError::NotPositive(field))
    } else {
        Ok(())
    }
}

fn in_range(v: f32, lo: f32, hi: f32, field: Field) -> Result<(), ConfigError> {
    if !v.is_finite() {
        Err(ConfigError::NonFinite(field))
    } else if v < lo || v > hi {
        Err(ConfigError::OutOfRange(field))
    } else {
        Ok(())
    }
}

/// A field of [`FocConfig`] named in a [`ConfigError`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(missing_docs)] // each variant is the field of the same name
pub enum Field {
    Ts,
    AngleAdvance,
    CurrentBandwidth,
    CurrentGains,
    SpeedBandwidth,
    Inertia,
    SpeedGains,
    SpeedDivider,
    CurrentLimit,
    OverCurrent,
    UdcMin,
    UdcMax,
    MaxSpeed,
    SpeedSlew,
    MaxModulation,
    DeadTime,
    DeadTimeBand,
    AlignCurrent,
    AlignTime,
    AlignAngle,
    IfCurrent,
    Accel,
    HandoverSpeed,
    BlendTime,
    ExitSpeedRatio,
    AcquireTimeout,
    /// `startup.damping_ratio`.
    DampingRatio,
    /// `startup.kick_speed_ratio`.
    KickSpeedRatio,
    HealthWindow,
    NisLimit,
    /// `health.flux_range`.
    FluxRange,
    SpeedTolerance,
    LockAngle,
    LostTime,
    LockTime,
    StallTime,
    MaxCurrentStep,
    MissingTripTicks,
    OverCurrentTripTicks,
    StuckAngle,
    /// `flux_map`: its torque constant is not the motor's (`1.5 p psi_f`) within 1e-4.
    FluxMap,
    /// `d_excitation`: amplitude not positive or above the current limit, a half period
    /// under 2 ticks, or a minimum speed negative or not finite.
    DExcitation,
    /// `field_weakening.voltage_margin`.
    FwVoltageMargin,
    /// `field_weakening.bandwidth_rad_s`.
    FwBandwidth,
    /// `field_weakening.max_negative_id_a` (or its default).
    FwMaxNegativeId,
}

/// Why a [`FocConfig`] was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    /// The motor or observer configuration is invalid.
    Observer(ekf_core::ConfigError),
    /// `observer.motor` or `observer.ts_s` differ from `motor` / `ts_s`.
    ObserverMismatch,
    /// The field is NaN or infinite.
    NonFinite(Field),
    /// The field is zero or negative.
    NotPositive(Field),
    /// The field is outside its range, or inconsistent with another (`over_current_a` not
    /// above `current_limit_a`, `u_dc_max_v` not above `u_dc_min_v`, a start-up current above
    /// the limit, the hand-over speed not below the maximum speed, a dead time not below half
    /// the PWM period, ...).
    OutOfRange(Field),
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConfigError::Observer(e) => write!(f, "observer configuration: {e}"),
            ConfigError::ObserverMismatch => {
                f.write_str("observer.motor / observer.ts_s differ from motor / ts_s")
            }
            ConfigError::NonFinite(x) => write!(f, "{x:?} is not finite"),
            ConfigError::NotPositive(x) => write!(f, "{x:?} must be positive"),
            ConfigError::OutOfRange(x) => write!(f, "{x:?} is out of range"),
        }
    }
}

impl core::error::Error for ConfigError {}
