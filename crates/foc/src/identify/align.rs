//! Step [`IdentifyStep::Align`](super::IdentifyStep::Align): the rotor pulled to the phase-a
//! axis by the test current, first at 90 deg, then at 0 deg.

use crate::pi::Pi;
use crate::transforms::AlphaBeta;

use super::context::{Context, HoldLoop, Saturation, Tick};
use super::numeric::ticks;
use super::outcome::IdentifyError;
use super::resistance::Resistance;

/// The half of the alignment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Half {
    /// The current ramps up (over 40 % of the half) along the 90 deg axis.
    Quadrature,
    /// The full current along the phase-a axis (0 deg).
    PhaseA,
}

/// The alignment in progress.
#[derive(Clone, Copy, Debug)]
pub(super) struct Align {
    /// Ticks in the half.
    n: u32,
    half: Half,
    /// The d-axis loop (kept for the resistance step).
    hold: HoldLoop,
}

impl Align {
    /// Starts with the d-axis PI `pi` (frame already at 90 deg).
    #[inline]
    pub(super) fn new(pi: Pi) -> Self {
        Self {
            n: 0,
            half: Half::Quadrature,
            hold: HoldLoop {
                pi,
                sat: Saturation::default(),
            },
        }
    }

    /// One tick: the d current toward the test current, q voltage zero (the swinging rotor's
    /// EMF drives a braking current). Each half lasts `align_time_s / 2`.
    #[inline]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        let half = ticks(0.5 * ctx.cfg.align_time_s, ctx.cfg.ts_s);
        let i_t = ctx.cfg.test_current_a;
        let i_ref = if self.half == Half::Quadrature {
            i_t * (self.n as f32 / (0.4 * half as f32)).min(1.0)
        } else {
            i_t
        };
        let u = self.hold.hold(ctx, i_ab, i_ref)?;
        let mut done = false;
        if self.n >= half {
            if self.half == Half::Quadrature {
                self.half = Half::PhaseA;
                self.n = 0;
                // Same voltage vector expressed in the new frame: the d loop starts from it.
                ctx.frame.set(0.0);
            } else {
                done = true;
            }
        }
        Ok(Tick::then(Some(u), done))
    }

    /// The resistance step that follows, with this step's d-axis PI.
    #[inline]
    pub(super) fn next(&self) -> Resistance {
        Resistance::new(self.hold.pi)
    }
}
