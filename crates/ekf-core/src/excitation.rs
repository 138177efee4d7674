//! `Rs` and `Ls` from a square-wave d-axis current excitation, independent of the angle error.
//!
//! # The method
//!
//! The drive adds a square wave of `+-a` to its closed-loop d-current reference, `N` samples
//! per half period (foc: `FocConfig::d_excitation`). In any frame that turns uniformly with
//! the rotor (the observer's estimated frame, off the rotor's by an unknown constant angle
//! `dth`), the voltage equation of a surface motor is, as complex numbers `d + j q`,
//!
//! ```text
//! u = Rs i + Ls di/dt + j w Ls i + j w psi_f e^{-j dth}
//! ```
//!
//! Over each half, after the current loop's transient (`M` samples skipped), `di/dt` is
//! zero on average, and the averages `U`, `I` of consecutive halves at the same speed
//! differ only by the excitation: the back-EMF term is the same in all and cancels. Each
//! half is compared with the mean of its two neighbours (three consecutive halves `A`, `B`,
//! `C`; `dU = (U_A + U_C) / 2 - U_B`, `dI` alike), so that a back-EMF that drifts linearly
//! over them (a speed ramp: `psi_f dw` is large against `w Ls dI`, 0.1 % of the speed moves
//! it by 2 % of the excitation's voltage on the 2.2 kW motor) cancels too:
//!
//! ```text
//! dU = (Rs + j w Ls) dI      =>      Rs = Re(dU / dI),   Ls = Im(dU / dI) / w
//! ```
//!
//! The frame offset multiplies `dU` and `dI` alike and drops out of the ratio: the estimate
//! does not depend on the angle error that a wrong `Ls` causes in the observer, so handing
//! it to the observer ([`PmsmObserver::set_inductances`](crate::PmsmObserver::set_inductances))
//! removes that error.
//!
//! **Held voltage, sampled current.** The drive holds each voltage over a period in the
//! stationary frame and samples the current at the period's end, and at high `w Ts` the
//! continuous relation above is off by terms of order `(w Ts)^2 w Ls`, which land on the
//! small `Rs` (a 50 % error at `w Ts = 0.25` on the small fast motor). The exact relation: with
//! `V_k` the voltage held over the period ending at sample `k` and both it and the current
//! turned into the frame at that sample's angle, the excitation's part obeys the motor's
//! `Rs`-`Ls` step, `dI_k = alpha dI_(k-1) + (1 - alpha) / Rs dV_k` (stationary frame,
//! `alpha = exp(-Rs Ts / Ls)`), and a `dI` constant in the turning frame gives
//!
//! ```text
//! z = dU / dI = Rs (1 - alpha e^(-j w Ts)) / (1 - alpha)
//!   =>  Rs = Re z - Im z tan(w Ts / 2),   Ls = Rs Ts / ln(1 + Rs sin(w Ts) / Im z)
//! ```
//!
//! (`Rs + j w Ls` as `Ts -> 0`; at `w = 0`, `Rs = Re z`.)
//!
//! Each half, with the two before it, gives one `dU / dI` (a "pair": the middle half against
//! the outer ones' mean). A pair is used when its three halves are whole (`N` samples of one
//! sign, no refused sample), the speed moved by at most
//! [`ExcitationConfig::max_speed_change`] per half over them, and `dI` is at least the
//! amplitude `a` and lies within [`ExcitationConfig::max_iq_change`] of the frame's d axis
//! (a load step or a speed transient moves `i_q`); otherwise it is counted as rejected. The
//! estimates are running means over the pairs (the last [`ExcitationConfig::memory_pairs`]
//! weighted alike, older ones fading), with their standard deviations from the pairs'
//! scatter, reported once [`ExcitationConfig::min_pairs`] pairs are in. The `Ls` pairs are
//! weighted by `w^2` (the noise of `Im z / w` falls as `1 / w`): a low-speed stretch does not
//! wash out what higher speeds measured.
//!
//! # When it works
//!
//! - `Rs` at any speed, zero included (the EMF cancels): where the observer needs it, at low
//!   speed.
//! - `Ls` when `w Ls` is not small against `Rs` and the noise of `dU`: above
//!   [`ExcitationConfig::min_ls_speed_rad_s`] (a few % of rated speed); below it the pairs
//!   update `Rs` only.
//! - Interior motors: the d excitation gives `Ld` from the q row (`dU_q = w Ld dI_d`) and
//!   `Rs` from the d row; `Lq` needs a q excitation. This estimator reports the q row's
//!   inductance as `Ls`: `Ld` on an interior motor.
//! - Not through a speed or load transient (the pairs are rejected) and not when the voltage
//!   limit cuts the excitation (the halves' currents do not settle).
//!
//! `no_std`, no allocation, `f32` or `f64`; one [`ExcitationEstimator::push`] per sample
//! (two sines, a few multiplications), the division once per half period.

