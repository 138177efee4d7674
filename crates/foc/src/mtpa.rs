//! Maximum torque per ampere (MTPA) and the torque-to-current conversion with reluctance
//! torque.
//!
//! # Torque command
//!
//! The speed loop outputs a **torque command** expressed as the surface-equivalent current
//! `i_T = T* / k_t` (ampere, `k_t = 1.5 p psi_f`): on a surface motor `i_T` is the q current
//! reference itself (no conversion, no extra arithmetic on the surface path). On a salient
//! motor the torque
//!
//! ```text
//! T = 1.5 p (psi_f i_q + (Ld - Lq) i_d i_q) = 1.5 p (psi_f - a i_d) i_q,   a = Lq - Ld
//! ```
//!
//! so for a given d current the q current that makes the commanded torque is
//!
//! ```text
//! i_q = psi_f i_T / (psi_f - a i_d)                                  (torque conversion)
//! ```
//!
//! (the denominator is the "active flux" `psi_f + (Ld - Lq) i_d`; it is floored at
//! `0.2 psi_f`, reached only by an inversely salient motor deep in field weakening).
//!
//! # MTPA curve
//!
//! The current vector of smallest magnitude for a torque (`dT/d(angle) = 0` at constant
//! magnitude `I`) has
//!
//! ```text
//! i_d = (psi_f - sqrt(psi_f^2 + 8 a^2 I^2)) / (4 a)   = -2 a I^2 / (psi_f + sqrt(psi_f^2 + 8 a^2 I^2))
//! i_d = (psi_f - sqrt(psi_f^2 + 4 a^2 i_q^2)) / (2 a) = -2 a i_q^2 / (psi_f + sqrt(psi_f^2 + 4 a^2 i_q^2))
//! ```
//!
//! (docs/design.md, "The real motor"; the second line is the same curve parameterized by `i_q`, from
//! `psi_f i_d + a (i_d^2 - i_q^2) = 0`). The right-hand forms are the rationalized ones used
//! here: exact for `a -> 0` (surface: `i_d = 0`), no cancellation, and the same formula
//! gives the positive `i_d` of an inversely salient motor (`a < 0`).
//!
//! # Solving for a torque
//!
//! Torque and the MTPA curve together are a quartic in `i_q`. The controller solves it by the
//! fixed-point iteration
//!
//! ```text
//! i_d(n) = mtpa_id(i_q(n)),   i_q(n+1) = psi_f i_T / (psi_f - a (i_d(n) + i_d,extra))
//! ```
//!
//! warm-started with the previous tick's `i_q`: one square root and two divisions a tick.
//! It contracts with a factor below `i_q^2 / (i_q^2 + (psi_f / 2a)^2)` (below 0.1 for both
//! reference IPMSMs at their current limit), and the torque command changes only at the
//! speed loop's rate (every `speed_divider` ticks), so it converges within a few ticks.
//! Every iterate lies on the MTPA curve, so the torque per ampere is optimal even before
//! convergence; only the torque itself settles.
//! [`Mtpa::currents_for_torque`] iterates to convergence from scratch (tests, tools).

use ekf_core::MotorParams;

use crate::transforms::Dq;
use crate::trig::{max2, sqrt};

/// The constants of the MTPA law and the torque conversion for one motor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mtpa {
    /// `a = Lq - Ld`, H.
    a: f32,
    /// `psi_f`, Wb.
    psi: f32,
    /// `psi_f^2`.
    psi2: f32,
    /// `4 a^2`.
    four_a2: f32,
    /// Smallest active flux in the torque conversion, Wb (`0.2 psi_f`).
    psi_min: f32,
}

impl Mtpa {
    /// The law for `motor` (`psi_f` as configured; see [`with_flux`](Self::with_flux)).
    pub fn new(motor: &MotorParams<f32>) -> Self {
        Self::with_flux(motor.lq_h - motor.ld_h, motor.psi_f_wb)
    }

    /// The law for saliency `a = Lq - Ld` (H) and flux linkage `psi_f` (Wb).
    pub fn with_flux(a: f32, psi_f: f32) -> Self {
        Self {
            a,
            psi: psi_f,
            psi2: psi_f * psi_f,
            four_a2: 4.0 * a * a,
            psi_min: 0.2 * psi_f,
        }
    }

