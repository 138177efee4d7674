//! Tuning on a `pmsm-sim` MCAP log: the log read into a [`LoggedRun`] (the voltages the observer was fed, by the simulator's rule), tuned, and the default filter replayed to check the log.

use super::*;

/// A run read back from a `pmsm-sim` MCAP log, aligned on the period.
#[derive(Clone, Debug)]
pub struct LoggedRun {
    /// The scenario the log was written for.
    pub scenario: Scenario,
    /// The voltage the simulator's observer was given for each period (held over
    /// `[t_k, t_k+1)`; module docs), V.
    pub u_ab: Vec<[f64; 2]>,
    /// Measured currents at `t_k`, A.
    pub i_ab: Vec<[f64; 2]>,
    /// True electrical angle, rad.
    pub theta_true: Vec<f64>,
    /// True electrical speed, rad/s.
    pub omega_true: Vec<f64>,
    /// The logged default observer's angle, rad.
    pub observer_theta: Vec<f64>,
    /// The logged default observer's NIS.
    pub observer_nis: Vec<f64>,
}

impl LoggedRun {
    /// Reads a log written by `pmsm-sim` (protobuf or JSON period channel).
    pub fn read(path: &Path) -> Result<Self, TuneError> {
        let raw = mcap_read::read_log(path)?;
        let sc = raw.scenario;
        let delay = sc.inverter.delay;
        let p = &raw.periods;
        // The simulator's rule (sim.rs): with the PWM on, the controller's expected voltage
        // for the duties now applied (its last tick's with the delay, this tick's without;
        // the first period with the delay has none: the commanded voltage of the applied
        // duties); zero with the PWM off.
        let u_ab = p
            .iter()
            .enumerate()
            .map(|(k, x)| {
                if !x.pwm_enabled {
                    [0.0; 2]
                } else if !delay {
                    x.u_ab_ref
                } else if k == 0 {
                    x.u_commanded
                } else {
                    p[k - 1].u_ab_ref
                }
            })
            .collect();
        Ok(Self {
            u_ab,
            i_ab: p.iter().map(|x| x.i_meas).collect(),
            theta_true: p.iter().map(|x| x.theta_true).collect(),
            omega_true: p.iter().map(|x| x.omega_true).collect(),
            observer_theta: p.iter().map(|x| x.observer_theta).collect(),
            observer_nis: p.iter().map(|x| x.observer_nis).collect(),
            scenario: sc,
        })
    }
}

/// Tolerance of [`McapTuneReport::replay_matches_log`], rad.
pub const REPLAY_TOL_RAD: f64 = 1e-6;

/// [`tune_qr`] on a log, with what the log adds.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct McapTuneReport {
    /// Scenario name.
    pub scenario: String,
    /// Angle-error window: `|omega_true|` at least this, rad/s electrical.
    pub min_speed_rad_s: f64,
    /// Periods in the log.
    pub periods: usize,
    /// The `R` the scenario's current sensor produces ([`sensor_r_ab`]), A^2.
    pub sensor_r: [[f64; 2]; 2],
    /// Largest difference between the default filter replayed on the log and the logged
    /// observer's angle, rad: 0 for a protobuf log (bit-exact doubles); a JSON log's decimal
    /// numbers may read back one unit in the last place off.
    pub replay_max_diff_rad: f64,
    /// `replay_max_diff_rad <= 1e-6`: the record was read as the simulator ran it.
    pub replay_matches_log: bool,
    /// The tuner's result (motor and `Ts` of the scenario's observer).
    pub report: TuneReport,
}

/// Reads a `pmsm-sim` MCAP log and runs [`tune_qr`] on it ([`tune_logged_run`]).
pub fn tune_qr_mcap(path: &Path, opts: &TuneOptions) -> Result<McapTuneReport, TuneError> {
    tune_logged_run(&LoggedRun::read(path)?, opts)
}

/// [`tune_qr`] on a run read from a log, with the true angle from the log and, unless set,
/// the angle-error window above 5 % of the scenario's rated speed; checks that the default
/// filter replayed on the log reproduces the logged observer.
pub fn tune_logged_run(run: &LoggedRun, opts: &TuneOptions) -> Result<McapTuneReport, TuneError> {
    let sc = &run.scenario;
    let motor = sc.observer_params();
    let ts = sc.ts_s();
    let mut o = *opts;
    if o.min_speed_rad_s.is_none() {
        o.min_speed_rad_s = Some(0.05 * sc.rated_speed_e_rad_s());
    }
    let truth = AngleTruth {
        theta_rad: &run.theta_true,
        omega_rad_s: Some(&run.omega_true),
    };
    let report = tune_qr(&motor, ts, &run.u_ab, &run.i_ab, Some(truth), &o)?;
    // Replay of the simulator's observer (its own configuration, zero initial state).
    let replay_max_diff_rad = match PmsmObserver::new(&sc.observer_config()) {
        Ok(mut obs) => {
            let mut prev = [0.0; 2];
            let mut diff = 0.0f64;
            for (k, i) in run.i_ab.iter().enumerate() {
                match obs.step(prev, *i) {
                    Ok(e) => {
                        let d = ekf_core::wrap_angle(e.theta_rad - run.observer_theta[k]).abs();
                        // NaN (a non-finite logged angle) counts as a mismatch.
                        diff = if d.is_nan() {
                            f64::INFINITY
                        } else {
                            diff.max(d)
                        };
                    }
                    Err(_) => diff = f64::INFINITY,
                }
                prev = run.u_ab[k];
            }
            diff
        }
        Err(_) => f64::INFINITY,
    };
    Ok(McapTuneReport {
        scenario: sc.name.clone(),
        min_speed_rad_s: o.min_speed_rad_s.unwrap_or(0.0),
        periods: run.i_ab.len(),
        sensor_r: sensor_r_ab(&sc.sensors),
        replay_max_diff_rad,
        replay_matches_log: replay_max_diff_rad <= REPLAY_TOL_RAD,
        report,
    })
}

