//! The observer type [`PmsmObserver`]: its state, its construction and its accessors.

#[cfg(feature = "acceleration-feedforward")]
use super::feedforward::FeedforwardState;
use super::{AdaptationState, ObserverConfig, ObserverCounters, PmsmModel};
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use super::model::Discrete;
use super::safeguards::{BranchState, ConsistencyState, Events, GateState, HealthState};
use super::structured::Sym4;
use super::tracking::{Tracker, TrackerSlow};
use crate::ekf::{Correction, EkfError, finite};
use crate::{ConfigError, Float, to_t, wrap_angle};

/// The PMSM alpha-beta EKF observer (seed's model; module docs give equations and timing).
///
/// Its steps run a hand-scheduled update on the 10 unique entries of the symmetric covariance
/// (the `structured` module), which gives the same results as [`Ekf`](crate::Ekf) driven by
/// [`PmsmModel`]
/// (to rounding; tested) at a fraction of the cost, followed by the safeguards of the
/// configuration (branch check, innovation gate, covariance health; module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PmsmObserver<T: Float> {
    pub(super) model: PmsmModel<T>,
    pub(super) x: Vector4<T>,
    pub(super) p: Sym4<T>,
    pub(super) last: Correction<T, 2>,
    pub(super) inv_pole_pairs: T,
    /// Configured `(psi_f, Rs, reference temperature)`, reported when tracking is off.
    pub(crate) nominal: (T, T, T),
    /// Largest plausible `|u|^2` of an input voltage, V^2 (module docs, "Implausible
    /// input").
    pub(crate) u_max2: T,
    /// Largest plausible `|i|^2` of a measured current, A^2 (the same section).
    pub(crate) i_max2: T,
    pub(super) angle_var_limit: T,
    /// Salient motors: the filter has locked (angle tracked with settled innovations) and
    /// keeps the angle tracked since; the d-axis transient correction applies (module docs).
    pub(super) locked: bool,
    pub(super) branch: Option<BranchState<T>>,
    pub(super) gate: Option<GateState<T>>,
    pub(super) health: Option<HealthState<T>>,
    pub(crate) consistency: Option<ConsistencyState<T>>,
    pub(super) adaptation: Option<AdaptationState<T>>,
    /// The acceleration feedforward's state (`None` when off).
    #[cfg(feature = "acceleration-feedforward")]
    pub(super) feedforward: Option<FeedforwardState<T>>,
    /// `ObserverConfig::voltage_delay_s`.
    pub(super) voltage_delay: T,
    /// `ObserverConfig::inverter_voltage_v` and the linear band of its signs, A.
    pub(super) inverter: (T, T),
    /// A voltage delay, an inverter voltage or the speed noise adaptation is configured (their code runs out of
    /// line, behind this one test).
    pub(super) extras: bool,
    /// A voltage delay or an inverter voltage is configured (the voltage applied differs from
    /// the logged one): one test of a flag where the speed noise adaptation alone is on.
    pub(super) timing: bool,
    /// Steps left in which a fused angle ([`Self::correct_angle`]) makes the angle observable
    /// at any speed.
    pub(super) fused: u32,
    /// Steps refused in a row for a singular `S` or a non-finite result (counted with the
    /// covariance health check on; a plain field: reset by every step without a test).
    pub(super) refusals: u32,
    /// Online parameter tracking (`None` when off).
    pub(super) tracking: Option<Tracking<T>>,
    /// The step's constants at a tracked `Rs` (`model.discrete_at(_, rs)`) and that `Rs`:
    /// `Rs` changes only once per window of the split filter, so a step whose `Rs` is this one
    /// recomputes only the flux's term (refreshed by [`Self::refresh_rs_constants`]).
    pub(super) rs_constants: (T, Discrete<T>),
    pub(super) events: Events,
    pub(super) counters: ObserverCounters,
    /// The online input calibration (`ObserverConfig::input_calibration`; `None` when off).
    #[cfg(feature = "std")]
    pub(super) calibration: Option<std::boxed::Box<crate::calibration::OnlineCalibration<T>>>,
    /// The configuration it was built from (host builds: the priming's second pass is built
    /// from it, [`Self::prime_input_calibration`]).
    #[cfg(feature = "std")]
    pub(crate) config: std::boxed::Box<ObserverConfig<T>>,
}

