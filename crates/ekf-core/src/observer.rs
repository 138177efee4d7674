//! The seed's PMSM observer: an EKF on the alpha-beta model of a surface-mounted PMSM.
//!
//! State `x = [i_a, i_b, w_e, theta]` (A, A, rad/s electrical, rad electrical), input
//! `u = [u_a, u_b]` (V), measurement `z = [i_a, i_b]` (A), `H = [I2 0]`.
//! Continuous model (`design.md` section 2, with the sign of `u` of the seed's matrix form):
//!
//! ```text
//! di_a/dt = (-Rs i_a + w psi sin(th) + u_a) / Ls
//! di_b/dt = (-Rs i_b - w psi cos(th) + u_b) / Ls
//! dw/dt   = 0        (random walk through Q)
//! dth/dt  = w
//! ```
//!
//! # Timing (design section 4)
//!
//! `step(u_prev, i)` at sample `k` predicts over `[t_{k-1}, t_k)` with `u_prev = u[k-1]`, the
//! voltage the inverter held over that period, then corrects with `i = i[k]`, the currents
//! sampled at `t_k`. A new observer's `x0`, `P0` describe the estimate one period before its first
//! sample, and its first call passes `u_prev = 0`. The angle is wrapped to `[-pi, pi)` after the
//! prediction and after the correction.
//!
//! # Discretizations ([`Discretization`])
//!
//! With `a = Rs / Ls`, `c = psi_f / Ls`, `x = [i_a, i_b, w, th]` the posterior at `t_{k-1}`:
//!
//! **`ForwardEuler`** (the seed's loop, exactly): `x- = x + Ts (f(x) + B u)`,
//! `Phi = I + Ts F(x)`:
//!
//! ```text
//! i_a- = i_a + Ts (-a i_a + c w sin th + u_a / Ls)
//! i_b- = i_b + Ts (-a i_b - c w cos th + u_b / Ls)
//! w-   = w,   th- = th + Ts w
//! ```
//!
//! The back-EMF is frozen at the start-of-period angle, although the rotor turns by `w Ts`
//! during the period; the angle estimate is biased by about `w Ts / 2`.
//!
//! **`LagFree`** (the default): the exact solution of the current equations over one period
//! for a voltage held constant and a rotor turning at constant speed `w`. With
//! `alpha = exp(-a Ts)` and the complex gain
//!
//! ```text
//! G(w) = (exp(j w Ts) - alpha) / (a + j w)            [s],   G -> Ts as a, w -> 0
//! i-   = alpha i + (1 - alpha) / Rs u + c w Re/Im{ -j e^{j th} G(w) }
//!      i.e. i_a- = alpha i_a + (1 - alpha) u_a / Rs + c w ( sin th Re G + cos th Im G)
//!           i_b- = alpha i_b + (1 - alpha) u_b / Rs + c w ( sin th Im G - cos th Re G)
//! w- = w,   th- = th + Ts w
//! ```
//!
//! For small `a Ts`, `G ~ Ts e^{j w Ts / 2}`: the EMF is in effect taken at the mid-period angle
//! `th + w Ts / 2`, which removes the lag. `Phi` is the exact Jacobian of this map
//! (`d/dth` rotates the EMF term by 90 deg; `d/dw` uses `d(w G)/dw = G + w G'`,
//! `G' = j (Ts e^{j w Ts} - G) / (a + j w)`).
//!
//! # Safeguards (on in [`ObserverConfig::new`], off in [`ObserverConfig::seed`])
//!
//! After the correction of every step, in this order; each is an `Option` field of
//! [`ObserverConfig`], reported per step in [`Estimate`] and counted in [`ObserverCounters`].
//! Together they add a few tens of instructions to a step (no division, no square root).
//!
//! **Innovation gate** ([`InnovationGate`]). The correction's `NIS = y^T S^-1 y` is, for a
//! consistent filter, chi-square distributed with 2 degrees of freedom: `P(NIS > g) =
//! exp(-g / 2)`. While the filter is *settled* (angle variance below the status limit and the
//! running mean of the accepted NIS, each clamped to the threshold, at most `settled_nis`), a
//! sample with `NIS > nis_threshold` is rejected: the step keeps the prediction
//! (`x = x-`, `P = P-`, as if the sample were missing) and reports `rejected`. After
//! `max_consecutive` rejections in a row the next sample is accepted whatever its NIS and the
//! gate stays open until an accepted NIS is below the threshold again, so that a real change
//! is not locked out (counted as `gate_reopened`). During the initial convergence (NIS far
//! above 2) the gate does not act.
//!
//! **Wrong branch** ([`BranchCheck`]). `(w, th)` and `(-w, th + pi)` give the same back-EMF
//! (design section 3); only `dth/dt = w` tells them apart. On the wrong branch the prediction
//! turns the angle at `w_hat` while the measured EMF turns the other way, so the corrections
//! `K_th y` keep cancelling the predicted motion. A CUSUM test accumulates that missing motion
//! (in radians) while the filter is tracking above a minimum speed; past `threshold_rad` the
//! state moves to the other branch: `theta += pi`, `w = -w`, `P = T P T` with
//! `T = diag(1, 1, -1, 1)`, and the angle variance is raised by `flip_angle_sigma_rad^2`
//! (reported as `branch_flipped`). Near standstill, where the EMF and hence the branch is not
//! observable, the test sleeps and forgets.
//!
//! **Covariance health** ([`CovarianceHealth`]). `P` must have a positive diagonal and
//! `trace(P) <= trace_factor * trace(P0)` (its entries are finite: every step that would make
//! them non-finite is refused), and the state must be plausible: `|i_a| + |i_b|` at most
//! `current_factor` (100) times the short-circuit current `psi_f / Ls`, `|w_e| Ts <= pi`. (The
//! state bound matters after absurd but finite data, e.g. a sample of 1e30 A accepted during
//! convergence: without it the next steps overflow and are refused forever.) `trace(P)` mixes units; with [`default_p0`] it is dominated by
//! the speed variance, `(0.05 / Ts)^2`, so the default bound (factor 100) means a speed
//! standard deviation of about `0.5 / Ts` (5000 rad/s el. at 10 kHz): the filter has lost the
//! rotor entirely. On failure the observer resets itself: currents = the measured currents
//! (after [`PmsmObserver::predict`]: the estimated ones), each 0 when beyond its bound;
//! speed kept when within its bound, angle when finite (else 0), `P = P0`, gate and branch test restarted; reported as `covariance_reset`. The
//! check runs after every `step`, `predict` and `correct`, and also when a step is refused
//! for a singular `S` or a non-finite result: when the stored `P` or state is unhealthy, or
//! at the [`MAX_REFUSALS`]-th (3rd) such refusal in a row, the reset replaces the error (so the
//! filter is never stuck on a state it cannot step from, e.g. an `S` singular to rounding in
//! `f32`). Refusals of non-finite input are the caller's and do not count.

