//! The prediction of the observer on a flux map ([`MapObserver`](crate::saturated::MapObserver);
//! the formulation is in the module docs of [`saturated`](crate::saturated)), written out in
//! scalars for the structured covariance schedule; the correction and the safeguards are
//! those of the constant-parameter observer.

use nalgebra::{Matrix4, Vector4};

use super::model::TransitionTerms;
use super::structured::{self, Sym4};
use super::{Estimate, PmsmObserver};
use crate::Status;
use crate::ekf::EkfError;
use crate::fluxmap::FluxMap;
use crate::trig::sin_cos_small;
use crate::{Float, to_t, wrap_angle};

/// What a step on the map hands to the map observer's flux-offset tracking
/// ([`MapObserver`](crate::saturated::MapObserver)): the voltage the prediction used (after
/// the voltage timing and the inverter voltage) and the map's stator flux at the prediction's
/// start (the previous posterior), turned to the stationary frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MapStepInputs<T> {
    pub(crate) u: [T; 2],
    pub(crate) psi_ab0: [T; 2],
}

/// The map's flux-consistent step from the posterior `x` over a period `ts` with the stator
/// voltage `u` held, and its Jacobian (the incremental inductances held over the step) in the
/// form the structured covariance schedule takes: `(x-, terms, the map's stator flux at x in
/// the stationary frame)`. Until the filter has `locked`, the Newton step's inverse inductance
/// is `I / L_qq` (module docs of [`saturated`](crate::saturated), "Before the lock").
#[inline(always)]
pub(crate) fn map_transition<T: Float, const N: usize>(
    map: &FluxMap<T, N>,
    rs: T,
    ts: T,
    x: &Vector4<T>,
    u: [T; 2],
    locked: bool,
) -> (Vector4<T>, TransitionTerms<T>, [T; 2]) {
    let (ia, ib, w, th) = (x[0], x[1], x[2], x[3]);
    let (s0, c0) = th.sin_cos_angle();
    // Rotation over the period by its half angle: sin, and cos - 1 without cancellation.
    let (sh, ch) = sin_cos_small(w * ts * to_t(0.5));
    let two = T::one() + T::one();
    let sw = two * sh * ch;
    let cwm1 = -two * sh * sh;
    let cw = T::one() + cwm1;
    let (s1, c1) = (s0 * cw + c0 * sw, c0 * cw - s0 * sw);
    // Rotor-frame currents at the start, the map there.
    let id = c0 * ia + s0 * ib;
    let iq = c0 * ib - s0 * ia;
    let p = map.eval(id, iq);
    let (g00, g01, g10, g11) = if locked {
        let inv_det = T::one() / (p.l_dd * p.l_qq - p.l_dq * p.l_qd);
        (
            p.l_qq * inv_det,
            -p.l_dq * inv_det,
            -p.l_qd * inv_det,
            p.l_dd * inv_det,
        )
    } else {
        // Not locked: the response through the q axis's inductance on both axes (module docs
        // of `saturated`, "Before the lock").
        let g = T::one() / p.l_qq;
        (g, T::zero(), T::zero(), g)
    };
    // Voltage less the resistive drop, in the end-of-period rotor frame.
    let (va, vb) = (u[0] - rs * ia, u[1] - rs * ib);
    let vd1 = c1 * va + s1 * vb;
    let vq1 = c1 * vb - s1 * va;
    // The start flux turned back by the period's rotation, R(-w Ts) psi.
    let pwd = cw * p.psi_d + sw * p.psi_q;
    let pwq = cw * p.psi_q - sw * p.psi_d;
    // Flux change seen in the end frame: (R(-w Ts) - I) psi + Ts R1^T v.
    let ed = (cwm1 * p.psi_d + sw * p.psi_q) + ts * vd1;
    let eq = (cwm1 * p.psi_q - sw * p.psi_d) + ts * vq1;
    let id1 = id + (g00 * ed + g01 * eq);
    let iq1 = iq + (g10 * ed + g11 * eq);
    let ia1 = c1 * id1 - s1 * iq1;
    let ib1 = s1 * id1 + c1 * iq1;
    // d i1 / d i = R(w Ts) + R1 G N, N = (R(-w Ts) - I) L R0^T - Ts Rs R1^T.
    // K L with K = [[cw - 1, sw], [-sw, cw - 1]].
    let m00 = cwm1 * p.l_dd + sw * p.l_qd;
    let m01 = cwm1 * p.l_dq + sw * p.l_qq;
    let m10 = cwm1 * p.l_qd - sw * p.l_dd;
    let m11 = cwm1 * p.l_qq - sw * p.l_dq;
    let tr = ts * rs;
    // (K L) R0^T - Ts Rs R1^T, R0^T = [[c0, s0], [-s0, c0]].
    let n00 = m00 * c0 - m01 * s0 - tr * c1;
    let n01 = m00 * s0 + m01 * c0 - tr * s1;
    let n10 = m10 * c0 - m11 * s0 + tr * s1;
    let n11 = m10 * s0 + m11 * c0 - tr * c1;
    // G N.
    let q00 = g00 * n00 + g01 * n10;
    let q01 = g00 * n01 + g01 * n11;
    let q10 = g10 * n00 + g11 * n10;
    let q11 = g10 * n01 + g11 * n11;
    // d / d th = J i1 + R1 [ -J i0 + G (K L (-J i0) - Ts J R1^T v) ], -J i0 = (iq, -id).
    let kd = m00 * iq - m01 * id + ts * vq1;
    let kq = m10 * iq - m11 * id - ts * vd1;
    let hd = iq + (g00 * kd + g01 * kq);
    let hq = -id + (g10 * kd + g11 * kq);
    // d / d w = Ts J i1 + R1 Ts G ((pwq, -pwd) + Ts (vq1, -vd1)).
    let (fd, fq) = (ts * (pwq + ts * vq1), -ts * (pwd + ts * vd1));
    let wd = g00 * fd + g01 * fq;
    let wq = g10 * fd + g11 * fq;
    let t = TransitionTerms {
        ea: T::zero(),
        eb: T::zero(),
        ea_w: -ts * ib1 + (c1 * wd - s1 * wq),
        eb_w: ts * ia1 + (s1 * wd + c1 * wq),
        ea_th: -ib1 + (c1 * hd - s1 * hq),
        eb_th: ia1 + (s1 * hd + c1 * hq),
        ea_psi: T::zero(),
        eb_psi: T::zero(),
        da: T::zero(),
        db: T::zero(),
        a00: cw + (c1 * q00 - s1 * q10),
        a01: -sw + (c1 * q01 - s1 * q11),
        a10: sw + (s1 * q00 + c1 * q10),
        a11: cw + (s1 * q01 + c1 * q11),
        sin_th: s0,
        cos_th: c0,
    };
    let psi_ab0 = [c0 * p.psi_d - s0 * p.psi_q, s0 * p.psi_d + c0 * p.psi_q];
    (
        Vector4::new(ia1, ib1, w, wrap_angle(th + ts * w)),
        t,
        psi_ab0,
    )
}

