//! Rows with the d-axis excitation (module docs of [`super`], "Known limits"): foc sensored
//! adds a square wave of [`AMPLITUDE_FRACTION`] of the rated current to its d-current
//! reference ([`HALF_PERIOD`] samples per half, `foc::config::DExcitation`), and the default
//! EKF, told the true motor or `Ls` +-20 %, is handed the `Ls` of the excitation estimator
//! (`ekf_core::excitation`) fed with its own angle and speed, once the estimate's standard
//! deviation is within [`HANDOVER_SIGMA`] of it (`PmsmObserver::set_inductances`). `Rs` is
//! reported, not handed over (the default EKF has no `Rs` state; with parameter tracking on,
//! `set_parameters` would take it).
//!
//! The runs are the main run's plan (convergence at 50 %, windows at 10 %, 50 %, 100 % and
//! 100 % under rated load) and the reversal's (module [`super::reversal`]: +10 % to -10 %
//! under rated load) on the three surface motors, and the main run once more without the
//! excitation and without observers for the cost: the extra copper loss, the torque ripple
//! and the voltage the excitation takes, per window.

use std::cell::RefCell;
use std::rc::Rc;

use ekf_core::{ExcitationConfig, ExcitationEstimator, excitation_sign};

use super::*;

/// Excitation amplitude, fraction of the rated current (rated torque over `1.5 p psi_f`).
pub const AMPLITUDE_FRACTION: f64 = 0.1;
/// Samples per half period of the square wave (5 ms at 10 kHz).
pub const HALF_PERIOD: u32 = 50;
/// `Ls` is handed to the EKF once its standard deviation is at most this fraction of it.
pub const HANDOVER_SIGMA: f64 = 0.02;
/// `Ls` from this fraction of rated speed on; the excitation is off below it.
pub const MIN_LS_SPEED_FRACTION: f64 = 0.2;
/// Goal: RMS angle error (deg el.) with the excitation at >= 50 % speed, any case.
pub const GOAL_RMS_DEG: f64 = 0.5;
/// Goal: RMS angle error (deg el.) with the excitation at 10 % speed, any case.
pub const GOAL_LOW_SPEED_RMS_DEG: f64 = 1.0;
/// The known limit of a failing reversal row with the excitation (seeds 2 and 3; seed 1 passes).
pub const KNOWN_LIMIT_REVERSAL: &str = "known limit: with the d excitation on above 20 % of rated speed, the reversal under load at 10 % misses 1 deg on the 2.2 kW motor on some noise seeds (the Ls estimate from the no-load pairs, up to 7.6 % high: the dead-time compensation's residual with the current noise, docs/accuracy.md)";
/// Goal: `|Ls|` estimate error (%) at the end of a window at >= 50 % speed.
pub const GOAL_LS_PCT: f64 = 5.0;

/// The cases: the true motor and the two `Ls` mismatches.
const CASES: [(&str, f64); 3] = [("exact", 1.0), ("Ls +20 %", 1.2), ("Ls -20 %", 0.8)];

/// One EKF with the excitation estimator, in one window.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExcitationRow {
    /// Motor.
    pub motor: SuiteMotor,
    /// Case (`"exact"`, `"Ls +20 %"`, `"Ls -20 %"`: what the EKF is told at the start).
    pub case: &'static str,
    /// Condition (as [`SteadyRow::condition`]).
    pub condition: String,
    /// Speed, fraction of rated.
    pub speed_fraction: f64,
    /// Angle error over the window.
    pub angle: AngleStats,
    /// `Ls` estimate at the window's end against the truth, % (`None`: no estimate yet).
    pub ls_error_pct: Option<f64>,
    /// Its standard deviation, % of the truth.
    pub ls_sigma_pct: Option<f64>,
    /// The `Ls` in the EKF's model at the window's end against the truth, %.
    pub ekf_ls_error_pct: f64,
    /// `Rs` estimate at the window's end against the truth, % (`None`: no estimate yet).
    pub rs_error_pct: Option<f64>,
    /// Its standard deviation, % of the truth.
    pub rs_sigma_pct: Option<f64>,
    /// Pairs used for `Ls` by the window's end.
    pub ls_pairs: u32,
    /// Pairs rejected by the window's end.
    pub rejected_pairs: u32,
}

/// What the excitation costs in one window (against the same run without it).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExcitationCost {
    /// Motor.
    pub motor: SuiteMotor,
    /// Condition.
    pub condition: String,
    /// Excitation amplitude, A.
    pub amplitude_a: f64,
    /// Extra copper loss: the mean `i_d^2 + i_q^2` with less without, over the rated
    /// current squared, % (the rated copper loss's share; `a^2 / I_rated^2` = 1 % expected).
    pub copper_loss_pct: f64,
    /// Torque standard deviation over the window with / without the excitation, N m.
    pub torque_std_nm: [f64; 2],
    /// Largest `|u_dq|` over the linear limit `u_dc / sqrt 3` with / without, %.
    pub voltage_peak_pct: [f64; 2],
}

