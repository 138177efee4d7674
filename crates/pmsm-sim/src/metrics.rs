//! Metrics of a run (`design.md` section 5).
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
//!
//! For the run: simulated time, wall time and the real-time factor, and a few sanity figures of
//! the drive.

use serde::Serialize;

use crate::scenario::Scenario;
use crate::sim::{ObserverSample, RunOutput, Sample};

/// `|e_th|` below which the observer counts as converged, electrical degrees.
pub const CONVERGED_DEG: f64 = 5.0;
/// Samples with `|w_e|` below this fraction of the rated speed are left out of the window.
pub const LOW_SPEED_FRACTION: f64 = 0.05;

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
}

impl ObserverMetrics {
    /// Scores the observer that `pick` selects from each sample; `None` when some sample has
    /// no estimate from it (e.g. a comparison filter that was not run or was dropped) or the
    /// trace is empty.
    pub fn compute(
        samples: &[Sample],
        ts_s: f64,
        rated_omega_e_rad_s: f64,
        pick: impl Fn(&Sample) -> Option<ObserverSample>,
    ) -> Option<Self> {
        let est: Vec<ObserverSample> = samples.iter().map(&pick).collect::<Option<_>>()?;
        let first = samples.first()?;
        let err_deg: Vec<f64> = samples
            .iter()
            .zip(&est)
            .map(|(s, e)| s.angle_error_deg(e))
            .collect();
        // Index of the first sample of the final run of |e| < 5 deg.
        let start = match err_deg.iter().rposition(|e| e.abs() >= CONVERGED_DEG) {
            None => Some(0),
            Some(last_bad) if last_bad + 1 < samples.len() => Some(last_bad + 1),
            Some(_) => None,
        };
        let convergence_time_s = start.map(|i| samples[i].t_s - first.t_s);
        let from = start.unwrap_or(0);
        let w_min = LOW_SPEED_FRACTION * rated_omega_e_rad_s;

        let mut n = 0usize;
        let (mut sum_e, mut sum_e2, mut max_e) = (0.0, 0.0, 0.0f64);
        let (mut sum_w2, mut max_w) = (0.0, 0.0f64);
        let mut tracking = 0usize;
        for i in from..samples.len() {
            let s = &samples[i];
            if s.omega_e_rad_s.abs() < w_min {
                continue;
            }
            let e = err_deg[i];
            let ew = s.speed_error_rad_s(&est[i]);
            n += 1;
            sum_e += e;
            sum_e2 += e * e;
            max_e = max_e.max(e.abs());
            sum_w2 += ew * ew;
            max_w = max_w.max(ew.abs());
            tracking += usize::from(est[i].tracking);
        }
        let nf = n as f64;
        let speed_rms = (sum_w2 / nf).sqrt();
        Some(Self {
            converged: start.is_some(),
            convergence_time_s,
            window_samples: n,
            window_s: nf * ts_s,
            angle_error_rms_deg: (sum_e2 / nf).sqrt(),
            angle_error_max_deg: if n > 0 { max_e } else { f64::NAN },
            angle_error_mean_deg: sum_e / nf,
            speed_error_rms_rad_s: speed_rms,
            speed_error_rms_pct: 100.0 * speed_rms / rated_omega_e_rad_s,
            speed_error_max_rad_s: if n > 0 { max_w } else { f64::NAN },
            tracking_pct: 100.0 * tracking as f64 / nf,
        })
    }
}

/// Sanity figures of the (sensored) drive.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DriveMetrics {
    /// Largest current vector magnitude, A.
    pub peak_current_a: f64,
    /// Largest `|speed reference - speed|`, mechanical rpm.
    pub max_speed_tracking_error_rpm: f64,
    /// Mechanical speed at the end of the run, rpm.
    pub final_speed_rpm: f64,
    /// Share of periods in which the voltage vector was limited, %.
    pub voltage_limited_pct: f64,
}

impl DriveMetrics {
    /// The figures of a trace.
    pub fn compute(samples: &[Sample]) -> Self {
        let mut peak = 0.0f64;
        let mut max_track = 0.0f64;
        let mut limited = 0usize;
        for s in samples {
            peak = peak.max(s.plant.i_alpha_a.hypot(s.plant.i_beta_a));
            let ref_rpm = s.speed_ref_mech_rad_s * crate::scenario::RPM_PER_RAD_S;
            max_track = max_track.max((ref_rpm - s.speed_rpm()).abs());
            limited += usize::from(s.voltage_limited);
        }
        Self {
            peak_current_a: peak,
            max_speed_tracking_error_rpm: max_track,
            final_speed_rpm: samples.last().map_or(0.0, Sample::speed_rpm),
            voltage_limited_pct: 100.0 * limited as f64 / samples.len().max(1) as f64,
        }
    }
}

