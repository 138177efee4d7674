//! The seed's PMSM observer: an EKF on the alpha-beta model of a surface-mounted PMSM, and of
//! an interior one through the active flux (section below).
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
//! # Interior (salient) motors: the active-flux model
//!
//! With `Ld != Lq` ([`MotorParams::kind`](crate::MotorParams::kind)) the stator equations in the
//! alpha-beta frame have an angle-dependent inductance matrix. Of the two usual ways to write
//! an observer model for them, the **active flux** (Boldea 2008) is used here, not the
//! extended EMF (Chen 2003): it keeps the state, the input and, above all, the structure of the
//! surface model (a diagonal current block in `Phi`, the same 10-entry covariance schedule, the
//! same lag-free discretization and safeguards), so `Ld == Lq` *is* the surface observer and a
//! salient step costs a few tens of instructions more, not a new filter. The extended EMF
//! would need the EMF's magnitude, which changes with the load and the current's derivative,
//! as a state or a fast parameter.
//!
//! The active flux `psi_a = psi_f + (Ld - Lq) i_d` along the rotor's d axis turns the machine
//! into a non-salient one of inductance `Lq`:
//!
//! ```text
//! Lq di/dt = u - Rs i - j w psi_a e^{j th} - (d psi_a/dt) e^{j th}        (i = i_a + j i_b)
//! ```
//!
//! **Step.** The surface step above with `Ls -> Lq` and `c = psi_a / Lq`, where
//! `i_d = i_a cos th + i_b sin th` comes from the posterior at the start of the period. In
//! steady state `psi_a` is constant and the step is exact (no lag, no bias: measured below 0.03
//! deg on both interior reference motors at `w_e Ts` from 0.02 to 0.3, `tests/salient.rs`). The
//! last term, `(Ld - Lq) di_d/dt`, matters only while `i_d` moves (MTPA load steps): the model
//! lets `i_d` respond through `Lq`, the motor through `Ld`, so to first order the motor's
//! change of `i_d` over the period is `Lq / Ld` times the model's. The step adds
//!
//! ```text
//! (Lq / Ld - 1) (i_d- - i_d) e^{j (th + w Ts)}       (i_d- the model's predicted d current)
//! ```
//!
//! which is zero in steady state (so it cannot bias) and keeps load steps clean (measured on
//! the traction motor, 30 % -> 100 % load step: 0.15 deg peak with it, 25 deg without). It
//! applies once the filter has **locked** (angle tracked and the innovations settled, the
//! gate's running NIS at or below its settled level) and while the angle stays tracked;
//! during the initial convergence the d axis is unknown, and the correction would triple
//! (traction motor: `Lq / Ld = 3`) the model's d-axis response along a wrong axis (measured:
//! 10-15 of the 144 cells of the interior convergence grid failed with it always on).
//!
//! **Jacobian.** `Phi` keeps the block structure `[[A, J], [0, B]]`; for a salient motor the
//! current block `A` is a full 2 x 2 (`decay I` plus the active flux's `d psi_a / d i =
//! (Ld - Lq) (cos th, sin th)` and the correction's dependence on the currents), and `J`
//! carries both terms' derivatives in `w` and `th` (`d psi_a / d th = (Ld - Lq) i_q`). The
//! covariance schedule then has a salient variant (a dozen more products). Leaving these terms
//! out (tried first) changes the gain, not the fixed point, but the convergence grid failed
//! cells with the correction on. The generic [`PmsmModel`] carries the same terms, so the
//! structured update still equals the generic `Ekf` (`tests/structured.rs`).
//!
//! **Tracking.** The tracked parameter is the magnet flux `psi_f`; `psi_a` follows from it and
//! `i_d` each step (`d psi_a / d psi_f = 1`: the flux's Jacobian column is the surface one).
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
//!
//! **Divergence** (part of the covariance health). A filter can settle where its covariance
//! claims to know the angle while its innovations say the model cannot explain the data:
//! measured on the traction IPM at rated load (`Lq i_q` 1.6 x `psi_f`), a start 120 deg off
//! ended 135 deg off, at 1.5 x the true speed, with `NIS` about 30 000 every sample. When the
//! `NIS` exceeds `divergence_nis` (1000: a chi-square(2) tail of `e^-500`) in
//! `divergence_samples` (200) tracked steps in a row (counted by the innovation gate: the check
//! needs it), the observer resets itself as above. On
//! the surface reference motors it never fires in the suite.
//!
//! **Consistency** ([`ConsistencyCheck`]). The covariance reflects the model's noise, not a
//! model error: it stays small while the filter sits on a wrong solution or falls behind a
//! fast transient it cannot follow. The innovations see it. The check keeps a fast mean
//! (4 samples) and a slow, clamped baseline (1024 samples) of the `NIS`; while the fast mean
//! exceeds 8 times the baseline, or one sample 10 times, the status reads
//! [`Status::Uncertain`] (reported as [`Estimate::inconsistent`]), until the fast mean has
//! stayed at or below half that limit for 32 steps. The baseline learns the innovation level
//! of the data (a recorded drive's noise and model error that the configured `R` does not
//! describe); its clamp at 4 times itself keeps a loss from teaching it, its ceiling (400)
//! bounds the error ever accepted as noise. It changes no state: only the status. With the
//! check on, the status also requires the back-EMF to be known to be there: the speed
//! estimate away from zero by three of its standard deviations (`w^2 >= 9 P22`), or an angle
//! fused by [`PmsmObserver::correct_angle`] within the last 64 steps (high-frequency
//! injection at standstill). At a start from rest the filter's angle variance collapses
//! within a few samples although no EMF has told it anything; this rule keeps such a start
//! `Uncertain`. ([`Estimate::angle_tracked`] and [`Estimate::inconsistent`] give the parts.)
//! On three real ESC recordings (4.5 kHz, steps and reversals up to 5000 rad/s el.) samples
//! reported [`Status::Tracking`] while more than 45 deg off went from 489 / 0 / 427 to
//! 0 / 0 / 0.
//!
//! **Irregular periods.** [`PmsmObserver::step_dt`] predicts over the period that actually
//! ended at the sample (a skipped control cycle, a log's time stamps) with the model for that
//! period ([`PmsmModel::with_period`]); at `dt == Ts` it is [`PmsmObserver::step`] itself.