impl<T: Float> PmsmObserver<T> {
    /// The prediction on the map over a period `dt_s` (`Ts` for the regular step), with the
    /// voltage timing, the inverter voltage and the speed noise adaptation applied as in the
    /// constant-parameter prior; `Q` scaled by `dt_s / Ts`.
    #[inline(always)]
    fn map_prior<const N: usize>(
        &self,
        map: &FluxMap<T, N>,
        u_prev: [T; 2],
        dt_s: T,
    ) -> (Vector4<T>, Sym4<T>, MapStepInputs<T>) {
        let ts = self.model.ts();
        let q_owned: Matrix4<T>;
        let mut q = self.model.q_sym();
        let mut u = u_prev;
        if self.extras {
            if self.timing {
                u = self.applied(u);
            }
            if let Some(a) = &self.adaptation
                && a.factor > T::one()
            {
                q_owned = self.adapted_q(a.factor);
                q = &q_owned;
            }
        }
        let scaled: Matrix4<T>;
        if dt_s != ts {
            scaled = q * (dt_s / ts);
            q = &scaled;
        }
        let (xm, t, psi_ab0) = map_transition(map, self.nominal.1, dt_s, &self.x, u, self.locked);
        let inputs = MapStepInputs { u, psi_ab0 };
        (
            xm,
            structured::predict_cov_salient(&t, dt_s, q, &self.p),
            inputs,
        )
    }