use nalgebra::{Cholesky, Matrix2, Matrix4, SMatrix, Vector2, Vector4};

use crate::ekf::{
    Correction, CovarianceUpdate, EkfError, MeasurementModel, ProcessModel, all_finite, finite,
};
use crate::motor::positive;
use crate::structured;
use crate::structured::{Outcome, Sym4};
use crate::trig::sin_cos_small;
use crate::{ConfigError, Float, Matrix, MotorParams, NoiseCovariances, Param, to_t, wrap_angle};

/// How the continuous model is turned into one step of the filter (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Discretization {
    /// The seed's forward-Euler step; EMF at the start-of-period angle (lags by ~`w Ts / 2`).
    ForwardEuler,
    /// Exact for a held voltage and a constant-speed rotation; no half-sample lag.
    #[default]
    LagFree,
}

/// Everything the observer needs; start from [`ObserverConfig::new`] or
/// [`ObserverConfig::seed`] and change fields as needed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObserverConfig<T: Float> {
    /// Motor parameters.
    pub motor: MotorParams<T>,
    /// Sample (PWM) period, seconds.
    pub ts_s: T,
    /// Discretization of the model.
    pub discretization: Discretization,
    /// Process and measurement noise covariances.
    pub noise: NoiseCovariances<T>,
    /// Initial estimate `[i_a, i_b, w_e, theta]`, one period before the first sample.
    pub x0: Vector4<T>,
    /// Initial covariance `P0` (4 x 4).
    pub p0: Matrix4<T>,
    /// Covariance update method of the correction.
    pub covariance_update: CovarianceUpdate,
    /// The status reads [`Status::Uncertain`] while the angle's standard deviation
    /// `sqrt(P[3][3])` exceeds this limit, radians. The innovation gate and the branch check
    /// act only while the angle's variance is below this limit ("tracking").
    pub angle_sigma_limit_rad: T,
    /// Wrong-branch (`theta + pi`) detection and recovery; `None` turns it off.
    pub branch_check: Option<BranchCheck<T>>,
    /// Innovation (NIS) gate against measurement glitches; `None` turns it off.
    pub innovation_gate: Option<InnovationGate<T>>,
    /// Covariance health check with self-reset; `None` turns it off.
    pub covariance_health: Option<CovarianceHealth<T>>,
}

/// Wrong-branch detection (module docs, "Wrong branch"): `(w, th)` and `(-w, th + pi)` give
/// the same back-EMF, and only `dth/dt = w` tells them apart. On the wrong branch the
/// prediction turns the angle estimate at `w_hat` while the corrections hold it on the
/// measured back-EMF, which turns the other way: the corrections `K_th y` keep cancelling the
/// predicted motion. The check accumulates that "missing motion" (a CUSUM test on the angle):
///
/// ```text
/// b_k = min(-w_hat K_th y_k, 2 Ts w_hat^2)        backward correction times |w_hat|
/// S_k = max(0, S_k-1 + b_k - allowance Ts w_hat^2)   while tracking and |w_hat| > min_speed_rad_s
/// S_k = 0                                             otherwise
/// flip when S_k > threshold_rad |w_hat|
/// ```
///
/// `S` is the missing motion weighted by `|w_hat|` (rad^2/s), which needs neither the sign of
/// `w_hat` nor a division; at a steady speed `S / |w_hat|` is the missing motion in radians.
/// The clamp of `b_k` (at most two predicted steps' worth per sample) keeps the first samples
/// of a convergence, where the filter makes large jumps, from counting as much evidence.
///
/// On the right branch the corrections average zero and `S` stays near 0 (it drifts by
/// `-allowance |w| Ts` rad per sample); on the wrong branch they cancel about `|w| Ts` per
/// sample and `S` grows by about `(1 - allowance) |w| Ts` rad per sample. The flip moves the state to the
/// other branch: `theta += pi`, `w = -w`, `P = T P T` with `T = diag(1, 1, -1, 1)`, then
/// `P33 += flip_angle_sigma_rad^2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchCheck<T> {
    /// Missing motion (rad) that triggers the flip.
    pub threshold_rad: T,
    /// The check sleeps (and forgets) while `|w_hat|` is at or below this speed, rad/s
    /// electrical (near standstill the back-EMF, hence the branch, is not observable).
    pub min_speed_rad_s: T,
    /// Fraction of the predicted motion `|w_hat| Ts` the corrections may cancel per sample
    /// without counting as evidence (between 0 and 1).
    pub allowance: T,
    /// Added to the angle's standard deviation (in quadrature, `P33 += sigma^2`) by a flip:
    /// the wrong branch's equilibrium is not exactly `pi` away, and the flipped estimate
    /// must be free to move.
    pub flip_angle_sigma_rad: T,
}

