//! Fusion of an external angle measurement (high-frequency injection) into the estimate:
//! [`PmsmObserver::correct_angle`].

use super::PmsmObserver;
use super::pmsm::Tracking;
use nalgebra::Vector4;

use super::structured::{self, Sym4};
use crate::ekf::EkfError;
use crate::{Float, wrap_angle};

/// Steps after a fused angle ([`PmsmObserver::correct_angle`]) in which the angle counts as
/// observable at any speed (the status's observability rule, module docs "Consistency").
pub(super) const FUSED_STEPS: u32 = 64;

impl<T: Float> PmsmObserver<T> {
    /// Fuses an external measurement of the rotor angle `theta_rad` (rad el., e.g. from
    /// high-frequency injection) of variance `variance_rad2` (rad^2) into the current
    /// estimate: one scalar Kalman correction with `H = [0 0 0 1]`, after a
    /// [`step`](Self::step) and before the next.
    ///
    /// ```text
    /// y = wrap(theta - th),  S = P33 + r,  k = P[:, 3] / S
    /// x += k y  (angle wrapped),  P -= P[:, 3] P[3, :] / S   (P33 = P33 r / S)
    /// ```
    ///
    /// With the parameter tracking active the flux takes its share too (its
    /// cross-covariance with the angle over `S`; clamped to its range like a step's); frozen,
    /// that cross-covariance is zero and nothing of the tracking changes. The innovation gate,
    /// the branch check and the lock are not involved; the covariance health check runs after
    /// it (a reset as after [`predict`](Self::predict)). The new estimate is read with
    /// [`state`](Self::state) or [`estimate`](Self::estimate) (not returned: a controller that
    /// needs only the angle and speed saves building it).
    ///
    /// Refused, nothing changed: a non-finite angle or variance, or a variance not above zero
    /// ([`EkfError::NonFiniteMeasurement`]), or a non-finite result
    /// ([`EkfError::NonFiniteResult`]).
    pub fn correct_angle(&mut self, theta_rad: T, variance_rad2: T) -> Result<(), EkfError> {
        // One test for both (`v - v` is 0 for a finite `v`, NaN otherwise), and `r > 0`.
        #[allow(clippy::eq_op)]
        let finite_in = (theta_rad - theta_rad) + (variance_rad2 - variance_rad2) == T::zero();
        if !(finite_in && variance_rad2 > T::zero()) {
            return Err(EkfError::NonFiniteMeasurement);
        }
        let p = &self.p;
        let r = variance_rad2;
        let inv_s = T::one() / (p.p33 + r);
        let y = wrap_angle(theta_rad - self.x[3]);
        // The angle's column of P, the gain, and `r / S` (the angle's row after the update:
        // `P_i3 - P_i3 P33 / S = P_i3 r / S`, a form that cannot change sign).
        let c = [p.p03, p.p13, p.p23, p.p33];
        let k = [c[0] * inv_s, c[1] * inv_s, c[2] * inv_s, c[3] * inv_s];
        let rs = r * inv_s;
        let x = Vector4::new(
            self.x[0] + k[0] * y,
            self.x[1] + k[1] * y,
            self.x[2] + k[2] * y,
            wrap_angle(self.x[3] + k[3] * y),
        );
        let pn = Sym4 {
            p00: p.p00 - k[0] * c[0],
            p01: p.p01 - k[0] * c[1],
            p02: p.p02 - k[0] * c[2],
            p03: c[0] * rs,
            p11: p.p11 - k[1] * c[1],
            p12: p.p12 - k[1] * c[2],
            p13: c[1] * rs,
            p22: p.p22 - k[2] * c[2],
            p23: c[2] * rs,
            p33: c[3] * rs,
        };
        let sum = structured::check_sum(&[
            x[0], x[1], x[2], x[3], pn.p00, pn.p01, pn.p02, pn.p03, pn.p11, pn.p12, pn.p13, pn.p22,
            pn.p23, pn.p33,
        ]);
        #[allow(clippy::eq_op)]
        if sum - sum != T::zero() {
            return Err(EkfError::NonFiniteResult);
        }
        // The flux (tracking active): its cross-covariance `X` with the angle takes its share.
        let active = self.tracking.as_ref().is_some_and(|k| k.t.s.active);
        if active && !self.correct_angle_flux(y, k, inv_s, rs) {
            return Err(EkfError::NonFiniteResult);
        }
        self.x = x;
        self.p = pn;
        self.fused = FUSED_STEPS;
        // The step's events stay reported (a reset below adds its own).
        if self.unhealthy(&self.x, &self.p) {
            self.self_reset(None);
        }
        Ok(())
    }

    /// [`correct_angle`](Self::correct_angle)'s update of the tracked flux (innovation `y`,
    /// the state's gain `k`, `1 / S`, `r / S`): `X -= k X_3`, `X_3 = X_3 r / S`,
    /// `psi += X_3 y / S` (clamped to its range), `C_pp -= X_3^2 / S` (floored like a step's).
    /// `false`, nothing changed, for a non-finite result. Out of line: tracking is frozen at
    /// the low speeds where an angle is fused.
    #[cold]
    #[inline(never)]
    pub(super) fn correct_angle_flux(&mut self, y: T, k: [T; 4], inv_s: T, rs: T) -> bool {
        let Some(Tracking { t, slow }) = &mut self.tracking else {
            return false;
        };
        let kx = &slow.k;
        let l = t.s.x[3];
        let kp = l * inv_s;
        let xn = [
            t.s.x[0] - k[0] * l,
            t.s.x[1] - k[1] * l,
            t.s.x[2] - k[2] * l,
            l * rs,
        ];
        let cpp = t.s.c_pp - kp * l;
        let floor = kx.var_floor_psi;
        let psi = t.psi + kp * y;
        let psi = if psi < kx.psi_min {
            kx.psi_min
        } else if psi > kx.psi_max {
            kx.psi_max
        } else {
            psi
        };
        let sum = structured::check_sum(&[xn[0], xn[1], xn[2], xn[3], cpp, psi]);
        #[allow(clippy::eq_op)]
        if sum - sum != T::zero() {
            return false;
        }
        t.s.x = xn;
        t.s.c_pp = if cpp > floor { cpp } else { floor };
        t.psi = psi;
        true
    }
}