use crate::Float;
use crate::to_t;

/// The estimator's settings ([`ExcitationEstimator`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExcitationConfig<T> {
    /// Excitation amplitude `a`, A (the d-current reference steps by `2 a`).
    pub amplitude_a: T,
    /// Samples per half period `N` (the drive's).
    pub half_period: u32,
    /// Samples skipped at the start of each half (the current loop's transient) `M < N`.
    pub skip: u32,
    /// Sample time `Ts`, s.
    pub ts_s: T,
    /// Pairs before an estimate is reported (at least 2).
    pub min_pairs: u32,
    /// Pairs weighted alike in the running means (older ones fade): the memory.
    pub memory_pairs: u32,
    /// Largest speed change per half over the three halves of a pair, fraction of the speed.
    pub max_speed_change: T,
    /// Largest `|dI_q| / |dI_d|` of a pair (transients move `i_q`; the frame's angle error
    /// tilts `dI` by that error).
    pub max_iq_change: T,
    /// Speed (electrical, rad/s) from which a pair updates `Ls`.
    pub min_ls_speed_rad_s: T,
}

impl<T: Float> ExcitationConfig<T> {
    /// Defaults for an excitation of `amplitude_a`, `half_period` samples at `ts_s`: skip
    /// half of each half, 4 pairs before an estimate, a memory of 64 pairs, speed within
    /// 2 %, `dI` within 0.25 (14 deg) of the d axis, `Ls` from `min_ls_speed_rad_s`.
    pub fn new(amplitude_a: T, half_period: u32, ts_s: T, min_ls_speed_rad_s: T) -> Self {
        Self {
            amplitude_a,
            half_period,
            skip: half_period / 2,
            ts_s,
            min_pairs: 4,
            memory_pairs: 64,
            max_speed_change: to_t(0.02),
            max_iq_change: to_t(0.25),
            min_ls_speed_rad_s,
        }
    }

    /// Checks the settings: positive finite amplitude, `Ts` and speed bound, `0 <= M < N`,
    /// `N >= 2`, `min_pairs >= 2`, `memory_pairs >= min_pairs`, the fractions positive.
    pub fn validate(&self) -> Result<(), ExcitationError> {
        let pos = |v: T| v.is_finite() && v > T::zero();
        if !pos(self.amplitude_a) {
            return Err(ExcitationError::InvalidConfig("amplitude_a"));
        }
        if !pos(self.ts_s) {
            return Err(ExcitationError::InvalidConfig("ts_s"));
        }
        if self.half_period < 2 || self.skip >= self.half_period {
            return Err(ExcitationError::InvalidConfig("half_period/skip"));
        }
        if self.min_pairs < 2 || self.memory_pairs < self.min_pairs {
            return Err(ExcitationError::InvalidConfig("min_pairs/memory_pairs"));
        }
        if !pos(self.max_speed_change) || !pos(self.max_iq_change) {
            return Err(ExcitationError::InvalidConfig(
                "max_speed_change/max_iq_change",
            ));
        }
        if !(self.min_ls_speed_rad_s.is_finite() && self.min_ls_speed_rad_s >= T::zero()) {
            return Err(ExcitationError::InvalidConfig("min_ls_speed_rad_s"));
        }
        Ok(())
    }
}

/// What the estimator refuses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExcitationError {
    /// A setting is out of range (its name).
    InvalidConfig(&'static str),
    /// A sample's angle, speed, voltage or current is not finite: refused, and the half in
    /// progress is dropped (not used for a pair).
    NonFiniteInput,
}

