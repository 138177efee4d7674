//! Metrics of a run (docs/design.md, "Metrics"), computed on the fly (no trace needed).
//!
//! For an observer:
//!
//! - **angle error** `e_th = wrap(th_hat - th)`, electrical degrees: RMS, max `|e_th|` and mean
//!   (bias) over the **window**;
//! - **speed error** `w_hat - w_e`, electrical rad/s, RMS (also in % of the rated electrical
//!   speed) and max, over the window;
//! - **convergence time**: the first sample time after which `|e_th| < 5 deg` holds for the rest
//!   of the run (`None` when the last sample is not within 5 deg). Taken over the whole run,
//!   low speed included, exactly as the design defines it: an excursion during a speed reversal
//!   therefore counts.
//! - **window**: samples at or after the convergence time with `|w_e| >= 5 %` of rated speed.
//!   When the observer never converged, the window is every sample with `|w_e| >= 5 %` (so the
//!   errors show how far off it is) and `converged` is false.
//! - **NIS mean** over the window: about 2 (the measurement dimension) for a filter whose
//!   noise model matches the data.
//!
//! Streaming: a sample with `|e_th| >= 5 deg` restarts the window, so the window accumulated at
//! the end is exactly the one after the convergence time.
//!
//! The same scores are computed for the **controller's own observer** when it has one (`foc`'s
//! `f32` EKF), and for it also over the **closed-loop window**: the periods in which the
//! controller runs on that observer's angle (`foc` states `handover` and `closed_loop`) with
//! `|w_e| >= 5 %` of rated, i.e. its accuracy after the hand-over, which is what the drive
//! depends on (its docs/design.md, "Metrics" convergence time also counts the start-up and the
//! zero-speed crossings, where `foc` does not use it).
//!
//! For the run: simulated time, wall time and the real-time factor, and figures of the drive:
//! time to closed loop, the first fault, the speed error once settled (the reference constant
//! and no load step for [`SETTLE_S`]), peak current, tracking errors. The wall time and the
//! real-time factor are the only fields that differ between identical runs: `pmsm-sim run`
//! writes them to `timing.json`, the rest to `metrics.json`
//! ([`report::json_split`](crate::output::report::json_split)).
//!
//! For a sensorless start (`foc`: states `align`, then `open_loop`, then `handover`), the
//! **start-up** figures ([`StartupMetrics`]), over the first start of the run (from the first
//! `align` or `open_loop` period to the first `handover` period, or the end of the run):
//!
//! - **worst backward speed**: the largest `-speed` (true mechanical speed, rpm; 0 when the
//!   rotor never turned backwards), also in % of rated speed;
//! - **worst ramp deviation**: the largest `|speed - ramp speed|` (the controller's own speed
//!   reference, which under I/f is the ramp's speed) from 0.1 s ([`RAMP_SETTLE_S`]) after the
//!   end of the alignment to the hand-over, rpm and % of rated;
//! - **hand-over**: its time and speed (the ramp's speed in the last `open_loop` period before
//!   the first `handover` period, rpm and % of rated; the true speed then as well).
//!
//! For the **speed reversals** ([`ReversalMetrics`], window in [`ReversalScore`]): the
//! longest time outside closed loop within a reversal, the exits from closed loop and the
//! worst `|speed reference - speed|` (rpm and % of rated).

use serde::Serialize;

use crate::output::record::{ObserverSample, Sample, Truth};
use crate::scenario::{RPM_PER_RAD_S, Scenario};

mod drive;
pub use drive::*;

/// `|e_th|` below which the observer counts as converged, electrical degrees.
pub const CONVERGED_DEG: f64 = 5.0;

/// Whether an angle error (deg) counts as converged: `|e| <` [`CONVERGED_DEG`] (NaN does not).
#[inline]
pub(crate) fn is_converged(angle_error_deg: f64) -> bool {
    !(angle_error_deg.abs() >= CONVERGED_DEG || angle_error_deg.is_nan())
}
/// Samples with `|w_e|` below this fraction of the rated speed are left out of the window.
pub const LOW_SPEED_FRACTION: f64 = 0.05;
/// The speed counts as settled once the speed reference has been constant, and the load
/// torque has not jumped (by more than [`LOAD_STEP_FRACTION`] of the rated torque from one
/// period to the next), for this long, s.
pub const SETTLE_S: f64 = 0.2;
/// A load change larger than this fraction of the rated torque within one period is a step
/// (restarts the settling time); fan loads and ramps change less.
pub const LOAD_STEP_FRACTION: f64 = 0.01;

