//! The PMSM process and measurement model and its discretization (module docs of
//! [`observer`](crate::observer) give the equations).

use nalgebra::{Matrix2, Matrix4, SMatrix, Vector2, Vector4};

use super::ObserverConfig;
use crate::ekf::{CovarianceUpdate, MeasurementModel, ProcessModel};
use crate::trig::sin_cos_small;
use crate::{Float, to_t, wrap_angle};

/// How the continuous model is turned into one step of the filter (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Discretization {
    /// The seed's forward-Euler step; EMF at the start-of-period angle (lags by ~`w Ts / 2`).
    ForwardEuler,
    /// Exact for a held voltage and a constant-speed rotation; no half-sample lag.
    #[default]
    LagFree,
}

/// The constants of one discrete step: `Ts`, `a = Rs / Lq`, `c = psi_f / Lq`, the current
/// decay and the input gain. Fixed for the configured parameters ([`PmsmModel::discrete`]),
/// or recomputed each step from the tracked `psi_f` and `Rs` ([`PmsmModel::discrete_at`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Discrete<T> {
    pub discretization: Discretization,
    pub ts: T,
    /// `a = Rs / Ls`, 1/s.
    pub a: T,
    /// `c = psi_f / Ls`, A/rad.
    pub c: T,
    /// `1 / Lq`, 1/H (`1 / Ls` of a surface motor).
    pub inv_ls: T,
    /// Saliency of the active-flux model, `(Ld - Lq) / Lq` (0 for a surface motor).
    pub saliency: T,
    /// `Ld != Lq`: the EMF scale `c` gains `saliency * i_d` each step.
    pub salient: bool,
    /// `Lq / Ld - 1`: the d-axis transient correction's gain (0 for a surface motor).
    pub kd: T,
    /// Current decay per sample: `alpha = exp(-a Ts)` (lag-free) or `1 - a Ts` (Euler).
    pub decay: T,
    /// `1 - decay`, computed without cancellation.
    pub one_minus_decay: T,
    /// Input gain per sample: `(1 - alpha) / Rs` (lag-free) or `Ts / Ls` (Euler), A/V.
    pub input_gain: T,
}

/// The PMSM process and measurement model with its per-`Ts` constants; implements
/// [`ProcessModel`] (input `[u_a, u_b]`) and [`MeasurementModel`] (`z = [i_a, i_b]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PmsmModel<T: Float> {
    /// The step's constants for the configured `Rs`, `Ls`, `psi_f`.
    disc: Discrete<T>,
    /// Configured `Rs`, ohm.
    rs: T,
    /// `Q` made symmetric, `(Q + Q^T) / 2`.
    q: Matrix4<T>,
    /// `R` made symmetric, `(R + R^T) / 2`.
    r: Matrix2<T>,
    update: CovarianceUpdate,
}

/// Back-EMF term of one step and its derivatives (lag-free or forward Euler).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TransitionTerms<T> {
    /// EMF contribution to `i_a-`, `i_b-`.
    pub ea: T,
    pub eb: T,
    /// `d i_a- / d w`, `d i_a- / d th`.
    pub ea_w: T,
    pub ea_th: T,
    /// `d i_b- / d w`, `d i_b- / d th`.
    pub eb_w: T,
    pub eb_th: T,
    /// `d i_a- / d psi_f`, `d i_b- / d psi_f` (the EMF term per weber).
    pub ea_psi: T,
    pub eb_psi: T,
    /// The d-axis transient correction of a salient motor (module docs; 0 for a surface
    /// motor), added to `i_a-`, `i_b-`.
    pub da: T,
    pub db: T,
    /// The current block of `Phi` of a salient motor, `d i- / d i` (row-major; the surface
    /// block is `decay I`): the active flux's and the correction's dependence on the currents.
    pub a00: T,
    pub a01: T,
    pub a10: T,
    pub a11: T,
    /// `sin th`, `cos th` of the start-of-period angle.
    pub sin_th: T,
    pub cos_th: T,
}

