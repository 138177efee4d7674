//! The settings of the identification ([`IdentifyConfig`]) and their validation; the
//! defaults and why are in the module docs of [`identify`](crate::identify).

use core::f32::consts::TAU;
use core::fmt;

use crate::config::ComputationDelay;

use super::numeric::ticks;

/// Settings of the identification (SI units; speeds electrical).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifyConfig {
    /// PWM (tick) period, s.
    pub ts_s: f32,
    /// When the duties of a tick take effect (as for the controller).
    pub delay: ComputationDelay,
    /// Test current: the align, resistance and injection bias level, A.
    pub test_current_a: f32,
    /// Software over-current trip, A (phase-vector magnitude).
    pub over_current_a: f32,
    /// Bus under-voltage trip, V.
    pub u_dc_min_v: f32,
    /// Bus over-voltage trip, V.
    pub u_dc_max_v: f32,
    /// Fraction of the linear range `u_dc / sqrt(3)` the voltage may use, `(0, 1]`.
    pub max_modulation: f32,
    /// Bandwidth of the current loops, rad/s.
    pub current_bw_rad_s: f32,
    /// Injection frequency for the inductances, Hz (rounded to a whole number of ticks per
    /// period, at least 4).
    pub hf_frequency_hz: f32,
    /// Length of the alignment (two halves), s.
    pub align_time_s: f32,
    /// Length of each of the two resistance levels (30 % settling, 70 % averaging), s.
    pub resistance_time_s: f32,
    /// Length of the averaging window of each inductance measurement, s.
    pub inductance_time_s: f32,
    /// Spin speed for `psi_f`, rad/s electrical; 0 skips the spin (`psi_f` not measured).
    pub spin_speed_rad_s: f32,
    /// Acceleration of the I/f ramp, rad/s^2 electrical (the rotor must be able to follow
    /// it with `spin_current_a`).
    pub spin_accel_rad_s2: f32,
    /// Current of the I/f spin, A.
    pub spin_current_a: f32,
    /// Settling time at the spin speed before the averaging, s.
    pub spin_settle_time_s: f32,
    /// Averaging window at the spin speed, s.
    pub spin_measure_time_s: f32,
    /// Measure the inertia after `psi_f` (needs the spin).
    pub measure_inertia: bool,
    /// Pole pairs (for the mechanical quantities), >= 1.
    pub pole_pairs: u32,
}

impl IdentifyConfig {
    /// Defaults for a drive with PWM period `ts_s`, nominal bus `u_dc_nominal_v` and a test
    /// current `test_current_a` (about half the motor's rated current is a good choice): a
    /// 1 kHz injection, 0.3 s alignment, 2 x 0.13 s resistance, 0.08 s per inductance
    /// window, no spin (set `spin_speed_rad_s` and `spin_accel_rad_s2` to measure `psi_f`).
    pub fn new(ts_s: f32, u_dc_nominal_v: f32, test_current_a: f32) -> Self {
        Self {
            ts_s,
            delay: ComputationDelay::OnePeriod,
            test_current_a,
            over_current_a: 2.5 * test_current_a,
            u_dc_min_v: 0.5 * u_dc_nominal_v,
            u_dc_max_v: 1.25 * u_dc_nominal_v,
            max_modulation: 0.95,
            current_bw_rad_s: TAU * 300.0,
            hf_frequency_hz: 1000.0,
            align_time_s: 0.3,
            resistance_time_s: 0.13,
            inductance_time_s: 0.08,
            spin_speed_rad_s: 0.0,
            spin_accel_rad_s2: 0.0,
            spin_current_a: test_current_a,
            spin_settle_time_s: 0.15,
            spin_measure_time_s: 0.2,
            measure_inertia: false,
            pole_pairs: 1,
        }
    }

    /// With a spin to `speed_rad_s` (electrical) at `accel_rad_s2`.
    pub fn with_spin(mut self, speed_rad_s: f32, accel_rad_s2: f32) -> Self {
        self.spin_speed_rad_s = speed_rad_s;
        self.spin_accel_rad_s2 = accel_rad_s2;
        self
    }

    /// Ticks per injection period (the shorter one).
    pub fn hf_period_ticks(&self) -> u32 {
        ticks(1.0 / self.hf_frequency_hz, self.ts_s)
    }