/// The ramp deviation of the start-up is scored from this long after the alignment, s.
pub const RAMP_SETTLE_S: f64 = 0.1;

/// Scores of one observer over one run (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ObserverMetrics {
    /// Whether `|e_th| < 5 deg` holds at the end of the run.
    pub converged: bool,
    /// Convergence time, s (`None`: not converged).
    pub convergence_time_s: Option<f64>,
    /// Samples in the window.
    pub window_samples: usize,
    /// Window length, s (sum of its samples' periods).
    pub window_s: f64,
    /// RMS angle error over the window, electrical degrees.
    pub angle_error_rms_deg: f64,
    /// Largest `|e_th|` over the window, electrical degrees.
    pub angle_error_max_deg: f64,
    /// Mean angle error (bias) over the window, electrical degrees.
    pub angle_error_mean_deg: f64,
    /// RMS speed error over the window, electrical rad/s.
    pub speed_error_rms_rad_s: f64,
    /// RMS speed error over the window, % of the rated electrical speed.
    pub speed_error_rms_pct: f64,
    /// Largest `|w_hat - w_e|` over the window, electrical rad/s.
    pub speed_error_max_rad_s: f64,
    /// Fraction of the window in which the observer reported `Tracking`, %.
    pub tracking_pct: f64,
    /// Fraction of the whole run (start-up and low speed included) in which the observer
    /// reported `Tracking`, %.
    pub tracking_run_pct: f64,
    /// Samples of the whole run with status `Tracking` while more than 45 deg off (an honest
    /// status has none).
    pub tracking_while_lost: usize,
    /// Mean normalized innovation squared over the window.
    pub nis_mean: f64,
    /// Its flux linkage (tracked, or the configured one) at the last sample against the
    /// plant's then, %.
    pub psi_f_error_end_pct: f64,
    /// Its stator resistance (tracked, or the configured one) at the last sample against the
    /// plant's then, %.
    pub rs_error_end_pct: f64,
}

/// An estimate more than this far off (deg el.) has lost the rotor: its status must not be
/// `Tracking`.
pub const LOST_DEG: f64 = 45.0;

/// Running sums of an observer's errors over a window: the one accumulator behind every
/// score of the simulator (these metrics, the suite's rows, the fault suite's worst error).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Sums {
    pub(crate) n: usize,
    /// Periods in the window without an estimate (the observer's step failed).
    pub(crate) failures: usize,
    pub(crate) sum_e: f64,
    pub(crate) sum_e2: f64,
    pub(crate) max_e: f64,
    pub(crate) sum_w2: f64,
    pub(crate) max_w: f64,
    pub(crate) tracking: usize,
    /// Samples with status `Tracking` while more than [`LOST_DEG`] off.
    pub(crate) tracking_lost: usize,
    /// Samples more than [`LOST_DEG`] off.
    pub(crate) lost: usize,
    pub(crate) sum_nis: f64,
}

impl Sums {
    #[inline]
    pub(crate) fn add(&mut self, e: f64, ew: f64, tracking: bool, nis: f64) {
        self.n += 1;
        self.sum_e += e;
        self.sum_e2 += e * e;
        self.max_e = self.max_e.max(e.abs());
        self.sum_w2 += ew * ew;
        self.max_w = self.max_w.max(ew.abs());
        self.tracking += usize::from(tracking);
        let lost = e.abs() > LOST_DEG;
        self.tracking_lost += usize::from(tracking && lost);
        self.lost += usize::from(lost);
        self.sum_nis += nis;
    }

    /// Adds an observer's scored sample.
    #[inline]
    pub(crate) fn add_sample(&mut self, s: &ObserverSample) {
        self.add(s.angle_error_deg, s.speed_error_rad_s, s.tracking, s.nis);
    }

    /// Adds a period without an estimate.
    #[inline]
    pub(crate) fn add_failure(&mut self) {
        self.failures += 1;
    }

    /// RMS angle error over the window, deg (NaN when empty).
    pub(crate) fn angle_rms_deg(&self) -> f64 {
        (self.sum_e2 / self.n as f64).sqrt()
    }

    /// Mean angle error over the window, deg (NaN when empty).
    pub(crate) fn angle_mean_deg(&self) -> f64 {
        self.sum_e / self.n as f64
    }

    /// Share of the samples with status `Tracking`, % (0 when empty).
    pub(crate) fn tracking_pct(&self) -> f64 {
        100.0 * self.tracking as f64 / self.n.max(1) as f64
    }

    /// RMS speed error over the window, rad/s el. (NaN when empty).
    pub(crate) fn speed_rms_rad_s(&self) -> f64 {
        (self.sum_w2 / self.n as f64).sqrt()
    }
}