impl<T: Float> BranchCheck<T> {
    /// The default for a sample time: threshold `0.5` rad, minimum speed `0.002 / Ts`
    /// (0.002 rad per sample, 20 rad/s at 10 kHz), allowance `0.5`,
    /// `flip_angle_sigma_rad = 0.5`.
    pub fn default_for(ts_s: T) -> Self {
        Self {
            threshold_rad: to_t(0.5),
            min_speed_rad_s: to_t::<T>(0.002) / ts_s,
            allowance: to_t(0.5),
            flip_angle_sigma_rad: to_t(0.5),
        }
    }
}

/// Innovation gate (module docs, "Innovation gate"): while settled, a sample whose normalized
/// innovation squared `NIS = y^T S^-1 y` exceeds `nis_threshold` is not used (the step is
/// prediction only). For a consistent filter NIS is chi-square with 2 degrees of freedom, so
/// `P(NIS > g) = exp(-g / 2)`: `g = 2 ln(1 / p)` rejects a fraction `p` of good samples
/// (`g = 13.8` for `p = 1e-3`, `27.6` for `1e-6`, `41.4` for `1e-9`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InnovationGate<T> {
    /// NIS above which a sample is rejected (chi-square, 2 degrees of freedom).
    pub nis_threshold: T,
    /// After this many consecutive rejections the next sample is accepted whatever its NIS,
    /// and the gate stays open until an accepted sample's NIS is back below the threshold (so
    /// a real change of the currents is not locked out). 0 never rejects.
    pub max_consecutive: u32,
    /// The gate acts only while the filter is settled: the angle's standard deviation below
    /// `angle_sigma_limit_rad` and the running mean of the accepted samples' NIS (each clamped
    /// to `nis_threshold`, averaged over about 16 samples) at or below this level. A
    /// consistent filter's mean NIS is 2; during a convergence it is far larger.
    pub settled_nis: T,
}

impl<T: Float> Default for InnovationGate<T> {
    /// `nis_threshold = 41.4` (a good sample is rejected with probability 1e-9, once in 28 h
    /// at 10 kHz), `max_consecutive = 2`, `settled_nis = 6`.
    ///
    /// `max_consecutive` is small on purpose: a glitch is one sample (two at most), while a
    /// real fast transient (a rated load step on a low-inertia motor) also raises the NIS past
    /// the threshold; with 10 the gate held off 10 real samples there and the angle error of
    /// the small fast motor reached 8.3 deg (pmsm-sim suite), with 2 it is 1.9 deg.
    fn default() -> Self {
        Self {
            nis_threshold: to_t(41.4),
            max_consecutive: 2,
            settled_nis: to_t(6.0),
        }
    }
}

/// Covariance health check (module docs, "Covariance health"): after every step
/// `P` must be finite, its diagonal positive, and `trace(P) <= trace_factor * trace(P0)`, and
/// the state plausible (`|i_a| + |i_b| <= current_factor * psi_f / Ls`,
/// `|w_e| Ts <= max_w_ts_rad`); otherwise the observer resets itself (currents = the measured
/// currents, speed and angle kept when plausible, `P = P0`) and reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CovarianceHealth<T> {
    /// Bound on `trace(P)` as a multiple of `trace(P0)`.
    pub trace_factor: T,
    /// Bound on `|i_a| + |i_b|` as a multiple of the characteristic current `psi_f / Ls` (the
    /// short-circuit current, the largest steady current of the machine at any speed).
    pub current_factor: T,
    /// Bound on `|w_e| Ts`, rad per sample (`pi`: the Nyquist limit of the sampled model).
    pub max_w_ts_rad: T,
}

impl<T: Float> Default for CovarianceHealth<T> {
    /// `trace_factor = 100`, `current_factor = 100`, `max_w_ts_rad = pi`.
    fn default() -> Self {
        Self {
            trace_factor: to_t(100.0),
            current_factor: to_t(100.0),
            max_w_ts_rad: T::pi(),
        }
    }
}

impl<T: Float> ObserverConfig<T> {
    /// The project default: [`Discretization::LagFree`], [`NoiseCovariances::scaled`], Joseph
    /// update, `x0 = 0` (rotor angle and speed unknown), [`default_p0`], and the three
    /// safeguards on: [`BranchCheck::default_for`], [`InnovationGate::default`],
    /// [`CovarianceHealth::default`].
    pub fn new(motor: MotorParams<T>, ts_s: T) -> Self {
        Self {
            motor,
            ts_s,
            discretization: Discretization::LagFree,
            noise: NoiseCovariances::scaled(&motor, ts_s),
            x0: Vector4::zeros(),
            p0: default_p0(&motor, ts_s),
            covariance_update: CovarianceUpdate::Joseph,
            angle_sigma_limit_rad: to_t(0.2),
            branch_check: Some(BranchCheck::default_for(ts_s)),
            innovation_gate: Some(InnovationGate::default()),
            covariance_health: Some(CovarianceHealth::default()),
        }
    }

    /// The seed's filter: [`Discretization::ForwardEuler`], [`NoiseCovariances::seed`] and the
    /// standard covariance update (seed step 6, made symmetric); `x0`, `P0` as in
    /// [`new`](Self::new); no branch check, no innovation gate, no covariance health check.
    pub fn seed(motor: MotorParams<T>, ts_s: T) -> Self {
        Self {
            discretization: Discretization::ForwardEuler,
            noise: NoiseCovariances::seed(),
            covariance_update: CovarianceUpdate::StandardSymmetrized,
            branch_check: None,
            innovation_gate: None,
            covariance_health: None,
            ..Self::new(motor, ts_s)
        }
    }