mod config;
#[cfg(all(feature = "std", target_arch = "x86_64"))]
mod host;
pub(crate) mod model;
#[doc(hidden)]
pub mod parts;
mod safeguards;
pub mod tracking;

pub use config::{ObserverConfig, default_p0};
pub use model::{Discretization, PmsmModel};
pub use safeguards::{
    BranchCheck, ConsistencyCheck, CovarianceHealth, InnovationGate, MAX_REFUSALS,
};
pub use tracking::{ParameterTracking, RsTracking};

/// Steps after a fused angle ([`PmsmObserver::correct_angle`]) in which the angle counts as
/// observable at any speed (the status's observability rule, module docs "Consistency").
const FUSED_STEPS: u32 = 64;

/// The longest period [`PmsmObserver::step_dt`] accepts, in sample times `Ts`.
pub const MAX_PERIOD_FACTOR: f64 = 64.0;

use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use crate::ekf::{Correction, EkfError, finite};
use crate::structured;
use crate::structured::{Outcome, Sym4};
use crate::{ConfigError, Float, to_t, wrap_angle};
use model::Discrete;
pub(crate) use safeguards::ConsistencyState;
use safeguards::{
    BranchState, Events, GateState, HealthState, Verdict, gate_accepted_high, gate_verdict,
};
use tracking::{Tracker, TrackerSlow, TrackerStep};

