//! The safeguards of the observer (module docs of [`observer`](crate::observer)): their
//! configuration ([`BranchCheck`], [`InnovationGate`], [`CovarianceHealth`]) and running state.

use super::ObserverCounters;
use super::structured::Sym4;
use crate::motor::positive;
use crate::{ConfigError, Float, Param, to_t};

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
    /// Divergence: a step's `NIS` above `divergence_nis` ...
    pub divergence_nis: T,
    /// ... in every one of this many steps in a row while the angle is tracked means the
    /// filter has settled on a state its model cannot explain (its covariance says it knows
    /// the angle, its innovations say otherwise); it resets itself. 0: off. Needs the
    /// innovation gate (which watches the innovations); without it the check is off.
    pub divergence_samples: u32,
}

impl<T: Float> Default for CovarianceHealth<T> {
    /// `trace_factor = 100`, `current_factor = 100`, `max_w_ts_rad = pi`,
    /// `divergence_nis = 1000` (a chi-square(2) tail of `e^-500`), `divergence_samples = 200`.
    fn default() -> Self {
        Self {
            trace_factor: to_t(100.0),
            current_factor: to_t(100.0),
            max_w_ts_rad: T::pi(),
            divergence_nis: to_t(1000.0),
            divergence_samples: 200,
        }
    }
}

/// Innovation consistency (module docs, "Consistency"): the angle is trusted only while the
/// innovations are consistent with the noise the filter has seen. The covariance alone
/// cannot tell: it reflects the model's noise, not a model error, and stays small while the
/// filter sits on a wrong solution.
///
/// ```text
/// n_k  = NIS_k
/// f_k  = f_k-1 + (n_k - f_k-1) / fast_samples                       fast mean (about 2-4 ms)
/// b    = b + (mean of min(n_k, 4 b) over 8 samples - b) 8 / slow_samples
///        once per 8 samples, b in [2, max_baseline]                  baseline, clamped
/// d_k  = d_k-1 + (K_th y_k - d_k-1) / drift_samples                mean angle correction
/// inconsistent when f_k > ratio b_k or n_k > single_ratio b_k (one sample far out: the onset
/// of a loss), or |d_k| > drift_ratio |w Ts| + drift_sigmas sqrt(P_ww) Ts (speed drift), or
/// at a block's end the model's flux is implausible (module docs, "Model fit");
/// trusted again after hold_samples steps in a row with f_k <= ratio b_k / 2 and |d_k| at or
/// below half its limit
/// ```
///
/// For a consistent filter `NIS` is chi-square with 2 degrees of freedom (mean 2); a
/// recorded drive's innovations also carry noise and model error the configured `R` does not
/// describe, which the baseline learns (a real record's median `NIS` with the default `R` is
/// 10-100). A filter that has lost the rotor (the model cannot explain the currents) shows a
/// fast mean 100-10^4 times that level. The baseline's clamp at `4 b` keeps such an episode
/// from teaching it: over 20 ms at 4.5 kHz it rises by at most 30 %. Its ceiling
/// `max_baseline` bounds how much unexplained variance is ever accepted as noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConsistencyCheck<T> {
    /// Samples of the fast mean's time constant.
    pub fast_samples: T,
    /// Samples of the baseline's time constant.
    pub slow_samples: T,
    /// The fast mean above `ratio` times the baseline is inconsistent.
    pub ratio: T,
    /// One sample above `single_ratio` times the baseline is inconsistent (the onset of a
    /// loss, before the fast mean has grown).
    pub single_ratio: T,
    /// Steps in a row with the fast mean at or below half the limit before the angle is
    /// trusted again.
    pub hold_samples: u32,
    /// Ceiling of the baseline.
    pub max_baseline: T,
    /// Speed drift: the angle's mean correction per step above `drift_ratio |w| Ts +
    /// drift_sigmas sqrt(P_ww) Ts` is inconsistent (the angle moves at another speed than the
    /// filter's speed state).
    pub drift_ratio: T,
    /// See [`drift_ratio`](Self::drift_ratio).
    pub drift_sigmas: T,
    /// Samples of the mean angle correction's time constant.
    pub drift_samples: T,
}

