//! One step of the observer: prediction, correction with the innovation gate and the branch
//! check, and the tracking's per-step work (module docs of [`observer`](crate::observer)).

#[cfg(all(feature = "std", target_arch = "x86_64"))]
use super::host;
use super::pmsm::Tracking;
use super::{Estimate, PmsmObserver};
use nalgebra::{Matrix4, Vector4};

use super::model::Discrete;
use super::safeguards::{Events, Verdict, gate_accepted_high, gate_verdict};
use super::structured::{self, Outcome, Sym4};
use super::tracking::TrackerStep;
use crate::ekf::{EkfError, finite};
use crate::{Float, to_t};

/// The told inverter voltage's standard deviation as a share of it (the consistency check's
/// EMF floor, module docs of [`observer`](crate::observer), "Consistency").
pub(super) const INVERTER_VOLTAGE_SIGMA_SHARE: f64 = 0.5;

/// `v <= max`, false for a NaN `v`.
#[inline(always)]
pub(crate) fn within<T: Float>(v: T, max: T) -> bool {
    v <= max
}

/// The longest period [`PmsmObserver::step_dt`] accepts, in sample times `Ts`.
pub const MAX_PERIOD_FACTOR: f64 = 64.0;

/// A record filtered row by row with its periods (a log): a refused row is a skipped cycle.
/// Its period joins the next row's, which predicts over both with its own voltage (when the
/// joined period is refused too, e.g. longer than [`MAX_PERIOD_FACTOR`] sample times, over
/// its own), and the refused row reports the estimate with its angle advanced to the row's
/// time ([`advance`](Self::advance)). `pyfoc`'s `Ekf.run` with periods and `pmsm-sim replay`
/// use it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SkippedCycles<T> {
    /// Periods of the refused rows since the last accepted one, s.
    carried: T,
}

impl<T: Float> SkippedCycles<T> {
    /// The row's step over `dt` plus the carried periods, through `step` (e.g.
    /// `|d| obs.step_dt(u, i, d)`); an error leaves the row's period carried.
    pub fn step<R, E>(&mut self, dt: T, mut step: impl FnMut(T) -> Result<R, E>) -> Result<R, E> {
        let mut r = step(dt + self.carried);
        if r.is_err() && self.carried > T::zero() {
            r = step(dt);
        }
        self.carried = if r.is_err() {
            self.carried + dt
        } else {
            T::zero()
        };
        r
    }

    /// The angle `theta` of the last accepted estimate, advanced at its speed `w` over the
    /// periods carried: what a refused row reports.
    pub fn advance(&self, theta: T, w: T) -> T {
        crate::wrap_angle(theta + w * self.carried)
    }
}

/// The largest stator-flux change an input voltage may make over one sample time, in magnet
/// fluxes: `|u| Ts <= MAX_INPUT_FLUX_RATIO psi_f` (module docs of
/// [`observer`](crate::observer), "Implausible input"); beyond it a step is refused with
/// [`EkfError::ImplausibleInput`].
pub const MAX_INPUT_FLUX_RATIO: f64 = 20.0;

/// The largest measured current a step takes, in characteristic currents `psi_f / L_d`
/// (module docs of [`observer`](crate::observer), "Implausible input"); beyond it a step is
/// refused with [`EkfError::ImplausibleMeasurement`]. The covariance health check's default
/// bound on the state's currents is the same.
pub const MAX_CURRENT_RATIO: f64 = 100.0;

