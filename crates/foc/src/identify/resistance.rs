//! Step [`IdentifyStep::Resistance`](super::IdentifyStep::Resistance): `Rs` and the
//! inverter's voltage error from two DC current levels along the aligned d axis.

use crate::pi::Pi;
use crate::transforms::AlphaBeta;

use super::context::{Context, HoldLoop, Saturation, Tick};
use super::inductance::{Axis, Injection};
use super::numeric::{Sums, ticks};
use super::outcome::{IdentifyError, Quantity};

/// The two levels, and the sums of `(u_d, i_d)` at each.
#[derive(Clone, Copy, Debug)]
pub(super) struct Resistance {
    /// Ticks in the level.
    n: u32,
    /// At the full test current (else half of it).
    full: bool,
    /// The d-axis loop (from the alignment).
    hold: HoldLoop,
    /// `(u_d, i_d)` at half the test current.
    low: Sums,
    /// `(u_d, i_d)` at the test current.
    high: Sums,
    /// The mean d voltage at the test current, V (once measured).
    u_hold: f32,
}

impl Resistance {
    /// Starts at half the test current with the alignment's PI `pi`.
    #[inline]
    pub(super) fn new(pi: Pi) -> Self {
        Self {
            n: 0,
            full: false,
            hold: HoldLoop {
                pi,
                sat: Saturation::default(),
            },
            low: Sums::default(),
            high: Sums::default(),
            u_hold: 0.0,
        }
    }

    /// One tick: each level lasts `resistance_time_s`, the last 70 % averaged. Then
    /// `Rs = (U2 - U1) / (I2 - I1)` and the voltage error `U2 - Rs I2`.
    #[inline]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        let len = ticks(ctx.cfg.resistance_time_s, ctx.cfg.ts_s);
        let settle = (len * 3) / 10;
        let i_t = ctx.cfg.test_current_a;
        let i_ref = if !self.full { 0.5 * i_t } else { i_t };
        let u = self.hold.hold(ctx, i_ab, i_ref)?;
        if self.n > settle {
            let (i_d, _) = ctx.frame.dq(i_ab);
            let (u_d, _) = ctx.frame.dq(u);
            let s = if !self.full {
                &mut self.low
            } else {
                &mut self.high
            };
            s.add([u_d, i_d, 0.0, 0.0]);
        }
        let mut done = false;
        if self.n >= len {
            if !self.full {
                self.full = true;
                self.n = 0;
            } else {
                let [u1, i1, ..] = self.low.mean();
                let [u2, i2, ..] = self.high.mean();
                let rs = (u2 - u1) / (i2 - i1);
                if !(rs.is_finite() && rs > 1e-4 && rs < 1e4) {
                    return Err(IdentifyError::Implausible {
                        quantity: Quantity::Resistance,
                        value: rs,
                    });
                }
                ctx.found.rs = rs;
                ctx.found.v_err = u2 - rs * i2;
                self.u_hold = u2;
                done = true;
            }
        }
        Ok(Tick::then(Some(u), done))
    }

    /// The `d` injection that follows, on top of the full level's voltage.
    #[inline]
    pub(super) fn next(&self, ctx: &Context) -> Injection {
        Injection::new(ctx, Axis::D, self.u_hold)
    }
}