/// The online parameter tracking: the per-step part and the slow part (its constants and
/// split filter), present together (one test of one `Option` on the step's path).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Tracking<T> {
    pub(super) t: Tracker<T>,
    pub(super) slow: TrackerSlow<T>,
}

/// The share of the told flux by which a priming copy's change of `Rs`, times the record's mean
/// `|i| / |w|`, must move the back-EMF per unit speed for the observer to be built again told
/// that `Rs` ([`PmsmObserver::prime_input_calibration`]; module docs of
/// [`crate::calibration`], "Told by the record").
#[cfg(feature = "std")]
pub const RETELL_SHARE: f64 = 0.0025;

/// The most times [`PmsmObserver::prime_input_calibration`] builds the observer again told a
/// priming copy's `Rs` (each time one more pass over the record).
#[cfg(feature = "std")]
pub const MAX_RETELLS: usize = 6;

/// The least share of a record's rows a priming copy must read `Tracking` on for its `Rs` to
/// be told ([`PmsmObserver::prime_input_calibration`]; module docs of [`crate::calibration`],
/// "Told by the record"): a copy that was mostly uncertain has no resistance to tell.
#[cfg(feature = "std")]
pub const RETELL_MIN_TRACKING: f64 = 0.25;

pub(super) fn zero_correction<T: Float>() -> Correction<T, 2> {
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
        #[cfg(not(feature = "acceleration-feedforward"))]
        if cfg.acceleration_feedforward.is_some() {
            return Err(ConfigError::FeedforwardNotCompiled);
        }
        #[cfg(not(feature = "std"))]
        if cfg.parameter_tracking.is_some_and(|t| t.transient_flux) {
            return Err(ConfigError::TransientFluxNotCompiled);
        }
        #[cfg(not(feature = "std"))]
        if cfg.parameter_tracking.is_some_and(|t| t.link_follows_data) {
            return Err(ConfigError::LinkFollowsDataNotCompiled);
        }
        let mut x0 = cfg.x0;
        x0[3] = wrap_angle(x0[3]);
        let ts = cfg.ts_s;
        let p0 = Sym4::from_matrix(&cfg.p0);
        let tracking = cfg.parameter_tracking.map(|t| {
            let m = &cfg.motor;
            let (t, slow) = Tracker::new(&t, m.psi_f_wb, m.rs_ohm, (m.ld_h, m.lq_h), ts);
            Tracking { t, slow }
        });
        let model = PmsmModel::new(cfg);
        let rs_constants = (
            cfg.motor.rs_ohm,
            model.discrete_at(cfg.motor.psi_f_wb, cfg.motor.rs_ohm),
        );
        let mut observer = Self {
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
            u_max2: {
                let u = to_t::<T>(super::MAX_INPUT_FLUX_RATIO) * cfg.motor.psi_f_wb / ts;
                u * u
            },
            i_max2: {
                let i = to_t::<T>(super::MAX_CURRENT_RATIO) * cfg.motor.characteristic_current_a();
                i * i
            },
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
                trace_bound: h.trace_factor * p0.trace(),
                current_bound: h.current_factor * cfg.motor.characteristic_current_a(),
                speed_bound: h.max_w_ts_rad / cfg.ts_s,
                p0,
                divergence_nis: h.divergence_nis,
                divergence_samples: h.divergence_samples,
            }),
            consistency: cfg.consistency.as_ref().map(ConsistencyState::new),
            adaptation: cfg
                .speed_noise_adaptation
                .as_ref()
                .map(AdaptationState::new),
            #[cfg(feature = "acceleration-feedforward")]
            feedforward: cfg.acceleration_feedforward.as_ref().map(|c| {
                let r = cfg.noise.r;
                FeedforwardState::new(c, &cfg.motor, cfg.ts_s, r[(0, 0)].max(r[(1, 1)]))
            }),
            voltage_delay: cfg.voltage_delay_s,
            inverter: (
                cfg.inverter_voltage_v,
                cfg.motor.characteristic_current_a() * to_t(0.02),
            ),
            extras: cfg.voltage_delay_s != T::zero()
                || cfg.inverter_voltage_v != T::zero()
                || cfg.speed_noise_adaptation.is_some(),
            timing: cfg.voltage_delay_s != T::zero() || cfg.inverter_voltage_v != T::zero(),
            fused: 0,
            refusals: 0,
            tracking,
            events: Events::default(),
            counters: ObserverCounters::default(),
            #[cfg(feature = "std")]
            calibration: if cfg.input_calibration {
                let d = crate::DriveConfig::new(cfg.motor, cfg.ts_s);
                Some(std::boxed::Box::new(
                    crate::calibration::OnlineCalibration::new(&d)?,
                ))
            } else {
                None
            },
            #[cfg(feature = "std")]
            config: std::boxed::Box::new(*cfg),
        };
        observer.refresh_emf_floor();
        Ok(observer)
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
        if let Some(Tracking { t, slow }) = &mut self.tracking {
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
        self.tracking
            .as_ref()
            .map(|k| (Vector4::from(k.t.s.x), k.t.s.c_pp))
    }

    /// The acceleration feedforward's learnt gain `k`, rad/s^2 of electrical speed per ampere
    /// of `i_q` (module docs, "Acceleration feedforward"); 0 while it has not seen enough
    /// current steps, or when it is off.
    pub fn acceleration_gain(&self) -> T {
        #[cfg(feature = "acceleration-feedforward")]
        return self.feedforward.as_ref().map_or(T::zero(), |f| f.k);
        #[cfg(not(feature = "acceleration-feedforward"))]
        T::zero()
    }

    /// Tracked `(psi_f, Rs)` (Wb, ohm); the configured values when tracking is off.
    pub fn parameters(&self) -> (T, T) {
        match &self.tracking {
            Some(k) => (k.t.psi, k.t.rs),
            None => (self.nominal.0, self.nominal.1),
        }
    }

    /// Sets the tracked `(psi_f, Rs)` (e.g. from a previous run or a commissioning) and
    /// clears their cross-covariance with the state; their variances are kept. The thermal
    /// link of the `Rs` split filter takes them as its temperature reference. Refused,
    /// nothing changed, when tracking is off, a value is not finite or outside the
    /// configured range.
    pub fn set_parameters(&mut self, psi_f_wb: T, rs_ohm: T) -> Result<(), EkfError> {
        let Some(Tracking { t, slow }) = &mut self.tracking else {
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

    /// Hands the observer new inductances `(L_d, L_q)` at run time (e.g. from the d-axis
    /// excitation's estimator, [`crate::excitation`]): the model's step constants, the
    /// tracking's cached constants at its `Rs` and the tracker's `(L_d, L_q)` are rebuilt
    /// from them; the state, covariance, `Q`, `R` (scaled from the configured motor by
    /// `ObserverConfig::new`: a tuning, kept) and every other setting are kept. `Rs` is not set
    /// here: with parameter tracking on it is the tracker's ([`Self::set_parameters`] sets
    /// it), otherwise the configured one. Refused, nothing changed, when a value is not
    /// finite or outside `[MIN_INDUCTANCE_H, MAX_INDUCTANCE_H]`, when `L_d == L_q` does not
    /// hold as it did at configuration (a surface motor stays a surface motor: the saliency
    /// decides the step's path and its safeguards' settings), when `L_q / L_d` leaves
    /// `[MIN_SALIENCY_RATIO, MAX_SALIENCY_RATIO]`, or (forward Euler) when `Rs Ts >= 2 L_q`.
    /// Not updated: the covariance health check's current bound and the acceleration
    /// feedforward's constants (both set from the configured motor; scales, not models).
    pub fn set_inductances(&mut self, ld_h: T, lq_h: T) -> Result<(), EkfError> {
        let lo = to_t::<T>(crate::MIN_INDUCTANCE_H);
        let hi = to_t::<T>(crate::MAX_INDUCTANCE_H);
        let in_range = |l: T| l >= lo && l <= hi;
        if !(in_range(ld_h) && in_range(lq_h)) {
            return Err(EkfError::NonFiniteInput);
        }
        let d = self.model.discrete();
        let ratio = lq_h / ld_h;
        if (ld_h != lq_h) != d.salient
            || ratio < to_t(crate::MIN_SALIENCY_RATIO)
            || ratio > to_t(crate::MAX_SALIENCY_RATIO)
            || (d.discretization == super::Discretization::ForwardEuler
                && self.model.rs() * d.ts >= to_t::<T>(2.0) * lq_h)
        {
            return Err(EkfError::NonFiniteInput);
        }
        self.model = self.model.with_inductances(self.nominal.0, ld_h, lq_h);
        if let Some(Tracking { slow, .. }) = &mut self.tracking {
            slow.k.ld = ld_h;
            slow.k.lq = lq_h;
        }
        let rs = self.rs_constants.0;
        self.rs_constants = (rs, self.model.discrete_at(self.nominal.0, rs));
        Ok(())
    }

    /// Sets the voltage timing at run time: `voltage_delay_s` and `inverter_voltage_v` as in
    /// [`ObserverConfig`](super::ObserverConfig) (e.g. from [`crate::calibration`]). Refused,
    /// nothing changed, when the delay is not finite or beyond two sample times, or the
    /// voltage not finite or outside `[0, 100]` V.
    pub fn set_voltage_errors(
        &mut self,
        voltage_delay_s: T,
        inverter_voltage_v: T,
    ) -> Result<(), EkfError> {
        let two_ts = self.model.ts() + self.model.ts();
        if !(voltage_delay_s >= -two_ts
            && voltage_delay_s <= two_ts
            && inverter_voltage_v >= T::zero()
            && inverter_voltage_v <= to_t(100.0))
        {
            return Err(EkfError::NonFiniteInput);
        }
        self.voltage_delay = voltage_delay_s;
        self.inverter.0 = inverter_voltage_v;
        self.timing = voltage_delay_s != T::zero() || inverter_voltage_v != T::zero();
        self.extras = self.timing || self.adaptation.is_some();
        self.refresh_emf_floor();
        Ok(())
    }

    /// The voltage timing in use, `(voltage_delay_s, inverter_voltage_v)`: the configured one,
    /// or the last set by [`Self::set_voltage_errors`] (the online input calibration's
    /// hand-overs set it too).
    pub fn voltage_errors(&self) -> (T, T) {
        (self.voltage_delay, self.inverter.0)
    }

    /// Primes the online input calibration (`ObserverConfig::input_calibration`) with a whole
    /// record, before the observer takes its first row (module docs of [`crate::calibration`],
    /// "Primed by the record" and "Told by the record"): a copy of this observer runs over
    /// `rows` (each row's `(u_prev, i, dt_s)`, as [`Self::step_dt`] takes them). With parameter
    /// tracking on, when the copy ends with a tracked `Rs` far enough from the told one (its
    /// change times the record's mean `|i| / |w|` above [`RETELL_SHARE`] of the flux), this
    /// observer is built again told that `Rs` (the reported winding temperature keeps the told
    /// `Rs` as its reference, the tracked `Rs` its bounds in ohms) and a copy of the new one
    /// runs over the rows once more; this repeats, at most [`MAX_RETELLS`] times, while the
    /// copy's change is above the share (a change against the previous one's direction is
    /// taken by half). The voltage delay the (last) copy's calibration handed over last and the
    /// innovation level its consistency check learnt (the baseline of the status) are set here.
    /// The inverter voltage, which the calibration hands over with `Rs`, is left to this
    /// observer's own hand-overs, and nothing else moves: its calibration starts afresh and
    /// hands over as it runs. Returns the delay set, or `None` when the copy handed over no
    /// other delay (e.g. a record whose filter flux leaves the told one: the hand-over guard
    /// holds everything); nothing at all changes when the calibration is off. Call it on a
    /// fresh observer (one built again starts from its initial state).
    #[cfg(feature = "std")]
    pub fn prime_input_calibration<I>(&mut self, rows: I) -> Option<T>
    where
        I: IntoIterator<Item = ([T; 2], [T; 2], T)> + Clone,
    {
        self.calibration.as_ref()?;
        let (mut copy, r, share) = self.primed_copy(rows.clone());
        // Each retelling starts the copy nearer the record's `Rs`, which its tracking then
        // moves by less: a fixed-point iteration. A change that turns back is taken by half (the
        // copies then bracket the record's `Rs`); the iteration ends when a change is within
        // the share or after `MAX_RETELLS`.
        let mut last: Option<T> = None;
        let retells = if share >= to_t(RETELL_MIN_TRACKING) {
            MAX_RETELLS
        } else {
            0
        };
        for _ in 0..retells {
            let Some(rs) = copy.tracking.as_ref().map(|k| k.t.rs) else {
                break;
            };
            let told = self.config.motor.rs_ohm;
            let change = rs - told;
            let (step, next) = if last.is_some_and(|prev| change * prev < T::zero()) {
                let half = change * to_t(0.5);
                (half, told + half)
            } else {
                (change, rs)
            };
            let Some(cfg) = copy.retold_config(r, next) else {
                break;
            };
            let Ok(retold) = Self::new(&cfg) else {
                break;
            };
            *self = retold;
            copy = self.primed_copy(rows.clone()).0;
            last = Some(step);
        }
        // The consistency check's innovation level, learnt over the whole record.
        if let (Some(c), Some(mine)) = (&copy.consistency, &mut self.consistency) {
            mine.baseline = c.baseline;
            mine.refresh();
        }
        let delay = copy.voltage_delay;
        if delay == self.voltage_delay {
            return None;
        }
        self.set_voltage_errors(delay, self.inverter.0).ok()?;
        Some(delay)
    }

    /// A copy of this observer after `rows` (a refused row changes nothing in the copy, as in
    /// the run that follows), the record's mean `|i| / |w|` over the rows the copy tracks
    /// above the tracking's minimum speed (0 when none): the ratio a resistance error is read
    /// against the flux with, and the share of the rows the copy read `Tracking` on.
    #[cfg(feature = "std")]
    fn primed_copy(&self, rows: impl IntoIterator<Item = ([T; 2], [T; 2], T)>) -> (Self, T, T) {
        let mut copy = self.clone();
        let min_speed2 = self
            .tracking
            .as_ref()
            .map_or(T::zero(), |k| k.slow.k.min_speed2);
        let (mut sum, mut n, mut tracked, mut total) = (T::zero(), 0_u32, 0_u32, 0_u32);
        for (u_prev, i, dt_s) in rows {
            total = total.saturating_add(1);
            if let Ok(e) = copy.step_dt(u_prev, i, dt_s) {
                let w = e.omega_e_rad_s;
                if e.status == crate::Status::Tracking {
                    tracked = tracked.saturating_add(1);
                    if w * w >= min_speed2 && w != T::zero() {
                        sum += (i[0] * i[0] + i[1] * i[1]).sqrt() / w.abs();
                        n += 1;
                    }
                }
            }
        }
        let r = if n > 0 {
            sum / to_t(f64::from(n))
        } else {
            T::zero()
        };
        let share = to_t::<T>(f64::from(tracked)) / to_t(f64::from(total.max(1)));
        (copy, r, share)
    }

    /// The configuration told `rs` (module docs of [`crate::calibration`], "Told by the
    /// record"), when its change from the told `Rs` times the record's mean `|i| / |w|` (`r`,
    /// the change of the back-EMF per unit speed it makes) is more than [`RETELL_SHARE`] of the
    /// told flux; `None` otherwise or with tracking off. The tracking's reference temperature
    /// becomes the winding temperature at `rs`, and its copper coefficient `alpha rs0 / rs`, so
    /// that the reported winding temperature keeps the told `Rs` as its reference
    /// (`T = T_ref + (Rs - rs0) / (alpha rs0)`, linear in `Rs`).
    #[cfg(feature = "std")]
    fn retold_config(&self, r: T, rs: T) -> Option<ObserverConfig<T>> {
        let tracking = self.tracking.as_ref()?;
        let k = &tracking.slow.k;
        if (rs - k.rs0).abs() * r <= to_t::<T>(RETELL_SHARE) * k.psi0 {
            return None;
        }
        let mut cfg = *self.config;
        let t = cfg.parameter_tracking.as_mut()?;
        t.reference_temperature_c = k.t_ref + (rs - k.rs0) * k.kelvin_per_ohm;
        t.rs_temperature_coefficient_per_k *= k.rs0 / rs;
        // The tracked `Rs` keeps its bounds in ohms (they are fractions of the told value).
        let [lo, hi] = t.rs_range;
        t.rs_range = [
            (lo * k.rs0 / rs).min(T::one()),
            (hi * k.rs0 / rs).max(T::one()),
        ];
        cfg.motor.rs_ohm = rs;
        Some(cfg)
    }

    /// The model's inductances `(L_d, L_q)`, H: the configured ones or the last set by
    /// [`Self::set_inductances`].
    pub fn inductances(&self) -> (T, T) {
        let d = self.model.discrete();
        let lq = T::one() / d.inv_ls;
        (lq / (T::one() + d.saliency), lq)
    }
}

#[cfg(all(test, feature = "std"))]
mod retell_tests {
    use super::*;

    #[test]
    fn a_retold_observer_keeps_the_told_bounds_and_temperature_scale() {
        let m = crate::MotorParams::<f64>::servo();
        let told = ObserverConfig::new(m, 1e-4);
        let mut obs = PmsmObserver::new(&told).unwrap();
        let rs0 = m.rs_ohm;
        let range = told.parameter_tracking.unwrap().rs_range;
        // A copy whose tracking ended 40 % above the told `Rs`.
        obs.tracking.as_mut().unwrap().t.rs = 1.4 * rs0;
        let k = obs.tracking.as_ref().unwrap().slow.k;
        let t_hot = obs.tracking.as_ref().unwrap().t.winding_temperature_c(&k);
        // A change below the share of the flux at this `|i| / |w|` is not retold.
        let small_r = 0.9 * RETELL_SHARE * m.psi_f_wb / (0.4 * rs0);
        assert!(obs.retold_config(small_r, 1.4 * rs0).is_none());
        let cfg = obs.retold_config(1.0, 1.4 * rs0).expect("retold");
        assert_eq!(cfg.motor.rs_ohm, 1.4 * rs0);
        let t = cfg.parameter_tracking.unwrap();
        // The bounds in ohms are the told ones; the temperature is read against the told `Rs`.
        for (new, old) in t.rs_range.iter().zip(range) {
            assert!((new * 1.4 * rs0 - old * rs0).abs() < 1e-12 * rs0);
        }
        let retold = PmsmObserver::new(&cfg).unwrap();
        let k2 = retold.tracking.as_ref().unwrap().slow.k;
        let t2 = retold
            .tracking
            .as_ref()
            .unwrap()
            .t
            .winding_temperature_c(&k2);
        assert!((t2 - t_hot).abs() < 1e-9, "{t2} vs {t_hot}");
        assert!((k2.rs_max - range[1] * rs0).abs() < 1e-12);
    }
}