impl<T: Float> PmsmModel<T> {
    /// The model for a validated configuration.
    pub fn new(cfg: &ObserverConfig<T>) -> Self {
        let m = &cfg.motor;
        let ts = cfg.ts_s;
        let a = m.rs_ohm / m.lq_h;
        let (decay, input_gain) = match cfg.discretization {
            Discretization::ForwardEuler => (T::one() - a * ts, ts / m.lq_h),
            Discretization::LagFree => {
                // 1 - exp(-a Ts) without cancellation.
                let one_minus_alpha = -(-a * ts).exp_m1();
                (T::one() - one_minus_alpha, one_minus_alpha / m.rs_ohm)
            }
        };
        Self {
            disc: Discrete {
                discretization: cfg.discretization,
                ts,
                a,
                c: m.psi_f_wb / m.lq_h,
                inv_ls: T::one() / m.lq_h,
                saliency: (m.ld_h - m.lq_h) / m.lq_h,
                salient: m.is_salient(),
                kd: m.lq_h / m.ld_h - T::one(),
                decay,
                one_minus_decay: T::one() - decay,
                input_gain,
            },
            rs: m.rs_ohm,
            q: (cfg.noise.q + cfg.noise.q.transpose()) * to_t::<T>(0.5),
            r: (cfg.noise.r + cfg.noise.r.transpose()) * to_t::<T>(0.5),
            update: cfg.covariance_update,
        }
    }

    /// The same model for one period of `dt_s` seconds instead of `Ts` (an irregular period:
    /// a skipped or late control cycle). The step's constants are those of the configured
    /// parameters recomputed for `dt_s` (`alpha = exp(-a dt)`, the input gain, the EMF gain
    /// `G(w)` over `dt`), and `Q` is scaled by `dt / Ts` (the process noises are random walks
    /// whose variance grows with time). `dt_s == Ts` gives a copy of this model.
    pub fn with_period(&self, dt_s: T) -> Self {
        let d = &self.disc;
        let (decay, input_gain) = match d.discretization {
            Discretization::ForwardEuler => (T::one() - d.a * dt_s, dt_s * d.inv_ls),
            Discretization::LagFree => {
                let one_minus_alpha = -(-d.a * dt_s).exp_m1();
                (T::one() - one_minus_alpha, one_minus_alpha / self.rs)
            }
        };
        let scale = dt_s / d.ts;
        Self {
            disc: Discrete {
                ts: dt_s,
                decay,
                one_minus_decay: T::one() - decay,
                input_gain,
                ..*d
            },
            q: self.q * scale,
            ..*self
        }
    }

    /// The same model with the inductances `(ld_h, lq_h)` instead of the configured ones
    /// (the flux `psi_f_wb` and the configured `Rs`, `Ts`, `Q`, `R` kept): every constant
    /// that depends on `L` (`a = Rs / Lq`, `c = psi_f / Lq`, `1 / Lq`, the saliency, the
    /// d-axis correction's gain, the decay and the input gain) recomputed as
    /// [`PmsmModel::new`] does. The caller validates the values
    /// ([`PmsmObserver::set_inductances`](super::PmsmObserver::set_inductances)).
    pub(crate) fn with_inductances(&self, psi_f_wb: T, ld_h: T, lq_h: T) -> Self {
        let d = &self.disc;
        let ts = d.ts;
        let a = self.rs / lq_h;
        let (decay, input_gain) = match d.discretization {
            Discretization::ForwardEuler => (T::one() - a * ts, ts / lq_h),
            Discretization::LagFree => {
                let one_minus_alpha = -(-a * ts).exp_m1();
                (T::one() - one_minus_alpha, one_minus_alpha / self.rs)
            }
        };
        Self {
            disc: Discrete {
                a,
                c: psi_f_wb / lq_h,
                inv_ls: T::one() / lq_h,
                saliency: (ld_h - lq_h) / lq_h,
                salient: ld_h != lq_h,
                kd: lq_h / ld_h - T::one(),
                decay,
                one_minus_decay: T::one() - decay,
                input_gain,
                ..*d
            },
            ..*self
        }
    }

    /// Configured `Rs`, ohm (the model's; a tracked one is the observer's).
    pub(crate) fn rs(&self) -> T {
        self.rs
    }

    /// Sample time `Ts`, s.
    pub fn ts(&self) -> T {
        self.disc.ts
    }

    /// Current decay per sample (`alpha` or `1 - a Ts`).
    pub fn decay(&self) -> T {
        self.disc.decay
    }

    /// Voltage-to-current gain per sample, A/V.
    pub fn input_gain(&self) -> T {
        self.disc.input_gain
    }

    /// Covariance update method the observer uses with this model.
    pub fn covariance_update(&self) -> CovarianceUpdate {
        self.update
    }

