//! Dead-time compensation: duty offsets against the inverter's dead-time voltage error, and
//! the duties the bridge then realizes (what the observer is fed).
//!
//! # The error (switching-cycle average model)
//!
//! Each turn-on of a bridge leg is delayed by the dead time `t_dead`; while both switches are
//! off the freewheeling diodes conduct according to the current. Averaged over a PWM period
//! `Ts`, leg `x` realizes the duty
//!
//! ```text
//! d_eff_x = clamp01(d_x - sgn(i_x) t_dead / Ts)
//! ```
//!
//! (`i_x` > 0 flows into the motor): a positive phase current loses `t_dead / Ts` of its duty,
//! a negative one gains it. On a 300 V bus at 10 kHz, 0.5 us is 1.5 V per leg, up to 2 V on
//! the stator vector, always against the current. This is the model of `pmsm-sim`'s inverter
//! (`crates/pmsm-sim/src/plant/inverter.rs`, as in `motulator`), which takes `sgn` from the true
//! current at the start of the application interval, with `sgn(0) = 0`.
//!
//! # The compensation
//!
//! Per phase the controller adds the offset
//!
//! ```text
//! delta_x = sgn_s(i_x) t_dead / Ts,   sgn_s(i) = clamp(i / band, -1, 1)
//! duty_x  = clamp01(d_x + delta_x)            (d_x: the SVPWM duty of the intended voltage)
//! ```
//!
//! `sgn_s` is a sign that is linear within `+-band` of zero
//! ([`FocConfig::dead_time_band`](crate::FocConfig::dead_time_band), default 2 % of the
//! current limit): near a zero crossing the sign of the current is uncertain (tracking
//! error, noise, offsets, the prediction below), and a hard sign would toggle a
//! `2 t_dead / Ts` step on every wrong guess. On real hardware the dead-time error itself
//! fades out near zero current (the current ripple reverses within the period, over about
//! half the peak-to-peak ripple: set the band there if it is known); against the
//! simulator's hard sign the linear part leaves a small error over `|i| < band`. Measured in
//! `pmsm-sim`'s default scenario (0.5 us, 4.5 A limit; `dead_time_band_a` in
//! `[controller.foc]`): observer angle error after the hand-over 0.068 / 0.071 / 0.114 deg RMS
//! with a band of 1 / 2 / 5 % (0.060 with no dead time; 0.114 at 1.5 us with the default band).
//!
//! # Which current
//!
//! The offsets of tick `k` act while its duties are applied, over `[t_k+1, t_k+2)` with a
//! one-period computation delay. The controller uses the phase currents **predicted** for
//! the middle of that interval: the current **reference** of the control frame (which the
//! current loops will have reached by then, and which carries no sensor noise), or the
//! measured current `i_dq[k]` while the voltage limit holds the loops off their reference,
//! turned back to alpha-beta with the same angle as the voltage (`th_k + 1.5 w Ts`): the
//! current vector moved on with the frame. It costs one inverse Park and one inverse Clarke
//! (the sine and cosine are already there). Measured in `pmsm-sim` (observer angle error
//! after the hand-over, RMS / mean, deg el., band 0.09 A):
//!
//! | sign from | 0.5 us | 1.5 us |
//! |---|---|---|
//! | measured current of `t_k` | 0.129 / +0.101 | 0.398 / +0.333 |
//! | measured current, turned to the interval's middle | 0.086 / +0.010 | 0.176 / +0.027 |
//! | measured current, turned to the interval's start | 0.095 / +0.042 | 0.210 / +0.118 |
//! | reference, turned to the interval's middle (this) | 0.078 / +0.004 | 0.108 / -0.004 |
//!
//! (The simulator takes the sign of the true current at the start of the interval; the
//! middle is nevertheless better: the smooth sign spreads each crossing over the band.) On
//! the self-written plant of `tests/dead_time.rs` (20 kHz, 1 us, 40 mA noise, unloaded, band
//! 0.02 A) the reference gives 0.32 deg RMS where the turned measured current gives 0.42.
//!
//! # What the observer is fed
//!
//! The observer must see the voltage the bridge applies, not the duties loaded into the
//! timer. With the average model above, and the sign taken as `sgn_s`, the leg realizes
//!
//! ```text
//! d_eff_x = clamp01(duty_x - delta_x)
//! ```
//!
//! which is the intended duty `d_x` unless `d_x + delta_x` had to be clamped (near the
//! hexagon's edge: then the bridge realizes `1 - delta_x` or `-delta_x -> 0`, and the
//! observer is told so). [`compensate`] returns both; the controller feeds the observer (and
//! its [`Telemetry::u_ab`](crate::Telemetry::u_ab)) `duties_to_alpha_beta(d_eff, u_dc)`.
//! Feeding the duties themselves would hand the observer the compensation as if it reached
//! the motor, an error as large as the uncompensated one with the opposite sign.
//!
//! Where the estimate of the sign is wrong (within the band of a zero crossing) the observer
//! is still off by the residual; elsewhere it sees what the motor gets.
//!
//! # Cost
//!
//! When `dead_time_s = 0` (the default) the controller skips all of this behind one
//! comparison (8 instructions per tick on the Cortex-M4F, counted as in the crate README).
//! Otherwise: inverse Park and Clarke of the current (6 multiplications), per phase one
//! multiplication, two saturations of the offset, one of the duty, an addition and a
//! subtraction; no division. Counted: 86 instructions per tick more than with it off.

use crate::svpwm::clamp01;
use crate::transforms::Abc;