impl core::fmt::Display for ExcitationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ExcitationError::InvalidConfig(name) => {
                write!(f, "excitation estimator: setting {name} out of range")
            }
            ExcitationError::NonFiniteInput => {
                f.write_str("excitation estimator: sample not finite (NaN or infinity); refused")
            }
        }
    }
}

impl core::error::Error for ExcitationError {}

/// The estimates with their standard deviations (of the mean) and the pairs behind them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExcitationEstimate<T> {
    /// `Rs`, ohm.
    pub rs_ohm: T,
    /// Standard deviation of `Rs`, ohm.
    pub rs_sigma_ohm: T,
    /// Pairs behind `Rs`.
    pub rs_pairs: u32,
    /// `Ls` (the q row's inductance: `Ld` of an interior motor), H; `None` before
    /// [`ExcitationConfig::min_pairs`] pairs above the speed bound.
    pub ls_h: Option<T>,
    /// Standard deviation of `Ls`, H (0 while `ls_h` is `None`).
    pub ls_sigma_h: T,
    /// Pairs behind `Ls`.
    pub ls_pairs: u32,
}

/// A weighted running mean and variance with forgetting: weights decay by
/// `1 - 1 / memory` per value, so about the last `memory` values count.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Running<T> {
    n: u32,
    mean: T,
    var: T,
    /// Sum of the (decayed) weights and of their squares.
    sw: T,
    sw2: T,
}

impl<T: Float> Running<T> {
    fn new() -> Self {
        Self {
            n: 0,
            mean: T::zero(),
            var: T::zero(),
            sw: T::zero(),
            sw2: T::zero(),
        }
    }

    /// West's weighted update of the mean and variance, after the decay of the old weights.
    fn add(&mut self, x: T, weight: T, memory: u32) {
        let lambda = T::one() - T::one() / to_t(f64::from(memory));
        self.n = self.n.saturating_add(1);
        self.sw = lambda * self.sw + weight;
        self.sw2 = lambda * lambda * self.sw2 + weight * weight;
        let f = weight / self.sw;
        let d = x - self.mean;
        self.mean += f * d;
        self.var = (T::one() - f) * (self.var + f * d * d);
    }

    /// Standard deviation of the mean: `sqrt(var / (n_eff - 1))`, `n_eff = (sum w)^2 /
    /// sum w^2` (0 while `n_eff < 2`).
    fn sigma(&self) -> T {
        if self.sw2 <= T::zero() {
            return T::zero();
        }
        let n_eff = self.sw * self.sw / self.sw2;
        if n_eff < to_t(2.0) {
            return T::zero();
        }
        (self.var / (n_eff - T::one())).sqrt()
    }
}

/// The averages of one whole half: voltage and current `(d, q)` in the frame, speed.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Half<T> {
    u: (T, T),
    i: (T, T),
    w: T,
    positive: bool,
}

/// The estimator (module docs): one [`push`](Self::push) per sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExcitationEstimator<T> {
    cfg: ExcitationConfig<T>,
    /// Sign of the half in progress (`None` before the first sample).
    sign: Option<bool>,
    /// Samples of the half in progress.
    count: u32,
    /// A sample of the half in progress was refused.
    spoiled: bool,
    /// Sums of the half in progress over its scored samples.
    sum_u: (T, T),
    sum_i: (T, T),
    sum_w: T,
    /// The last whole half.
    last: Option<Half<T>>,
    /// The whole half before it.
    before_last: Option<Half<T>>,
    rs: Running<T>,
    ls: Running<T>,
    rejected: u32,
}