impl<T: Float> ConsistencyCheck<T> {
    /// Checks every field: the sample counts at least 1, the ratios and the ceiling finite
    /// and above zero.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !self.fast_samples.is_finite() || self.fast_samples < T::one() {
            return Err(ConfigError::NotPositive(Param::ConsistencyFastSamples));
        }
        if !self.slow_samples.is_finite() || self.slow_samples < T::one() {
            return Err(ConfigError::NotPositive(Param::ConsistencySlowSamples));
        }
        positive(self.ratio, Param::ConsistencyRatio)?;
        positive(self.single_ratio, Param::ConsistencyRatio)?;
        positive(self.drift_ratio, Param::ConsistencyRatio)?;
        positive(self.drift_sigmas, Param::ConsistencyRatio)?;
        if !self.drift_samples.is_finite() || self.drift_samples < T::one() {
            return Err(ConfigError::NotPositive(Param::ConsistencyFastSamples));
        }
        positive(self.max_baseline, Param::ConsistencyMaxBaseline)
    }

    /// `fast_samples = 4`, `slow_samples = 1024`, `ratio = 8`, `single_ratio = 10`,
    /// `hold_samples = 32`, `max_baseline = 400`, `drift_ratio = 0.25`, `drift_sigmas = 3`,
    /// `drift_samples = 32`.
    ///
    /// For a consistent filter (baseline 2), one sample exceeds `single_ratio b = 20` with a
    /// probability of `e^-10 = 4.5e-5` (at 10 kHz about once in 2 s, then 32 samples
    /// uncertain: 0.15 % of the time), and the fast mean (about a chi-square with 8 degrees of
    /// freedom over 4) exceeds 16 far less often. On real records the single-sample rule
    /// catches the first samples of a loss (48-49 deg off, innovations 13-19 times the
    /// baseline) that the fast mean reaches a few samples later.
    pub fn default_for(_ts_s: T) -> Self {
        Self {
            fast_samples: to_t(4.0),
            slow_samples: to_t(1024.0),
            ratio: to_t(8.0),
            single_ratio: to_t(10.0),
            hold_samples: 32,
            max_baseline: to_t(400.0),
            drift_ratio: to_t(0.25),
            drift_sigmas: to_t(3.0),
            drift_samples: to_t(32.0),
        }
    }
}

/// Consistency check state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ConsistencyState<T> {
    pub(crate) k_fast: T,
    /// `BASELINE_BLOCK / slow_samples`: the baseline's gain per block.
    pub(crate) k_block: T,
    pub(crate) ratio: T,
    pub(crate) single_ratio: T,
    pub(crate) hold_samples: u32,
    pub(crate) max_baseline: T,
    pub(crate) fast: T,
    pub(crate) baseline: T,
    /// `2 / baseline` (refreshed with it): the speed noise adaptation's scale.
    pub(crate) two_over_baseline: T,
    /// Limits from the baseline (refreshed with it): `ratio b`, `ratio b / 2`,
    /// `single_ratio b`, `4 b`.
    pub(crate) limit: T,
    pub(crate) half_limit: T,
    pub(crate) single: T,
    pub(crate) clamp: T,
    /// The block's sum of clamped NIS and its count.
    pub(crate) block_sum: T,
    pub(crate) block_n: u32,
    /// Steps in a row below half the limit while inconsistent.
    pub(crate) calm: u32,
    pub(crate) inconsistent: bool,
    /// Speed drift: the mean angle correction per step, the angle at the block's start
    /// (known once primed), the mean's gain per block, the limit's factors.
    pub(crate) drift: T,
    pub(crate) block_theta: T,
    pub(crate) drift_primed: bool,
    pub(crate) k_drift: T,
    pub(crate) drift_ratio: T,
    pub(crate) drift_sigmas: T,
    /// The mean angle correction is above its limit / at or below half of it.
    pub(crate) drifting: bool,
    pub(crate) drift_calm: bool,
    /// `9 sigma_Rs^2 Ts^2 / psi_f^2` from the parameter tracking (0 without; refreshed with
    /// its deviations): the back-EMF is observable at a block's end when `(w Ts)^2` is above
    /// it times `|i|^2` and above `9 P_ww Ts^2` (module docs, "Consistency").
    pub(crate) emf_floor: T,
    /// `9 sigma_v^2 Ts^2 / psi_f^2` with `sigma_v` the told inverter voltage's uncertainty
    /// (half of it; 0 untold): added to the floor above (module docs, "Consistency").
    pub(crate) emf_floor_v: T,
    /// Blocks in a row, up to [`OBSERVED_BLOCKS`], whose ends found the back-EMF observable;
    /// `observed`: at least that many (the status may read `Tracking`).
    pub(crate) observed_blocks: u32,
    pub(crate) observed: bool,
    /// The last block's end found the model's flux implausible (module docs, "Model fit"):
    /// inconsistent, like a speed drift, until a block's end finds it plausible again and the
    /// hold has passed.
    pub(crate) implausible: bool,
    /// The model fit tests the active flux of the constant-parameter model (off for the
    /// observer on a flux map; kept through restarts).
    pub(crate) active_flux: bool,
}

/// The baseline is updated once per block of this many samples, from their clamped mean (it
/// moves over about a thousand samples: the block changes nothing of it but the cost).
const BASELINE_BLOCK: u32 = 8;

