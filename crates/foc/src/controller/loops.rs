//! The parts of the current loops (module docs of [`controller`](super), "Current loops",
//! "Current references in closed loop"): the feed-forward, the integrators re-expressed at
//! a frame change, the shaped references and the voltage held over a bad sample.

use super::Foc;
use crate::startup::{Frame, Plan};
use crate::transforms::{AlphaBeta, Dq};
use crate::trig::{at_most, sin_cos, sqrt, wrap};

#[cfg(feature = "flux-map")]
#[path = "map_path.rs"]
mod map_path;

impl Foc {
    /// Closed-loop current references from the plan's (module [`crate::mtpa`]: `r.q` is the
    /// torque command as a surface-equivalent current, `r.d` a hand-over's fading d
    /// current): d from MTPA (one fixed-point step from the last MTPA point) plus the
    /// field-weakening correction, limited to `[-max_negative_id, current_limit_a]`; q from
    /// the torque with that d; then the current circle, cutting q first.
    ///
    /// First the field-weakening integrator (module [`crate::fieldweak`]) takes the loops'
    /// steady-state voltage, their integrators (as the last tick left them) plus this tick's
    /// feed-forward `ff`, against `u_max` (only on an accepted sample). Out of the observer's
    /// frame (align, I/f) the plan's references are returned and the correction is reset.
    #[inline(never)]
    pub(super) fn shaped_refs(&mut self, plan: Plan, ff: Dq, u_max: f32, sample_ok: bool) -> Dq {
        if !plan.frame.emf {
            self.fw.reset();
            self.iq_last = 0.0;
            #[cfg(feature = "flux-map")]
            if self.cfg.flux_map.is_some() {
                self.reset_map();
            }
            return plan.i_ref;
        }
        #[cfg(feature = "flux-map")]
        if let Some(r) = self.map_refs(plan, u_max) {
            return r;
        }
        if cfg!(feature = "field-weakening") && self.fw_on && sample_ok {
            let v = Dq {
                d: self.pi_d.integrator() + ff.d,
                q: self.pi_q.integrator() + ff.q,
            };
            self.fw
                .update(v.norm_squared(), u_max, plan.frame.omega, self.id_base);
        }
        let r = plan.i_ref;
        let lim = self.cfg.current_limit_a;
        // The MTPA point of the torque command alone (one fixed-point step from the last
        // one): field weakening and the current circle stay out of the iteration, which
        // they would turn into an oscillation.
        let id_base = if self.mtpa_on {
            let m = self.mtpa.step(r.q, self.iq_last, 0.0);
            self.iq_last = m.q;
            r.d + m.d
        } else {
            r.d
        };
        self.id_base = id_base;
        let d = crate::pi::limit(id_base + self.fw.id(), -self.max_neg_id, lim);
        let q = if self.salient {
            self.mtpa.iq_for_torque(r.q, d)
        } else {
            r.q
        };
        let q_max_sq = lim * lim - d * d;
        let q = if at_most(q * q, q_max_sq) {
            q
        } else {
            let m = sqrt(q_max_sq);
            crate::pi::limit(q, -m, m)
        };
        Dq { d, q }
    }

    /// The last dq voltage for a tick over a bad sample: in this tick's frame (rotated when
    /// the frame changed) and within the voltage limit `u_max`; and whether it was limited.
    #[cold]
    #[inline(never)]
    pub(super) fn held_voltage(
        &self,
        reframed_from: Option<Frame>,
        frame: Frame,
        u_max: f32,
    ) -> (Dq, bool) {
        let mut u = self.u_dq_last;
        if let Some(old) = reframed_from {
            let (s, c) = sin_cos(wrap(old.theta - frame.theta));
            u = u.rotate(s, c);
        }
        let n2 = u.norm_squared();
        if at_most(n2, u_max * u_max) {
            (u, false)
        } else {
            (u * (u_max / sqrt(n2)), true)
        }
    }

    /// Decoupling and back-EMF feed-forward in `frame` for the measured currents `i`, with
    /// the observer's tracked flux linkage (the configured one when its parameter tracking is
    /// off): `u_d = -w Lq i_q`, `u_q = w Ld i_d + w psi_f`. The tracked flux is the one that,
    /// with the `Rs` the observer uses, explains the q-axis voltage, so a warm motor's EMF is
    /// fed forward as it is. The resistive drop is left to the PI integrators: a term
    /// `Rs i` on the measured currents would cancel the winding's own damping of the rotor's
    /// swing under I/f (a restart then failed to hand over in `tests/state_machine.rs`).
    #[inline]
    pub(super) fn feed_forward(&self, i: Dq, frame: Frame) -> Dq {
        #[cfg(feature = "flux-map")]
        if let Some(ff) = self.map_feed_forward(i, frame) {
            return ff;
        }
        let wlq = frame.omega * self.cfg.motor.lq_h;
        let wld = frame.omega * self.cfg.motor.ld_h;
        let emf = if frame.emf {
            frame.omega * self.observer.parameters().0
        } else {
            0.0
        };
        Dq {
            d: -wlq * i.q,
            q: wld * i.d + emf,
        }
    }

    /// Re-expresses the current integrators of frame `old` in frame `new` so that the
    /// voltage `integrator + feed-forward` is the same vector in alpha-beta.
    #[inline]
    pub(super) fn reframe(&mut self, old: Frame, new: Frame, i_ab: AlphaBeta, ff_new: Dq) {
        let ff_old = self.feed_forward(i_ab.to_dq_angle(old.theta), old);
        let v_old = Dq {
            d: self.pi_d.integrator() + ff_old.d,
            q: self.pi_q.integrator() + ff_old.q,
        };
        let (s, c) = sin_cos(wrap(old.theta - new.theta));
        let v_new = v_old.rotate(s, c);
        self.pi_d.set_integrator(v_new.d - ff_new.d);
        self.pi_q.set_integrator(v_new.q - ff_new.q);
    }
}