    /// Checks every field; the observer's constructor calls it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.motor.validate()?;
        positive(self.ts_s, Param::Ts)?;
        positive(self.angle_sigma_limit_rad, Param::AngleSigmaLimit)?;
        check_psd(&self.noise.q, Matrix::Q)?;
        check_psd(&self.noise.r, Matrix::R)?;
        // S = H P H^T + R must stay invertible whatever P becomes: R positive definite.
        let r = &self.noise.r;
        // (R is finite here: `check_psd` refused NaN and infinities.)
        if r[(0, 0)] <= T::zero() || r[(0, 0)] * r[(1, 1)] - r[(0, 1)] * r[(1, 0)] <= T::zero() {
            return Err(ConfigError::NotPositiveDefinite(Matrix::R));
        }
        check_psd(&self.p0, Matrix::P0)?;
        // Forward Euler's current pole `1 - Rs Ts / Ls` must lie inside the unit circle.
        if self.discretization == Discretization::ForwardEuler
            && self.motor.rs_ohm * self.ts_s >= to_t::<T>(2.0) * self.motor.ls_h
        {
            return Err(ConfigError::TooLargeForTs(Param::Rs));
        }
        if !all_finite(&self.x0) {
            return Err(ConfigError::NonFiniteInitialState);
        }
        if let Some(b) = &self.branch_check {
            positive(b.threshold_rad, Param::BranchThreshold)?;
            non_negative(b.min_speed_rad_s, Param::BranchMinSpeed)?;
            non_negative(b.allowance, Param::BranchAllowance)?;
            non_negative(b.flip_angle_sigma_rad, Param::BranchFlipSigma)?;
        }
        if let Some(g) = &self.innovation_gate {
            positive(g.nis_threshold, Param::GateNisThreshold)?;
            positive(g.settled_nis, Param::GateSettledNis)?;
        }
        if let Some(h) = &self.covariance_health {
            positive(h.trace_factor, Param::HealthTraceFactor)?;
            positive(h.current_factor, Param::HealthCurrentFactor)?;
            positive(h.max_w_ts_rad, Param::HealthMaxSpeed)?;
            // P0 is finite and positive semi-definite here, so its trace is finite and >= 0.
            if self.p0.trace() <= T::zero() {
                return Err(ConfigError::ZeroInitialCovarianceTrace);
            }
            // The bound itself must be finite, or an overflowing P would pass it.
            if !(h.trace_factor * self.p0.trace()).is_finite() {
                return Err(ConfigError::TooLargeInitialCovariance);
            }
        }
        Ok(())
    }
}

/// `Ok` when `v` is finite and not negative.
fn non_negative<T: Float>(v: T, param: Param) -> Result<(), ConfigError> {
    if !v.is_finite() {
        Err(ConfigError::NonFinite(param))
    } else if v < T::zero() {
        Err(ConfigError::NotPositive(param))
    } else {
        Ok(())
    }
}

/// Default initial covariance: `diag((0.1 I_c)^2, (0.1 I_c)^2, (0.05 / Ts)^2, pi^2)`, i.e. the
/// currents roughly known, the speed unknown up to `0.05` rad per sample, the angle unknown.
pub fn default_p0<T: Float>(motor: &MotorParams<T>, ts_s: T) -> Matrix4<T> {
    let si = motor.characteristic_current_a() * to_t(0.1);
    let sw = to_t::<T>(0.05) / ts_s;
    let pi = T::pi();
    Matrix4::from_diagonal(&Vector4::new(si * si, si * si, sw * sw, pi * pi))
}

/// Symmetric (to rounding) and positive semi-definite: `m + delta I` has a Cholesky factor for
/// `delta = 1e3 eps max|m_ij|`, i.e. no eigenvalue below `-delta`.
fn check_psd<T: Float, const N: usize>(
    m: &SMatrix<T, N, N>,
    which: Matrix,
) -> Result<(), ConfigError> {
    if !all_finite(m) {
        return Err(ConfigError::NonFiniteMatrix(which));
    }
    let scale = m.iter().fold(T::zero(), |acc, v| acc.max(v.abs()));
    if scale == T::zero() {
        return Ok(());
    }
    let tol = T::default_epsilon() * to_t(1e3) * scale;
    if (m - m.transpose()).iter().any(|d| d.abs() > tol) {
        return Err(ConfigError::NotSymmetric(which));
    }
    let shifted = m + SMatrix::<T, N, N>::identity() * tol;
    if Cholesky::new(shifted).is_none() {
        return Err(ConfigError::NotPositiveSemiDefinite(which));
    }
    Ok(())
}

/// The PMSM process and measurement model with its per-`Ts` constants; implements
/// [`ProcessModel`] (input `[u_a, u_b]`) and [`MeasurementModel`] (`z = [i_a, i_b]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PmsmModel<T: Float> {
    discretization: Discretization,
    ts: T,
    /// `a = Rs / Ls`, 1/s.
    a: T,
    /// `c = psi_f / Ls`, A/rad.
    c: T,
    /// Current decay per sample: `alpha = exp(-a Ts)` (lag-free) or `1 - a Ts` (Euler).
    decay: T,
    /// Input gain per sample: `(1 - alpha) / Rs` (lag-free) or `Ts / Ls` (Euler), A/V.
    input_gain: T,
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
}

