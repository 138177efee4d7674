//! The carrier (module [`crate::hfi`], "Method"): a square wave of amplitude `V_h` along the
//! tracked d axis advanced to the middle of its application interval, `+V_h` for `N` ticks
//! and `-V_h` for `N` ticks, and the history of what was applied, which the demodulation
//! needs (the sample at `t_k` answers the carrier computed one tick ago, or two with the
//! one-period computation delay).

use crate::transforms::AlphaBeta;
use crate::trig::{add_angles, sin_cos, sin_cos_small};

/// One carrier period as it was applied: sign and axis (sine, cosine).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Carrier {
    pub sign: f32,
    pub sin: f32,
    pub cos: f32,
    /// Position in the carrier period (0 to `2 N - 1`).
    pub phase: u8,
}

/// The carrier generator and its history.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Injector {
    /// Amplitude `V_h`, V.
    v: f32,
    /// The controller's angle advance, s.
    advance_s: f32,
    one_period_delay: bool,
    /// Ticks per half period of the carrier (1 to [`MAX_HALF_PERIOD`](super::MAX_HALF_PERIOD)),
    /// and per period.
    half: u8,
    period: u8,
    /// Position in the carrier period of the next carrier.
    phase: u8,
    /// Carrier computed one and two ticks ago.
    hist: [Carrier; 2],
}

impl Injector {
    /// `half` ticks per half period (already clamped), amplitude `v` (V), angle advance
    /// `advance_s` (s).
    pub fn new(v: f32, half: u8, advance_s: f32, one_period_delay: bool) -> Self {
        Self {
            v,
            advance_s,
            one_period_delay,
            half,
            period: 2 * half,
            phase: 0,
            hist: [Carrier::default(); 2],
        }
    }

    /// Forgets what was applied (no carrier on the next samples).
    #[inline]
    pub fn clear(&mut self) {
        self.hist = [Carrier::default(); 2];
    }

    /// The carrier applied over the last period `[t_k-1, t_k)` (sign 0 when none was).
    #[inline]
    pub fn applied(&self) -> Carrier {
        if self.one_period_delay {
            self.hist[1]
        } else {
            self.hist[0]
        }
    }

    /// The voltage of [`applied`](Self::applied), alpha-beta, V.
    #[inline]
    pub fn applied_voltage(&self) -> AlphaBeta {
        let c = self.applied();
        let a = self.v * c.sign;
        AlphaBeta {
            alpha: a * c.cos,
            beta: a * c.sin,
        }
    }

    /// The carrier voltage for this tick (alpha-beta, V) along the tracked angle `theta`
    /// advanced by the speed `omega` to the middle of its application interval; `+V_h` in
    /// the first half of the period, `-V_h` in the second.
    #[inline]
    pub fn next(&mut self, theta: f32, omega: f32) -> AlphaBeta {
        let sign = if self.phase < self.half { 1.0 } else { -1.0 };
        let phase = self.phase;
        self.phase = (self.phase + 1) % self.period;
        let (s0, c0) = sin_cos(theta);
        let (sd, cd) = sin_cos_small(omega * self.advance_s);
        let (s, c) = add_angles(s0, c0, sd, cd);
        self.hist = [
            Carrier {
                sign,
                sin: s,
                cos: c,
                phase,
            },
            self.hist[0],
        ];
        let a = self.v * sign;
        AlphaBeta {
            alpha: a * c,
            beta: a * s,
        }
    }
}