    /// `Q` as configured, made symmetric at construction, `(Q + Q^T) / 2`.
    pub(crate) fn q_sym(&self) -> &Matrix4<T> {
        &self.q
    }

    /// `R` as configured, made symmetric at construction, `(R + R^T) / 2`.
    pub(crate) fn r_sym(&self) -> &Matrix2<T> {
        &self.r
    }

    /// The discretization in use.
    pub fn discretization(&self) -> Discretization {
        self.disc.discretization
    }

    /// The step's constants for the configured parameters.
    #[inline(always)]
    pub(crate) fn discrete(&self) -> &Discrete<T> {
        &self.disc
    }

    /// The step's constants for a flux linkage `psi_f` and a resistance `rs` (tracked values;
    /// `Ls` as configured). Lag-free: `alpha = alpha0 exp(-x)` with
    /// `x = (rs - Rs0) Ts / Ls`, the exponential by its Taylor series to `x^4` (relative
    /// error below `x^5 / 120`, 1e-6 for `|x| <= 0.16`, i.e. `rs` within `Rs0 +- 2 Rs0` on
    /// the reference motors); no `exp` on the MCU.
    #[inline(always)]
    pub(crate) fn discrete_at(&self, psi_f: T, rs: T) -> Discrete<T> {
        let d0 = &self.disc;
        let a = rs * d0.inv_ls;
        let c = psi_f * d0.inv_ls;
        match d0.discretization {
            Discretization::ForwardEuler => {
                let one_minus_decay = a * d0.ts;
                Discrete {
                    a,
                    c,
                    decay: T::one() - one_minus_decay,
                    one_minus_decay,
                    ..*d0
                }
            }
            Discretization::LagFree => {
                let x = (rs - self.rs) * d0.ts * d0.inv_ls;
                // 1 - exp(-x) = x - x^2/2 + x^3/6 - x^4/24 (Horner).
                let one_minus_ex = x
                    * (T::one()
                        - x * (to_t::<T>(0.5)
                            - x * (to_t::<T>(1.0 / 6.0) - x * to_t::<T>(1.0 / 24.0))));
                // 1 - alpha0 e^{-x} = (1 - alpha0) + alpha0 (1 - e^{-x}).
                let one_minus_decay = d0.one_minus_decay + d0.decay * one_minus_ex;
                Discrete {
                    a,
                    c,
                    decay: T::one() - one_minus_decay,
                    one_minus_decay,
                    input_gain: one_minus_decay / rs,
                    ..*d0
                }
            }
        }
    }

    /// [`discrete_at`](Self::discrete_at) from the constants `at_rs` it returned for the same
    /// `rs`: only the flux's `c` is recomputed (bit for bit the same result).
    #[inline(always)]
    pub(crate) fn discrete_with_flux(&self, at_rs: &Discrete<T>, psi_f: T) -> Discrete<T> {
        Discrete {
            c: psi_f * self.disc.inv_ls,
            ..*at_rs
        }
    }

    /// The back-EMF term of the step from `(i_a, i_b, th, w)` and the input `u`, and its
    /// derivatives (module docs).
    #[inline(always)]
    pub(crate) fn transition_terms(
        &self,
        ia: T,
        ib: T,
        th: T,
        w: T,
        u: [T; 2],
    ) -> TransitionTerms<T> {
        if self.disc.salient {
            self.disc.transition_terms::<true>(ia, ib, th, w, u, true)
        } else {
            self.disc.transition_terms::<false>(ia, ib, th, w, u, true)
        }
    }
}

