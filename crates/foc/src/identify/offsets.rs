//! Step [`IdentifyStep::Offsets`](super::IdentifyStep::Offsets): the current-sensor offsets,
//! PWM off.

use super::context::{Context, Tick};
use super::numeric::{Sums, ticks};
use super::outcome::{IdentifyError, Quantity};
use super::probe::Probe;

/// Averaging the raw currents with the bridge off.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Offsets {
    /// Ticks in the step.
    n: u32,
    /// Sums of the two raw currents.
    sums: Sums,
}

impl Offsets {
    /// One tick with the raw currents (phases a and b, or alpha and beta), A. After
    /// `max(20 ms, 16 ticks)`: the mean of all but the first 3 ticks (a bridge just turned off
    /// settles), refused above 20 % of the test current.
    #[inline]
    pub(super) fn step(&mut self, ctx: &mut Context, raw: [f32; 2]) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        if self.n > 3 {
            self.sums.add([raw[0], raw[1], 0.0, 0.0]);
        }
        if self.n >= ticks(0.02, ctx.cfg.ts_s).max(16) {
            let m = self.sums.mean();
            let lim = 0.2 * ctx.cfg.test_current_a;
            for v in [m[0], m[1]] {
                if v.is_nan() || v.abs() > lim {
                    return Err(IdentifyError::Implausible {
                        quantity: Quantity::CurrentOffset,
                        value: v,
                    });
                }
            }
            ctx.found.offsets = [m[0], m[1]];
            return Ok(Tick::then(None, true));
        }
        Ok(Tick::then(None, false))
    }

    /// The probe that follows, from this tick's voltage limit.
    #[inline]
    pub(super) fn next(&self, ctx: &Context) -> Probe {
        Probe::new(ctx.u_lim)
    }
}