    /// The map observer's lock (module docs of [`saturated`](crate::saturated), "Before the
    /// lock"): besides the constant-parameter rule (angle tracked with the innovations
    /// settled, [`update_lock`](Self::update_lock) in the correction), a step whose status
    /// reads `Tracking` locks the filter; it stays locked while the angle stays tracked.
    #[inline(always)]
    fn map_lock(&mut self, r: &Result<Estimate<T>, EkfError>) {
        if let Ok(e) = r
            && e.status == Status::Tracking
        {
            self.locked = true;
        }
    }

    /// Marks the observer as the map observer's (its prediction runs on the map): the model
    /// fit's active-flux test, which reads the constant-parameter model's flux, is off.
    pub(crate) fn on_map(mut self) -> Self {
        if let Some(w) = &mut self.consistency {
            w.active_flux = false;
        }
        self
    }

    /// One step on the map over a period `dt_s` (the body of
    /// [`MapObserver::step`](crate::saturated::MapObserver::step)); inputs checked as in
    /// [`step`](Self::step).
    pub(crate) fn map_step<const N: usize>(
        &mut self,
        map: &FluxMap<T, N>,
        u_prev: [T; 2],
        i: [T; 2],
        dt_s: T,
    ) -> Result<Estimate<T>, EkfError> {
        self.check_sample(u_prev, i)?;
        let (xm, pm, _) = self.map_prior(map, u_prev, dt_s);
        let r = self.correct_prior::<false, true>(xm, pm, None, i);
        self.map_lock(&r);
        r
    }

    /// [`map_step`](Self::map_step), also handing out what the flux-offset tracking takes
    /// ([`MapStepInputs`]). A separate body: the plain step built on this one cost the
    /// Cortex-M4F map step 40 instructions (1378 against 1338).
    pub(crate) fn map_step_inputs<const N: usize>(
        &mut self,
        map: &FluxMap<T, N>,
        u_prev: [T; 2],
        i: [T; 2],
        dt_s: T,
    ) -> Result<(Estimate<T>, MapStepInputs<T>), EkfError> {
        self.check_sample(u_prev, i)?;
        let (xm, pm, inputs) = self.map_prior(map, u_prev, dt_s);
        let r = self.correct_prior::<false, true>(xm, pm, None, i);
        self.map_lock(&r);
        r.map(|e| (e, inputs))
    }

