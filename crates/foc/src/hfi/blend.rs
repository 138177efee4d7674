//! The hand-over band to the observer (module [`crate::hfi`], "Hand-over band"): while
//! tracking, the carrier's switch with hysteresis, the observer's weight in the control
//! angle, the observer's re-seed when its weight leaves zero, and the rule of the long
//! carrier period.
//!
//! ```text
//! carrier off   when |w_hfi| > blend_high                 (by HFI's speed)
//! carrier on    when |w_o,lp| < 0.8 blend_high            (tracker restarted at the observer's
//!                                                          angle and w_o,lp, load = a_ff)
//! w_o,lp       += min(w_n Ts, 1) (w_o - w_o,lp)           (the observer's speed, low-passed)
//! lambda        = clamp((|w| - blend_low) / (blend_high - blend_low), 0, 1) with the carrier on
//!                 (w = w_hfi, or the faster of w_hfi and w_o,lp with a long carrier period),
//!                 1 with it off
//! theta         = wrap(theta_hfi + lambda wrap(theta_o - theta_hfi))
//! omega         = w_hfi + lambda (w_o - w_hfi)
//! ```
//!
//! On the tick `lambda` first leaves 0 the observer is re-seeded at HFI's angle and speed
//! and the control angle stays HFI's for that tick.

use super::config::HfiConfig;
use super::polarity::Polarity;
use super::tracker::HfiTracker;
use crate::config::FocConfig;
use crate::trig::{max2, wrap};

/// Electrical angle (rad) the rotor may turn in one carrier period at the top of the blend
/// band (`blend_high_rad_s 2 N Ts`) before the observer's weight follows the faster of HFI's
/// speed and the observer's low-passed speed instead of HFI's alone (module [`crate::hfi`],
/// "Hand-over band"): 0.05 rad (2.9 deg). The industrial IPM of the tests turns 0.12 rad
/// (`N = 7`), the traction IPM 0.016 rad (`N = 2` at 20 kHz).
pub const HFI_PERIOD_ANGLE_RAD: f32 = 0.05;

/// Whether the carrier period is long (module [`crate::hfi`], "Hand-over band"): the rotor
/// turns more than [`HFI_PERIOD_ANGLE_RAD`] per carrier period (`2 N Ts`,
/// `N = half_period_ticks`) at the top of the blend band `blend_high_rad_s`. HFI is then the
/// weak side there: its angle is not fused into the observer ([`HfiConfig::new`]'s default
/// `fusion_sigma_rad`) and the observer's weight follows the faster of the two speeds.
#[inline]
pub fn long_carrier_period(blend_high_rad_s: f32, half_period_ticks: u8, ts_s: f32) -> bool {
    blend_high_rad_s * 2.0 * f32::from(half_period_ticks) * ts_s > HFI_PERIOD_ANGLE_RAD
}

/// Observer weight in the control angle for an electrical speed magnitude `w` (linear from
/// `lo` to `hi`).
pub(crate) fn observer_weight(w: f32, lo: f32, hi: f32) -> f32 {
    let x = (w - lo) / (hi - lo);
    crate::pi::limit(x, 0.0, 1.0)
}

/// The band's constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Band {
    /// `blend_low_rad_s`, `blend_high_rad_s`.
    low: f32,
    high: f32,
    /// Gain of the observer speed's low-pass per tick.
    lp_gain: f32,
    /// Whether the observer's weight follows the faster of HFI's speed and the observer's
    /// low-passed speed (a long carrier period: [`HFI_PERIOD_ANGLE_RAD`]).
    pub weight_on_faster: bool,
}

impl Band {
    pub fn new(foc: &FocConfig, cfg: &HfiConfig) -> Self {
        Self {
            low: cfg.blend_low_rad_s,
            high: cfg.blend_high_rad_s,
            lp_gain: crate::trig::min2(cfg.pll_bandwidth_rad_s * foc.ts_s, 1.0),
            weight_on_faster: long_carrier_period(
                cfg.blend_high_rad_s,
                cfg.half_period_ticks,
                foc.ts_s,
            ),
        }
    }
}

