//! The inverter: duties -> phase voltages, with computation delay, dead time and DC-bus
//! ripple.
//!
//! # Model (switching-cycle average over one PWM period)
//!
//! The PWM period `[t_k, t_k+1)` is the control period (single update, sampling at the PWM
//! centre, `design.md` section 4). Over a period the inverter applies the duties `d_x` it
//! holds; the averaged pole voltage of leg `x` (against the negative rail) is
//!
//! ```text
//! v_xN = (d_x - sign(i_x) t_dead / Ts) u_dc,    d_x - sign(i_x) t_dead / Ts clamped to [0, 1]
//! ```
//!
//! The dead time `t_dead` delays every turn-on; while both switches are off the diodes
//! conduct according to the current, so a positive phase current loses `t_dead / Ts` of the
//! duty and a negative one gains it. `sign(i_x)` is taken from the true phase current at
//! `t_k` and held over the period (`sign(0) = 0`), as in `motulator`'s averaged model. The
//! motor is star-connected with an isolated neutral, so the phase voltage is the pole
//! voltage minus the mean of the three, `v_x = v_xN - (v_aN + v_bN + v_cN) / 3`, and the
//! applied stationary voltage is its Clarke transform.
//!
//! - **Computation delay.** With `delay = true`, duties computed in period `k` are loaded at
//!   `t_k+1` and held over `[t_k+1, t_k+2)`: one period of delay, as on a real MCU that
//!   computes during the period. Before the first computed duties arrive the inverter holds
//!   50 % on every leg (zero voltage). With `delay = false` the duties act at once.
//! - **DC-bus ripple.** `u_dc(t) = U_dc (1 + r sin(2 pi f_r t))`, sampled at `t_k` and held
//!   over the period; the same value is what the controller measures.

use core::f64::consts::TAU;

use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::error::FieldError;
use crate::svpwm::clarke;

/// Inverter settings (`[inverter]` in a scenario).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InverterConfig {
    /// PWM and control period, s.
    pub ts_s: f64,
    /// Nominal DC-bus voltage, V.
    pub u_dc_v: f64,
    /// Dead time, s (0: ideal switches). Must be shorter than half the period.
    #[serde(default)]
    pub dead_time_s: f64,
    /// One period of computation delay between the sample and the duties taking effect.
    #[serde(default = "yes")]
    pub delay: bool,
    /// DC-bus ripple amplitude as a fraction of `u_dc_v` (0: none).
    #[serde(default)]
    pub ripple_fraction: f64,
    /// DC-bus ripple frequency, Hz.
    #[serde(default)]
    pub ripple_hz: f64,
}

fn yes() -> bool {
    true
}

impl InverterConfig {
    /// Checks the settings; errors name the field (`inverter.<name>`).
    pub fn validate(&self) -> Result<(), FieldError> {
        let f = |name: &str| format!("inverter.{name}");
        if !(self.ts_s.is_finite() && self.ts_s > 0.0) {
            return Err(FieldError::new(
                f("ts_s"),
                format!("must be finite and > 0, is {}", self.ts_s),
            ));
        }
        if !(self.u_dc_v.is_finite() && self.u_dc_v > 0.0) {
            return Err(FieldError::new(
                f("u_dc_v"),
                format!("must be finite and > 0, is {}", self.u_dc_v),
            ));
        }
        if !(self.dead_time_s.is_finite() && self.dead_time_s >= 0.0) {
            return Err(FieldError::new(
                f("dead_time_s"),
                format!("must be finite and >= 0, is {}", self.dead_time_s),
            ));
        }
        if self.dead_time_s >= 0.5 * self.ts_s {
            return Err(FieldError::new(
                f("dead_time_s"),
                format!(
                    "{} s is not shorter than half the PWM period ts_s = {} s",
                    self.dead_time_s, self.ts_s
                ),
            ));
        }
        if !(self.ripple_fraction.is_finite() && (0.0..1.0).contains(&self.ripple_fraction)) {
            return Err(FieldError::new(
                f("ripple_fraction"),
                format!("must be in [0, 1), is {}", self.ripple_fraction),
            ));
        }
        if !(self.ripple_hz.is_finite() && self.ripple_hz >= 0.0) {
            return Err(FieldError::new(
                f("ripple_hz"),
                format!("must be finite and >= 0, is {}", self.ripple_hz),
            ));
        }
        Ok(())
    }
}

/// What the inverter applies over one period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Applied {
    /// Duties applied over the period.
    pub duties: [f64; 3],
    /// Stationary stator voltage actually applied (dead time included), V.
    pub u_ab_v: DVec2,
    /// The voltage the duties would give with ideal switches on the bus voltage the
    /// controller measured when it computed them, V: what a controller knows it commanded.
    pub u_ab_commanded_v: DVec2,
}

/// The inverter with its one-period delay line.
#[derive(Clone, Debug, PartialEq)]
pub struct Inverter {
    cfg: InverterConfig,
    dead_fraction: f64,
    /// Duties (and the bus voltage measured when they were computed) waiting for the next
    /// period, with the delay on.
    pending: ([f64; 3], f64),
}

