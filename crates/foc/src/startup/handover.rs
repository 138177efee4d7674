//! `Handover`: from the ramp's frame to the observer's with the same current vector
//! (module docs of [`startup`](super), "Hand-over"). At entry the ramp's vector
//! `(I_f, 0)` at `gamma` is turned into the observer's frame,
//! `i0 = I_f (cos(gamma - th), sin(gamma - th))`; its torque (as a surface-equivalent
//! current, `i0.q` on a surface motor) presets the speed loop's output, and its d part
//! `i0.d` fades linearly to zero over `blend_time_s`: `i_d = i0.d (1 - n / N)` on tick `n`
//! of `N`. The speed loop and the exits are those of closed loop (module `closed`).

use ekf_core::Estimate;

use super::ramp::Ramp;
use super::{Phase, Sequencer, State};
use crate::config::FocConfig;
use crate::pi::limit;
use crate::transforms::Dq;
use crate::trig::{sin_cos, wrap};

/// The blend's variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Blend {
    /// Ticks since the hand-over.
    pub timer: u32,
    /// d current of the ramp's vector at the hand-over, A.
    pub i_d0: f32,
}

impl Sequencer {
    /// I/f -> observer frame with the same current vector as the ramp `r` (module docs).
    pub(super) fn enter_handover(&mut self, cfg: &FocConfig, est: &Estimate<f32>, r: &Ramp) {
        let (s, c) = sin_cos(wrap(r.gamma - est.theta_rad));
        let i0 = Dq { d: r.amp, q: 0.0 }.rotate(s, c);
        let lim = cfg.current_limit_a;
        // The torque of the ramp's vector as a torque command (`i0.q` on a surface motor).
        let iq0 = limit(cfg.torque_current_of(i0.d, i0.q), -lim, lim);
        let sp = &mut self.speed;
        sp.i_q_ref = iq0;
        sp.div = 0;
        sp.still = 0;
        sp.saturated = false;
        sp.reference_mech = r.omega_ol * self.k.inv_pole_pairs;
        let err = sp.reference_mech - est.omega_e_rad_s * self.k.inv_pole_pairs;
        sp.pi.preset_output(iq0, err, 0.0);
        self.phase = Phase::Handover(Blend {
            timer: 0,
            i_d0: i0.d,
        });
        self.state = State::Handover;
    }
}