/// The virtual rotor sensor HFI gives the speed loop while tracking.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Blend {
    /// Angle (rad el.) and speed (rad/s el.) of the control frame.
    pub theta: f32,
    pub omega: f32,
    /// The observer must be re-seeded at this (angle, speed) first.
    pub reseed: Option<(f32, f32)>,
}

/// The tracking state: closed loop on the blended angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Track {
    /// The standstill test's outcome.
    pub(super) polarity: Polarity,
    /// Whether the carrier is on (the switch's hysteresis state).
    pub(super) injecting: bool,
    /// Observer weight of the last tick.
    pub(super) weight: f32,
    /// The observer's speed low-passed at the tracking loop's bandwidth, rad/s el.: what
    /// turns the carrier back on and seeds the tracker's speed (the observer's own speed is
    /// noisiest at the bottom of its range).
    omega_o_lp: f32,
}

impl Track {
    /// Tracking after the standstill test, carrier on, HFI's angle alone.
    pub fn new(polarity: Polarity) -> Self {
        Self {
            polarity,
            injecting: true,
            weight: 0.0,
            omega_o_lp: 0.0,
        }
    }

    /// The variance (rad^2) with which HFI's angle is fused into the observer this tick
    /// at the fusion's standard deviation `sigma` (module [`crate::hfi`], "Hand-over
    /// band"): with the carrier on and the observer's weight below 1,
    /// `sigma^2 / (1 - weight)` (the last tick's weight); `None` otherwise or with
    /// `sigma = 0`.
    #[inline]
    pub fn fusion_variance(&self, s: f32) -> Option<f32> {
        if self.injecting && self.weight < 1.0 && s > 0.0 {
            Some(s * s / (1.0 - self.weight))
        } else {
            None
        }
    }

    /// One tick of the band (module docs above) with the observer's estimate `theta_o`, `omega_o`
    /// and the drive's acceleration `accel` (rad/s^2 el.).
    #[inline]
    pub fn step(
        &mut self,
        c: &Band,
        tracker: &mut HfiTracker,
        accel: f32,
        theta_o: f32,
        omega_o: f32,
    ) -> Blend {
        // The weight follows HFI's own speed while the carrier is on (the observer's speed is
        // unreliable at the low end of the band and would feed back into its own weight),
        // the observer's, low-passed, while it is off.
        self.omega_o_lp += c.lp_gain * (omega_o - self.omega_o_lp);
        if !self.omega_o_lp.is_finite() {
            self.omega_o_lp = tracker.omega();
        }
        if self.injecting && tracker.omega().abs() > c.high {
            self.injecting = false;
            self.omega_o_lp = tracker.omega();
        } else if !self.injecting && self.omega_o_lp.abs() < 0.8 * c.high {
            self.injecting = true;
            tracker.reset(theta_o, self.omega_o_lp);
            // The load takes what the drive's torque gives (steady speed assumed): the
            // tracker starts with that disturbance instead of learning it.
            tracker.set_load(accel);
        }
        let mut lam = if self.injecting {
            // With a long carrier period HFI's speed lags the rotor's at the top of the band
            // (module [`crate::hfi`], "Hand-over band"): the weight follows the faster
            // estimate.
            let w_abs = if c.weight_on_faster {
                max2(tracker.omega().abs(), self.omega_o_lp.abs())
            } else {
                tracker.omega().abs()
            };
            observer_weight(w_abs, c.low, c.high)
        } else {
            1.0
        };
        let (th_h, w_h) = (tracker.theta(), tracker.omega());
        let reseed = if lam > 0.0 && self.weight == 0.0 {
            // The observer drifted while the speed was low: it restarts from HFI's angle and
            // takes over from the next tick.
            lam = 0.0;
            Some((th_h, w_h))
        } else {
            None
        };
        let theta = wrap(th_h + lam * wrap(theta_o - th_h));
        let omega = w_h + lam * (omega_o - w_h);
        // A reseed tick keeps weight 0 but must not reseed again: mark it with the smallest
        // positive weight.
        self.weight = if reseed.is_some() {
            f32::MIN_POSITIVE
        } else {
            lam
        };
        Blend {
            theta,
            omega,
            reseed,
        }
    }
}