/// Everything reported about one run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunMetrics {
    /// Scenario name.
    pub scenario: String,
    /// PWM periods simulated.
    pub periods: usize,
    /// PWM period, s.
    pub ts_s: f64,
    /// Simulated time, s.
    pub simulated_s: f64,
    /// Wall-clock time of the simulation loop, s.
    pub wall_time_s: f64,
    /// Simulated seconds per wall-clock second (plant, controller and every observer run).
    pub real_time_factor: f64,
    /// Rated electrical speed, rad/s (the 5 % low-speed exclusion and the % figures).
    pub rated_omega_e_rad_s: f64,
    /// The project's default observer (lag-free EKF, scaled noise).
    pub observer: Option<ObserverMetrics>,
    /// The seed's filter, when it was run and did not fail.
    pub seed_filter: Option<ObserverMetrics>,
    /// Why and where the seed filter was dropped, if it was.
    pub seed_filter_failure: Option<String>,
    /// The drive.
    pub drive: DriveMetrics,
}

impl RunMetrics {
    /// The metrics of a run of `scenario`.
    pub fn compute(scenario: &Scenario, run: &RunOutput) -> Self {
        let samples = &run.trace.samples;
        let ts = run.trace.ts_s;
        let rated = scenario.rated_speed_e_rad_s();
        Self {
            scenario: scenario.name.clone(),
            periods: samples.len(),
            ts_s: ts,
            simulated_s: run.simulated_s(),
            wall_time_s: run.wall_time_s,
            real_time_factor: run.real_time_factor(),
            rated_omega_e_rad_s: rated,
            observer: ObserverMetrics::compute(samples, ts, rated, |s| Some(s.observer)),
            seed_filter: if run.seed_filter_failure.is_some() {
                None
            } else {
                ObserverMetrics::compute(samples, ts, rated, |s| s.seed_filter)
            },
            seed_filter_failure: run
                .seed_filter_failure
                .map(|f| format!("sample {}: {}", f.k, f.error)),
            drive: DriveMetrics::compute(samples),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::PlantState;

    fn sample(t: f64, th_true: f64, th_hat: f64, w: f64, w_hat: f64) -> Sample {
        Sample {
            t_s: t,
            plant: PlantState {
                theta_e_rad: th_true,
                ..PlantState::default()
            },
            omega_e_rad_s: w,
            torque_nm: 0.0,
            i_meas_ab_a: [0.0; 2],
            u_ab_v: [0.0; 2],
            i_dq_ref_a: [0.0; 2],
            voltage_limited: false,
            speed_ref_mech_rad_s: 0.0,
            load_torque_nm: 0.0,
            observer: ObserverSample {
                theta_e_rad: th_hat,
                omega_e_rad_s: w_hat,
                tracking: true,
                nis: 0.0,
            },
            seed_filter: None,
        }
    }

    #[test]
    fn convergence_window_and_wrapping() {
        let d = 1f64.to_radians();
        let samples = vec![
            sample(0.0, 0.0, 1.0, 100.0, 0.0),        // 57 deg off
            sample(0.1, 3.1, -3.1, 100.0, 100.0),     // wraps: 4.8 deg off
            sample(0.2, 0.0, 10.0 * d, 100.0, 100.0), // 10 deg off: last bad one
            sample(0.3, 0.0, 2.0 * d, 100.0, 110.0),
            sample(0.4, 0.0, 99.0 * d, 1.0, 100.0), // below 5 % of rated (100): but still bad
            sample(0.5, 0.0, -2.0 * d, -100.0, -90.0),
        ];
        let m = ObserverMetrics::compute(&samples, 0.1, 100.0, |s| Some(s.observer));
        let m = m.expect("metrics");
        // Sample 4 is off by 99 deg: the convergence time counts low speed too.
        assert_eq!(m.convergence_time_s, Some(0.5));
        assert_eq!(m.window_samples, 1);
        assert!((m.angle_error_mean_deg + 2.0).abs() < 1e-9);
        assert!((m.speed_error_rms_rad_s - 10.0).abs() < 1e-9);
        assert!((m.speed_error_rms_pct - 10.0).abs() < 1e-9);

        let mut s2 = samples.clone();
        s2[4].observer.theta_e_rad = 0.0;
        let m = ObserverMetrics::compute(&s2, 0.1, 100.0, |s| Some(s.observer)).expect("metrics");
        assert_eq!(m.convergence_time_s, Some(0.3));
        // Samples 3 and 5 (sample 4 is below 5 % of rated speed).
        assert_eq!(m.window_samples, 2);
        assert!((m.angle_error_rms_deg - 2.0).abs() < 1e-9);
        assert!((m.angle_error_mean_deg).abs() < 1e-9);
        assert!((m.angle_error_max_deg - 2.0).abs() < 1e-9);

        let mut s3 = samples;
        s3[5].observer.theta_e_rad = 1.0;
        let m = ObserverMetrics::compute(&s3, 0.1, 100.0, |s| Some(s.observer)).expect("metrics");
        assert!(!m.converged);
        assert_eq!(m.convergence_time_s, None);
        assert!(ObserverMetrics::compute(&s3, 0.1, 100.0, |s| s.seed_filter).is_none());
    }
}
