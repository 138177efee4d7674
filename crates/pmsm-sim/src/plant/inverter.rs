//! The inverter: duties -> phase voltages, with computation delay, dead time and DC-bus
//! ripple.
//!
//! # Model (switching-cycle average over one PWM period)
//!
//! The PWM period `[t_k, t_k+1)` is the control period (single update, sampling at the PWM
//! centre, docs/design.md, "Conventions"). Over a period the inverter applies the duties `d_x` it
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
//! - **Longer voltage update delay** (`delay_periods`, off by default). Real drives often
//!   apply a voltage later than the one period a controller compensates: a PWM shadow
//!   register loaded at the period's end or its middle, a DMA or gate-driver latency, a
//!   computation that overruns. With `delay_periods = D` (`0 <= D <= 3`, fractional allowed)
//!   the duties computed at `t_k` are in force over `[t_k + D Ts, t_k+1 + D Ts)`. With
//!   `D = n + f` (`n` whole periods, `0 <= f < 1`) the period `[t_k, t_k+1)` therefore holds
//!   two voltages:
//!
//!   ```text
//!   [t_k,          t_k + f Ts): duties of tick k - n - 1
//!   [t_k + f Ts,   t_k+1):      duties of tick k - n
//!   ```
//!
//!   (one segment when `f = 0`; before a tick's duties exist, 50 % on every leg). The plant
//!   integrates the two sub-intervals one after the other, each with its own voltage and its
//!   own dead-time sign (the current at the sub-interval's start): exact, no averaging.
//!   `D = 1` is `delay = true`, `D = 0` is `delay = false`. The controller is not told: the
//!   voltage it "knows it commanded" ([`Applied::u_ab_commanded_v`], what the simulator's
//!   observers get) stays that of `delay` (the one period `foc` compensates), so an observer
//!   sees the extra `D - 1` periods as a model error, as on a real drive.
//! - **DC-bus ripple.** `u_dc(t) = U_dc (1 + r sin(2 pi f_r t))`, sampled at `t_k` and held
//!   over the period; the same value is what the controller measures.

use core::f64::consts::TAU;

use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::error::FieldError;
use crate::plant::frames::clarke;