/// The excitation section of the report.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ExcitationReport {
    /// Rows, by motor, case, window.
    pub rows: Vec<ExcitationRow>,
    /// The cost, by motor, window.
    pub cost: Vec<ExcitationCost>,
    /// Goals on the rows (they fail the exit code of `pmsm-sim suite`).
    pub checks: Vec<Check>,
}

/// The estimator's last estimate and the EKF's `Ls`, shared with the scoring.
#[derive(Clone, Copy, Debug, Default)]
struct Latest {
    rs: Option<(f64, f64)>,
    ls: Option<(f64, f64)>,
    ekf_ls: f64,
    ls_pairs: u32,
    rejected: u32,
}

/// The default EKF fed by the excitation estimator.
struct Excited {
    ekf: PmsmObserver<f64>,
    est: ExcitationEstimator<f64>,
    k: u32,
    latest: Rc<RefCell<Latest>>,
}

impl Observer for Excited {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        self.k = self.k.wrapping_add(1);
        let e = Observer::step(&mut self.ekf, u_prev, i_ab_a)?;
        let positive = excitation_sign(self.k, HALF_PERIOD);
        // Only while the EKF tracks (its frame turns with the rotor); a skipped sample
        // drops the half in progress.
        if e.tracking
            && let Ok(true) =
                self.est
                    .push(e.theta_e_rad, e.omega_e_rad_s, u_prev, i_ab_a, positive)
            && let Some(r) = self.est.estimate()
        {
            let mut l = self.latest.borrow_mut();
            l.rs = Some((r.rs_ohm, r.rs_sigma_ohm));
            l.ls = r.ls_h.map(|ls| (ls, r.ls_sigma_h));
            l.ls_pairs = r.ls_pairs;
            l.rejected = self.est.rejected_pairs();
            if let Some(ls) = r.ls_h
                && r.ls_sigma_h <= HANDOVER_SIGMA * ls
                && self.ekf.set_inductances(ls, ls).is_ok()
            {
                l.ekf_ls = ls;
            }
        }
        Ok(e)
    }
}

/// [`Scored`] with the estimator's state at each window's end.
struct ExcitedScored {
    scored: Scored,
    latest: Rc<RefCell<Latest>>,
    at_end: Vec<Latest>,
}

impl Observer for ExcitedScored {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        self.scored.step(u_prev, i_ab_a)
    }
}

impl SideObserver for ExcitedScored {
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>) {
        self.scored.record(sample, own);
        for (w, l) in self.scored.plan.windows.iter().zip(self.at_end.iter_mut()) {
            if sample.t_s >= w.3 && sample.t_s < w.4 {
                *l = *self.latest.borrow();
            }
        }
    }
}

/// Per window: sums of `i_d^2 + i_q^2`, torque, torque^2, the largest `|u_dq|` and samples.
struct CostSink {
    windows: Vec<(f64, f64)>,
    u_lin: f64,
    sums: Vec<[f64; 5]>,
}

impl crate::sim::SampleSink for CostSink {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        for (w, a) in self.windows.iter().zip(self.sums.iter_mut()) {
            if s.t_s >= w.0 && s.t_s < w.1 {
                let i = s.truth.i_dq_a;
                let u = s.control.telemetry.u_dq_ref_v;
                let t = s.truth.torque_nm;
                a[0] += i[0] * i[0] + i[1] * i[1];
                a[1] += t;
                a[2] += t * t;
                a[3] = a[3].max(u[0].hypot(u[1]) / self.u_lin);
                a[4] += 1.0;
            }
        }
        Ok(())
    }
}

impl CostSink {
    fn new(plan: &Plan, sc: &Scenario) -> Self {
        Self {
            windows: plan.windows.iter().map(|w| (w.3, w.4)).collect(),
            u_lin: sc.inverter.u_dc_v / 3f64.sqrt(),
            sums: vec![[0.0; 5]; plan.windows.len()],
        }
    }

    /// `(mean i^2, torque std, peak |u| / u_lin)` of window `k`.
    fn of(&self, k: usize) -> (f64, f64, f64) {
        let a = self.sums[k];
        let n = a[4].max(1.0);
        let mean = a[1] / n;
        (a[0] / n, (a[2] / n - mean * mean).max(0.0).sqrt(), a[3])
    }
}