/// Duties of one compensated modulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compensated {
    /// Duties for the PWM timer: `clamp01(d_x + delta_x)`, each finite and in `[0, 1]`.
    pub duties: [f32; 3],
    /// Duties the bridge is expected to realize with its dead time (average model):
    /// `clamp01(duties_x - delta_x)` (see [`compensate`]). Equal to the uncompensated duties
    /// unless clamping cut the compensation; the observer is fed the voltage of these.
    pub effective: [f32; 3],
}

/// Dead-time compensation with its constants precomputed (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeadTimeCompensation {
    /// `t_dead / Ts`: the largest duty offset.
    dead_fraction: f32,
    /// `dead_fraction / band`: duty offset per ampere within the band.
    slope: f32,
}

impl DeadTimeCompensation {
    /// Compensation of `dead_time_s` at the PWM period `ts_s` with the linear band
    /// `band_a` (A). Off (zero offsets) unless `dead_time_s / ts_s` is positive and below
    /// 1/2 and `band_a` positive and finite; [`FocConfig::validate`](crate::FocConfig::validate)
    /// checks the fields of the controller's own one.
    pub fn new(dead_time_s: f32, ts_s: f32, band_a: f32) -> Self {
        let dead_fraction = dead_time_s / ts_s;
        let slope = dead_fraction / band_a;
        // `!(x > 0)` also catches NaN.
        if !(dead_fraction > 0.0 && dead_fraction < 0.5 && slope > 0.0 && slope.is_finite()) {
            return Self::default();
        }
        Self {
            dead_fraction,
            slope,
        }
    }

    /// Whether it does anything (a positive dead time).
    pub fn is_active(&self) -> bool {
        self.dead_fraction > 0.0
    }

    /// `t_dead / Ts`, the offset of a phase current beyond the band.
    pub fn dead_fraction(&self) -> f32 {
        self.dead_fraction
    }

    /// Duty offsets `delta_x = clamp(i_x / band, -1, 1) t_dead / Ts` for the phase currents
    /// `i` (A). Finite whatever `i` (NaN gives `+t_dead / Ts`).
    #[inline]
    pub fn offsets(&self, i: Abc) -> [f32; 3] {
        let f = self.dead_fraction;
        [
            clamp_sym(i.a * self.slope, f),
            clamp_sym(i.b * self.slope, f),
            clamp_sym(i.c * self.slope, f),
        ]
    }

    /// The SVPWM `duties` compensated for the phase currents `i` expected while they are
    /// applied ([`compensate`] with [`offsets`](Self::offsets)).
    #[inline]
    pub fn apply(&self, duties: [f32; 3], i: Abc) -> Compensated {
        compensate(duties, self.offsets(i))
    }
}

/// Adds the duty offsets `delta` to `duties` and clamps (module docs); `effective` is what
/// the bridge realizes when its dead-time error is `-delta`: `duties - delta`, which equals
/// `clamp01(duties - delta)` (the bridge's own clamp) for `duties` in `[0, 1]` and
/// `|delta| < 1/2`, as [`DeadTimeCompensation`] and SVPWM guarantee. `duties` are always
/// finite and in `[0, 1]` for finite offsets.
#[inline]
pub fn compensate(duties: [f32; 3], delta: [f32; 3]) -> Compensated {
    let [da, db, dc] = duties;
    let [xa, xb, xc] = delta;
    let out = [clamp01(da + xa), clamp01(db + xb), clamp01(dc + xc)];
    // `clamp01(out - delta)` without the clamp: for `d` in [0, 1] and `|delta| < 1/2`,
    // `out - delta` is `d` (not clamped), `1 - delta` (clamped at 1, delta > 0) or `-delta`
    // (clamped at 0, delta < 0), all in [0, 1].
    Compensated {
        duties: out,
        effective: [out[0] - xa, out[1] - xb, out[2] - xc],
    }
}

/// The smooth sign of the compensation: `clamp(i / band, -1, 1)` (`band_a` > 0, A).
pub fn smooth_sign(i_a: f32, band_a: f32) -> f32 {
    clamp_sym(i_a / band_a, 1.0)
}

/// `x` limited to `[-m, m]` by two comparisons (`m >= 0`); NaN gives `m`.
#[inline]
fn clamp_sym(x: f32, m: f32) -> f32 {
    let y = if x < m { x } else { m };
    if y > -m { y } else { -m }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturations_handle_nan() {
        assert_eq!(clamp_sym(f32::NAN, 0.5), 0.5);
        assert_eq!(clamp_sym(-3.0, 0.5), -0.5);
        let c = DeadTimeCompensation::new(1e-6, 1e-4, 0.1);
        let o = c.offsets(Abc {
            a: f32::NAN,
            b: f32::INFINITY,
            c: f32::NEG_INFINITY,
        });
        assert_eq!(o, [0.01, 0.01, -0.01]);
    }

    #[test]
    fn invalid_settings_turn_it_off() {
        for (t, ts, band) in [
            (0.0, 1e-4, 0.1),
            (-1e-6, 1e-4, 0.1),
            (f32::NAN, 1e-4, 0.1),
            (1e-6, 0.0, 0.1),
            (1e-6, 1e-4, 0.0),
            (1e-6, 1e-4, f32::NAN),
            (60e-6, 1e-4, 0.1),
        ] {
            let c = DeadTimeCompensation::new(t, ts, band);
            assert!(!c.is_active(), "{t} {ts} {band}");
            assert_eq!(
                c.offsets(Abc {
                    a: 1.0,
                    b: -1.0,
                    c: 0.0
                }),
                [0.0; 3]
            );
        }
    }
}