    /// Prediction only on the map (the body of
    /// [`MapObserver::predict`](crate::saturated::MapObserver::predict)).
    pub(crate) fn map_predict<const N: usize>(
        &mut self,
        map: &FluxMap<T, N>,
        u_prev: [T; 2],
    ) -> Result<(), EkfError> {
        if !super::step::within(u_prev[0] * u_prev[0] + u_prev[1] * u_prev[1], self.u_max2) {
            self.check_input(u_prev)?;
        }
        let (x, p, _) = self.map_prior(map, u_prev, self.model.ts());
        self.commit_prediction(x, p, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ekf::ProcessModel;
    use crate::saturated::MapModel;
    use crate::saturation::PM_SYRM_5K6;
    use nalgebra::Vector2;

    /// The PM-SyRM's map on a 12 x 16 grid, its `Rs` (ohm) and `Ts` (s).
    fn pm_syrm() -> (FluxMap<f64, 16>, f64, f64) {
        let i_d: [f64; 12] = core::array::from_fn(|k| -20.0 + 30.0 * k as f64 / 11.0);
        let i_q: [f64; 16] = core::array::from_fn(|k| -30.0 + 60.0 * k as f64 / 15.0);
        let map = PM_SYRM_5K6.flux_map::<f64, 16>(&i_d, &i_q).unwrap();
        (map, 0.63, 1e-4)
    }

    /// The currents' rows of the transition Jacobian, columns `(i_a, i_b, w, th)`.
    fn current_rows(t: &TransitionTerms<f64>) -> [[f64; 4]; 2] {
        [
            [t.a00, t.a01, t.ea_w, t.ea_th],
            [t.a10, t.a11, t.eb_w, t.eb_th],
        ]
    }

    /// The scalar step and its Jacobian are the generic model's ([`MapModel`], matrix form)
    /// to rounding, over operating points across the map, both speed signs and both
    /// directions of the voltage.
    #[test]
    fn scalar_step_is_the_matrix_models() {
        let (map, rs, ts) = pm_syrm();
        let model = MapModel::new(map.clone(), rs, 2, ts).unwrap();
        let mut worst = 0.0f64;
        for k in 0..200 {
            let f = k as f64;
            let x = Vector4::new(
                12.0 * (0.37 * f).sin(),
                12.0 * (0.91 * f + 1.0).cos(),
                700.0 * (0.13 * f).sin(),
                3.0 * (0.71 * f).sin(),
            );
            let u = [300.0 * (0.5 * f).cos(), 250.0 * (0.29 * f).sin()];
            let (xs, t, psi0) = map_transition(&map, rs, ts, &x, u, true);
            // The start flux handed out is the map's at the start currents and angle.
            let (s0, c0) = x[3].sin_cos();
            let f = map.eval(c0 * x[0] + s0 * x[1], c0 * x[1] - s0 * x[0]);
            assert!((psi0[0] - (c0 * f.psi_d - s0 * f.psi_q)).abs() < 1e-12);
            assert!((psi0[1] - (s0 * f.psi_d + c0 * f.psi_q)).abs() < 1e-12);
            let (xm, phi) = model.transition(&x, &Vector2::new(u[0], u[1]));
            let scalar = current_rows(&t);
            for r in 0..2 {
                worst = worst.max((xs[r] - xm[r]).abs() / (1.0 + xm[r].abs()));
                for c in 0..4 {
                    let scale = 1.0 + phi[(r, c)].abs();
                    worst = worst.max((scalar[r][c] - phi[(r, c)]).abs() / scale);
                }
            }
            assert_eq!(xs[2], xm[2]);
            assert!((wrap_angle(xs[3] - xm[3])).abs() < 1e-12);
        }
        assert!(worst < 1e-9, "largest relative difference {worst:e}");
    }

    /// Before the lock (the isotropic response): the Jacobian is the derivative of the
    /// prediction (central differences) but for the map's second derivatives, which it leaves
    /// out as the locked step does; and the voltage's effect on the currents does not depend on
    /// the angle.
    #[test]
    fn unlocked_step_jacobian_is_its_derivative() {
        let (map, rs, ts) = pm_syrm();
        let mut worst = 0.0f64;
        for k in 0..50 {
            let f = k as f64;
            // Near zero current (where the unlocked step runs: acquisition), so that the
            // incremental inductances held over the step are the ones differentiated.
            let x = Vector4::new(
                0.05 * (0.37 * f).sin(),
                0.05 * (0.91 * f + 1.0).cos(),
                300.0 * (0.13 * f).sin(),
                3.0 * (0.71 * f).sin(),
            );
            let u = [150.0 * (0.5 * f).cos(), 120.0 * (0.29 * f).sin()];
            let (_, t, _) = map_transition(&map, rs, ts, &x, u, false);
            let jac = current_rows(&t);
            let steps = [1e-6, 1e-6, 1e-4, 1e-7];
            for c in 0..4 {
                let (mut xp, mut xm) = (x, x);
                xp[c] += steps[c];
                xm[c] -= steps[c];
                let (fp, _, _) = map_transition(&map, rs, ts, &xp, u, false);
                let (fm, _, _) = map_transition(&map, rs, ts, &xm, u, false);
                for r in 0..2 {
                    let num = (fp[r] - fm[r]) / (2.0 * steps[c]);
                    worst = worst.max((num - jac[r][c]).abs() / (1.0 + num.abs()));
                }
            }
            // At zero current, the same speed at another angle: the voltage's share of the
            // current change is the same in the stationary frame (`Ts u / L_qq`).
            let x = Vector4::new(0.0, 0.0, x[2], x[3]);
            let turned = Vector4::new(0.0, 0.0, x[2], x[3] + 1.3);
            let du = |x: &Vector4<f64>| {
                let (a, _, _) = map_transition(&map, rs, ts, x, u, false);
                let (b, _, _) = map_transition(&map, rs, ts, x, [0.0, 0.0], false);
                [a[0] - b[0], a[1] - b[1]]
            };
            let (a, b) = (du(&x), du(&turned));
            assert!((a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
        }
        // What is left is the map's second derivatives, which the Jacobian leaves out locked
        // or not (here `1 / L_qq` held over the step: 1.8e-3; the locked step's `L^-1` held,
        // at these states, 9.8e-3).
        assert!(worst < 5e-3, "largest relative difference {worst:e}");
    }
}