/// Blocks in a row with the back-EMF observable before the status may read `Tracking`: 64
/// samples, twice the speed drift's time constant, in which a filter that has started (or come
/// out of a zero crossing) on the `theta + pi` branch shows it in its mean angle correction.
pub(crate) const OBSERVED_BLOCKS: u32 = 8;

impl<T: Float> ConsistencyState<T> {
    pub(crate) fn new(c: &ConsistencyCheck<T>) -> Self {
        let two: T = to_t(2.0);
        let mut s = Self {
            k_fast: T::one() / c.fast_samples,
            k_block: to_t::<T>(f64::from(BASELINE_BLOCK)) / c.slow_samples,
            ratio: c.ratio,
            single_ratio: c.single_ratio,
            hold_samples: c.hold_samples,
            max_baseline: c.max_baseline,
            fast: two,
            baseline: two,
            two_over_baseline: T::one(),
            limit: T::zero(),
            half_limit: T::zero(),
            single: T::zero(),
            clamp: T::zero(),
            block_sum: T::zero(),
            block_n: 0,
            calm: 0,
            inconsistent: true,
            drift: T::zero(),
            block_theta: T::zero(),
            drift_primed: false,
            k_drift: {
                let k = to_t::<T>(f64::from(BASELINE_BLOCK)) / c.drift_samples;
                if k > T::one() { T::one() } else { k }
            },
            drift_ratio: c.drift_ratio,
            drift_sigmas: c.drift_sigmas,
            drifting: false,
            drift_calm: true,
            emf_floor: T::zero(),
            emf_floor_v: T::zero(),
            observed_blocks: 0,
            observed: false,
            implausible: false,
            active_flux: true,
        };
        if s.k_block > T::one() {
            s.k_block = T::one();
        }
        s.refresh();
        s
    }

    /// The limits from the baseline, overridden by the speed drift and the model fit:
    /// drifting or implausible, the fast mean's limit is -1 (always exceeded); not calm or
    /// implausible, its half limit is -1 (never calm). The step's test then needs no term of
    /// its own.
    pub(crate) fn refresh(&mut self) {
        self.limit = if self.drifting || self.implausible {
            -T::one()
        } else {
            self.ratio * self.baseline
        };
        self.half_limit = if self.drift_calm && !self.implausible {
            self.ratio * self.baseline * to_t(0.5)
        } else {
            -T::one()
        };
        self.single = self.single_ratio * self.baseline;
        self.clamp = self.baseline * to_t(4.0);
        self.two_over_baseline = to_t::<T>(2.0) / self.baseline;
    }

    /// Restarts after a reset: untrusted until the hold has passed; the baseline is kept.
    pub(crate) fn restart(&mut self) {
        self.fast = self.baseline;
        self.calm = 0;
        self.inconsistent = true;
        self.drift = T::zero();
        self.drift_primed = false;
        self.drifting = false;
        self.drift_calm = true;
        self.observed_blocks = 0;
        self.observed = false;
        self.implausible = false;
        self.refresh();
    }

    /// The speed drift's update at the end of a block (module docs, "Consistency"), with the
    /// angle estimate `theta` (rad), the speed estimate times the period `w_ts` (rad) and the
    /// speed's variance times the period squared `var_w_ts2` (rad^2). The block's mean angle
    /// correction is the angle's advance over the block less `BASELINE_BLOCK w Ts` (the speed
    /// changes little over eight samples), divided by `BASELINE_BLOCK`; it enters the mean
    /// `drift` (gain `BASELINE_BLOCK / drift_samples`), compared with its limit. `implausible`:
    /// the model fit's verdict at the block's end (module docs, "Model fit"). Out of line:
    /// once in eight samples, when [`watch`](Self::watch) has just closed a block.
    #[cold]
    #[inline(never)]
    pub(crate) fn update_drift(
        &mut self,
        theta: T,
        w_ts: T,
        var_w_ts2: T,
        i: (T, T),
        implausible: bool,
    ) {
        if implausible != self.implausible {
            self.implausible = implausible;
            self.refresh();
        }
        let w2 = w_ts * w_ts;
        let observable = w2 >= to_t::<T>(25.0) * var_w_ts2
            && w2 >= self.emf_floor * (i.0 * i.0 + i.1 * i.1) + self.emf_floor_v;
        self.observed_blocks = if observable {
            (self.observed_blocks + 1).min(OBSERVED_BLOCKS)
        } else {
            0
        };
        self.observed = self.observed_blocks >= OBSERVED_BLOCKS;
        let n: T = to_t(f64::from(BASELINE_BLOCK));
        let start = self.block_theta;
        self.block_theta = theta;
        if !self.drift_primed {
            self.drift_primed = true;
            return;
        }
        // The deviation from the advance the speed predicts is wrapped, not the advance: over a
        // block the angle advances by up to `8 |w Ts|`, beyond pi when `|w Ts| > pi / 8`.
        let mean = crate::wrap_angle(theta - start - n * w_ts) / n;
        self.drift += (mean - self.drift) * self.k_drift;
        // |drift| - ratio |w Ts| against sigmas sqrt(var): compared in squares (no sqrt).
        let a = self.drift.abs();
        let r = self.drift_ratio * w_ts.abs();
        let s2 = self.drift_sigmas * self.drift_sigmas * var_w_ts2;
        let excess = a - r;
        self.drifting = excess > T::zero() && excess * excess > s2;
        // Half the limit: |drift| <= (ratio |w Ts| + sigmas sd) / 2.
        let half = a * to_t(2.0) - r;
        self.drift_calm = half <= T::zero() || half * half <= s2;
        self.refresh();
    }