impl<T: Float> ExcitationEstimator<T> {
    /// An estimator with validated settings.
    pub fn new(cfg: &ExcitationConfig<T>) -> Result<Self, ExcitationError> {
        cfg.validate()?;
        Ok(Self {
            cfg: *cfg,
            sign: None,
            count: 0,
            spoiled: false,
            sum_u: (T::zero(), T::zero()),
            sum_i: (T::zero(), T::zero()),
            sum_w: T::zero(),
            last: None,
            before_last: None,
            rs: Running::new(),
            ls: Running::new(),
            rejected: 0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &ExcitationConfig<T> {
        &self.cfg
    }

    /// One sample: the observer's estimated angle `theta_rad` (at the sample) and electrical
    /// speed `omega_rad_s`, the voltage `u_ab` applied over the period before the sample
    /// (alpha-beta, V), the measured current `i_ab` (A) and the sign of the excitation over
    /// that period (`true`: `+a`). Returns `true` when a pair was used (the estimates
    /// changed). A non-finite input is refused ([`ExcitationError::NonFiniteInput`]), the
    /// estimates unchanged, and the half in progress dropped.
    pub fn push(
        &mut self,
        theta_rad: T,
        omega_rad_s: T,
        u_ab: [T; 2],
        i_ab: [T; 2],
        positive: bool,
    ) -> Result<bool, ExcitationError> {
        let finite = theta_rad.is_finite()
            && omega_rad_s.is_finite()
            && u_ab[0].is_finite()
            && u_ab[1].is_finite()
            && i_ab[0].is_finite()
            && i_ab[1].is_finite();
        if !finite {
            self.spoiled = true;
            return Err(ExcitationError::NonFiniteInput);
        }
        let mut used = false;
        if self.sign != Some(positive) {
            if self.sign.is_some() {
                used = self.close_half();
            }
            self.sign = Some(positive);
            self.count = 0;
            self.spoiled = false;
            self.sum_u = (T::zero(), T::zero());
            self.sum_i = (T::zero(), T::zero());
            self.sum_w = T::zero();
        }
        self.count = self.count.saturating_add(1);
        if self.count > self.cfg.skip && self.count <= self.cfg.half_period {
            // Voltage and current in the frame at the sample's angle (module docs).
            let (sn, cs) = theta_rad.sin_cos_angle();
            self.sum_u.0 += u_ab[0] * cs + u_ab[1] * sn;
            self.sum_u.1 += u_ab[1] * cs - u_ab[0] * sn;
            self.sum_i.0 += i_ab[0] * cs + i_ab[1] * sn;
            self.sum_i.1 += i_ab[1] * cs - i_ab[0] * sn;
            self.sum_w += omega_rad_s;
        }
        Ok(used)
    }

    /// Ends the half in progress: a whole one is paired with the last one (opposite sign).
    fn close_half(&mut self) -> bool {
        let whole = self.count == self.cfg.half_period && !self.spoiled;
        if !whole {
            self.last = None;
            self.before_last = None;
            return false;
        }
        let n: T = to_t(f64::from(self.cfg.half_period - self.cfg.skip));
        let this = Half {
            u: (self.sum_u.0 / n, self.sum_u.1 / n),
            i: (self.sum_i.0 / n, self.sum_i.1 / n),
            w: self.sum_w / n,
            positive: self.sign == Some(true),
        };
        let used = match (self.before_last, self.last) {
            (Some(a), Some(b)) if a.positive == this.positive && b.positive != this.positive => {
                // The outer halves' mean against the middle one: a linear drift of the
                // back-EMF (a speed ramp) cancels (module docs).
                let outer = Half {
                    u: (
                        (a.u.0 + this.u.0) * to_t(0.5),
                        (a.u.1 + this.u.1) * to_t(0.5),
                    ),
                    i: (
                        (a.i.0 + this.i.0) * to_t(0.5),
                        (a.i.1 + this.i.1) * to_t(0.5),
                    ),
                    w: (a.w + this.w) * to_t(0.5),
                    positive: this.positive,
                };
                let drift = (this.w - a.w) * to_t(0.5);
                self.pair(&b, &outer, drift)
            }
            _ => false,
        };
        self.before_last = self.last;
        self.last = Some(this);
        used
    }

    /// One pair, the middle half `a` against the outer halves' mean `b` (`drift`: the speed
    /// change per half over the three): `dU / dI` if the pair passes the tests (module docs).
    fn pair(&mut self, a: &Half<T>, b: &Half<T>, drift: T) -> bool {
        let c = &self.cfg;
        let (did, diq) = (b.i.0 - a.i.0, b.i.1 - a.i.1);
        let (dud, duq) = (b.u.0 - a.u.0, b.u.1 - a.u.1);
        let w = (a.w + b.w) * to_t(0.5);
        let di2 = did * did + diq * diq;
        let ok = drift.abs()
            <= c.max_speed_change * a.w.abs().max(b.w.abs())
                + c.max_speed_change * c.min_ls_speed_rad_s
            && di2 >= c.amplitude_a * c.amplitude_a
            && diq.abs() <= c.max_iq_change * did.abs();
        if !ok {
            self.rejected = self.rejected.saturating_add(1);
            return false;
        }
        // z = dU / dI = dU conj(dI) / |dI|^2.
        let zr = (dud * did + duq * diq) / di2;
        let zi = (duq * did - dud * diq) / di2;
        // The held voltage's exact relation (module docs): Rs = Re z - Im z tan(w Ts / 2),
        // Ls = Rs Ts / ln(1 + Rs sin(w Ts) / Im z).
        let half_angle = w * c.ts_s * to_t(0.5);
        let (sh, ch) = half_angle.sin_cos_angle();
        let rs = zr - zi * sh / ch;
        if !(rs.is_finite() && zi.is_finite()) {
            self.rejected = self.rejected.saturating_add(1);
            return false;
        }
        self.rs.add(rs, T::one(), c.memory_pairs);
        if w.abs() >= c.min_ls_speed_rad_s && w != T::zero() {
            // K = Im z / sin(w Ts) = Rs alpha / (1 - alpha); Ls = K Ts x / ln(1 + x), x = Rs / K.
            let two = T::one() + T::one();
            let k = zi / (two * sh * ch);
            let x = rs / k;
            let ratio = if x.abs() < to_t(1e-6) {
                T::one() + x * to_t(0.5)
            } else {
                x / x.ln_1p()
            };
            let ls = k * c.ts_s * ratio;
            if ls.is_finite() && ls > T::zero() && x > to_t(-0.5) {
                // Weighted by w^2: the noise of Im z / w falls as 1 / w.
                let r = w * c.ts_s;
                self.ls.add(ls, r * r, c.memory_pairs);
            }
        }
        true
    }

    /// The estimates, once [`ExcitationConfig::min_pairs`] pairs updated `Rs` (`None`
    /// before).
    pub fn estimate(&self) -> Option<ExcitationEstimate<T>> {
        (self.rs.n >= self.cfg.min_pairs).then(|| {
            let ls_ready = self.ls.n >= self.cfg.min_pairs;
            ExcitationEstimate {
                rs_ohm: self.rs.mean,
                rs_sigma_ohm: self.rs.sigma(),
                rs_pairs: self.rs.n,
                ls_h: ls_ready.then_some(self.ls.mean),
                ls_sigma_h: if ls_ready { self.ls.sigma() } else { T::zero() },
                ls_pairs: self.ls.n,
            }
        })
    }

    /// Pairs rejected (speed moved, `i_q` moved, `dI` too small).
    pub fn rejected_pairs(&self) -> u32 {
        self.rejected
    }
}

/// The excitation's sign at a tick (`true`: `+a`) for a half period of `half_period`
/// ticks: `+a` over ticks `[0, N)`, `-a` over `[N, 2 N)`, and so on (foc's
/// `DExcitation::sign` is the same function of its tick counter).
pub fn excitation_sign(tick: u32, half_period: u32) -> bool {
    (tick / half_period.max(1)) & 1 == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A surface motor at speed `w` with a square-wave d current, the frame `dth` off the
    /// rotor: the motor's `Rs`-`Ls` step in the stationary frame driven by held voltages
    /// (the EMF's part a constant in the turning frame, which cancels: module docs), from
    /// rest; the voltage is the one that holds the dq current of each half once settled.
    fn run(dth: f64, w: f64, iq: f64, samples: u32) -> ExcitationEstimator<f64> {
        run_drifting(dth, w, iq, samples, 0.0)
    }

    /// [`run`] with a back-EMF that drifts by `slope` V/s along the frame's q axis (a speed
    /// ramp seen by the EMF while the frame's speed is held).
    fn run_drifting(
        dth: f64,
        w: f64,
        iq: f64,
        samples: u32,
        slope: f64,
    ) -> ExcitationEstimator<f64> {
        let (rs, ls, psi, ts, a): (f64, f64, f64, f64, f64) = (0.5, 2e-4, 0.1, 1e-4, 1.0);
        // Current time constant 4 samples, half period 200: settled to 1e-10 after the skip.
        let n = 200;
        let mut cfg = ExcitationConfig::new(a, n, ts, 50.0);
        cfg.min_pairs = 3;
        let mut e = ExcitationEstimator::new(&cfg).unwrap();
        let alpha = (-rs * ts / ls).exp();
        let g = (1.0 - alpha) / rs;
        // z = Rs (1 - alpha e^{-j w Ts}) / (1 - alpha) as (re, im).
        let (zr, zi) = (
            rs * (1.0 - alpha * (w * ts).cos()) / (1.0 - alpha),
            rs * alpha * (w * ts).sin() / (1.0 - alpha),
        );
        let mut i = [0.0f64; 2];
        let mut emf_part = [0.0f64; 2];
        for k in 0..samples {
            let positive = excitation_sign(k, n);
            let id = if positive { a } else { -a };
            let th = w * ts * f64::from(k);
            // Voltage in the frame at th: z (id + j iq) plus an EMF-like constant j w psi.
            let vd = zr * id - zi * iq;
            let emf = w * psi + slope * ts * f64::from(k);
            let vq = zi * id + zr * iq + emf;
            let u = [vd * th.cos() - vq * th.sin(), vd * th.sin() + vq * th.cos()];
            // The plant: the linear part from u less the constant's own response (the
            // constant j w psi is what the EMF would absorb: its current part is removed so
            // that the current's dq value is z^-1 of the rest).
            let c = [-emf * th.sin(), emf * th.cos()];
            emf_part = [
                alpha * emf_part[0] + g * c[0],
                alpha * emf_part[1] + g * c[1],
            ];
            i = [alpha * i[0] + g * u[0], alpha * i[1] + g * u[1]];
            let meas = [i[0] - emf_part[0], i[1] - emf_part[1]];
            e.push(th + dth, w, u, meas, positive).unwrap();
        }
        e
    }

    #[test]
    fn exact_whatever_the_angle_error() {
        for dth in [0.0, 0.05, -0.2] {
            for w in [300.0, 3000.0] {
                let e = run(dth, w, 3.0, 4000).estimate().unwrap();
                assert!((e.rs_ohm - 0.5).abs() < 1e-6, "{dth} {w} {e:?}");
                let ls = e.ls_h.unwrap();
                assert!((ls - 2e-4).abs() < 1e-10, "{dth} {w} {e:?}");
                assert!(e.rs_sigma_ohm < 1e-6 && e.ls_sigma_h < 1e-10);
            }
        }
    }

    #[test]
    fn a_drifting_emf_cancels() {
        // 6 V/s moves the EMF by 0.12 V per half: a tenth of the excitation's `w Ls 2a`
        // (1.2 V at 3000 rad/s), which two halves alone would read as `Ls` 10 % off.
        let e = run_drifting(0.05, 3000.0, 3.0, 4000, 6.0)
            .estimate()
            .unwrap();
        let ls = e.ls_h.unwrap();
        assert!((ls - 2e-4).abs() < 1e-9, "{e:?}");
        assert!((e.rs_ohm - 0.5).abs() < 1e-5, "{e:?}");
    }

    #[test]
    fn low_speed_gives_rs_only() {
        let e = run(0.1, 10.0, 3.0, 4000).estimate().unwrap();
        assert!((e.rs_ohm - 0.5).abs() < 1e-6);
        assert_eq!(e.ls_h, None);
        assert_eq!(e.ls_pairs, 0);
    }

    #[test]
    fn too_few_pairs_no_estimate() {
        // 3 halves: 1 pair < 3.
        assert!(run(0.0, 300.0, 3.0, 640).estimate().is_none());
    }

    #[test]
    fn bad_input_refused_state_kept() {
        let mut e = run(0.0, 300.0, 3.0, 4000);
        let before = e.estimate();
        for bad in [f64::NAN, f64::INFINITY] {
            assert_eq!(
                e.push(bad, 300.0, [0.0; 2], [0.0; 2], true),
                Err(ExcitationError::NonFiniteInput)
            );
            assert_eq!(
                e.push(0.0, 300.0, [0.0, bad], [0.0; 2], true),
                Err(ExcitationError::NonFiniteInput)
            );
        }
        assert_eq!(e.estimate(), before);
    }

    #[test]
    fn settings_checked() {
        let ok = ExcitationConfig::new(1.0, 50, 1e-4, 10.0);
        assert!(ExcitationEstimator::new(&ok).is_ok());
        for (cfg, name) in [
            (
                ExcitationConfig {
                    amplitude_a: f64::NAN,
                    ..ok
                },
                "amplitude_a",
            ),
            (ExcitationConfig { skip: 50, ..ok }, "half_period/skip"),
            (
                ExcitationConfig { min_pairs: 1, ..ok },
                "min_pairs/memory_pairs",
            ),
            (ExcitationConfig { ts_s: 0.0, ..ok }, "ts_s"),
        ] {
            assert_eq!(
                ExcitationEstimator::new(&cfg).err(),
                Some(ExcitationError::InvalidConfig(name))
            );
        }
    }

    #[test]
    fn transient_pairs_rejected() {
        // i_q steps between halves: the pairs across the step are rejected.
        let (ts, a, n) = (1e-4, 1.0, 50);
        let cfg = ExcitationConfig::new(a, n, ts, 50.0);
        let mut e = ExcitationEstimator::<f64>::new(&cfg).unwrap();
        for k in 0..400 {
            let positive = excitation_sign(k, n);
            let id = if positive { a } else { -a };
            let iq = if k < 200 { 0.0 } else { 3.0 };
            e.push(0.0, 100.0, [0.5 * id, 0.5 * iq], [id, iq], positive)
                .unwrap();
        }
        assert!(e.rejected_pairs() >= 1);
    }

    #[test]
    fn f32_builds_and_estimates() {
        let cfg = ExcitationConfig::<f32>::new(1.0, 20, 1e-4, 1.0);
        let mut e = ExcitationEstimator::new(&cfg).unwrap();
        for k in 0..400u32 {
            let p = excitation_sign(k, 20);
            let id = if p { 1.0 } else { -1.0 };
            e.push(0.0, 0.0, [0.5 * id, 0.0], [id, 0.0], p).unwrap();
        }
        let r = e.estimate().unwrap();
        assert!((r.rs_ohm - 0.5).abs() < 1e-5);
    }

    #[test]
    fn set_inductances_rebuilds_the_model() {
        use crate::{MotorParams, ObserverConfig, PmsmObserver};
        let m = MotorParams::<f64>::servo();
        for tracking in [false, true] {
            let cfg = |l: f64| {
                let mut c = ObserverConfig::new(
                    MotorParams {
                        ld_h: l,
                        lq_h: l,
                        ..m
                    },
                    1e-4,
                );
                if !tracking {
                    c.parameter_tracking = None;
                }
                c
            };
            let l1 = 1.2 * m.lq_h;
            let mut told = PmsmObserver::new(&cfg(m.lq_h)).unwrap();
            // Built for `l1` with the noise tuning and start of the one told `L0` (the
            // setter keeps `Q`, `R`, the state and `P`).
            let (c0, mut c1) = (cfg(m.lq_h), cfg(l1));
            (c1.noise, c1.p0, c1.x0) = (c0.noise, c0.p0, c0.x0);
            let mut fresh = PmsmObserver::new(&c1).unwrap();
            told.set_inductances(l1, l1).unwrap();
            assert_eq!(told.model(), fresh.model());
            let (ld, lq) = told.inductances();
            assert!((ld - l1).abs() < 1e-15 && (lq - l1).abs() < 1e-15);
            for k in 0..200 {
                let t = f64::from(k) * 1e-4;
                let u = [10.0 * (300.0 * t).cos(), 10.0 * (300.0 * t).sin()];
                let i = [0.5 * (300.0 * t).sin(), -0.5 * (300.0 * t).cos()];
                let a = told.step(u, i).map(|e| e.theta_rad);
                let b = fresh.step(u, i).map(|e| e.theta_rad);
                assert_eq!(a, b, "step {k}");
            }
            // Refused, nothing changed.
            let before = told.clone();
            for (ld, lq) in [(f64::NAN, l1), (l1, -1.0), (l1, 20.0), (1.1 * l1, l1)] {
                assert!(told.set_inductances(ld, lq).is_err());
                assert_eq!(told, before);
            }
        }
    }
}