impl Inverter {
    /// An inverter holding 50 % duties (zero voltage) until the first computed ones act.
    pub fn new(cfg: InverterConfig) -> Self {
        Self {
            cfg,
            dead_fraction: cfg.dead_time_s / cfg.ts_s,
            pending: ([0.5; 3], cfg.u_dc_v),
        }
    }

    /// The settings.
    pub fn config(&self) -> &InverterConfig {
        &self.cfg
    }

    /// DC-bus voltage at `t_s` (held over the period that starts there), V.
    #[inline]
    pub fn u_dc_at(&self, t_s: f64) -> f64 {
        if self.cfg.ripple_fraction == 0.0 {
            self.cfg.u_dc_v
        } else {
            self.cfg.u_dc_v
                * (1.0 + self.cfg.ripple_fraction * (TAU * self.cfg.ripple_hz * t_s).sin())
        }
    }

    /// Takes the duties computed in this period (with the bus voltage the controller
    /// measured, `u_dc_meas_v`) and returns what is applied over this period on the actual
    /// bus `u_dc_v`, with the true phase currents `i_abc_a` at the period's start (for the
    /// dead time).
    #[inline]
    pub fn apply(
        &mut self,
        duties: [f64; 3],
        u_dc_meas_v: f64,
        u_dc_v: f64,
        i_abc_a: [f64; 3],
    ) -> Applied {
        let (d, u_dc_cmd) = if self.cfg.delay {
            core::mem::replace(&mut self.pending, (duties, u_dc_meas_v))
        } else {
            (duties, u_dc_meas_v)
        };
        let eff = if self.dead_fraction == 0.0 {
            d
        } else {
            let mut e = [0.0; 3];
            for ((ex, dx), ix) in e.iter_mut().zip(d).zip(i_abc_a) {
                let sign = if ix > 0.0 {
                    1.0
                } else if ix < 0.0 {
                    -1.0
                } else {
                    0.0
                };
                *ex = (dx - sign * self.dead_fraction).clamp(0.0, 1.0);
            }
            e
        };
        Applied {
            duties: d,
            u_ab_v: DVec2::from(clarke(eff)) * u_dc_v,
            u_ab_commanded_v: DVec2::from(clarke(d)) * u_dc_cmd,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::svpwm::svpwm;

    fn cfg(delay: bool, dead: f64) -> InverterConfig {
        InverterConfig {
            ts_s: 1e-4,
            u_dc_v: 300.0,
            dead_time_s: dead,
            delay,
            ripple_fraction: 0.0,
            ripple_hz: 0.0,
        }
    }

    #[test]
    fn delay_holds_duties_one_period() {
        let mut inv = Inverter::new(cfg(true, 0.0));
        let d1 = svpwm([50.0, 20.0], 300.0).d;
        let d2 = svpwm([-30.0, 10.0], 300.0).d;
        let a = inv.apply(d1, 300.0, 300.0, [0.0; 3]);
        assert_eq!(a.u_ab_v, DVec2::ZERO);
        let b = inv.apply(d2, 300.0, 300.0, [0.0; 3]);
        assert!((b.u_ab_v - DVec2::new(50.0, 20.0)).abs().max_element() < 1e-9);
        assert_eq!(b.u_ab_v, b.u_ab_commanded_v);
        let mut now = Inverter::new(cfg(false, 0.0));
        let c = now.apply(d2, 300.0, 300.0, [0.0; 3]);
        assert!((c.u_ab_v.x + 30.0).abs() < 1e-9);
    }

    #[test]
    fn dead_time_error_opposes_the_current() {
        // 2 us at 100 us: 2 % of 300 V = 6 V per leg. Current +1 A in a, -0.5 A in b and c:
        // v_aN loses 6 V, v_bN and v_cN gain 6 V; phase a loses 8 V, alpha = -8 V.
        let mut inv = Inverter::new(cfg(false, 2e-6));
        let a = inv.apply([0.5; 3], 300.0, 300.0, [1.0, -0.5, -0.5]);
        assert!(
            (a.u_ab_v - DVec2::new(-8.0, 0.0)).abs().max_element() < 1e-9,
            "{a:?}"
        );
        assert_eq!(a.u_ab_commanded_v, DVec2::ZERO);
    }

    #[test]
    fn invalid_settings_are_refused_with_the_field_name() {
        let mut c = cfg(true, 60e-6);
        assert_eq!(
            c.validate().map_err(|e| e.field),
            Err("inverter.dead_time_s".to_string())
        );
        c.dead_time_s = 0.0;
        c.ts_s = 0.0;
        assert_eq!(
            c.validate().map_err(|e| e.field),
            Err("inverter.ts_s".to_string())
        );
    }

    #[test]
    fn ripple_modulates_the_bus() {
        let mut c = cfg(true, 0.0);
        c.ripple_fraction = 0.05;
        c.ripple_hz = 100.0;
        let inv = Inverter::new(c);
        assert!((inv.u_dc_at(0.0025) - 315.0).abs() < 1e-9);
        assert!((inv.u_dc_at(0.0075) - 285.0).abs() < 1e-9);
    }
}