/// Streaming scorer of one observer (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ObserverScore {
    rated_omega_e_rad_s: f64,
    w_min: f64,
    t_first: Option<f64>,
    /// Time of the first sample of the present run of `|e| < 5 deg`.
    run_start: Option<f64>,
    /// Window since `run_start`.
    window: Sums,
    /// Every sample above the low-speed limit (the window when never converged).
    all: Sums,
    /// The last sample's parameters: estimated and true `psi_f`, `Rs`.
    params: [f64; 4],
    /// Every sample of the whole run (start-up and low speed included): the status shares.
    run: Sums,
}

impl ObserverScore {
    /// A scorer for a motor rated at `rated_omega_e_rad_s` (electrical).
    pub fn new(rated_omega_e_rad_s: f64) -> Self {
        Self {
            rated_omega_e_rad_s,
            w_min: LOW_SPEED_FRACTION * rated_omega_e_rad_s,
            t_first: None,
            run_start: None,
            window: Sums::default(),
            all: Sums::default(),
            params: [f64::NAN; 4],
            run: Sums::default(),
        }
    }

    /// Records the parameters of the latest sample: the observer's `psi_f`, `Rs` and the
    /// plant's (for the errors at the end).
    #[inline]
    pub fn params(&mut self, est: &ObserverSample, truth: &Truth) {
        self.params = [est.psi_f_wb, est.rs_ohm, truth.psi_f_wb, truth.rs_ohm];
    }

    /// Adds one sample: time, true electrical speed, and the observer's sample.
    #[inline]
    pub fn push(&mut self, t_s: f64, omega_e_true_rad_s: f64, est: &ObserverSample) {
        if self.t_first.is_none() {
            self.t_first = Some(t_s);
        }
        let e = est.angle_error_deg;
        self.run.add_sample(est);
        if !is_converged(e) {
            self.run_start = None;
            self.window = Sums::default();
        } else if self.run_start.is_none() {
            self.run_start = Some(t_s);
        }
        if omega_e_true_rad_s.abs() >= self.w_min {
            let ew = est.speed_error_rad_s;
            self.all.add(e, ew, est.tracking, est.nis);
            if self.run_start.is_some() {
                self.window.add(e, ew, est.tracking, est.nis);
            }
        }
    }

    /// The metrics so far, with samples of period `ts_s`; `None` before the first sample.
    pub fn finish(&self, ts_s: f64) -> Option<ObserverMetrics> {
        let first = self.t_first?;
        let converged = self.run_start.is_some();
        let s = if converged { &self.window } else { &self.all };
        let nf = s.n as f64;
        let speed_rms = s.speed_rms_rad_s();
        Some(ObserverMetrics {
            converged,
            convergence_time_s: self.run_start.map(|t| t - first),
            window_samples: s.n,
            window_s: nf * ts_s,
            angle_error_rms_deg: s.angle_rms_deg(),
            angle_error_max_deg: if s.n > 0 { s.max_e } else { f64::NAN },
            angle_error_mean_deg: s.angle_mean_deg(),
            speed_error_rms_rad_s: speed_rms,
            speed_error_rms_pct: 100.0 * speed_rms / self.rated_omega_e_rad_s,
            speed_error_max_rad_s: if s.n > 0 { s.max_w } else { f64::NAN },
            tracking_pct: 100.0 * s.tracking as f64 / nf,
            tracking_run_pct: self.run.tracking_pct(),
            tracking_while_lost: self.run.tracking_lost,
            nis_mean: s.sum_nis / nf,
            psi_f_error_end_pct: 100.0 * (self.params[0] / self.params[2] - 1.0),
            rs_error_end_pct: 100.0 * (self.params[1] / self.params[3] - 1.0),
        })
    }
}

impl ObserverMetrics {
    /// Scores the observer that `pick` selects from each sample of a recorded trace; `None`
    /// when some sample has no estimate from it or the trace is empty.
    pub fn compute(
        samples: &[Sample],
        ts_s: f64,
        rated_omega_e_rad_s: f64,
        pick: impl Fn(&Sample) -> Option<ObserverSample>,
    ) -> Option<Self> {
        let mut score = ObserverScore::new(rated_omega_e_rad_s);
        for s in samples {
            let est = pick(s)?;
            score.push(s.t_s, s.truth.omega_e_rad_s, &est);
            score.params(&est, &s.truth);
        }
        score.finish(ts_s)
    }
}

