//! What the steps share: the settings, this tick's voltage limit, the frame the voltages are
//! set in, the results so far, and the d-axis current loop of the standstill steps.

use crate::pi::Pi;
use crate::transforms::AlphaBeta;
use crate::trig::{sin_cos, wrap};

use super::config::IdentifyConfig;
use super::numeric::ticks;
use super::outcome::IdentifyError;

/// The shared context every step reads (and some write).
#[derive(Clone, Copy, Debug)]
pub(super) struct Context {
    /// The settings (validated).
    pub(super) cfg: IdentifyConfig,
    /// Periods of computation delay (0 or 1).
    pub(super) d: u32,
    /// Ticks per injection period ([`IdentifyConfig::hf_period_ticks`]).
    pub(super) hf_n: u32,
    /// This tick's voltage limit `max_modulation u_dc / sqrt(3)`, V.
    pub(super) u_lim: f32,
    /// The frame the current loops and the voltages are set in.
    pub(super) frame: Frame,
    /// What has been measured so far.
    pub(super) found: Found,
}

/// The frame of the align, resistance, inductance and I/f steps: its angle (phase-a axis 0)
/// and its speed.
#[derive(Clone, Copy, Debug)]
pub(super) struct Frame {
    /// Angle, rad (wrapped).
    pub(super) angle: f32,
    /// `(sin, cos)` of the angle.
    sc: (f32, f32),
    /// Speed, rad/s electrical (non-zero during the spin and the inertia move only).
    pub(super) omega: f32,
}

impl Frame {
    /// At rest at angle 0.
    pub(super) fn new() -> Self {
        Self {
            angle: 0.0,
            sc: (0.0, 1.0),
            omega: 0.0,
        }
    }

    /// Sets the angle (wrapped).
    #[inline]
    pub(super) fn set(&mut self, angle: f32) {
        self.angle = wrap(angle);
        self.sc = sin_cos(self.angle);
    }

    /// `(d, q)` of `v` in the frame.
    #[inline]
    pub(super) fn dq(&self, v: AlphaBeta) -> (f32, f32) {
        let (s, c) = self.sc;
        (c * v.alpha + s * v.beta, -s * v.alpha + c * v.beta)
    }

    /// `(d, q)` in the frame to alpha-beta.
    #[inline]
    pub(super) fn ab(&self, d: f32, q: f32) -> AlphaBeta {
        let (s, c) = self.sc;
        AlphaBeta {
            alpha: c * d - s * q,
            beta: s * d + c * q,
        }
    }
}

/// The results so far (zero until measured).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Found {
    /// Current-sensor offsets, A (phases a and b, or alpha and beta).
    pub(super) offsets: [f32; 2],
    /// The probe's largest inductance `U t / di` (of the three axes), H.
    pub(super) l_max: f32,
    /// Stator resistance, ohm.
    pub(super) rs: f32,
    /// Inverter voltage error at the test current, V.
    pub(super) v_err: f32,
    /// d-axis inductance, H.
    pub(super) ld: f32,
    /// q-axis inductance, H.
    pub(super) lq: f32,
    /// Flux linkage, Wb.
    pub(super) psi: Option<f32>,
    /// Inertia, kg m^2.
    pub(super) j: Option<f32>,
}

/// Counts the ticks a current loop spends at its voltage limit short of its reference.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Saturation(u32);

impl Saturation {
    /// [`IdentifyError::BusTooLow`] after more than 20 ms at the limit (`at_limit`) with the
    /// current `i` below 90 % of `i_ref`; any other tick starts the count again.
    #[inline]
    pub(super) fn check(
        &mut self,
        ctx: &Context,
        at_limit: bool,
        i: f32,
        i_ref: f32,
    ) -> Result<(), IdentifyError> {
        if at_limit && i.abs() < 0.9 * i_ref.abs() {
            self.0 += 1;
            if self.0 > ticks(0.02, ctx.cfg.ts_s) {
                return Err(IdentifyError::BusTooLow {
                    limit_v: ctx.u_lim,
                    current_a: i.abs(),
                    target_a: i_ref.abs(),
                });
            }
        } else {
            self.0 = 0;
        }
        Ok(())
    }
}

/// The d-axis current loop of the align and resistance steps, in the fixed frame, with the q
/// voltage at zero.
#[derive(Clone, Copy, Debug)]
pub(super) struct HoldLoop {
    /// The d-axis PI.
    pub(super) pi: Pi,
    /// Its saturation count.
    pub(super) sat: Saturation,
}

impl HoldLoop {
    /// One tick toward the d current `i_ref`: the voltage, alpha-beta; checks the limit.
    #[inline]
    pub(super) fn hold(
        &mut self,
        ctx: &Context,
        i_ab: AlphaBeta,
        i_ref: f32,
    ) -> Result<AlphaBeta, IdentifyError> {
        let (i_d, _) = ctx.frame.dq(i_ab);
        let lim = ctx.u_lim;
        let u_d = self.pi.step(i_ref - i_d, 0.0, -lim, lim);
        self.sat.check(ctx, u_d.abs() >= 0.999 * lim, i_d, i_ref)?;
        Ok(ctx.frame.ab(u_d, 0.0))
    }
}

/// What a step asks of its tick: the voltage to apply (`None`: PWM off) and whether the step
/// is over (its `next` then gives the state that follows, in the same tick).
#[derive(Clone, Copy, Debug)]
pub(super) struct Tick {
    /// Voltage, alpha-beta, V (limited and modulated by the dispatcher).
    pub(super) u: Option<AlphaBeta>,
    /// The step is over.
    pub(super) done: bool,
}

impl Tick {
    /// Stays, applying `u`.
    #[inline]
    pub(super) fn stay(u: AlphaBeta) -> Self {
        Self {
            u: Some(u),
            done: false,
        }
    }

    /// Applies `u`; the step is over when `done`.
    #[inline]
    pub(super) fn then(u: Option<AlphaBeta>, done: bool) -> Self {
        Self { u, done }
    }
}