/// Smallest DC-bus voltage, V.
pub const MIN_U_DC_V: f64 = 1.0;
/// Largest DC-bus voltage, V.
pub const MAX_U_DC_V: f64 = 1e5;

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
    /// Delay from the sample at `t_k` to the duties taking effect, in periods, `[0, 3]`,
    /// fractional allowed (module docs); `None` (the default): `delay` decides (1 or 0). Needs
    /// `delay = true` (the controller is told one period, its default compensation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_periods: Option<f64>,
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
        use crate::error::plain;
        use ekf_core::observer::{MAX_TS_S, MIN_TS_S};
        if !(self.ts_s >= MIN_TS_S && self.ts_s <= MAX_TS_S) {
            return Err(FieldError::new(
                f("ts_s"),
                format!(
                    "allowed: {} <= x <= {} s (the observer's range), is {}",
                    plain(MIN_TS_S),
                    plain(MAX_TS_S),
                    plain(self.ts_s)
                ),
            ));
        }
        if !(self.u_dc_v >= MIN_U_DC_V && self.u_dc_v <= MAX_U_DC_V) {
            return Err(FieldError::new(
                f("u_dc_v"),
                format!(
                    "allowed: {} <= x <= {} V, is {}",
                    plain(MIN_U_DC_V),
                    plain(MAX_U_DC_V),
                    plain(self.u_dc_v)
                ),
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
        if let Some(d) = self.delay_periods {
            if !(d.is_finite() && (0.0..=MAX_DELAY_PERIODS).contains(&d)) {
                return Err(FieldError::new(
                    f("delay_periods"),
                    format!("must be in [0, {MAX_DELAY_PERIODS}] periods, is {d}"),
                ));
            }
            if !self.delay {
                return Err(FieldError::new(
                    f("delay_periods"),
                    "needs delay = true: it replaces that one period (delay_periods = 0 for none)",
                ));
            }
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

/// Largest `delay_periods`.
pub const MAX_DELAY_PERIODS: f64 = 3.0;

/// Duties (and the bus voltage measured when they were computed) kept by the delay line:
/// enough for `delay_periods` up to [`MAX_DELAY_PERIODS`].
const HISTORY: usize = 5;

/// One sub-interval of a period with `delay_periods` (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Length as a fraction of the period (0: the segment is empty).
    pub fraction: f64,
    /// Duties in force.
    pub duties: [f64; 3],
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
    /// With `delay_periods`: the last [`HISTORY`] ticks' duties, by tick modulo `HISTORY`,
    /// the ticks pushed so far, and the period's two segments.
    history: [[f64; 3]; HISTORY],
    pushed: u64,
    segments: [Segment; 2],
}

impl Inverter {
    /// An inverter holding 50 % duties (zero voltage) until the first computed ones act.
    pub fn new(cfg: InverterConfig) -> Self {
        Self {
            cfg,
            dead_fraction: cfg.dead_time_s / cfg.ts_s,
            pending: ([0.5; 3], cfg.u_dc_v),
            history: [[0.5; 3]; HISTORY],
            pushed: 0,
            segments: [Segment {
                fraction: 0.0,
                duties: [0.5; 3],
            }; 2],
        }
    }

    /// The two sub-intervals of the present period with `delay_periods` set (the first
    /// may be empty), as scheduled by the last [`apply`](Self::apply); `None` without it (one
    /// voltage over the whole period: [`Applied::u_ab_v`]).
    pub fn segments(&self) -> Option<[Segment; 2]> {
        self.cfg.delay_periods.map(|_| self.segments)
    }

    /// The stationary voltage of `duties` on the bus `u_dc_v` with the dead time for the phase
    /// currents `i_abc_a` (module docs), V.
    #[inline]
    pub fn voltage(&self, duties: [f64; 3], u_dc_v: f64, i_abc_a: [f64; 3]) -> DVec2 {
        let eff = if self.dead_fraction == 0.0 {
            duties
        } else {
            let mut e = [0.0; 3];
            for ((ex, dx), ix) in e.iter_mut().zip(duties).zip(i_abc_a) {
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
        DVec2::from(clarke(eff)) * u_dc_v
    }

    /// Pushes tick `k`'s duties into the delay line and schedules period `k`'s segments.
    fn schedule(&mut self, duties: [f64; 3], delay_periods: f64) {
        let k = self.pushed;
        self.history[(k % HISTORY as u64) as usize] = duties;
        self.pushed += 1;
        let n = delay_periods.floor();
        let f = delay_periods - n;
        let back = |b: u64| {
            if b <= k {
                self.history[((k - b) % HISTORY as u64) as usize]
            } else {
                [0.5; 3]
            }
        };
        let n = n as u64;
        self.segments = [
            Segment {
                fraction: f,
                duties: if f > 0.0 { back(n + 1) } else { [0.5; 3] },
            },
            Segment {
                fraction: 1.0 - f,
                duties: back(n),
            },
        ];
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
        let u_ab_commanded_v = DVec2::from(clarke(d)) * u_dc_cmd;
        if let Some(dp) = self.cfg.delay_periods {
            // The delay line: the segments' duties; `u_ab_v` here is the period's mean with
            // the dead-time sign of the currents at `t_k` (the run loop steps the plant
            // segment by segment with [`voltage`](Self::voltage) and records the exact mean).
            self.schedule(duties, dp);
            let [s0, s1] = self.segments;
            let mut mean = [0.0; 3];
            for (m, (a, b)) in mean.iter_mut().zip(s0.duties.iter().zip(s1.duties)) {
                *m = s0.fraction * a + s1.fraction * b;
            }
            let u = self.voltage(s0.duties, u_dc_v, i_abc_a) * s0.fraction
                + self.voltage(s1.duties, u_dc_v, i_abc_a) * s1.fraction;
            return Applied {
                duties: mean,
                u_ab_v: u,
                u_ab_commanded_v,
            };
        }
        Applied {
            duties: d,
            u_ab_v: self.voltage(d, u_dc_v, i_abc_a),
            u_ab_commanded_v,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::frames::inverse_clarke;

    /// Duties realizing `u_ab_v` on `u_dc_v` (min-max zero-sequence injection).
    fn duties(u_ab_v: [f64; 2], u_dc_v: f64) -> [f64; 3] {
        let v = inverse_clarke(u_ab_v);
        let off = -(v.iter().copied().fold(f64::MIN, f64::max)
            + v.iter().copied().fold(f64::MAX, f64::min))
            / 2.0;
        v.map(|x| 0.5 + (x + off) / u_dc_v)
    }

    fn cfg(delay: bool, dead: f64) -> InverterConfig {
        InverterConfig {
            ts_s: 1e-4,
            u_dc_v: 300.0,
            dead_time_s: dead,
            delay,
            delay_periods: None,
            ripple_fraction: 0.0,
            ripple_hz: 0.0,
        }
    }

    #[test]
    fn delay_line_splits_the_period() {
        // 1.5 periods: period k holds tick k-2's duties over its first half, k-1's over the
        // second; 1 and 0 periods reproduce delay = true / false; 3 periods, tick k-3's.
        let ticks: Vec<[f64; 3]> = (0..8)
            .map(|j| [0.1 * f64::from(j), 0.5, 1.0 - 0.1 * f64::from(j)])
            .collect();
        for (dp, n, f) in [
            (1.5, 1, 0.5),
            (1.0, 1, 0.0),
            (0.0, 0, 0.0),
            (3.0, 3, 0.0),
            (2.25, 2, 0.25),
        ] {
            let mut c = cfg(true, 0.0);
            c.delay_periods = Some(dp);
            assert_eq!(c.validate(), Ok(()));
            let mut inv = Inverter::new(c);
            for (k, d) in ticks.iter().enumerate() {
                inv.apply(*d, 300.0, 300.0, [0.0; 3]);
                let [s0, s1] = inv.segments().unwrap_or_else(|| panic!("no segments"));
                let at = |b: usize| if b <= k { ticks[k - b] } else { [0.5; 3] };
                assert_eq!(s0.fraction, f);
                assert_eq!(s1.fraction, 1.0 - f);
                assert_eq!(s1.duties, at(n), "{dp} {k}");
                if f > 0.0 {
                    assert_eq!(s0.duties, at(n + 1), "{dp} {k}");
                }
            }
        }
        let mut c = cfg(true, 0.0);
        c.delay_periods = Some(3.5);
        assert_eq!(
            c.validate().map_err(|e| e.field),
            Err("inverter.delay_periods".to_string())
        );
        c.delay_periods = Some(1.5);
        c.delay = false;
        assert_eq!(
            c.validate().map_err(|e| e.field),
            Err("inverter.delay_periods".to_string())
        );
    }

    #[test]
    fn delay_holds_duties_one_period() {
        let mut inv = Inverter::new(cfg(true, 0.0));
        let d1 = duties([50.0, 20.0], 300.0);
        let d2 = duties([-30.0, 10.0], 300.0);
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