/// The excitation rows of the selected surface motors (module docs).
pub fn excitation_rows(
    opts: &SuiteOptions,
    selected: &[SuiteMotor],
) -> Result<ExcitationReport, SimError> {
    let mut report = ExcitationReport::default();
    for &motor in selected.iter().filter(|m| !m.is_interior()) {
        for (plan, reversal) in [
            (Plan::main(opts.short), false),
            (Plan::reversal(opts.short), true),
        ] {
            motor_rows(opts, motor, &plan, reversal, &mut report)?;
        }
    }
    report.checks = report.evaluate();
    Ok(report)
}

/// The rows of one motor over one plan (the cost over the main run's: not `reversal`).
fn motor_rows(
    opts: &SuiteOptions,
    motor: SuiteMotor,
    plan: &Plan,
    reversal: bool,
    report: &mut ExcitationReport,
) -> Result<(), SimError> {
    {
        let mut sc = scenario_with(motor, opts, plan, INITIAL_ANGLE_RAD);
        sc.name = format!("suite-{}-excitation", motor.name());
        let m = &sc.motor;
        let (ls_true, rs_true) = (m.lq_h, m.rs_ohm);
        let i_rated = sc.rated_torque_nm / (1.5 * f64::from(m.pole_pairs) * m.psi_f_wb);
        let a = AMPLITUDE_FRACTION * i_rated;
        let ts = sc.ts_s();
        let min_w = MIN_LS_SPEED_FRACTION * sc.rated_speed_e_rad_s();
        let mut excited = Vec::new();
        for (i, &(_, ls)) in CASES.iter().enumerate() {
            let mut scored = Scored::new(ObserverKind::DefaultEkf, None, &sc, plan.clone())?;
            let mut params = sc.observer_params();
            params.ld_h *= ls;
            params.lq_h *= ls;
            let latest = Rc::new(RefCell::new(Latest {
                ekf_ls: params.lq_h,
                ..Latest::default()
            }));
            let est = ExcitationEstimator::new(&ExcitationConfig::new(a, HALF_PERIOD, ts, min_w))
                .map_err(|e| SimError::Scenario {
                file: sc.name.clone(),
                field: "excitation".into(),
                problem: e.to_string(),
            })?;
            scored.est = Box::new(Excited {
                ekf: PmsmObserver::new(&ObserverConfig::new(params, ts))?,
                est,
                k: 0,
                latest: latest.clone(),
            });
            // The case index stands in `told` only to tell the rows apart here.
            scored.told = Some(i);
            excited.push(ExcitedScored {
                scored,
                at_end: vec![Latest::default(); plan.windows.len()],
                latest,
            });
        }
        let mut drive = drive_with_excitation(&sc, a)?;
        let mut with = CostSink::new(plan, &sc);
        run_excited(&sc, &mut drive, &mut excited, &mut with)?;
        let mut without = CostSink::new(plan, &sc);
        if !reversal {
            let mut plain = sensored_drive(&sc)?;
            run_excited(&sc, &mut plain, &mut [], &mut without)?;
        }
        for (i, x) in excited.iter().enumerate() {
            let case = CASES[i].0;
            for (k, w) in plan.windows.iter().enumerate() {
                let l = &x.at_end[k];
                let pct = |v: f64, t: f64| 100.0 * (v / t - 1.0);
                report.rows.push(ExcitationRow {
                    motor,
                    case,
                    condition: w.0.to_string(),
                    speed_fraction: w.1,
                    angle: AngleStats::of(&x.scored.windows[k]),
                    ls_error_pct: l.ls.map(|v| pct(v.0, ls_true)),
                    ls_sigma_pct: l.ls.map(|v| 100.0 * v.1 / ls_true),
                    ekf_ls_error_pct: pct(l.ekf_ls, ls_true),
                    rs_error_pct: l.rs.map(|v| pct(v.0, rs_true)),
                    rs_sigma_pct: l.rs.map(|v| 100.0 * v.1 / rs_true),
                    ls_pairs: l.ls_pairs,
                    rejected_pairs: l.rejected,
                });
            }
        }
        for (k, w) in plan.windows.iter().enumerate().filter(|_| !reversal) {
            let (i2, t_std, u_pk) = with.of(k);
            let (i2_0, t_std0, u_pk0) = without.of(k);
            report.cost.push(ExcitationCost {
                motor,
                condition: w.0.to_string(),
                amplitude_a: a,
                copper_loss_pct: 100.0 * (i2 - i2_0) / (i_rated * i_rated),
                torque_std_nm: [t_std, t_std0],
                voltage_peak_pct: [100.0 * u_pk, 100.0 * u_pk0],
            });
        }
    }
    Ok(())
}