impl McapTuneReport {
    /// The report as text: before/after table, the scenario's sensor `R`, the TOML snippet.
    pub fn render(&self, file: &str) -> String {
        use std::fmt::Write;
        let r = &self.report;
        let mut s = String::new();
        let ts_us = r.ts_s * 1e6;
        let _ = writeln!(s, "pmsm-sim tune: {file}");
        let _ = writeln!(
            s,
            "  scenario {}: {} periods, Ts = {ts_us} us, I_c = {:.4} A; first {} periods ({} s) \
             not scored, {} scored, {} rejected",
            self.scenario,
            self.periods,
            r.characteristic_current_a,
            r.skip,
            r.skip as f64 * r.ts_s,
            r.samples_scored,
            r.samples_rejected
        );
        let _ = writeln!(
            s,
            "  default filter replayed on the log: {} (largest angle difference {} rad)",
            if self.replay_matches_log {
                "matches the logged observer"
            } else {
                "DIFFERS from the logged observer (the record may not be what the observer saw)"
            },
            super::plain(four_digits(self.replay_max_diff_rad))
        );
        let _ = writeln!(
            s,
            "  search: R {:?}, {} filter runs, {}{}",
            r.r_shape,
            r.evaluations,
            if r.converged {
                "converged"
            } else {
                "NOT converged (evaluation budget used up)"
            },
            if r.at_bound.is_empty() {
                String::new()
            } else {
                format!("; on the search box: {}", r.at_bound.join(", "))
            }
        );
        let _ = writeln!(s, "\n  {:<34} {:>13} {:>13}", "", "default", "tuned");
        let mut row = |name: &str, a: String, b: String| {
            let _ = writeln!(s, "  {name:<34} {a:>13} {b:>13}");
        };
        let e = |v: f64| super::plain(four_digits(v));
        let (a, b) = (&r.start, &r.tuned);
        let cov_a = [a.sigma_z[0], a.sigma_z[1]].map(|x| (x * r.characteristic_current_a).powi(2));
        row("sigma_z alpha (x I_c)", e(a.sigma_z[0]), e(b.sigma_z[0]));
        row("sigma_z beta (x I_c)", e(a.sigma_z[1]), e(b.sigma_z[1]));
        row(
            "rho_z",
            format!("{:.4}", a.rho_z),
            format!("{:.4}", b.rho_z),
        );
        row("sigma_i (x I_c per sample)", e(a.sigma_i), e(b.sigma_i));
        row(
            "sigma_w (rad/sample per sample)",
            e(a.sigma_w),
            e(b.sigma_w),
        );
        row("sigma_th (rad per sample)", e(a.sigma_th), e(b.sigma_th));
        row("R alpha (A^2)", e(cov_a[0]), e(r.r[0][0]));
        row("R beta (A^2)", e(cov_a[1]), e(r.r[1][1]));
        row(
            "mean NIS (2 expected)",
            format!("{:.3}", r.before.mean_nis),
            format!("{:.3}", r.after.mean_nis),
        );
        row(
            "log-likelihood",
            format!("{:.1}", r.before.log_likelihood),
            format!("{:.1}", r.after.log_likelihood),
        );
        if let (Some(x), Some(y)) = (r.before.angle_error, r.after.angle_error) {
            let d = |v: f64| format!("{v:.4}");
            row("angle error rms (deg el.)", d(x.rms_deg), d(y.rms_deg));
            row("angle error mean (deg el.)", d(x.mean_deg), d(y.mean_deg));
            row(
                "angle error max |.| (deg el.)",
                d(x.max_abs_deg),
                d(y.max_abs_deg),
            );
            let _ = writeln!(
                s,
                "  (angle error over {} samples: after the skipped window, |w_e| >= {:.1} rad/s)",
                y.samples, self.min_speed_rad_s
            );
        }
        for (name, f) in [("default", &r.before.failure), ("tuned", &r.after.failure)] {
            if let Some(f) = f {
                let _ = writeln!(s, "  the {name} filter failed: {f}");
            }
        }
        let sr = &self.sensor_r;
        let _ = writeln!(
            s,
            "  R of the scenario's current sensor: [[{}, {}], [{}, {}]] A^2",
            e(sr[0][0]),
            e(sr[0][1]),
            e(sr[1][0]),
            e(sr[1][1])
        );
        let _ = writeln!(s, "\n{}", r.toml_snippet());
        s
    }
}

/// `v` rounded to four significant digits (printed with [`super::plain`]).
fn four_digits(v: f64) -> f64 {
    format!("{v:.3e}").parse().unwrap_or(v)
}
