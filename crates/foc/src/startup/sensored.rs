//! Sensored closed loop (reported as `ClosedLoop`): the speed loop on the sensor's angle and
//! speed, references `(0, i_q)`. A stall trips after `stall_time_s` with the speed loop at
//! its current limit and the speed below a tenth of the hand-over speed; a stop ends once
//! the reference is zero and the speed below that tenth.

use super::{Frame, Phase, Plan, Sequencer, Stop};
use crate::config::FocConfig;
use crate::fault::Fault;
use crate::transforms::Dq;
use crate::trig::wrap;

/// The sensored loop's variables.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Sensored {
    /// Ticks in a row at the current limit, slow.
    stall_count: u32,
    /// First tick: the speed reference starts at the sensor's speed.
    fresh: bool,
}

impl Sensored {
    /// The loop from its first tick.
    pub fn new() -> Self {
        Self {
            stall_count: 0,
            fresh: true,
        }
    }
}

impl Sequencer {
    /// One tick of the sensored loop on the sensor reading `(angle, speed)`, rad el. and
    /// rad/s el.
    #[inline(always)]
    pub(super) fn sensored(
        &mut self,
        cfg: &FocConfig,
        sensor: Option<(f32, f32)>,
    ) -> Result<Plan, Stop> {
        let Some((theta, w)) = sensor else {
            return Err(Stop::Trip(Fault::NonFiniteInput, f32::NAN));
        };
        let Phase::Sensored(s) = &mut self.phase else {
            return Err(Stop::Off);
        };
        let theta = wrap(theta);
        let k = &self.k;
        if s.fresh {
            s.fresh = false;
            self.speed.reference_mech = w * k.inv_pole_pairs;
            self.speed.i_q_ref = 0.0;
            self.speed.pi.reset();
        }
        self.speed
            .step(cfg, k, &self.cmd, true, w * k.inv_pole_pairs);
        let slow = w.abs() < 0.1 * k.handover;
        s.stall_count = if self.speed.saturated && slow {
            s.stall_count.saturating_add(1)
        } else {
            0
        };
        if s.stall_count >= k.stall_ticks {
            return Err(Stop::Trip(Fault::Stall, w));
        }
        if self.cmd.stop_requested && self.speed.reference_mech == 0.0 && slow {
            return Err(Stop::Idle);
        }
        Ok(Plan {
            frame: Frame {
                theta,
                omega: w,
                emf: true,
            },
            i_ref: Dq {
                d: 0.0,
                q: self.speed.i_q_ref,
            },
            reframe_from: None,
        })
    }
}
