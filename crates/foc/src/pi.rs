//! Discrete PI controller with feed-forward, output limits and anti-windup by conditional
//! integration.
//!
//! ```text
//! I'  = I + Ki T e                       (backward Euler, T = the loop's sample time)
//! u'  = Kp e + I' + ff
//! I   = I       if (u' > hi and e > 0) or (u' < lo and e < 0)    (would wind up: hold)
//!       I'      otherwise
//! I   = clamp(I, lo, hi)                 (the integrator alone never exceeds the limits)
//! u   = clamp(Kp e + I + ff, lo, hi)
//! ```
//!
//! While the output is saturated the integrator does not grow in the direction of the
//! saturation; as soon as the error changes sign the output leaves the limit within one
//! sample (no stored windup to unwind). The limits are passed on every call so that the
//! current loop can use a voltage limit that follows the DC bus and the speed loop a current
//! limit. A NaN anywhere resets the integrator and gives 0 (never a NaN output).

/// Proportional and integral gains.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PiGains {
    /// Proportional gain (output unit per error unit, e.g. V/A).
    pub kp: f32,
    /// Integral gain per second (output unit per error unit per second, e.g. V/(A s)).
    pub ki: f32,
}

impl PiGains {
    /// Whether both gains are finite and non-negative.
    pub fn is_valid(&self) -> bool {
        self.kp.is_finite() && self.ki.is_finite() && self.kp >= 0.0 && self.ki >= 0.0
    }
}

/// PI controller state (module docs give the law).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pi {
    kp: f32,
    /// `Ki T`.
    ki_t: f32,
    integ: f32,
}

impl Pi {
    /// A controller with `gains` run every `t_s` seconds, integrator at zero.
    pub fn new(gains: PiGains, t_s: f32) -> Self {
        Self {
            kp: gains.kp,
            ki_t: gains.ki * t_s,
            integ: 0.0,
        }
    }

    /// The output `Kp e + I' + ff` this call of [`step`](Self::step) would give before
    /// limiting (used to decide a limit that depends on the result, as the current loop's
    /// voltage circle does).
    pub fn unlimited(&self, err: f32, ff: f32) -> f32 {
        self.kp * err + self.integ + self.ki_t * err + ff
    }

    /// One sample with error `err`, feed-forward `ff` and finite output limits `lo <= hi`;
    /// returns the limited output `min(max(u, lo), hi)` (so `hi` wins if `lo > hi`). An
    /// infinite error saturates; a NaN resets the integrator and gives the limited 0.
    pub fn step(&mut self, err: f32, ff: f32, lo: f32, hi: f32) -> f32 {
        let p = self.kp * err;
        let i_new = self.integ + self.ki_t * err;
        let u_new = p + i_new + ff;
        // A NaN in `err` or `ff` (or an infinity that cancels) shows up here.
        if u_new.is_nan() {
            self.integ = 0.0;
            return limit(0.0, lo, hi);
        }
        let winds_up = (u_new > hi && err > 0.0) || (u_new < lo && err < 0.0);
        let i = limit(if winds_up { self.integ } else { i_new }, lo, hi);
        self.integ = i;
        limit(p + i + ff, lo, hi)
    }

    /// Replaces the proportional gain (gain scheduling; the integrator is kept), V/A.
    /// (Cargo feature `flux-map`.)
    #[cfg(feature = "flux-map")]
    #[inline]
    pub fn set_kp(&mut self, kp: f32) {
        self.kp = kp;
    }

    /// The integrator, in output units.
    pub fn integrator(&self) -> f32 {
        self.integ
    }

    /// Sets the integrator (bumpless transfer); a non-finite value sets 0.
    pub fn set_integrator(&mut self, value: f32) {
        self.integ = if value.is_finite() { value } else { 0.0 };
    }

    /// Sets the integrator so that the output for error `err` and feed-forward `ff` is
    /// `u` (bumpless start of a loop at a known output).
    pub fn preset_output(&mut self, u: f32, err: f32, ff: f32) {
        self.set_integrator(u - self.kp * err - ff);
    }

    /// Integrator back to zero.
    pub fn reset(&mut self) {
        self.integ = 0.0;
    }
}

/// `min(max(x, lo), hi)` that cannot panic (unlike `f32::clamp` with `lo > hi` or a NaN bound);
/// a NaN `x` gives `lo` limited by `hi`.
pub(crate) fn limit(x: f32, lo: f32, hi: f32) -> f32 {
    let y = if x > lo { x } else { lo };
    if y < hi { y } else { hi }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pure_gain_and_integration() {
        let mut pi = Pi::new(PiGains { kp: 2.0, ki: 100.0 }, 0.01);
        // e = 1: I = 1, u = 2 + 1.
        assert_eq!(pi.step(1.0, 0.0, -10.0, 10.0), 3.0);
        assert_eq!(pi.step(1.0, 0.5, -10.0, 10.0), 4.5);
        assert_eq!(pi.integrator(), 2.0);
        assert_eq!(pi.step(f32::NAN, 0.0, -10.0, 10.0), 0.0);
        assert_eq!(pi.integrator(), 0.0);
        assert_eq!(limit(f32::NAN, -1.0, 1.0), -1.0);
        assert_eq!(limit(5.0, 2.0, 1.0), 1.0);
    }
}