impl<T: Float> Discrete<T> {
    /// The back-EMF term of the step from the posterior `(i_a, i_b, th, w)` and the input
    /// `u`, and its derivatives (module docs; the currents and the input matter only for a
    /// salient motor, `S`, whose d-axis transient correction applies when `transient`).
    #[inline(always)]
    pub(crate) fn transition_terms<const S: bool>(
        &self,
        ia: T,
        ib: T,
        th: T,
        w: T,
        u: [T; 2],
        transient: bool,
    ) -> TransitionTerms<T> {
        let (s, co) = th.sin_cos_angle();
        let (_, (m_re, m_im), (mp_re, mp_im)) = self.emf_gain(w);
        // EMF term c w (-j e^{j th}) G, and its derivatives.
        let ua = s * m_re + co * m_im;
        let ub = s * m_im - co * m_re;
        let (c, c_th) = if S {
            // Active flux psi_f + (Ld - Lq) i_d over Lq; d i_d / d th = i_q.
            let k = self.saliency;
            (self.c + k * (ia * co + ib * s), k * (ib * co - ia * s))
        } else {
            (self.c, T::zero())
        };
        let mut t = TransitionTerms {
            ea: c * ua,
            eb: c * ub,
            ea_th: c * (co * m_re - s * m_im) + c_th * ua,
            eb_th: c * (co * m_im + s * m_re) + c_th * ub,
            da: T::zero(),
            db: T::zero(),
            ea_w: c * (s * mp_re + co * mp_im),
            eb_w: c * (s * mp_im - co * mp_re),
            ea_psi: self.inv_ls * ua,
            eb_psi: self.inv_ls * ub,
            a00: self.decay,
            a01: T::zero(),
            a10: T::zero(),
            a11: self.decay,
            sin_th: s,
            cos_th: co,
        };
        if S {
            // d c / d i = saliency (cos th, sin th).
            let (kc, ks) = (self.saliency * co, self.saliency * s);
            t.a00 += ua * kc;
            t.a01 = ua * ks;
            t.a10 = ub * kc;
            t.a11 += ub * ks;
            if transient {
                self.d_transient(&mut t, ia, ib, w, u);
            }
        }
        t
    }

    /// The d-axis transient correction of a salient motor (module docs): the active-flux
    /// model lets `i_d` respond through `Lq`, the motor through `Ld`. To first order the
    /// motor's change of `i_d` over the period is `Lq / Ld` times the model's, so the step adds
    /// `(Lq / Ld - 1) (i_d- - i_d)` along the end-of-period d axis, with `i_d-` the model's
    /// prediction. In steady state the model is exact and its `i_d- = i_d`: no bias. Its
    /// derivatives in `th`, `w` and `psi_f` join the EMF's (the columns of `Phi` keep their
    /// structure); those in the currents are left out.
    #[inline(always)]
    fn d_transient(&self, t: &mut TransitionTerms<T>, ia: T, ib: T, w: T, u: [T; 2]) {
        let (s, co) = (t.sin_th, t.cos_th);
        let ts = self.ts;
        // Rotation by w Ts: the end-of-period d axis e1 = (c1, s1).
        let (sw, cw) = match self.discretization {
            Discretization::ForwardEuler => sin_cos_small(w * ts),
            Discretization::LagFree => {
                let (sh, ch) = sin_cos_small(w * ts * to_t(0.5));
                let two = T::one() + T::one();
                (two * sh * ch, T::one() - two * sh * sh)
            }
        };
        let (s1, c1) = (s * cw + co * sw, co * cw - s * sw);
        // The model's prediction m and the change of i_d it predicts.
        let ma = self.decay * ia + self.input_gain * u[0] + t.ea;
        let mb = self.decay * ib + self.input_gain * u[1] + t.eb;
        let did = (ma * c1 + mb * s1) - (ia * co + ib * s);
        // d e / d th = j e, d e1 / d w = Ts j e1.
        let mq1 = mb * c1 - ma * s1;
        let did_th = t.ea_th * c1 + t.eb_th * s1 + mq1 - (ib * co - ia * s);
        let did_w = t.ea_w * c1 + t.eb_w * s1 + ts * mq1;
        let did_psi = t.ea_psi * c1 + t.eb_psi * s1;
        // d did / d i: the block so far projected on e1, less e0.
        let did_ia = t.a00 * c1 + t.a10 * s1 - co;
        let did_ib = t.a01 * c1 + t.a11 * s1 - s;
        let k = self.kd;
        let (kc, ks) = (k * c1, k * s1);
        let kdid = k * did;
        t.da = kdid * c1;
        t.db = kdid * s1;
        t.ea_th += did_th * kc - kdid * s1;
        t.eb_th += did_th * ks + kdid * c1;
        t.ea_w += did_w * kc - kdid * ts * s1;
        t.eb_w += did_w * ks + kdid * ts * c1;
        t.ea_psi += did_psi * kc;
        t.eb_psi += did_psi * ks;
        t.a00 += did_ia * kc;
        t.a01 += did_ib * kc;
        t.a10 += did_ia * ks;
        t.a11 += did_ib * ks;
    }