impl<T: Float> PmsmObserver<T> {
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
        #[cfg(feature = "std")]
        if self.calibration.is_some() {
            self.check_input(u_prev)?;
            self.check_measurement(i)?;
            self.calibrate(u_prev, i, self.model.ts());
        }
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
    /// ([`PmsmModel::with_period`](super::PmsmModel::with_period): the current decay, input gain and EMF gain over `dt_s`, the
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
        #[cfg(feature = "std")]
        if self.calibration.is_some() {
            self.check_input(u_prev)?;
            self.check_measurement(i)?;
            self.calibrate(u_prev, i, dt_s);
        }
        let model = self.model;
        let cached = self.rs_constants;
        self.model = model.with_period(dt_s);
        // The cached constants at the tracked `Rs` are for `Ts`: recompute them for `dt_s`.
        self.rs_constants = (cached.0, self.model.discrete_at(self.nominal.0, cached.0));
        let out = self.step_portable(u_prev, i);
        self.model = model;
        self.rs_constants = cached;
        // The resistance tracking's window assumes periods of `Ts`: it restarts (a refused
        // sample leaves the observer as it was).
        if out.is_ok()
            && let Some(Tracking { t, .. }) = &mut self.tracking
        {
            t.break_window();
        }
        out
    }

    /// The online input calibration's sample (`ObserverConfig::input_calibration`): its drive
    /// observer steps on the same sample, and every hand-over sets the voltage lead, the
    /// dead-time voltage and, when the calibrated `Rs` differs from the tracked one by more
    /// than 5 %, the tracked `Rs` (the flux kept).
    #[cfg(feature = "std")]
    #[inline(never)]
    fn calibrate(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) {
        // The filter's predicted angle for this sample (its state is the last sample's).
        let th = self.x[3] + self.x[2] * dt_s;
        let Some(c) = self
            .calibration
            .as_mut()
            .and_then(|c| c.step(u_prev, i, dt_s, th))
        else {
            return;
        };
        // The drive observer runs on the told flux, and a flux error reads to it as a lead
        // and a resistance: nothing is handed over while this filter's flux has left the
        // told one by more than 3 % (module docs of `crate::calibration`, "Online").
        let (psi, rs) = self.parameters();
        if (psi - self.nominal.0).abs() > self.nominal.0 * to_t(0.03) {
            return;
        }
        // Out of range values are refused by the setters, nothing changed.
        let _ = self.set_voltage_errors(-c.voltage_lead_s, c.dead_time_v);
        // Once the EKF's own tracking has ended a window it learns `Rs` itself, and a
        // calibration whose `Rs` has not left the told value (its drive observer learnt none)
        // would only reset it there.
        let told = self.nominal.1;
        let informed = (c.rs_ohm - told).abs() > told * to_t(0.05);
        let own = self
            .tracking
            .as_ref()
            .and_then(|k| k.slow.split.as_ref())
            .is_some_and(|s| s.tracked);
        if self.tracking.is_some() && (c.rs_ohm - rs).abs() > rs * to_t(0.05) && (informed || !own)
        {
            let _ = self.set_parameters(psi, c.rs_ohm);
        }
    }

    /// [`step`](Self::step) in the portable build (the code every target runs).
    #[doc(hidden)]
    #[inline(always)]
    pub fn step_portable(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        // One test on the common path; which argument was bad is sorted out only on failure.
        // `check_sample` written out: through the helper the Cortex-M4F step costs 14
        // instructions more (1031 against 1017, `bash scripts/qemu-firmware.sh`).
        let u2 = u_prev[0] * u_prev[0] + u_prev[1] * u_prev[1];
        let i2 = i[0] * i[0] + i[1] * i[1];
        if !(u2 <= self.u_max2 && i2 <= self.i_max2) {
            self.check_input(u_prev)?;
            self.check_measurement(i)?;
        }
        // Four monomorphic paths: the one without tracking carries none of its code, the
        // surface ones none of the salient model's.
        match (self.tracking.is_some(), self.model.discrete().salient) {
            (true, false) => {
                let (xm, pm, tm) = self.prior::<true, false>(u_prev);
                #[cfg(feature = "acceleration-feedforward")]
                let xm = self.feedforward_prior(xm);
                self.correct_prior::<true, false>(xm, pm, tm, i)
            }
            (false, false) => {
                let (xm, pm, _) = self.prior::<false, false>(u_prev);
                #[cfg(feature = "acceleration-feedforward")]
                let xm = self.feedforward_prior(xm);
                self.correct_prior::<false, false>(xm, pm, None, i)
            }
            (true, true) => {
                let (xm, pm, tm) = self.prior::<true, true>(u_prev);
                #[cfg(feature = "acceleration-feedforward")]
                let xm = self.feedforward_prior(xm);
                self.correct_prior::<true, true>(xm, pm, tm, i)
            }
            (false, true) => {
                let (xm, pm, _) = self.prior::<false, true>(u_prev);
                #[cfg(feature = "acceleration-feedforward")]
                let xm = self.feedforward_prior(xm);
                self.correct_prior::<false, true>(xm, pm, None, i)
            }
        }
    }

    /// The prediction `(x-, P-)` and, with tracking (`TRACK`, the tracker present), the prior
    /// of the tracked parameters (nothing is stored here). `S`: the motor is salient.
    #[inline(always)]
    pub(super) fn prior<const TRACK: bool, const S: bool>(
        &self,
        u_prev: [T; 2],
    ) -> (Vector4<T>, Sym4<T>, Option<TrackerStep<T>>) {
        // One test on the common path each for the voltage timing and the speed noise
        // adaptation's raised `Q` (both off in foc's drive); their work is out of line.
        let q_adapted;
        let mut q = self.model.q_sym();
        let mut u_prev = u_prev;
        if self.timing {
            u_prev = self.applied(u_prev);
        }
        if let Some(a) = &self.adaptation
            && a.factor > T::one()
        {
            q_adapted = self.adapted_q(a.factor);
            q = &q_adapted;
        }
        match &self.tracking {
            Some(Tracking { t: tr, slow }) if TRACK => {
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
                let tm = tr.predict::<S>(k, &disc, &t, (&self.x, u_prev), &mut pm, active);
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

    /// The voltage applied over the period from the logged `u` (module docs, "Voltage
    /// timing"): turned by `-w voltage_delay_s` at the speed estimate of the period's start,
    /// less the inverter's voltage error along the signs of the phase currents estimated at
    /// mid-period (the posterior currents turned by `w Ts / 2`).
    #[cold]
    #[inline(never)]
    pub(super) fn applied(&self, u: [T; 2]) -> [T; 2] {
        let w = self.x[2];
        let mut u = u;
        if self.voltage_delay != T::zero() {
            let (s, c) = crate::trig::sin_cos_small(-(w * self.voltage_delay));
            u = [c * u[0] - s * u[1], s * u[0] + c * u[1]];
        }
        let (v, band) = self.inverter;
        if v != T::zero() {
            let half: T = to_t(0.5);
            let (s, c) = crate::trig::sin_cos_small(w * self.model.ts() * half);
            let (ia, ib) = (self.x[0], self.x[1]);
            let (ma, mb) = (c * ia - s * ib, s * ia + c * ib);
            // Phase currents of the amplitude-invariant transform.
            let r3: T = to_t(0.866_025_403_784_438_6);
            let (pa, pb, pc) = (ma, -half * ma + r3 * mb, -half * ma - r3 * mb);
            let sgn = |x: T| {
                let y = x / band;
                if y > T::one() {
                    T::one()
                } else if y < -T::one() {
                    -T::one()
                } else {
                    y
                }
            };
            let (sa, sb, sc) = (sgn(pa), sgn(pb), sgn(pc));
            // (sa + sb e^(j 2pi/3) + sc e^(j 4pi/3)) / 2
            let da = half * (sa - half * (sb + sc));
            let db = half * r3 * (sb - sc);
            u = [u[0] - v * da, u[1] - v * db];
        }
        u
    }

    /// The acceleration feedforward's share of the prior `xm` (module docs, "Acceleration
    /// feedforward"; out of line: it is opt-in).
    #[cfg(feature = "acceleration-feedforward")]
    #[inline(always)]
    fn feedforward_prior(&self, xm: Vector4<T>) -> Vector4<T> {
        if self.feedforward.is_some() {
            self.feedforward_add(xm)
        } else {
            xm
        }
    }

    /// The work of [`feedforward_prior`](Self::feedforward_prior), out of line.
    #[cfg(feature = "acceleration-feedforward")]
    #[cold]
    #[inline(never)]
    fn feedforward_add(&self, mut xm: Vector4<T>) -> Vector4<T> {
        if let Some(f) = &self.feedforward {
            f.feedforward(&mut xm, self.model.ts());
        }
        xm
    }

    /// The acceleration feedforward's sample of the committed posterior: its q current (in its
    /// own frame) and speed (`trusted`: the step's angle was tracked and corrected).
    #[cfg(feature = "acceleration-feedforward")]
    #[cold]
    #[inline(never)]
    fn feedforward_commit(&mut self, trusted: bool) {
        if let Some(f) = &mut self.feedforward {
            let x = &self.x;
            let (s, c) = x[3].sin_cos_angle();
            f.watch(x[1] * c - x[0] * s, x[2], trusted);
        }
    }

    /// `Q` with `Q_ww` raised by the speed noise adaptation's `factor`.
    #[cold]
    #[inline(never)]
    pub(super) fn adapted_q(&self, factor: T) -> Matrix4<T> {
        let mut q = *self.model.q_sym();
        q[(2, 2)] *= factor;
        q
    }

    /// The speed noise adaptation's bookkeeping after an accepted correction (when it is on).
    #[inline(always)]
    fn adaptation_watch(&mut self, nis: T, tracking: bool) {
        if let Some(a) = &mut self.adaptation {
            a.watch(
                nis,
                self.consistency
                    .as_ref()
                    .map_or(T::one(), |w| w.two_over_baseline),
                tracking,
            );
        }
    }

    /// Salient motors: updates the lock (module docs) after a committed correction. Locked
    /// when the angle is tracked and the innovations are consistent (the gate's running mean of
    /// the NIS at or below its settled level; always, without a gate); stays locked while the
    /// angle stays tracked.
    #[inline(always)]
    pub(super) fn update_lock(&mut self) {
        let tracked = self.p.p33 <= self.angle_var_limit;
        let settled = self
            .gate
            .as_ref()
            .is_none_or(|g| g.nis_mean <= g.settled_nis);
        self.locked = tracked && (self.locked || settled);
    }

    /// The refusals of [`check_input`](Self::check_input) and
    /// [`check_measurement`](Self::check_measurement) with one comparison of each squared
    /// magnitude on the common path (a NaN fails it); which one failed is sorted out only then.
    #[inline(always)]
    pub(crate) fn check_sample(&self, u: [T; 2], i: [T; 2]) -> Result<(), EkfError> {
        let u2 = u[0] * u[0] + u[1] * u[1];
        let i2 = i[0] * i[0] + i[1] * i[1];
        if !(u2 <= self.u_max2 && i2 <= self.i_max2) {
            self.check_input(u)?;
            self.check_measurement(i)?;
        }
        Ok(())
    }

    /// Refuses an input voltage that is not finite ([`EkfError::NonFiniteInput`]) or beyond
    /// [`MAX_INPUT_FLUX_RATIO`] magnet fluxes per sample time ([`EkfError::ImplausibleInput`]).
    #[cold]
    #[inline(never)]
    pub(crate) fn check_input(&self, u: [T; 2]) -> Result<(), EkfError> {
        if !finite(&u) {
            return Err(EkfError::NonFiniteInput);
        }
        if u[0] * u[0] + u[1] * u[1] > self.u_max2 {
            return Err(EkfError::ImplausibleInput);
        }
        Ok(())
    }

    /// Refuses measured currents that are not finite ([`EkfError::NonFiniteMeasurement`]) or
    /// beyond [`MAX_CURRENT_RATIO`] characteristic currents
    /// ([`EkfError::ImplausibleMeasurement`]).
    #[cold]
    #[inline(never)]
    pub(crate) fn check_measurement(&self, i: [T; 2]) -> Result<(), EkfError> {
        if !finite(&i) {
            return Err(EkfError::NonFiniteMeasurement);
        }
        if i[0] * i[0] + i[1] * i[1] > self.i_max2 {
            return Err(EkfError::ImplausibleMeasurement);
        }
        Ok(())
    }

    /// Prediction only (e.g. to coast over a missing current sample), with the voltage held
    /// over the period just ended. Refused, state kept, for a non-finite input or result. The
    /// covariance health check (when on) runs after it; on a reset the currents are kept.
    pub fn predict(&mut self, u_prev: [T; 2]) -> Result<(), EkfError> {
        if !within(u_prev[0] * u_prev[0] + u_prev[1] * u_prev[1], self.u_max2) {
            self.check_input(u_prev)?;
        }
        let (x, p, tm) = match (self.tracking.is_some(), self.model.discrete().salient) {
            (true, false) => self.prior::<true, false>(u_prev),
            (false, false) => self.prior::<false, false>(u_prev),
            (true, true) => self.prior::<true, true>(u_prev),
            (false, true) => self.prior::<false, true>(u_prev),
        };
        #[cfg(feature = "acceleration-feedforward")]
        let x = self.feedforward_prior(x);
        self.commit_prediction(x, p, tm)
    }

    /// Stores a prediction `(x, p)` (and the tracker's prior `tm`) as the new estimate, with
    /// the checks of [`predict`](Self::predict): a non-finite result is refused (or resets
    /// the observer when the covariance health check asks for it), and the health check runs
    /// after it.
    #[inline(always)]
    pub(super) fn commit_prediction(
        &mut self,
        x: Vector4<T>,
        p: Sym4<T>,
        tm: Option<TrackerStep<T>>,
    ) -> Result<(), EkfError> {
        let tracker_finite = match (&tm, &self.tracking) {
            (Some(s), Some(Tracking { t, .. })) => t.finite_with(s, t.psi),
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
        self.refusals = 0;
        self.x = x;
        self.p = p;
        // The tracking's slow work (a window's end) waits for the correction, whose
        // posterior it reads, as in `step`.
        if let (Some(s), Some(Tracking { t, .. })) = (&tm, &mut self.tracking) {
            t.commit(s, t.psi);
        }
        #[cfg(feature = "acceleration-feedforward")]
        if self.feedforward.is_some() {
            self.feedforward_commit(false);
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
        if !within(i[0] * i[0] + i[1] * i[1], self.i_max2) {
            self.check_measurement(i)?;
        }
        match (self.tracking.is_some(), self.model.discrete().salient) {
            (true, false) => {
                let tm = self.tracking.map(|k| k.t.as_step());
                self.correct_prior::<true, false>(self.x, self.p, tm, i)
            }
            (false, false) => self.correct_prior::<false, false>(self.x, self.p, None, i),
            (true, true) => {
                let tm = self.tracking.map(|k| k.t.as_step());
                self.correct_prior::<true, true>(self.x, self.p, tm, i)
            }
            (false, true) => self.correct_prior::<false, true>(self.x, self.p, None, i),
        }
    }

    /// Correction of the prior `(xm, pm)` with the currents `i`, innovation gate, branch check
    /// and covariance health (module docs).
    #[inline(always)]
    pub(super) fn correct_prior<const TRACK: bool, const S: bool>(
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
            Ok(Outcome::Updated(post)) => match (&tm, &self.tracking) {
                (Some(s), Some(Tracking { t, slow })) if TRACK => {
                    let (step, psi, sum) = t.correct(&slow.k, s, &post);
                    // Both sums finite in one test on their sum (`v - v` is 0 for a finite
                    // `v`, NaN otherwise): the state's results and the tracker's (a sum of
                    // check sums, conservative like them).
                    let total = post.sum + sum;
                    #[allow(clippy::eq_op)]
                    let finite = total - total == T::zero();
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
                #[cfg(feature = "acceleration-feedforward")]
                if self.feedforward.is_some() {
                    self.feedforward_commit(false);
                }
                if TRACK && let (Some(s), Some(Tracking { t, .. })) = (&tm, &mut self.tracking) {
                    t.commit(s, t.psi);
                    self.tracker_housekeeping();
                }
                if let Some(w) = &mut self.consistency
                    && w.watch(c.nis)
                {
                    self.close_block();
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
        self.refusals = 0;
        self.x = x;
        self.p = post.p;
        if TRACK && let (Some((s, psi)), Some(Tracking { t, .. })) = (&tn, &mut self.tracking) {
            t.commit(s, *psi);
            self.tracker_housekeeping();
        }
        if let Some(w) = &mut self.consistency {
            if w.watch(c.nis) {
                self.close_block();
            }
            if self.fused != 0 {
                self.fused -= 1;
            }
        }
        self.adaptation_watch(c.nis, tracking);
        #[cfg(feature = "acceleration-feedforward")]
        if self.feedforward.is_some() {
            self.feedforward_commit(tracking);
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

    /// The consistency check's work at a block's end, on the step's committed state (`self.x`,
    /// `self.p`): the model fit's verdict ([`flux_implausible`]) and the speed drift with the
    /// back-EMF's observability ([`ConsistencyState::update_drift`](super::ConsistencyState)).
    /// Out of line: once in eight samples; the step passes nothing but `self`.
    #[cold]
    #[inline(never)]
    fn close_block(&mut self) {
        let ts = self.model.ts();
        let (x, var_w) = (self.x, self.p.p22);
        let (disc, psi0) = (self.model.discrete(), self.nominal.0);
        if let Some(w) = &mut self.consistency {
            let bad = flux_implausible(disc, self.tracking.as_ref(), psi0, w.active_flux, &x);
            w.update_drift(x[3], x[2] * ts, var_w * ts * ts, (x[0], x[1]), bad);
        }
    }

    /// The tracking's slow work after a committed step, when due (a full window of the split
    /// filter, the reported deviations).
    #[inline(always)]
    pub(super) fn tracker_housekeeping(&mut self) {
        if let Some(Tracking { t, slow }) = &mut self.tracking
            && t.housekeeping_due(&slow.k)
        {
            let troubled = self.consistency.as_ref().is_some_and(|c| c.inconsistent);
            t.housekeeping(slow, &self.x, troubled);
            self.refresh_rs_constants();
        }
    }

    /// The consistency check's EMF floor from the tracking's `Rs` deviation and flux (module
    /// docs, "Consistency"): `9 (sigma_Rs Ts / psi_f)^2`; and the told inverter voltage's,
    /// `9 (sigma_v Ts / psi_f)^2` with `sigma_v` half that voltage.
    pub(super) fn refresh_emf_floor(&mut self) {
        let ts = self.model.ts();
        let nine = to_t::<T>(9.0);
        // The tracked flux and `Rs` deviation, else the configured flux (no `Rs` term).
        let (psi, rs_sigma) = match &self.tracking {
            Some(Tracking { t, .. }) => (t.psi, Some(t.rs_sigma)),
            None => (self.nominal.0, None),
        };
        if let Some(c) = &mut self.consistency
            && psi > T::zero()
        {
            if let Some(sigma) = rs_sigma {
                let r = sigma * ts / psi;
                c.emf_floor = nine * r * r;
            }
            let v = self.inverter.0 * to_t(INVERTER_VOLTAGE_SIGMA_SHARE) * ts / psi;
            c.emf_floor_v = nine * v * v;
        }
    }

    /// Recomputes the step's constants for the tracked `Rs` when it has changed (after the
    /// split filter's window, `set_parameters`, a restart), and the EMF floor. Only a cache: a step whose `Rs`
    /// differs from the cached one computes its constants itself.
    #[cold]
    #[inline(never)]
    pub(super) fn refresh_rs_constants(&mut self) {
        self.refresh_emf_floor();
        if let Some(Tracking { t, .. }) = &self.tracking
            && t.rs != self.rs_constants.0
        {
            // At the configured flux, so that the cache is a function of `Rs` alone (its `c`
            // is replaced each step).
            self.rs_constants = (t.rs, self.model.discrete_at(self.nominal.0, t.rs));
        }
    }
}

/// The model fit at a block's end (module docs of [`observer`](crate::observer), "Model fit"):
/// `true` when the flux the model reads the angle from is not one a magnet can give. Either
/// the tracked `psi_f` is at a bound of its range (within 2 % of the configured `psi0`: the
/// data ask for a flux outside the range declared plausible), or the active flux
/// `psi_a = psi_f + (Ld - Lq) i_d` (the tracked flux, `i_d` in the estimated frame) is below
/// zero: the model reads the EMF of a flux its wrong d current invented, pointing against the
/// magnet. Compared as `psi_f / Lq + (Ld - Lq) / Lq i_d < 0` (no division).
/// Without `active_flux` (the observer on a flux map, whose flux is the map's, not the active
/// flux of the constants its configuration carries) only the tracked flux's bound applies
/// (tracking is off there, so none). Called at a block's end only
/// ([`PmsmObserver::close_block`]).
fn flux_implausible<T: Float>(
    disc: &Discrete<T>,
    tracking: Option<&Tracking<T>>,
    psi0: T,
    active_flux: bool,
    x: &Vector4<T>,
) -> bool {
    let (psi, pinned) = match tracking {
        Some(Tracking { t, slow }) => {
            let margin = psi0 * to_t(0.02);
            let k = &slow.k;
            (
                t.psi,
                t.psi <= k.psi_min + margin || t.psi >= k.psi_max - margin,
            )
        }
        None => (psi0, false),
    };
    let flux = if !active_flux {
        T::zero()
    } else if disc.salient {
        let (s, c) = x[3].sin_cos_angle();
        let id = x[0] * c + x[1] * s;
        psi * disc.inv_ls + disc.saliency * id
    } else {
        psi
    };
    // A NaN counts as implausible.
    let plausible = flux.is_finite() && flux >= T::zero();
    pinned || !plausible
}