/// Whether the angle estimate can be trusted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// The angle's standard deviation is below the configured limit and, with the
    /// consistency check on, the innovations are consistent and the speed is known to be away
    /// from zero (module docs, "Consistency").
    Tracking,
    /// The angle's standard deviation exceeds the limit (the filter has not converged yet, or
    /// the back-EMF is too small to observe the angle near standstill), or the innovations
    /// are far out of line with the noise seen before (the model no longer explains the
    /// currents: a lost or re-converging filter).
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
    /// Tracked permanent-magnet flux linkage, Wb (the configured value when tracking is off).
    pub psi_f_wb: T,
    /// Standard deviation of the tracked flux linkage, Wb (0 when tracking is off; refreshed
    /// every 64 samples).
    pub psi_f_sigma_wb: T,
    /// Tracked stator resistance, ohm (the configured value when tracking is off).
    pub rs_ohm: T,
    /// Standard deviation of the tracked resistance, ohm (0 when it is not tracked; refreshed
    /// every 64 samples).
    pub rs_sigma_ohm: T,
    /// Winding temperature derived from the tracked resistance, deg C:
    /// `T_ref + (Rs_hat / Rs_ref - 1) / alpha_cu` (the reference temperature when tracking is
    /// off).
    pub winding_temperature_c: T,
    /// The parameters were tracked in this step (else frozen: low speed, angle uncertain, or
    /// tracking off).
    pub parameters_tracking: bool,
    /// The consistency check finds the recent innovations out of line (the status is then
    /// [`Status::Uncertain`]); `false` with the check off.
    pub inconsistent: bool,
    /// The angle's standard deviation is below the configured limit (the covariance's part of
    /// the status, whatever the innovations say).
    pub angle_tracked: bool,
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
    /// Configured `(psi_f, Rs, reference temperature)`, reported when tracking is off.
    nominal: (T, T, T),
    angle_var_limit: T,
    /// Salient motors: the filter has locked (angle tracked with settled innovations) and
    /// keeps the angle tracked since; the d-axis transient correction applies (module docs).
    locked: bool,
    branch: Option<BranchState<T>>,
    gate: Option<GateState<T>>,
    health: Option<HealthState<T>>,
    consistency: Option<ConsistencyState<T>>,
    /// Steps left in which a fused angle ([`Self::correct_angle`]) makes the angle observable
    /// at any speed.
    fused: u32,
    tracker: Option<Tracker<T>>,
    /// The tracking's constants and split filter (present with `tracker`).
    slow: Option<TrackerSlow<T>>,
    /// The step's constants at a tracked `Rs` (`model.discrete_at(_, rs)`) and that `Rs`:
    /// `Rs` changes only once per window of the split filter, so a step whose `Rs` is this one
    /// recomputes only the flux's term (refreshed by [`Self::refresh_rs_constants`]).
    rs_constants: (T, Discrete<T>),
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
        let (tracker, slow) = match cfg.parameter_tracking {
            Some(t) => {
                let (tracker, slow) = Tracker::new(&t, cfg.motor.psi_f_wb, cfg.motor.rs_ohm, ts);
                (Some(tracker), Some(slow))
            }
            None => (None, None),
        };
        let model = PmsmModel::new(cfg);
        let rs_constants = (
            cfg.motor.rs_ohm,
            model.discrete_at(cfg.motor.psi_f_wb, cfg.motor.rs_ohm),
        );
        Ok(Self {
            model,
            rs_constants,
            x: x0,
            p: p0,
            last: zero_correction(),
            inv_pole_pairs: T::one() / to_t(f64::from(cfg.motor.pole_pairs)),
            nominal: (
                cfg.motor.psi_f_wb,
                cfg.motor.rs_ohm,
                cfg.parameter_tracking
                    .map_or(to_t(20.0), |t| t.reference_temperature_c),
            ),
            angle_var_limit: cfg.angle_sigma_limit_rad * cfg.angle_sigma_limit_rad,
            locked: false,
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
                inconsistent: 0,
            }),
            health: cfg.covariance_health.map(|h| HealthState {
                refusals: 0,
                trace_bound: h.trace_factor * p0.trace(),
                current_bound: h.current_factor * cfg.motor.characteristic_current_a(),
                speed_bound: h.max_w_ts_rad / cfg.ts_s,
                p0,
                divergence_nis: h.divergence_nis,
                divergence_samples: h.divergence_samples,
            }),
            consistency: cfg.consistency.as_ref().map(ConsistencyState::new),
            fused: 0,
            tracker,
            slow,
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
    ///
    /// On an x86-64 host (`std`) with AVX2 and FMA it runs the same code compiled for those
    /// extensions (three-operand instructions: a fifth fewer of them), chosen once at run
    /// time; the results are bit for bit the portable build's (no contraction of multiplies
    /// and adds into FMAs; tested).
    // Elsewhere `step` is the portable body itself, kept out of line as before the host
    // dispatch was added (the body is large; inlined into its callers it cost the Cortex-M4F
    // tick 17 instructions and 50 kB of flash).
    #[cfg_attr(not(all(feature = "std", target_arch = "x86_64")), inline(never))]
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if host::has_avx2_fma() {
            return host::step_avx2_fma(self, u_prev, i);
        }
        self.step_portable(u_prev, i)
    }

    /// [`step`](Self::step) over a period of `dt_s` seconds that ended at this sample (an
    /// irregular period: a skipped or late control cycle, or a log's time stamps). When
    /// `dt_s` equals the configured `Ts` this is `step` itself, bit for bit and at its cost;
    /// otherwise the prediction uses the model for that period
    /// ([`PmsmModel::with_period`]: the current decay, input gain and EMF gain over `dt_s`, the
    /// angle advanced by `w dt_s`, `Q` scaled by `dt_s / Ts`), and the correction and the
    /// safeguards are those of `step`.
    ///
    /// Refused with [`EkfError::InvalidPeriod`], state kept, when `dt_s` is not finite, not
    /// above zero, or longer than [`MAX_PERIOD_FACTOR`] sample times (a gap that long is a
    /// lost record: restart the observer).
    pub fn step_dt(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Result<Estimate<T>, EkfError> {
        let ts = self.model.ts();
        if dt_s == ts {
            return self.step(u_prev, i);
        }
        if !(dt_s > T::zero() && dt_s <= ts * to_t(MAX_PERIOD_FACTOR)) {
            return Err(EkfError::InvalidPeriod);
        }
        let model = self.model;
        let cached = self.rs_constants;
        self.model = model.with_period(dt_s);
        // The cached constants at the tracked `Rs` are for `Ts`: recompute them for `dt_s`.
        self.rs_constants = (cached.0, self.model.discrete_at(self.nominal.0, cached.0));
        let out = self.step_portable(u_prev, i);
        self.model = model;
        self.rs_constants = cached;
        out
    }

    /// [`step`](Self::step) in the portable build (the code every target runs).
    #[doc(hidden)]
    #[inline(always)]
    pub fn step_portable(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
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
        // Four monomorphic paths: the one without tracking carries none of its code, the
        // surface ones none of the salient model's.
        match (self.tracker.is_some(), self.model.discrete().salient) {
            (true, false) => {
                let (xm, pm, tm) = self.prior::<true, false>(u_prev);
                self.correct_prior::<true, false>(xm, pm, tm, i)
            }
            (false, false) => {
                let (xm, pm, _) = self.prior::<false, false>(u_prev);
                self.correct_prior::<false, false>(xm, pm, None, i)
            }
            (true, true) => {
                let (xm, pm, tm) = self.prior::<true, true>(u_prev);
                self.correct_prior::<true, true>(xm, pm, tm, i)
            }
            (false, true) => {
                let (xm, pm, _) = self.prior::<false, true>(u_prev);
                self.correct_prior::<false, true>(xm, pm, None, i)
            }
        }
    }

    /// The prediction `(x-, P-)` and, with tracking (`TRACK`, the tracker present), the prior
    /// of the tracked parameters (nothing is stored here). `S`: the motor is salient.
    #[inline(always)]
    fn prior<const TRACK: bool, const S: bool>(
        &self,
        u_prev: [T; 2],
    ) -> (Vector4<T>, Sym4<T>, Option<TrackerStep<T>>) {
        let q = self.model.q_sym();
        match (&self.tracker, &self.slow) {
            (Some(tr), Some(slow)) if TRACK => {
                let k = &slow.k;
                let tracked = self.p.p33 <= self.angle_var_limit;
                let trusted = self.locked;
                let active = tr.should_track(k, tracked, self.x[2], self.p.p22);
                let disc = if tr.rs == self.rs_constants.0 {
                    self.model.discrete_with_flux(&self.rs_constants.1, tr.psi)
                } else {
                    self.model.discrete_at(tr.psi, tr.rs)
                };
                let (xm, mut pm, t) =
                    structured::predict::<T, S>(&disc, q, &self.x, &self.p, u_prev, trusted);
                let tm = tr.predict::<S>(k, &disc, &t, &self.x, &mut pm, active);
                (xm, pm, Some(tm))
            }
            _ => {
                let trusted = self.locked;
                let (xm, pm, _) = structured::predict::<T, S>(
                    self.model.discrete(),
                    q,
                    &self.x,
                    &self.p,
                    u_prev,
                    trusted,
                );
                (xm, pm, None)
            }
        }
    }

    /// Salient motors: updates the lock (module docs) after a committed correction. Locked
    /// when the angle is tracked and the innovations are consistent (the gate's running mean of
    /// the NIS at or below its settled level; always, without a gate); stays locked while the
    /// angle stays tracked.
    #[inline(always)]
    fn update_lock(&mut self) {
        let tracked = self.p.p33 <= self.angle_var_limit;
        let settled = self
            .gate
            .as_ref()
            .is_none_or(|g| g.nis_mean <= g.settled_nis);
        self.locked = tracked && (self.locked || settled);
    }

    /// Prediction only (e.g. to coast over a missing current sample), with the voltage held
    /// over the period just ended. Refused, state kept, for a non-finite input or result. The
    /// covariance health check (when on) runs after it; on a reset the currents are kept.
    pub fn predict(&mut self, u_prev: [T; 2]) -> Result<(), EkfError> {
        if !finite(&u_prev) {
            return Err(EkfError::NonFiniteInput);
        }
        let (x, p, tm) = match (self.tracker.is_some(), self.model.discrete().salient) {
            (true, false) => self.prior::<true, false>(u_prev),
            (false, false) => self.prior::<false, false>(u_prev),
            (true, true) => self.prior::<true, true>(u_prev),
            (false, true) => self.prior::<false, true>(u_prev),
        };
        let tracker_finite = match (&tm, &self.tracker) {
            (Some(s), Some(t)) => t.finite_with(s, t.psi),
            _ => true,
        };
        if !(finite(x.as_slice()) && p.all_finite() && tracker_finite) {
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
        if let (Some(s), Some(t)) = (&tm, &mut self.tracker) {
            t.commit(s, t.psi);
            self.tracker_housekeeping();
        }
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
        match (self.tracker.is_some(), self.model.discrete().salient) {
            (true, false) => {
                let tm = self.tracker.map(|t| t.as_step());
                self.correct_prior::<true, false>(self.x, self.p, tm, i)
            }
            (false, false) => self.correct_prior::<false, false>(self.x, self.p, None, i),
            (true, true) => {
                let tm = self.tracker.map(|t| t.as_step());
                self.correct_prior::<true, true>(self.x, self.p, tm, i)
            }
            (false, true) => self.correct_prior::<false, true>(self.x, self.p, None, i),
        }
    }

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
        let active = self.tracker.as_ref().is_some_and(|t| t.s.active);
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
    fn correct_angle_flux(&mut self, y: T, k: [T; 4], inv_s: T, rs: T) -> bool {
        let (Some(t), Some(slow)) = (&mut self.tracker, &self.slow) else {
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
        let floor = T::default_epsilon() * kx.var0_psi;
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

    /// Correction of the prior `(xm, pm)` with the currents `i`, innovation gate, branch check
    /// and covariance health (module docs).
    #[inline(always)]
    fn correct_prior<const TRACK: bool, const S: bool>(
        &mut self,
        xm: Vector4<T>,
        pm: Sym4<T>,
        tm: Option<TrackerStep<T>>,
        i: [T; 2],
    ) -> Result<Estimate<T>, EkfError> {
        // Common path first: every test below is one comparison on good data; the rare
        // branches (rejection, reopening, flip, reset) are out-of-line functions.
        let tracking = pm.p33 <= self.angle_var_limit;
        // The gate decides from the NIS before the update is computed; its bookkeeping is
        // applied only once the step has succeeded (a refused step changes nothing).
        let mut verdict = Verdict::Low;
        let gate = &self.gate;
        let outcome = structured::correct_unchecked(&self.model, &xm, &pm, i, |nis| match gate {
            Some(g) if nis > g.threshold => {
                verdict = gate_verdict(g, tracking);
                verdict == Verdict::Reject
            }
            _ => false,
        });
        let (post, tn) = match outcome {
            Ok(Outcome::Updated(post)) => match (&tm, &self.tracker, &self.slow) {
                (Some(s), Some(t), Some(slow)) if TRACK => {
                    let (step, psi, sum) = t.correct(&slow.k, s, &post);
                    // Both sums finite in one test (`v - v` is 0 for a finite `v`, NaN
                    // otherwise): the state's results and the tracker's.
                    #[allow(clippy::eq_op)]
                    let finite = (post.sum - post.sum) + (sum - sum) == T::zero();
                    if !finite {
                        return self.refused(EkfError::NonFiniteResult, i);
                    }
                    (post, Some((step, psi)))
                }
                _ => {
                    if !post.sum.is_finite() {
                        return self.refused(EkfError::NonFiniteResult, i);
                    }
                    (post, None)
                }
            },
            Ok(Outcome::Skipped(c)) => {
                // Rejected by the gate: the step is the prediction only.
                self.x = xm;
                self.p = pm;
                if TRACK && let (Some(s), Some(t)) = (&tm, &mut self.tracker) {
                    t.commit(s, t.psi);
                    self.tracker_housekeeping();
                }
                if let Some(w) = &mut self.consistency {
                    w.watch(c.nis);
                }
                self.last = c;
                self.gate_rejected();
                if self.unhealthy(&self.x, &self.p) {
                    self.self_reset(Some(i));
                }
                return Ok(self.estimate());
            }
            Err(e) => return self.refused(e, i),
        };
        let (x, c, dth) = (post.x, post.correction, post.dth);
        if let Some(h) = &mut self.health {
            h.refusals = 0;
        }
        self.x = x;
        self.p = post.p;
        if TRACK && let (Some((s, psi)), Some(t)) = (&tn, &mut self.tracker) {
            t.commit(s, *psi);
            self.tracker_housekeeping();
        }
        if let Some(w) = &mut self.consistency {
            w.watch(c.nis);
            if self.fused != 0 {
                self.fused -= 1;
            }
        }
        self.last = c;
        self.events = Events::default();
        if let Some(g) = &mut self.gate {
            if verdict == Verdict::Low {
                g.consecutive = 0;
                g.open = false;
                g.inconsistent = 0;
                g.nis_mean += (c.nis - g.nis_mean) * to_t::<T>(1.0 / 16.0);
            } else {
                gate_accepted_high(g, &mut self.counters, verdict);
            }
        }
        if S {
            self.update_lock();
        }
        let diverged = verdict != Verdict::Low && self.diverging(c.nis, tracking);
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
        if diverged || self.unhealthy(&self.x, &self.p) {
            self.self_reset(Some(i));
        }
        Ok(self.estimate())
    }

    /// The divergence check (covariance health) for an accepted sample above the gate's
    /// threshold: counts tracked steps in a row with `NIS > divergence_nis`; `true` at
    /// `divergence_samples`. Out of line: the rare path.
    #[cold]
    #[inline(never)]
    fn diverging(&mut self, nis: T, tracking: bool) -> bool {
        let (Some(h), Some(g)) = (&self.health, &mut self.gate) else {
            return false;
        };
        if tracking && nis > h.divergence_nis {
            g.inconsistent = g.inconsistent.saturating_add(1);
            h.divergence_samples != 0 && g.inconsistent >= h.divergence_samples
        } else {
            g.inconsistent = 0;
            false
        }
    }

    /// The tracking's slow work after a committed step, when due (a full window of the split
    /// filter, the reported deviations).
    #[inline(always)]
    fn tracker_housekeeping(&mut self) {
        if let (Some(t), Some(slow)) = (&mut self.tracker, &mut self.slow)
            && t.housekeeping_due(&slow.k)
        {
            t.housekeeping(slow);
            self.refresh_rs_constants();
        }
    }

    /// Recomputes the step's constants for the tracked `Rs` when it has changed (after the
    /// split filter's window, `set_parameters`, a restart). Only a cache: a step whose `Rs`
    /// differs from the cached one computes its constants itself.
    #[cold]
    #[inline(never)]
    fn refresh_rs_constants(&mut self) {
        if let Some(t) = &self.tracker
            && t.rs != self.rs_constants.0
        {
            // At the configured flux, so that the cache is a function of `Rs` alone (its `c`
            // is replaced each step).
            self.rs_constants = (t.rs, self.model.discrete_at(self.nominal.0, t.rs));
        }
    }

    /// A step refused for `e` (singular `S`, non-finite result): the state is kept and the
    /// error returned, unless the health check resets the filter (then its estimate).
    #[cold]
    #[inline(never)]
    fn refused(&mut self, e: EkfError, i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        if self.refused_resets() {
            self.events = Events::default();
            self.self_reset(Some(i));
            return Ok(self.estimate());
        }
        Err(e)
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
        self.locked = false;
        self.x[2] = -self.x[2];
        self.x[3] = wrap_angle(self.x[3] + T::pi());
        self.p = self.p.flip_speed();
        self.p.p33 += b.flip_var;
        if let Some(t) = &mut self.tracker {
            t.flip_speed();
        }
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
        if let (Some(t), Some(slow)) = (&mut self.tracker, &mut self.slow) {
            t.restart(slow, true);
        }
        self.restart_safeguards();
        self.refresh_rs_constants();
        self.events.reset = true;
        self.counters.covariance_resets = self.counters.covariance_resets.saturating_add(1);
    }

    /// Clears the gate's and the branch check's running state.
    fn restart_safeguards(&mut self) {
        self.locked = false;
        if let Some(w) = &mut self.consistency {
            w.restart();
        }
        if let Some(g) = &mut self.gate {
            g.inconsistent = 0;
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
        let angle_tracked = self.p.p33 <= self.angle_var_limit;
        // With the consistency check: the innovations consistent, and the back-EMF known to be
        // there (the speed away from zero by three standard deviations, or an angle fused
        // recently).
        let (inconsistent, observable) = match &self.consistency {
            Some(w) => (
                w.inconsistent,
                self.fused > 0 || x[2] * x[2] >= to_t::<T>(9.0) * self.p.p22,
            ),
            None => (false, true),
        };
        let status = if !angle_tracked || inconsistent || !observable {
            Status::Uncertain
        } else {
            Status::Tracking
        };
        let (psi_f_wb, psi_f_sigma_wb, rs_ohm, rs_sigma_ohm, winding_temperature_c, tracking) =
            match (&self.tracker, &self.slow) {
                (Some(t), Some(slow)) => (
                    t.psi,
                    t.psi_sigma,
                    t.rs,
                    t.rs_sigma,
                    t.winding_temperature_c(&slow.k),
                    t.s.active,
                ),
                _ => (
                    self.nominal.0,
                    T::zero(),
                    self.nominal.1,
                    T::zero(),
                    self.nominal.2,
                    false,
                ),
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
            psi_f_wb,
            psi_f_sigma_wb,
            rs_ohm,
            rs_sigma_ohm,
            winding_temperature_c,
            parameters_tracking: tracking,
            inconsistent,
            angle_tracked,
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
        if let (Some(t), Some(slow)) = (&mut self.tracker, &mut self.slow) {
            t.restart(slow, false);
        }
        self.restart_safeguards();
        self.refresh_rs_constants();
        Ok(())
    }

    /// The flux's rows of the augmented covariance: its cross-covariance with
    /// `[i_a, i_b, w_e, theta]` and its variance (`None` when tracking is off). The cross-
    /// covariance is zero while the tracking is frozen.
    pub fn flux_covariance(&self) -> Option<(Vector4<T>, T)> {
        self.tracker
            .as_ref()
            .map(|t| (Vector4::from(t.s.x), t.s.c_pp))
    }

    /// Tracked `(psi_f, Rs)` (Wb, ohm); the configured values when tracking is off.
    pub fn parameters(&self) -> (T, T) {
        match &self.tracker {
            Some(t) => (t.psi, t.rs),
            None => (self.nominal.0, self.nominal.1),
        }
    }

    /// Sets the tracked `(psi_f, Rs)` (e.g. from a previous run or a commissioning) and
    /// clears their cross-covariance with the state; their variances are kept. The thermal
    /// link of the `Rs` split filter takes them as its temperature reference. Refused,
    /// nothing changed, when tracking is off, a value is not finite or outside the
    /// configured range.
    pub fn set_parameters(&mut self, psi_f_wb: T, rs_ohm: T) -> Result<(), EkfError> {
        let (Some(t), Some(slow)) = (&mut self.tracker, &mut self.slow) else {
            return Err(EkfError::NonFiniteInput);
        };
        let k = slow.k;
        if !(psi_f_wb >= k.psi_min
            && psi_f_wb <= k.psi_max
            && rs_ohm >= k.rs_min
            && rs_ohm <= k.rs_max)
        {
            return Err(EkfError::NonFiniteInput);
        }
        t.psi = psi_f_wb;
        t.rs = rs_ohm;
        t.restart(slow, false);
        if let Some(s) = &mut slow.split {
            s.anchor(psi_f_wb, rs_ohm, t.s.c_pp, &k);
        }
        self.refresh_rs_constants();
        Ok(())
    }
}