impl<T: Float> PmsmModel<T> {
    /// The model for a validated configuration.
    pub fn new(cfg: &ObserverConfig<T>) -> Self {
        let m = &cfg.motor;
        let ts = cfg.ts_s;
        let a = m.rs_ohm / m.ls_h;
        let (decay, input_gain) = match cfg.discretization {
            Discretization::ForwardEuler => (T::one() - a * ts, ts / m.ls_h),
            Discretization::LagFree => {
                // 1 - exp(-a Ts) without cancellation.
                let one_minus_alpha = -(-a * ts).exp_m1();
                (T::one() - one_minus_alpha, one_minus_alpha / m.rs_ohm)
            }
        };
        Self {
            discretization: cfg.discretization,
            ts,
            a,
            c: m.psi_f_wb / m.ls_h,
            decay,
            input_gain,
            q: (cfg.noise.q + cfg.noise.q.transpose()) * to_t::<T>(0.5),
            r: (cfg.noise.r + cfg.noise.r.transpose()) * to_t::<T>(0.5),
            update: cfg.covariance_update,
        }
    }

    /// Sample time `Ts`, s.
    pub fn ts(&self) -> T {
        self.ts
    }

    /// Current decay per sample (`alpha` or `1 - a Ts`).
    pub fn decay(&self) -> T {
        self.decay
    }

    /// Voltage-to-current gain per sample, A/V.
    pub fn input_gain(&self) -> T {
        self.input_gain
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

    /// The back-EMF term of the step from `(th, w)` and its derivatives (module docs).
    #[inline(always)]
    pub(crate) fn transition_terms(&self, th: T, w: T) -> TransitionTerms<T> {
        let (s, co) = th.sin_cos_angle();
        let (_, (m_re, m_im), (mp_re, mp_im)) = self.emf_gain(w);
        let c = self.c;
        // EMF term c w (-j e^{j th}) G, and its derivatives.
        TransitionTerms {
            ea: c * (s * m_re + co * m_im),
            eb: c * (s * m_im - co * m_re),
            ea_th: c * (co * m_re - s * m_im),
            eb_th: c * (co * m_im + s * m_re),
            ea_w: c * (s * mp_re + co * mp_im),
            eb_w: c * (s * mp_im - co * mp_re),
        }
    }

    /// The discretization in use.
    pub fn discretization(&self) -> Discretization {
        self.discretization
    }

    /// `(G, w G, d(w G)/dw)` of the lag-free step as `(re, im)` pairs (module docs).
    #[inline(always)]
    fn emf_gain(&self, w: T) -> ((T, T), (T, T), (T, T)) {
        let ts = self.ts;
        match self.discretization {
            Discretization::ForwardEuler => ((ts, T::zero()), (w * ts, T::zero()), (ts, T::zero())),
            Discretization::LagFree => {
                let a = self.a;
                let one_minus_alpha = T::one() - self.decay;
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
        }
    }
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
        } = self.transition_terms(th, w);
        let xn = Vector4::new(
            self.decay * ia + self.input_gain * u[0] + ea,
            self.decay * ib + self.input_gain * u[1] + eb,
            w,
            th + self.ts * w,
        );
        let z = T::zero();
        let o = T::one();
        #[rustfmt::skip]
        let phi = Matrix4::new(
            self.decay, z,          ea_w, ea_th,
            z,          self.decay, eb_w, eb_th,
            z,          z,          o,    z,
            z,          z,          self.ts, o,
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

/// Whether the angle estimate can be trusted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// The angle's standard deviation is below the configured limit.
    Tracking,
    /// The angle's standard deviation exceeds the limit: the filter has not converged yet, or
    /// the back-EMF is too small to observe the angle (near standstill).
    Uncertain,
}

/// One output sample of the observer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate<T> {
    /// Electrical rotor angle, rad, in `[-pi, pi)`.
    pub theta_rad: T,
    /// Electrical speed, rad/s.
    pub omega_e_rad_s: T,
    /// Mechanical speed `omega_e / pole_pairs`, rad/s.
    pub omega_mech_rad_s: T,
    /// Estimated alpha current, A.
    pub i_alpha_a: T,
    /// Estimated beta current, A.
    pub i_beta_a: T,
    /// Normalized innovation squared of the last correction (0 before the first one); also
    /// set for a sample the gate rejected.
    pub nis: T,
    /// Trust in the angle.
    pub status: Status,
    /// The innovation gate rejected this sample: the step was a prediction only.
    pub rejected: bool,
    /// The branch check moved the estimate to the other branch in this step
    /// (`theta += pi`, `w = -w`).
    pub branch_flipped: bool,
    /// The covariance health check failed in this step and the observer reset itself.
    pub covariance_reset: bool,
}

/// Event counters of an observer since its construction (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ObserverCounters {
    /// Samples rejected by the innovation gate.
    pub rejected: u32,
    /// Times the gate reopened after `max_consecutive` rejections in a row.
    pub gate_reopened: u32,
    /// Branch flips (`theta + pi` recoveries).
    pub branch_flips: u32,
    /// Self-resets by the covariance health check.
    pub covariance_resets: u32,
}

/// What happened in the last step (copied into [`Estimate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Events {
    rejected: bool,
    flipped: bool,
    reset: bool,
}

/// Branch check constants and state.
#[derive(Clone, Copy, Debug, PartialEq)]
struct BranchState<T> {
    threshold: T,
    /// `min_speed^2`.
    min_speed2: T,
    /// `allowance Ts`.
    k: T,
    /// `2 Ts`.
    two_ts: T,
    /// `flip_angle_sigma_rad^2`.
    flip_var: T,
    /// CUSUM of the missing motion weighted by `|w_hat|`, rad^2/s.
    sum: T,
}

