//! The closed-loop references, gains and decoupling of a drive told a flux map
//! ([`FocConfig::flux_map`](crate::FocConfig::flux_map), module [`crate::mapdrive`]).

use super::super::Foc;
use crate::mapdrive::MapPoint;
use crate::startup::{Frame, Plan};
use crate::transforms::Dq;
use crate::trig::{at_most, sqrt};

impl Foc {
    /// Back to the zero-torque point of the map and the configured gains (loops reset, out
    /// of closed loop).
    pub(in crate::controller) fn reset_map(&mut self) {
        self.map_point = match &self.cfg.flux_map {
            Some(m) => m.mtpa.lookup(0.0),
            None => MapPoint::ZERO,
        };
        self.pi_d.set_kp(self.cfg.current_pi_gains_d().kp);
        self.pi_q.set_kp(self.cfg.current_pi_gains().kp);
    }

    /// Closed-loop references from the map (`r.q` the torque command as a surface-equivalent
    /// current, `r.d` a hand-over's fading d current), `None` without a map. The point: the
    /// MTPA table's, or with field weakening on and the flux limit
    /// `psi_lim = (k u_max - Rs |i_r|) / |w|` below the MTPA flux (`|i_r|` the last
    /// reference), the field-weakening table's. The current PIs' `Kp` follow the point's
    /// incremental inductances (unless `current_gains` is set); `d` is limited to
    /// `[-max_negative_id, current_limit_a]`, then the current circle cuts `q` first.
    #[inline(never)]
    pub(in crate::controller) fn map_refs(&mut self, plan: Plan, u_max: f32) -> Option<Dq> {
        let m = self.cfg.flux_map.as_ref()?;
        let r = plan.i_ref;
        let p = if cfg!(feature = "field-weakening") && self.fw_on {
            let i = self.map_point.i;
            let u = self.cfg.field_weakening.voltage_margin * u_max
                - self.cfg.motor.rs_ohm * sqrt(i.norm_squared());
            let w = plan.frame.omega.abs();
            let (_, psi_hi) = m.fw.flux_range_wb();
            if at_most(psi_hi * w, u) {
                m.mtpa.lookup(r.q)
            } else {
                m.fw.lookup(r.q, u / w)
            }
        } else {
            m.mtpa.lookup(r.q)
        };
        self.map_point = p;
        if self.cfg.current_gains.is_none() {
            let bw = self.cfg.current_bw_rad_s;
            self.pi_d.set_kp(bw * p.l_dd);
            self.pi_q.set_kp(bw * p.l_qq);
        }
        let lim = self.cfg.current_limit_a;
        let d = crate::pi::limit(p.i.d + r.d, -self.max_neg_id, lim);
        self.id_base = d;
        self.iq_last = p.i.q;
        let q_max_sq = lim * lim - d * d;
        let q = if at_most(p.i.q * p.i.q, q_max_sq) {
            p.i.q
        } else {
            let s = sqrt(q_max_sq);
            crate::pi::limit(p.i.q, -s, s)
        };
        Some(Dq { d, q })
    }

    /// Decoupling and back-EMF from the map in closed loop, `None` otherwise: the fluxes at
    /// the measured currents `i` by the expansion at the last reference's point,
    /// `psi(i) = psi_r + L_r (i - i_r)`; `u_d = -w psi_q(i)`, `u_q = w psi_d(i)`.
    #[inline]
    pub(in crate::controller) fn map_feed_forward(&self, i: Dq, frame: Frame) -> Option<Dq> {
        if !frame.emf || self.cfg.flux_map.is_none() {
            return None;
        }
        let psi = self.map_point.flux_at(i);
        Some(Dq {
            d: -frame.omega * psi.q,
            q: frame.omega * psi.d,
        })
    }
}