/// The controller's own observer over the closed-loop window (module docs): where the
/// controller runs on its angle and `|w_e| >= 5 %` of rated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ClosedLoopObserverMetrics {
    /// Samples in the window.
    pub window_samples: usize,
    /// Window length, s.
    pub window_s: f64,
    /// RMS angle error, electrical degrees.
    pub angle_error_rms_deg: f64,
    /// Largest `|e_th|`, electrical degrees.
    pub angle_error_max_deg: f64,
    /// Mean angle error (bias), electrical degrees.
    pub angle_error_mean_deg: f64,
    /// RMS speed error, electrical rad/s.
    pub speed_error_rms_rad_s: f64,
    /// Largest speed error, electrical rad/s.
    pub speed_error_max_rad_s: f64,
}

/// Everything reported about one run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunMetrics {
    /// Scenario name.
    pub scenario: String,
    /// The controller (one line).
    pub controller: String,
    /// How the run ended (`completed`, or why it stopped early).
    pub end: String,
    /// PWM periods simulated.
    pub periods: usize,
    /// PWM period, s.
    pub ts_s: f64,
    /// Simulated time, s.
    pub simulated_s: f64,
    /// Wall-clock time of the simulation loop, s (logging included when it was on).
    pub wall_time_s: f64,
    /// Simulated seconds per wall-clock second.
    pub real_time_factor: f64,
    /// Rated electrical speed, rad/s (the 5 % low-speed exclusion and the % figures).
    pub rated_omega_e_rad_s: f64,
    /// The project's default observer (lag-free EKF, scaled noise).
    pub observer: Option<ObserverMetrics>,
    /// The reference filter, when it was run and did not fail.
    pub seed_filter: Option<ObserverMetrics>,
    /// Why and where the reference filter was dropped, if it was.
    pub seed_filter_failure: Option<String>,
    /// The controller's own observer (`foc`'s `f32` EKF), when it has one.
    pub controller_observer: Option<ObserverMetrics>,
    /// The controller's own observer over the closed-loop window (after the hand-over).
    pub controller_observer_closed_loop: Option<ClosedLoopObserverMetrics>,
    /// The drive.
    pub drive: DriveMetrics,
    /// The sensorless start (`None`: the controller has no start-up sequence).
    pub startup: Option<StartupMetrics>,
    /// The speed reversals (`None`: the reference never changes sign).
    pub reversal: Option<ReversalMetrics>,
    /// Control periods skipped (`[skipped_cycles]`: the controller did not tick; set by the
    /// run loop; not written when 0).
    #[serde(skip_serializing_if = "is_zero_u64")]
    pub skipped_control_periods: u64,
}

fn is_zero_u64(n: &u64) -> bool {
    *n == 0
}

/// Streaming accumulator of every metric of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct MetricsAccumulator {
    observer: ObserverScore,
    reference_filter: Option<ObserverScore>,
    controller_observer: Option<ObserverScore>,
    closed_loop: ClosedLoopScore,
    drive: DriveScore,
    startup: StartupScore,
    reversal: ReversalScore,
    periods: usize,
    rated_omega_e_rad_s: f64,
}

impl MetricsAccumulator {
    /// An empty accumulator for `scenario`.
    pub fn new(scenario: &Scenario) -> Self {
        let rated = scenario.rated_speed_e_rad_s();
        Self {
            observer: ObserverScore::new(rated),
            reference_filter: scenario
                .observer
                .reference_filter
                .then(|| ObserverScore::new(rated)),
            controller_observer: None,
            closed_loop: ClosedLoopScore::new(rated),
            drive: DriveScore::new(scenario.rated_torque_nm),
            startup: StartupScore::new(scenario.rated_speed_rpm),
            reversal: ReversalScore::new(scenario.rated_speed_rpm),
            periods: 0,
            rated_omega_e_rad_s: rated,
        }
    }

    /// Adds one sample.
    #[inline]
    pub fn push(&mut self, s: &Sample) {
        self.periods += 1;
        self.observer
            .push(s.t_s, s.truth.omega_e_rad_s, &s.observer);
        self.observer.params(&s.observer, &s.truth);
        if let (Some(score), Some(est)) = (self.reference_filter.as_mut(), s.seed_filter.as_ref()) {
            score.push(s.t_s, s.truth.omega_e_rad_s, est);
            score.params(est, &s.truth);
        }
        if let Some(est) = s.controller_observer.as_ref() {
            let rated = self.rated_omega_e_rad_s;
            let score = self
                .controller_observer
                .get_or_insert_with(|| ObserverScore::new(rated));
            score.push(s.t_s, s.truth.omega_e_rad_s, est);
            score.params(est, &s.truth);
        }
        self.closed_loop.push(s);
        self.drive.push(s);
        self.startup.push(s);
        self.reversal.push(s);
    }

