//! [`HfiTracker`]: the carrier ([`super::injection`]), its demodulation
//! ([`super::demod`]) and the tracking loop ([`super::pll`]) of one tick, in that order of
//! the signal: [`HfiTracker::update`] takes the sample, [`HfiTracker::inject`] gives the next
//! carrier.

use ekf_core::MotorParams;

use super::config::{HfiConfig, MAX_HALF_PERIOD};
use super::demod::{Demodulator, Response};
use super::injection::Injector;
use super::pll::Pll;
use crate::config::{ComputationDelay, FocConfig};
use crate::transforms::AlphaBeta;

/// The HFI angle tracker (module [`crate::hfi`]): carrier generation, demodulation, PLL.
/// Pure: it sees only the currents it is given and returns the voltage to add.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HfiTracker {
    carrier: Injector,
    demod: Demodulator,
    pll: Pll,
}

impl HfiTracker {
    /// A tracker for `motor` at the PWM period `ts_s` with the carrier `injection_v`, the loop
    /// bandwidth `pll_bandwidth_rad_s`, and the controller's delay and angle advance
    /// (periods). Angle and speed start at zero.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        motor: &MotorParams<f32>,
        ts_s: f32,
        injection_v: f32,
        half_period_ticks: u8,
        pll_bandwidth_rad_s: f32,
        delay: ComputationDelay,
        angle_advance_periods: f32,
    ) -> Self {
        let half = half_period_ticks.clamp(1, MAX_HALF_PERIOD);
        let y_d = 0.5 * (1.0 / motor.ld_h - 1.0 / motor.lq_h);
        Self {
            carrier: Injector::new(
                injection_v,
                half,
                angle_advance_periods * ts_s,
                delay == ComputationDelay::OnePeriod,
            ),
            demod: Demodulator::new(half, 1.0 / (2.0 * ts_s * injection_v * y_d)),
            pll: Pll::new(pll_bandwidth_rad_s, ts_s),
        }
    }

    /// The tracker for a controller configuration and HFI settings.
    pub fn from_config(cfg: &FocConfig, hfi: &HfiConfig) -> Self {
        Self::new(
            &cfg.motor,
            cfg.ts_s,
            hfi.injection_v,
            hfi.half_period_ticks,
            hfi.pll_bandwidth_rad_s,
            cfg.delay,
            cfg.angle_advance_periods,
        )
    }

    /// Restarts at angle `theta` (rad el.) and speed `omega` (rad/s el.), carrier history
    /// cleared (the first demodulation comes one carrier period of steps, `2 N + 1` samples,
    /// after the carrier is applied).
    pub fn reset(&mut self, theta: f32, omega: f32) {
        self.pll.reset(theta, omega);
        self.carrier.clear();
        self.demod.clear();
    }

    /// The carrier voltage applied over the last period `[t_k-1, t_k)` (alpha-beta, V; zero
    /// when none was), as the next [`update`](Self::update) demodulates it.
    pub fn applied_carrier(&self) -> AlphaBeta {
        self.carrier.applied_voltage()
    }

    /// The carrier's part of the last sample (alpha-beta, A): the measured per-period step
    /// accumulated with the applied signs, less its mean over a carrier period. The sample
    /// less this is the fundamental at the sample's own time (no averaging lag).
    pub fn carrier_current(&self) -> AlphaBeta {
        self.demod.carrier_current()
    }

    /// Sets the estimated load (disturbance) acceleration, rad/s^2 el.
    pub fn set_load(&mut self, accel_rad_s2: f32) {
        if accel_rad_s2.is_finite() {
            self.pll.load = accel_rad_s2;
        }
    }

    /// Turns the tracked axis by `pi` (after the polarity test).
    pub fn flip(&mut self) {
        self.pll.flip();
    }

    /// Tracked electrical angle, rad, in `[-pi, pi)`.
    pub fn theta(&self) -> f32 {
        self.pll.theta
    }

    /// Tracked electrical speed (the loop's integrator), rad/s.
    pub fn omega(&self) -> f32 {
        self.pll.omega_i
    }

    /// The last demodulation.
    pub fn response(&self) -> Response {
        self.demod.response()
    }

    /// A sample was missing or refused: the next `2 N + 1` accepted samples rebuild the
    /// history before the loop corrects again (the angle keeps integrating the speed).
    pub fn skip(&mut self, accel_rad_s2: f32) {
        self.demod.skip();
        self.pll.predict(accel_rad_s2);
    }

    /// Takes the current sample `i[k]` (alpha-beta, A) and the acceleration the drive's own
    /// torque command gives (rad/s^2 el., `p T* / J`; 0 if unknown): demodulates the carrier
    /// and steps the loop (module [`crate::hfi`]). Returns the response when there was one
    /// (a full carrier period of history), and the fundamental current, the mean of the last
    /// carrier period's samples (`i[k]` alone until there is one).
    pub fn update(&mut self, i: AlphaBeta, accel_rad_s2: f32) -> (Option<Response>, AlphaBeta) {
        let (resp, fund) = self.demod.update(i, self.carrier.applied());
        match resp {
            Some(r) => self.pll.correct(r.eps, accel_rad_s2),
            None => self.pll.predict(accel_rad_s2),
        }
        (resp, fund)
    }

    /// The carrier voltage for this tick (alpha-beta, V), along the tracked axis advanced to
    /// the middle of its application interval; the sign alternates every half period.
    pub fn inject(&mut self) -> AlphaBeta {
        self.carrier.next(self.pll.theta, self.pll.omega_i)
    }
}