/// Innovation gate constants and state.
#[derive(Clone, Copy, Debug, PartialEq)]
struct GateState<T> {
    threshold: T,
    max_consecutive: u32,
    settled_nis: T,
    /// Running mean of the accepted samples' clamped NIS (starts at the threshold: unsettled).
    nis_mean: T,
    consecutive: u32,
    /// Open after `max_consecutive` rejections, until an accepted NIS is below the threshold.
    open: bool,
}

/// Steps refused in a row (singular `S`, non-finite result) after which the covariance health
/// check resets the filter.
pub const MAX_REFUSALS: u32 = 3;

/// Covariance health constants.
#[derive(Clone, Copy, Debug, PartialEq)]
struct HealthState<T> {
    /// Steps refused in a row for a singular `S` or a non-finite result.
    refusals: u32,
    trace_bound: T,
    /// Bound on `|i_a| + |i_b|`, A.
    current_bound: T,
    /// Bound on `|w_e|`, rad/s.
    speed_bound: T,
    p0: Sym4<T>,
}

/// The gate's decision on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Verdict {
    /// NIS at or below the threshold (or no gate): accept.
    Low,
    /// NIS above the threshold but the gate does not act (not settled, or open): accept.
    High,
    /// NIS above the threshold after `max_consecutive` rejections: accept and open the gate.
    Reopen,
    /// Reject: prediction only.
    Reject,
}

/// The gate's decision for a sample with `NIS > threshold` (no state change here).
#[cold]
#[inline(never)]
fn gate_verdict<T: Float>(g: &GateState<T>, tracking: bool) -> Verdict {
    if !(tracking && g.nis_mean <= g.settled_nis && !g.open) {
        Verdict::High
    } else if g.consecutive < g.max_consecutive {
        Verdict::Reject
    } else {
        Verdict::Reopen
    }
}

/// Bookkeeping of an accepted sample whose NIS was above the threshold: it counts at the
/// threshold in the running mean; a reopening is counted and opens the gate.
#[cold]
#[inline(never)]
fn gate_accepted_high<T: Float>(g: &mut GateState<T>, counters: &mut ObserverCounters, v: Verdict) {
    if v == Verdict::Reopen {
        g.open = true;
        counters.gate_reopened = counters.gate_reopened.saturating_add(1);
    }
    g.consecutive = 0;
    g.nis_mean += (g.threshold - g.nis_mean) * to_t::<T>(1.0 / 16.0);
}

/// The PMSM alpha-beta EKF observer (seed's model; module docs give equations and timing).
///
/// Its steps run a hand-scheduled update on the 10 unique entries of the symmetric covariance
/// (the `structured` module), which gives the same results as [`Ekf`](crate::Ekf) driven by
/// [`PmsmModel`]
/// (to rounding; tested) at a fraction of the cost, followed by the safeguards of the
/// configuration (branch check, innovation gate, covariance health; module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PmsmObserver<T: Float> {
    model: PmsmModel<T>,
    x: Vector4<T>,
    p: Sym4<T>,
    last: Correction<T, 2>,
    inv_pole_pairs: T,
    angle_var_limit: T,
    branch: Option<BranchState<T>>,
    gate: Option<GateState<T>>,
    health: Option<HealthState<T>>,
    events: Events,
    counters: ObserverCounters,
}

fn zero_correction<T: Float>() -> Correction<T, 2> {
    Correction {
        innovation: Vector2::zeros(),
        innovation_covariance: Matrix2::zeros(),
        nis: T::zero(),
    }
}

impl<T: Float> PmsmObserver<T> {
    /// Validates `cfg` and builds the observer at `x0`, `P0`.
    pub fn new(cfg: &ObserverConfig<T>) -> Result<Self, ConfigError> {
        cfg.validate()?;
        let mut x0 = cfg.x0;
        x0[3] = wrap_angle(x0[3]);
        let ts = cfg.ts_s;
        let p0 = Sym4::from_matrix(&cfg.p0);
        Ok(Self {
            model: PmsmModel::new(cfg),
            x: x0,
            p: p0,
            last: zero_correction(),
            inv_pole_pairs: T::one() / to_t(f64::from(cfg.motor.pole_pairs)),
            angle_var_limit: cfg.angle_sigma_limit_rad * cfg.angle_sigma_limit_rad,
            branch: cfg.branch_check.map(|b| BranchState {
                threshold: b.threshold_rad,
                min_speed2: b.min_speed_rad_s * b.min_speed_rad_s,
                k: b.allowance * ts,
                two_ts: ts + ts,
                flip_var: b.flip_angle_sigma_rad * b.flip_angle_sigma_rad,
                sum: T::zero(),
            }),
            gate: cfg.innovation_gate.map(|g| GateState {
                threshold: g.nis_threshold,
                max_consecutive: g.max_consecutive,
                settled_nis: g.settled_nis,
                nis_mean: g.nis_threshold,
                consecutive: 0,
                open: false,
            }),
            health: cfg.covariance_health.map(|h| HealthState {
                refusals: 0,
                trace_bound: h.trace_factor * p0.trace(),
                current_bound: h.current_factor * cfg.motor.characteristic_current_a(),
                speed_bound: h.max_w_ts_rad / cfg.ts_s,
                p0,
            }),
            events: Events::default(),
            counters: ObserverCounters::default(),
        })
    }