    /// The baseline's update from a full block (out of line: once in eight samples).
    #[cold]
    #[inline(never)]
    fn update_baseline(&mut self) {
        let mean = self.block_sum / to_t(f64::from(BASELINE_BLOCK));
        let b = self.baseline + (mean - self.baseline) * self.k_block;
        let two: T = to_t(2.0);
        self.baseline = if b < two {
            two
        } else if b > self.max_baseline {
            self.max_baseline
        } else {
            b
        };
        self.block_sum = T::zero();
        self.block_n = 0;
        self.refresh();
    }

    /// One step's NIS (finite: a step with a non-finite result is refused before). `true` when
    /// it closed a block (the caller then updates the speed drift).
    #[inline(always)]
    pub(crate) fn watch(&mut self, nis: T) -> bool {
        self.fast += (nis - self.fast) * self.k_fast;
        self.block_sum += if nis < self.clamp { nis } else { self.clamp };
        self.block_n += 1;
        let closed = self.block_n == BASELINE_BLOCK;
        if closed {
            self.update_baseline();
        }
        if self.fast > self.limit || nis > self.single {
            self.inconsistent = true;
            self.calm = 0;
        } else if self.inconsistent {
            if self.fast <= self.half_limit {
                self.calm += 1;
                if self.calm >= self.hold_samples {
                    self.inconsistent = false;
                }
            } else {
                self.calm = 0;
            }
        }
        closed
    }
}

/// What happened in the last step (copied into [`Estimate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Events {
    pub(super) rejected: bool,
    pub(super) flipped: bool,
    pub(super) reset: bool,
}

/// Branch check constants and state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct BranchState<T> {
    pub(super) threshold: T,
    /// `min_speed^2`.
    pub(super) min_speed2: T,
    /// `allowance Ts`.
    pub(super) k: T,
    /// `2 Ts`.
    pub(super) two_ts: T,
    /// `flip_angle_sigma_rad^2`.
    pub(super) flip_var: T,
    /// CUSUM of the missing motion weighted by `|w_hat|`, rad^2/s.
    pub(super) sum: T,
}

/// Innovation gate constants and state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct GateState<T> {
    pub(super) threshold: T,
    pub(super) max_consecutive: u32,
    pub(super) settled_nis: T,
    /// Running mean of the accepted samples' clamped NIS (starts at the threshold: unsettled).
    pub(super) nis_mean: T,
    /// Tracked steps in a row whose `NIS` exceeded the health check's `divergence_nis` (the
    /// divergence check, counted here because only samples above the gate's threshold can).
    pub(super) inconsistent: u32,
    pub(super) consecutive: u32,
    /// Open after `max_consecutive` rejections, until an accepted NIS is below the threshold.
    pub(super) open: bool,
}

/// Steps refused in a row (singular `S`, non-finite result) after which the covariance health
/// check resets the filter.
pub const MAX_REFUSALS: u32 = 3;

/// Covariance health constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct HealthState<T> {
    pub(super) trace_bound: T,
    /// Bound on `|i_a| + |i_b|`, A.
    pub(super) current_bound: T,
    /// Bound on `|w_e|`, rad/s.
    pub(super) speed_bound: T,
    pub(super) p0: Sym4<T>,
    pub(super) divergence_nis: T,
    pub(super) divergence_samples: u32,
}

/// The gate's decision on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Verdict {
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
pub(super) fn gate_verdict<T: Float>(g: &GateState<T>, tracking: bool) -> Verdict {
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
pub(super) fn gate_accepted_high<T: Float>(
    g: &mut GateState<T>,
    counters: &mut ObserverCounters,
    v: Verdict,
) {
    if v == Verdict::Reopen {
        g.open = true;
        counters.gate_reopened = counters.gate_reopened.saturating_add(1);
    }
    g.consecutive = 0;
    g.nis_mean += (g.threshold - g.nis_mean) * to_t::<T>(1.0 / 16.0);
}