    /// Checks every setting; the error names the field.
    pub fn validate(&self) -> Result<(), IdentifyConfigError> {
        let err = |field: &'static str, problem: &'static str| {
            Err(IdentifyConfigError { field, problem })
        };
        let pos = |v: f32| v.is_finite() && v > 0.0;
        if !(pos(self.ts_s) && (1e-6..=1e-2).contains(&self.ts_s)) {
            return err("ts_s", "must be in [1e-6, 1e-2] s");
        }
        if !pos(self.test_current_a) {
            return err("test_current_a", "must be finite and positive");
        }
        if !pos(self.over_current_a) || self.over_current_a < 1.5 * self.test_current_a {
            return err(
                "over_current_a",
                "must be finite and at least 1.5 x the test current",
            );
        }
        if !pos(self.u_dc_min_v) {
            return err("u_dc_min_v", "must be finite and positive");
        }
        if !(self.u_dc_max_v.is_finite() && self.u_dc_max_v > self.u_dc_min_v) {
            return err("u_dc_max_v", "must be finite and above u_dc_min_v");
        }
        if !(pos(self.max_modulation) && self.max_modulation <= 1.0) {
            return err("max_modulation", "must be in (0, 1]");
        }
        if !(pos(self.current_bw_rad_s) && self.current_bw_rad_s * self.ts_s <= 0.5) {
            return err(
                "current_bw_rad_s",
                "must be positive and at most 0.5 / ts_s",
            );
        }
        if !pos(self.hf_frequency_hz) || self.hf_frequency_hz * self.ts_s > 0.25 {
            return err(
                "hf_frequency_hz",
                "must be positive with at least 4 ticks per period",
            );
        }
        if self.hf_period_ticks() > 2000 {
            return err(
                "hf_frequency_hz",
                "too low: more than 2000 ticks per period",
            );
        }
        let time = |v: f32, min_ticks: f32| pos(v) && v >= min_ticks * self.ts_s && v <= 10.0;
        if !time(self.align_time_s, 20.0) {
            return err("align_time_s", "must be in [20 ticks, 10 s]");
        }
        if !time(self.resistance_time_s, 20.0) {
            return err("resistance_time_s", "must be in [20 ticks, 10 s]");
        }
        let hf = self.hf_period_ticks() as f32;
        if !time(self.inductance_time_s, 2.0 * hf) {
            return err(
                "inductance_time_s",
                "must be in [2 injection periods, 10 s]",
            );
        }
        if !(self.spin_speed_rad_s.is_finite() && self.spin_speed_rad_s >= 0.0) {
            return err("spin_speed_rad_s", "must be finite and >= 0 (0: no spin)");
        }
        if self.spin_speed_rad_s > 0.0 {
            if self.spin_speed_rad_s * self.ts_s > 0.3 {
                return err("spin_speed_rad_s", "must be below 0.3 / ts_s");
            }
            if !pos(self.spin_accel_rad_s2) || self.spin_speed_rad_s / self.spin_accel_rad_s2 > 10.0
            {
                return err(
                    "spin_accel_rad_s2",
                    "must be positive, the ramp at most 10 s",
                );
            }
            if !pos(self.spin_current_a) || self.spin_current_a > 0.8 * self.over_current_a {
                return err(
                    "spin_current_a",
                    "must be positive and at most 0.8 x over_current_a",
                );
            }
            if !time(self.spin_settle_time_s, 1.0) {
                return err("spin_settle_time_s", "must be in [1 tick, 10 s]");
            }
            if !time(self.spin_measure_time_s, 20.0) {
                return err("spin_measure_time_s", "must be in [20 ticks, 10 s]");
            }
        } else if self.measure_inertia {
            return err("measure_inertia", "needs the spin (spin_speed_rad_s > 0)");
        }
        if self.pole_pairs == 0 || self.pole_pairs > 1000 {
            return err("pole_pairs", "must be in [1, 1000]");
        }
        Ok(())
    }
}

/// A refused [`IdentifyConfig`]: the field and what is wrong with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IdentifyConfigError {
    /// The field of [`IdentifyConfig`].
    pub field: &'static str,
    /// The problem.
    pub problem: &'static str,
}

impl fmt::Display for IdentifyConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "identification setting `{}` {}",
            self.field, self.problem
        )
    }
}

impl core::error::Error for IdentifyConfigError {}