    /// One sample: predict with `u_prev = [u_a, u_b]` (V, held over the previous period), then
    /// correct with the sampled currents `i = [i_a, i_b]` (A), then apply the safeguards.
    ///
    /// A non-finite input or measurement returns the error and leaves the observer as it was.
    /// So does a singular innovation covariance or a non-finite result, unless the covariance
    /// health check is on and finds the stored covariance unhealthy: then the observer resets
    /// itself from the measured currents and returns that estimate
    /// ([`Estimate::covariance_reset`]).
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        // One test on the common path; which argument was bad is sorted out only on failure.
        if !(u_prev[0] + u_prev[1] + i[0] + i[1]).is_finite() {
            if !finite(&u_prev) {
                return Err(EkfError::NonFiniteInput);
            }
            if !finite(&i) {
                return Err(EkfError::NonFiniteMeasurement);
            }
            // All four finite but their sum overflows: absurd, yet valid input; go on.
        }
        let (xm, pm) = structured::predict(&self.model, &self.x, &self.p, u_prev);
        self.correct_prior(xm, pm, i)
    }

    /// Prediction only (e.g. to coast over a missing current sample), with the voltage held
    /// over the period just ended. Refused, state kept, for a non-finite input or result. The
    /// covariance health check (when on) runs after it; on a reset the currents are kept.
    pub fn predict(&mut self, u_prev: [T; 2]) -> Result<(), EkfError> {
        if !finite(&u_prev) {
            return Err(EkfError::NonFiniteInput);
        }
        let (x, p) = structured::predict(&self.model, &self.x, &self.p, u_prev);
        if !(finite(x.as_slice()) && p.all_finite()) {
            if self.refused_resets() {
                self.events = Events::default();
                self.self_reset(None);
                return Ok(());
            }
            return Err(EkfError::NonFiniteResult);
        }
        if let Some(h) = &mut self.health {
            h.refusals = 0;
        }
        self.x = x;
        self.p = p;
        self.events = Events::default();
        if self.unhealthy(&self.x, &self.p) {
            self.self_reset(None);
        }
        Ok(())
    }

    /// Correction only, with the currents sampled now, then the safeguards. Refused, state
    /// kept, for a non-finite measurement; other errors as for [`step`](Self::step).
    pub fn correct(&mut self, i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        if !finite(&i) {
            return Err(EkfError::NonFiniteMeasurement);
        }
        self.correct_prior(self.x, self.p, i)
    }

    /// Correction of the prior `(xm, pm)` with the currents `i`, innovation gate, branch check
    /// and covariance health (module docs).
    #[inline(always)]
    fn correct_prior(
        &mut self,
        xm: Vector4<T>,
        pm: Sym4<T>,
        i: [T; 2],
    ) -> Result<Estimate<T>, EkfError> {
        // Common path first: every test below is one comparison on good data; the rare
        // branches (rejection, reopening, flip, reset) are out-of-line functions.
        let tracking = pm.p33 <= self.angle_var_limit;
        // The gate decides from the NIS before the update is computed; its bookkeeping is
        // applied only once the step has succeeded (a refused step changes nothing).
        let mut verdict = Verdict::Low;
        let gate = &self.gate;
        let outcome = structured::correct(&self.model, &xm, &pm, i, |nis| match gate {
            Some(g) if nis > g.threshold => {
                verdict = gate_verdict(g, tracking);
                verdict == Verdict::Reject
            }
            _ => false,
        });
        let (x, p, c, dth) = match outcome {
            Ok(Outcome::Updated(post)) => post,
            Ok(Outcome::Skipped(c)) => {
                // Rejected by the gate: the step is the prediction only.
                self.x = xm;
                self.p = pm;
                self.last = c;
                self.gate_rejected();
                if self.unhealthy(&self.x, &self.p) {
                    self.self_reset(Some(i));
                }
                return Ok(self.estimate());
            }
            Err(e) => {
                if self.refused_resets() {
                    self.events = Events::default();
                    self.self_reset(Some(i));
                    return Ok(self.estimate());
                }
                return Err(e);
            }
        };
        if let Some(h) = &mut self.health {
            h.refusals = 0;
        }
        self.x = x;
        self.p = p;
        self.last = c;
        self.events = Events::default();
        if let Some(g) = &mut self.gate {
            if verdict == Verdict::Low {
                g.consecutive = 0;
                g.open = false;
                g.nis_mean += (c.nis - g.nis_mean) * to_t::<T>(1.0 / 16.0);
            } else {
                gate_accepted_high(g, &mut self.counters, verdict);
            }
        }
        if let Some(b) = &mut self.branch {
            let w = x[2];
            let w2 = w * w;
            if tracking && w2 > b.min_speed2 {
                // Plain comparisons: `min`/`max` are libm calls (NaN rules) on the MCU.
                let back = -(dth * w);
                let cap = b.two_ts * w2;
                let back = if back < cap { back } else { cap };
                let sum = b.sum + back - b.k * w2;
                b.sum = if sum > T::zero() { sum } else { T::zero() };
                if b.sum > b.threshold * w.abs() {
                    self.flip();
                }
            } else {
                b.sum = T::zero();
            }
        }
        if self.unhealthy(&self.x, &self.p) {
            self.self_reset(Some(i));
        }
        Ok(self.estimate())
    }

    /// Bookkeeping of a rejected sample: counted and reported.
    #[cold]
    #[inline(never)]
    fn gate_rejected(&mut self) {
        if let Some(g) = &mut self.gate {
            g.consecutive += 1;
        }
        self.counters.rejected = self.counters.rejected.saturating_add(1);
        self.events = Events {
            rejected: true,
            ..Events::default()
        };
    }

    /// Moves the estimate to the other branch: `theta += pi`, `w = -w`, `P = T P T`
    /// (`T = diag(1, 1, -1, 1)`), `P33 += flip_angle_sigma_rad^2`; restarts the test.
    #[cold]
    #[inline(never)]
    fn flip(&mut self) {
        let Some(b) = &mut self.branch else {
            return;
        };
        b.sum = T::zero();
        self.x[2] = -self.x[2];
        self.x[3] = wrap_angle(self.x[3] + T::pi());
        self.p = self.p.flip_speed();
        self.p.p33 += b.flip_var;
        self.counters.branch_flips = self.counters.branch_flips.saturating_add(1);
        self.events.flipped = true;
    }

    /// `true` when the health check is on and fails: a non-positive (or NaN) diagonal entry
    /// of `P`, `trace(P)` above the bound (or NaN), or a current or speed estimate beyond its
    /// bound (or NaN).
    #[inline(always)]
    fn unhealthy(&self, x: &Vector4<T>, p: &Sym4<T>) -> bool {
        match &self.health {
            Some(h) => {
                let z = T::zero();
                !((p.p00 + p.p11) + (p.p22 + p.p33) <= h.trace_bound
                    && p.p00 > z
                    && p.p11 > z
                    && p.p22 > z
                    && p.p33 > z
                    && x[0].abs() + x[1].abs() <= h.current_bound
                    && x[2].abs() <= h.speed_bound)
            }
            None => false,
        }
    }

    /// Whether a step refused for a singular `S` or a non-finite result must reset the filter
    /// (health check on): the stored `P` or state is unhealthy, or this is the
    /// [`MAX_REFUSALS`]-th such refusal in a row (the filter cannot step from where it is,
    /// e.g. an `S` that is singular to rounding in `f32`). Counts the refusal otherwise.
    #[cold]
    #[inline(never)]
    fn refused_resets(&mut self) -> bool {
        let unhealthy = self.unhealthy(&self.x, &self.p);
        match &mut self.health {
            Some(h) => {
                h.refusals += 1;
                if unhealthy || h.refusals >= MAX_REFUSALS {
                    h.refusals = 0;
                    true
                } else {
                    false
                }
            }
            None => false,
        }
    }

    /// The self-reset of the health check: currents = the measured currents (or the current
    /// estimate if none; 0 beyond the bound), speed kept if within its bound, angle if finite
    /// (else 0),
    /// `P = P0`, gate and branch check restarted; reported in the events and counters.
    #[cold]
    #[inline(never)]
    fn self_reset(&mut self, i: Option<[T; 2]>) {
        let Some(h) = &self.health else {
            return;
        };
        // `!(|v| <= bound)` also catches NaN.
        let keep = |v: T, bound: T| if v.abs() <= bound { v } else { T::zero() };
        let ib_max = h.current_bound;
        let (ia, ib) = match i {
            Some([a, b]) => (keep(a, ib_max), keep(b, ib_max)),
            None => (keep(self.x[0], ib_max), keep(self.x[1], ib_max)),
        };
        let w = keep(self.x[2], h.speed_bound);
        let th = if self.x[3].is_finite() {
            wrap_angle(self.x[3])
        } else {
            T::zero()
        };
        self.x = Vector4::new(ia, ib, w, th);
        self.p = h.p0;
        self.restart_safeguards();
        self.events.reset = true;
        self.counters.covariance_resets = self.counters.covariance_resets.saturating_add(1);
    }

    /// Clears the gate's and the branch check's running state.
    fn restart_safeguards(&mut self) {
        if let Some(g) = &mut self.gate {
            g.consecutive = 0;
            g.open = false;
            g.nis_mean = g.threshold;
        }
        if let Some(b) = &mut self.branch {
            b.sum = T::zero();
        }
    }

    /// The current estimate.
    pub fn estimate(&self) -> Estimate<T> {
        let x = &self.x;
        let status = if self.p.p33 > self.angle_var_limit {
            Status::Uncertain
        } else {
            Status::Tracking
        };
        Estimate {
            theta_rad: x[3],
            omega_e_rad_s: x[2],
            omega_mech_rad_s: x[2] * self.inv_pole_pairs,
            i_alpha_a: x[0],
            i_beta_a: x[1],
            nis: self.last.nis,
            status,
            rejected: self.events.rejected,
            branch_flipped: self.events.flipped,
            covariance_reset: self.events.reset,
        }
    }

    /// Event counters (gate rejections and reopenings, branch flips, health resets).
    pub fn counters(&self) -> &ObserverCounters {
        &self.counters
    }

    /// State `[i_a, i_b, w_e, theta]`.
    pub fn state(&self) -> &Vector4<T> {
        &self.x
    }

    /// State covariance `P` (4 x 4, symmetric).
    pub fn covariance(&self) -> Matrix4<T> {
        self.p.to_matrix()
    }

    /// Innovation, its covariance and the NIS of the last correction (zeros before the first).
    pub fn last_correction(&self) -> &Correction<T, 2> {
        &self.last
    }

    /// The process/measurement model.
    pub fn model(&self) -> &PmsmModel<T> {
        &self.model
    }

    /// Replaces the estimate and covariance (angle wrapped, covariance made symmetric), clears
    /// the last correction's diagnostics (innovation, `S`, NIS read 0 until the next
    /// correction), the events and the running state of the gate and the branch check (the
    /// counters are kept). Refused, nothing changed, when either is not finite. The covariance
    /// is not checked here: an unhealthy one is caught by the health check of the next step.
    pub fn reset(&mut self, mut x: Vector4<T>, p: Matrix4<T>) -> Result<(), EkfError> {
        if !(finite(x.as_slice()) && finite(p.as_slice())) {
            return Err(EkfError::NonFiniteResult);
        }
        x[3] = wrap_angle(x[3]);
        self.x = x;
        self.p = Sym4::from_matrix(&p);
        self.last = zero_correction();
        self.events = Events::default();
        self.restart_safeguards();
        Ok(())
    }
}
