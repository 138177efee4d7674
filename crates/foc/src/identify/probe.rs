//! Step [`IdentifyStep::Probe`](super::IdentifyStep::Probe): the wiring check and a rough
//! inductance, from bipolar voltage pulses along the three phase axes.

use core::f32::consts::FRAC_PI_2;

use crate::pi::{Pi, PiGains};
use crate::transforms::AlphaBeta;

use super::align::Align;
use super::context::{Context, Tick};
use super::outcome::IdentifyError;

/// The pulse voltage doubles from this fraction of the limit.
const PROBE_START: f32 = 1.0 / 512.0;
/// The probe stops when an axis reaches this fraction of the test current.
const PROBE_TARGET: f32 = 0.4;
/// Longest probe pulse, ticks.
pub(super) const PROBE_MAX_M: u32 = 64;
/// Repetitions of the deciding probe level.
const PROBE_REPS: u32 = 4;

/// The pulse in progress and what the pulses so far found.
#[derive(Clone, Copy, Debug)]
pub(super) struct Probe {
    /// Ticks in the pulse.
    n: u32,
    /// Pulse voltage, V.
    u: f32,
    /// Pulse half-length, ticks.
    m: u32,
    /// The axis pulsed: 0 a, 1 b, 2 c.
    axis: u32,
    /// Repetition of the deciding level (0 while searching).
    rep: u32,
    /// Axis current at the start of the pulse, A.
    base: f32,
    /// Sum over the repetitions of each axis's current change, A.
    delta: [f32; 3],
    /// The current loop's gains, once decided.
    gains: PiGains,
}

/// Unit vector of phase axis `x` (0 a, 1 b, 2 c).
#[inline]
fn axis(x: u32) -> (f32, f32) {
    match x {
        0 => (1.0, 0.0),
        1 => (-0.5, 0.866_025_4),
        _ => (-0.5, -0.866_025_4),
    }
}

impl Probe {
    /// The first pulse: `PROBE_START u_lim`, one tick.
    #[inline]
    pub(super) fn new(u_lim: f32) -> Self {
        Self {
            n: 0,
            u: PROBE_START * u_lim,
            m: 1,
            axis: 0,
            rep: 0,
            base: 0.0,
            delta: [0.0; 3],
            gains: PiGains { kp: 0.0, ki: 0.0 },
        }
    }

    /// One tick of a pulse on one axis: `+U` for `m` ticks, `-U` for `m` ticks, zero for
    /// `m + 3` ticks (and the delay). The current change over the `+U` half is summed per
    /// axis; after the three axes, [`level_done`](Self::level_done) decides.
    #[inline]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        let m = self.m;
        let (ex, ey) = axis(self.axis);
        let i_x = i_ab.alpha * ex + i_ab.beta * ey;
        let k = self.n - 1; // 0-based tick within the pulse
        if k == 0 {
            self.base = i_x;
        }
        if k == m + ctx.d {
            let delta = (i_x - self.base).abs();
            if let Some(s) = self.delta.get_mut(self.axis as usize) {
                *s += delta;
            }
        }
        let u = if k < m {
            self.u
        } else if k < 2 * m {
            -self.u
        } else {
            0.0
        };
        if k + 1 >= 3 * m + 3 + ctx.d {
            // Pulse done: next axis, next repetition or next level.
            self.n = 0;
            self.axis += 1;
            if self.axis == 3 {
                self.axis = 0;
                if self.level_done(ctx)? {
                    return Ok(Tick::then(Some(AlphaBeta::default()), true));
                }
            }
        }
        Ok(Tick::stay(AlphaBeta {
            alpha: u * ex,
            beta: u * ey,
        }))
    }

    /// After the three axes of a level: the next level (the voltage doubles up to half the
    /// limit, then the length up to [`PROBE_MAX_M`]) until an axis reaches
    /// [`PROBE_TARGET`] of the test current; that level is repeated [`PROBE_REPS`] times and
    /// decides: no axis above 10 % of the target is no motor, one axis below 10 % of the
    /// largest an open phase. Else the inductance bounds `U t / di` (the smallest sizes the
    /// current loop, the largest the injection): `true`, the probe is over.
    fn level_done(&mut self, ctx: &mut Context) -> Result<bool, IdentifyError> {
        let target = PROBE_TARGET * ctx.cfg.test_current_a;
        let reps = (self.rep + 1) as f32;
        let d = self.delta.map(|x| x / reps);
        let dmax = d[0].max(d[1]).max(d[2]);
        let last = self.u >= 0.5 * ctx.u_lim && self.m >= PROBE_MAX_M;
        if self.rep == 0 && dmax < target && !last {
            // Next level: double the voltage up to half the limit, then the length.
            if self.u < 0.5 * ctx.u_lim {
                self.u = (2.0 * self.u).min(0.5 * ctx.u_lim);
            } else {
                self.m *= 2;
            }
            self.delta = [0.0; 3];
            return Ok(false);
        }
        if self.rep + 1 < PROBE_REPS {
            self.rep += 1;
            return Ok(false);
        }
        // Decide.
        if dmax < 0.1 * target {
            return Err(IdentifyError::NoMotor);
        }
        let (mut imin, mut dmin) = (0u8, d[0]);
        for (i, &x) in d.iter().enumerate() {
            if x < dmin {
                dmin = x;
                imin = i as u8;
            }
        }
        if dmin < 0.1 * dmax {
            return Err(IdentifyError::OpenPhase { phase: imin });
        }
        let ut = self.u * self.m as f32 * ctx.cfg.ts_s;
        let l_min = ut / dmax;
        ctx.found.l_max = ut / dmin;
        // Current loop from the smallest inductance (the safe side); R unknown yet.
        let kp = l_min * ctx.cfg.current_bw_rad_s;
        let gains = PiGains {
            kp,
            ki: kp * ctx.cfg.current_bw_rad_s * 0.125,
        };
        self.gains = gains;
        ctx.frame.set(FRAC_PI_2);
        Ok(true)
    }

    /// The alignment that follows, with the current loop the probe sized.
    #[inline]
    pub(super) fn next(&self, ctx: &Context) -> Align {
        Align::new(Pi::new(self.gains, ctx.cfg.ts_s))
    }
}