    /// `(G, w G, d(w G)/dw)` of the lag-free step as `(re, im)` pairs (module docs).
    #[inline(always)]
    fn emf_gain(&self, w: T) -> ((T, T), (T, T), (T, T)) {
        let ts = self.ts;
        match self.discretization {
            Discretization::ForwardEuler => ((ts, T::zero()), (w * ts, T::zero()), (ts, T::zero())),
            Discretization::LagFree => lag_free_gain(self.a, self.one_minus_decay, w, ts),
        }
    }
}

/// The lag-free EMF gain over a period `ts` (module docs of [`observer`](crate::observer)):
/// `(G, w G, d(w G)/dw)` as `(re, im)` pairs, `G(w) = (e^{j w ts} - alpha) / (a + j w)` with
/// `a = Rs / Ls` and `1 - alpha = one_minus_alpha`.
#[inline(always)]
pub(crate) fn lag_free_gain<T: Float>(
    a: T,
    one_minus_alpha: T,
    w: T,
    ts: T,
) -> ((T, T), (T, T), (T, T)) {
    let (sh, ch) = sin_cos_small(w * ts * to_t(0.5));
    let two = T::one() + T::one();
    // e^{j w Ts} = cos + j sin, with cos - 1 = -2 sin^2(w Ts / 2).
    let cos_m1 = -two * sh * sh;
    let (ex_re, ex_im) = (T::one() + cos_m1, two * sh * ch);
    // N = e^{j w Ts} - alpha.
    let (n_re, n_im) = (cos_m1 + one_minus_alpha, ex_im);
    let inv_d2 = T::one() / (a * a + w * w);
    // G = N / (a + j w) = N (a - j w) / (a^2 + w^2).
    let g_re = (n_re * a + n_im * w) * inv_d2;
    let g_im = (n_im * a - n_re * w) * inv_d2;
    // G' = j (Ts e^{j w Ts} - G) / (a + j w).
    let (t_re, t_im) = (ts * ex_re - g_re, ts * ex_im - g_im);
    // j (t) = -t_im + j t_re; divide by (a + j w).
    let (jt_re, jt_im) = (-t_im, t_re);
    let gp_re = (jt_re * a + jt_im * w) * inv_d2;
    let gp_im = (jt_im * a - jt_re * w) * inv_d2;
    (
        (g_re, g_im),
        (w * g_re, w * g_im),
        (g_re + w * gp_re, g_im + w * gp_im),
    )
}

impl<T: Float> ProcessModel<T, 4, 2> for PmsmModel<T> {
    fn transition(&self, x: &Vector4<T>, u: &Vector2<T>) -> (Vector4<T>, Matrix4<T>) {
        let (ia, ib, w, th) = (x[0], x[1], x[2], x[3]);
        let TransitionTerms {
            ea,
            eb,
            ea_w,
            ea_th,
            eb_w,
            eb_th,
            da,
            db,
            a00,
            a01,
            a10,
            a11,
            ..
        } = self.transition_terms(ia, ib, th, w, [u[0], u[1]]);
        let d = &self.disc;
        let xn = Vector4::new(
            d.decay * ia + d.input_gain * u[0] + ea + da,
            d.decay * ib + d.input_gain * u[1] + eb + db,
            w,
            th + d.ts * w,
        );
        let z = T::zero();
        let o = T::one();
        #[rustfmt::skip]
        let phi = Matrix4::new(
            a00,     a01,     ea_w, ea_th,
            a10,     a11,     eb_w, eb_th,
            z,       z,       o,    z,
            z,       z,       d.ts, o,
        );
        (xn, phi)
    }

    fn process_noise(&self) -> &Matrix4<T> {
        &self.q
    }

    fn normalize(&self, x: &mut Vector4<T>) {
        x[3] = wrap_angle(x[3]);
    }
}

impl<T: Float> MeasurementModel<T, 4, 2> for PmsmModel<T> {
    fn observe(&self, x: &Vector4<T>) -> (Vector2<T>, SMatrix<T, 2, 4>) {
        let z = T::zero();
        let o = T::one();
        #[rustfmt::skip]
        let h = SMatrix::<T, 2, 4>::new(
            o, z, z, z,
            z, o, z, z,
        );
        (Vector2::new(x[0], x[1]), h)
    }

    fn measurement_noise(&self) -> &Matrix2<T> {
        &self.r
    }

    fn normalize(&self, x: &mut Vector4<T>) {
        x[3] = wrap_angle(x[3]);
    }
}