    /// Drops the reference filter's score (it failed and was dropped from the run).
    pub fn drop_reference_filter(&mut self) {
        self.reference_filter = None;
    }

    /// The metrics of the samples pushed so far.
    pub fn finish(
        &self,
        scenario: &Scenario,
        end: String,
        wall_time_s: f64,
        seed_filter_failure: Option<String>,
    ) -> RunMetrics {
        let ts = scenario.ts_s();
        let simulated = self.periods as f64 * ts;
        RunMetrics {
            scenario: scenario.name.clone(),
            controller: scenario.controller_description(),
            end,
            periods: self.periods,
            ts_s: ts,
            simulated_s: simulated,
            wall_time_s,
            real_time_factor: simulated / wall_time_s,
            rated_omega_e_rad_s: scenario.rated_speed_e_rad_s(),
            observer: self.observer.finish(ts),
            seed_filter: self.reference_filter.as_ref().and_then(|s| s.finish(ts)),
            seed_filter_failure,
            controller_observer: self.controller_observer.as_ref().and_then(|s| s.finish(ts)),
            controller_observer_closed_loop: self.closed_loop.finish(ts),
            drive: self.drive.finish(ts),
            startup: self.startup.finish(),
            reversal: self.reversal.finish(ts),
            skipped_control_periods: 0,
        }
    }
}

/// Mechanical speed in rpm from rad/s.
pub fn rpm(omega_mech_rad_s: f64) -> f64 {
    omega_mech_rad_s * RPM_PER_RAD_S
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::record::Sample;

    fn sample(t: f64, th_err_deg: f64, w: f64, w_hat: f64) -> Sample {
        let mut s = Sample {
            t_s: t,
            ..Sample::default()
        };
        s.truth.omega_e_rad_s = w;
        s.observer = ObserverSample {
            theta_e_rad: 0.0,
            omega_e_rad_s: w_hat,
            angle_error_deg: th_err_deg,
            speed_error_rad_s: w_hat - w,
            p_diag: [0.0; 4],
            nis: 2.0,
            tracking: true,
            ..ObserverSample::default()
        };
        s
    }

    #[test]
    fn convergence_window_and_streaming() {
        let samples = vec![
            sample(0.0, 57.0, 100.0, 0.0),
            sample(0.1, -4.8, 100.0, 100.0),
            sample(0.2, 10.0, 100.0, 100.0), // last bad one
            sample(0.3, 2.0, 100.0, 110.0),
            sample(0.4, 99.0, 1.0, 100.0), // below 5 % of rated (100): but still bad
            sample(0.5, -2.0, -100.0, -90.0),
        ];
        let m = ObserverMetrics::compute(&samples, 0.1, 100.0, |s| Some(s.observer));
        let m = m.expect("metrics");
        // Sample 4 is off by 99 deg: the convergence time counts low speed too.
        assert_eq!(m.convergence_time_s, Some(0.5));
        assert_eq!(m.window_samples, 1);
        assert!((m.angle_error_mean_deg + 2.0).abs() < 1e-9);
        assert!((m.speed_error_rms_rad_s - 10.0).abs() < 1e-9);
        assert!((m.speed_error_rms_pct - 10.0).abs() < 1e-9);
        assert!((m.nis_mean - 2.0).abs() < 1e-12);

        let mut s2 = samples.clone();
        s2[4].observer.angle_error_deg = 0.0;
        let m = ObserverMetrics::compute(&s2, 0.1, 100.0, |s| Some(s.observer)).expect("metrics");
        assert_eq!(m.convergence_time_s, Some(0.3));
        // Samples 3 and 5 (sample 4 is below 5 % of rated speed).
        assert_eq!(m.window_samples, 2);
        assert!((m.angle_error_rms_deg - 2.0).abs() < 1e-9);
        assert!((m.angle_error_mean_deg).abs() < 1e-9);
        assert!((m.angle_error_max_deg - 2.0).abs() < 1e-9);

        let mut s3 = samples;
        s3[5].observer.angle_error_deg = 57.0;
        let m = ObserverMetrics::compute(&s3, 0.1, 100.0, |s| Some(s.observer)).expect("metrics");
        assert!(!m.converged);
        assert_eq!(m.convergence_time_s, None);
        // Not converged: the window is every sample above 5 % of rated speed.
        assert_eq!(m.window_samples, 5);
        assert!(ObserverMetrics::compute(&s3, 0.1, 100.0, |s| s.seed_filter).is_none());
    }
}
