//! The tracking loop (module [`crate::hfi`], "Tracking loop"): a type-3 PLL on the
//! normalised angle error with the drive's own acceleration fed forward,
//!
//! ```text
//! theta += Ts (w + Kp eps)          Kp = 3 w_n
//! w     += Ki Ts eps + Ts (a_ff - a_L)   Ki = 3 w_n^2
//! a_L   -= K3 Ts eps                K3 = w_n^3   (poles at -w_n, triple)
//! ```
//!
//! and, on a tick without a response, the prediction alone (`eps = 0`).

use core::f32::consts::PI;

use crate::trig::wrap;

/// The loop's gains and state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Pll {
    ts: f32,
    kp: f32,
    ki_t: f32,
    k3_t: f32,
    /// Tracked angle, rad el., in `[-pi, pi)`.
    pub theta: f32,
    /// Tracked speed (the integrator), rad/s el.
    pub omega_i: f32,
    /// Estimated load (disturbance) acceleration, rad/s^2 el.
    pub load: f32,
}

impl Pll {
    /// Gains for the natural frequency `w` (rad/s) at the period `ts` (s); at rest.
    pub fn new(w: f32, ts: f32) -> Self {
        Self {
            ts,
            kp: 3.0 * w,
            ki_t: 3.0 * w * w * ts,
            k3_t: w * w * w * ts,
            theta: 0.0,
            omega_i: 0.0,
            load: 0.0,
        }
    }

    /// Restarts at `theta` (rad el.) and `omega` (rad/s el.; 0 if not finite), no load.
    #[inline]
    pub fn reset(&mut self, theta: f32, omega: f32) {
        self.theta = wrap(theta);
        self.omega_i = if omega.is_finite() { omega } else { 0.0 };
        self.load = 0.0;
    }

    /// Turns the tracked axis by `pi`.
    #[inline]
    pub fn flip(&mut self) {
        self.theta = wrap(self.theta + PI);
    }

    /// One tick corrected by the error `eps`, with the drive's acceleration `accel` (rad/s^2
    /// el.) fed forward.
    #[inline]
    pub fn correct(&mut self, eps: f32, accel: f32) {
        self.theta = wrap(self.theta + self.ts * (self.omega_i + self.kp * eps));
        self.omega_i += self.ki_t * eps + self.ts * (accel - self.load);
        self.load -= self.k3_t * eps;
    }

    /// One tick without a measurement.
    #[inline]
    pub fn predict(&mut self, accel: f32) {
        self.theta = wrap(self.theta + self.ts * self.omega_i);
        self.omega_i += self.ts * (accel - self.load);
    }
}