    /// MTPA d current for the q current `i_q`, A (`0` for a surface motor).
    #[inline]
    pub fn id_for_iq(&self, i_q: f32) -> f32 {
        let q2 = i_q * i_q;
        -2.0 * self.a * q2 / (self.psi + sqrt(self.psi2 + self.four_a2 * q2))
    }

    /// MTPA d current for the current magnitude `i_s`, A.
    pub fn id_for_magnitude(&self, i_s: f32) -> f32 {
        let s2 = i_s * i_s;
        -2.0 * self.a * s2 / (self.psi + sqrt(self.psi2 + 2.0 * self.four_a2 * s2))
    }

    /// The q current that makes the torque `k_t i_t` with the d current `i_d`:
    /// `psi_f i_t / (psi_f - a i_d)` (module docs), A.
    #[inline]
    pub fn iq_for_torque(&self, i_t: f32, i_d: f32) -> f32 {
        self.psi * i_t / max2(self.psi - self.a * i_d, self.psi_min)
    }

    /// The torque of `(i_d, i_q)` as a surface-equivalent current, `(psi_f - a i_d) i_q /
    /// psi_f`, A (the inverse of [`iq_for_torque`](Self::iq_for_torque)).
    pub fn torque_current(&self, i: Dq) -> f32 {
        (self.psi - self.a * i.d) * i.q / self.psi
    }

    /// One step of the fixed-point iteration (module docs) from the q current `i_q_prev`, with
    /// `i_d_extra` added to the MTPA d current (field weakening, a hand-over's fading d
    /// current): the new `(i_d, i_q)`.
    #[inline]
    pub fn step(&self, i_t: f32, i_q_prev: f32, i_d_extra: f32) -> Dq {
        let d = self.id_for_iq(i_q_prev) + i_d_extra;
        Dq {
            d,
            q: self.iq_for_torque(i_t, d),
        }
    }

    /// The MTPA currents for the torque command `i_t` (A, surface-equivalent): the iteration
    /// of the module docs from `i_q = i_t`, 24 steps (converged to f32 precision for
    /// `|i_q| < 3 psi_f / (2 |a|)`).
    pub fn currents_for_torque(&self, i_t: f32) -> Dq {
        let mut i = Dq { d: 0.0, q: i_t };
        for _ in 0..24 {
            i = self.step(i_t, i.q, 0.0);
        }
        i
    }

    /// The largest torque command (surface-equivalent current, A) the current magnitude
    /// `i_s` can make on the MTPA curve: `i_s` for a surface motor, more for a salient one.
    pub fn torque_current_at_magnitude(&self, i_s: f32) -> f32 {
        let d = self.id_for_magnitude(i_s);
        let q = sqrt(max2(i_s * i_s - d * d, 0.0));
        self.torque_current(Dq { d, q })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_motor_has_no_d_current() {
        let m = Mtpa::new(&MotorParams::servo());
        assert_eq!(m.id_for_iq(5.0), 0.0);
        assert_eq!(m.id_for_magnitude(5.0), 0.0);
        let i = m.currents_for_torque(3.0);
        assert_eq!(i.d, 0.0);
        assert!((i.q - 3.0).abs() < 1e-6);
    }

    #[test]
    fn both_parameterizations_agree_and_make_the_torque() {
        for motor in [MotorParams::industrial_ipm(), MotorParams::traction_ipm()] {
            let m = Mtpa::new(&motor);
            let lim = 0.25 * motor.characteristic_current_a();
            let i = m.currents_for_torque(lim);
            let mag = sqrt(i.d * i.d + i.q * i.q);
            assert!(i.d < 0.0);
            assert!((m.id_for_magnitude(mag) - i.d).abs() < 1e-4 * lim, "{i:?}");
            assert!((m.torque_current(i) - lim).abs() < 1e-5 * lim);
            // Reluctance torque: less current than the surface-equivalent.
            assert!(mag < lim);
        }
    }
}