/// A sensored drive ([`sensored_drive`]) with the excitation on.
fn drive_with_excitation(
    sc: &Scenario,
    a: f64,
) -> Result<crate::drive::foc_adapter::FocDrive, SimError> {
    sensored_drive_with(sc, |cfg| {
        cfg.d_excitation = Some(foc::config::DExcitation {
            amplitude_a: a as f32,
            half_period_ticks: HALF_PERIOD,
            min_speed_rad_s: (MIN_LS_SPEED_FRACTION * sc.rated_speed_e_rad_s()) as f32,
        });
    })
}

/// One run with the excited observers alongside and a cost sink.
fn run_excited(
    sc: &Scenario,
    drive: &mut crate::drive::foc_adapter::FocDrive,
    excited: &mut [ExcitedScored],
    sink: &mut CostSink,
) -> Result<(), SimError> {
    let mut side: Vec<&mut dyn SideObserver> = excited
        .iter_mut()
        .map(|s| s as &mut dyn SideObserver)
        .collect();
    let opts = crate::sim::RunOptions {
        sinks: vec![sink],
        ..Default::default()
    };
    let out = run_with_side_observers(sc, drive, opts, &mut side)?;
    if !out.end.is_completed() {
        return Err(SimError::Stopped {
            t_s: out.end.stop_time_s().unwrap_or(0.0),
            reason: format!("suite scenario {}: {}", sc.name, out.end.describe()),
        });
    }
    Ok(())
}

impl ExcitationReport {
    /// The goals on the rows (module docs): RMS at most [`GOAL_RMS_DEG`] at >= 50 % speed
    /// and [`GOAL_LOW_SPEED_RMS_DEG`] at 10 %; the `Ls` estimate within [`GOAL_LS_PCT`] at
    /// >= 50 % speed.
    fn evaluate(&self) -> Vec<Check> {
        let mut checks = Vec::new();
        for r in &self.rows {
            let row = format!("{}, {}", r.condition, r.case);
            let rms_goal = if r.speed_fraction >= 0.5 {
                GOAL_RMS_DEG
            } else {
                GOAL_LOW_SPEED_RMS_DEG
            };
            let mut c = tables::check(
                "excitation: EKF RMS (deg)",
                r.motor,
                &row,
                r.angle.rms_deg,
                rms_goal,
            );
            if !c.pass && r.condition == reversal::CONDITION {
                c.known_limit = Some(KNOWN_LIMIT_REVERSAL);
            }
            checks.push(c);
            if r.speed_fraction >= 0.5 {
                checks.push(tables::check(
                    "excitation: |Ls estimate error| (%)",
                    r.motor,
                    &row,
                    r.ls_error_pct.map_or(f64::INFINITY, f64::abs),
                    GOAL_LS_PCT,
                ));
            }
        }
        checks
    }

    /// The section as markdown (empty without rows).
    pub fn to_markdown(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        if self.rows.is_empty() {
            return s;
        }
        let _ = writeln!(
            s,
            "\n## With the d-axis excitation (foc sensored, +-{} % of rated current, {HALF_PERIOD} samples per half; the default EKF handed the estimator's Ls)\n",
            100.0 * AMPLITUDE_FRACTION
        );
        let _ = writeln!(
            s,
            "| motor | told at start | row | RMS (deg) | max (deg) | mean (deg) | Ls est. err (%) | Ls sigma (%) | EKF Ls err (%) | Rs est. err (%) | Rs sigma (%) | Ls pairs | rejected |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        );
        let o = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        for r in &self.rows {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3} | {:.2} | {:.3} | {} | {} | {:.2} | {} | {} | {} | {} |",
                r.motor.name(),
                r.case,
                r.condition,
                r.angle.rms_deg,
                r.angle.max_deg,
                r.angle.mean_deg,
                o(r.ls_error_pct),
                o(r.ls_sigma_pct),
                r.ekf_ls_error_pct,
                o(r.rs_error_pct),
                o(r.rs_sigma_pct),
                r.ls_pairs,
                r.rejected_pairs
            );
        }
        let _ = writeln!(
            s,
            "\nCost (the same run without the excitation for reference):\n\n| motor | row | amplitude (A) | extra copper loss (% of rated) | torque std with / without (N m) | peak |u| / (u_dc / sqrt 3) with / without (%) |\n|---|---|---|---|---|---|"
        );
        for c in &self.cost {
            let _ = writeln!(
                s,
                "| {} | {} | {:.3} | {:.2} | {:.4} / {:.4} | {:.1} / {:.1} |",
                c.motor.name(),
                c.condition,
                c.amplitude_a,
                c.copper_loss_pct,
                c.torque_std_nm[0],
                c.torque_std_nm[1],
                c.voltage_peak_pct[0],
                c.voltage_peak_pct[1]
            );
        }
        let _ = writeln!(
            s,
            "\n| check | motor | row | value | limit | result |\n|---|---|---|---|---|---|"
        );
        super::tables::write_check_rows(&mut s, &self.checks);
        s
    }
}
