//! Convergence of the default EKF's online `psi_f` tracking on a start-up with a load step
//! (docs/accuracy.md, "Online parameter tracking"), against the goal: told a flux 10 % off,
//! the tracked flux within 1 % of the truth and the angle error within 0.3 deg el. no later
//! than 0.1 s after the rotor passes 10 % of its rated speed.
//!
//! `cargo test --release -p pmsm-sim --test convergence -- --nocapture` prints the table.
//!
//! # Scenario
//!
//! Each surface reference motor of the suite (servo, industrial 2.2 kW, small fast) with the
//! suite's realistic sensing and inverter (noise, 12-bit ADC, offsets and gain errors, dead
//! time, one period of delay) and its fan load, driven by `foc` in sensored mode (the
//! trajectory does not depend on the observer under test) with the speed slew raised a
//! hundredfold, as in the suite. From standstill (rotor at 2 rad el., the observers start at
//! zero speed and angle):
//!
//! ```text
//! 0 - 0.2 s      speed reference ramp 0 -> 50 % rated (10 % is passed at about 0.04 s)
//! 0.2 - 0.4 s    50 % rated
//! 0.4 s          rated load torque steps on
//! 0.4 - 0.7 s    50 % rated, rated load (the speed loop recovers the dip)
//! ```
//!
//! The EKF (`ObserverConfig::new`, online `psi_f` and `Rs` tracking) without the start-up flux
//! (the M4F build, where it is not compiled) steps alongside, told `psi_f` +10 % and -10 % (and
//! the motor 100 K hot and cold: `psi_f` and `Rs` both off; reported, not held to the goal),
//! and once told the right motor (the reference below); then the same five with the start-up
//! flux (`ParameterTracking::transient_flux`, the default in host builds: the split filter's
//! windows of an acceleration correct the flux while it is frozen), each set against its own
//! filter told the right motor.
//!
//! # Measure
//!
//! `t10`: the first sample at which the true speed reaches 10 % of rated. Converged at `t`
//! when `|psi_f_hat / psi_f - 1| <= 1 %` and the angle error, averaged over the last
//! [`ANGLE_MEAN_S`] (the sensor noise alone moves single samples by up to 0.7 deg on the
//! 2.2 kW motor; the goal is about the estimate's bias), is within 0.3 deg el. The
//! convergence time is the first time after which both hold up to the load step; the load
//! step's transient (the speed dips by a sixth on the small fast motor, and the angle follows
//! a current step the model sees one period late) is excused for [`STEP_SETTLE_S`], after
//! which both must hold again to the end of the run. The angle error is taken twice: against
//! the filter told the right motor in the same run (what the wrong flux costs; the sensing's
//! own errors, the same for both, drop out) and against the truth.
//!
//! With the start-up flux (the host default) the goal is met on the servo (0.06 s after `t10`)
//! and, against the filter told the right motor, on the small fast motor (0.01-0.07 s; 0.07-0.11 s
//! against the truth); not on the 2.2 kW motor (0.27 s): its flux tracking starts at the ramp's
//! end, where the speed loop sheds its overshoot with the current through zero, the dead time is
//! compensated worst, and the angle moves 2.2 deg told the right motor too.
//!
//! Not met without the start-up flux (the M4F build; docs/accuracy.md has the table): converged
//! 0.10-0.18 s after `t10` on the servo, 0.27-0.34 s on the 2.2 kW motor, 0.28 s on the small fast
//! motor. The EKF's tracking is frozen while the speed estimate departs from its 64-sample
//! low-pass by more than 1 % (module docs of `ekf_core::observer::tracking`), which holds it off
//! through the whole ramp; it starts at the ramp's end. The test asserts the measured bounds.

use ekf_core::{EkfError, ObserverConfig, PmsmObserver};
use pmsm_sim::analysis::suite::{
    FAN_LOAD_FRACTION, MISMATCHES, Mismatch, SuiteMotor, SuiteOptions, suite_scenario,
};
use pmsm_sim::drive::foc_adapter::FocDrive;
use pmsm_sim::drive::rotor_observers::{Observer, ObserverEstimate};
use pmsm_sim::output::record::{ObserverSample, Sample};
use pmsm_sim::plant::load::{LoadTerm, Profile};
use pmsm_sim::scenario::{RPM_PER_RAD_S, Scenario};
use pmsm_sim::sim::{self, SideObserver};

/// Goal: converged no later than this after the rotor passes 10 % of rated speed, s.
const GOAL_S: f64 = 0.1;
/// Flux tolerance, fraction of the true `psi_f`.
const PSI_TOL: f64 = 0.01;
/// Angle tolerance, deg el.
const ANGLE_TOL_DEG: f64 = 0.3;
/// The angle error is averaged over this, s.
const ANGLE_MEAN_S: f64 = 0.005;
/// End of the speed ramp, s.
const RAMP_END_S: f64 = 0.2;
/// The rated load step, s.
const STEP_S: f64 = 0.4;
/// The load step's transient excused for this, s.
const STEP_SETTLE_S: f64 = 0.1;
/// End of the run, s.
const END_S: f64 = 0.7;
/// Speed of the run, fraction of rated.
const SPEED_FRACTION: f64 = 0.5;

/// The start-up scenario of one motor (module docs).
fn scenario(motor: SuiteMotor) -> Scenario {
    let mut sc = suite_scenario(motor, &SuiteOptions::default());
    sc.name = format!("convergence-{}", motor.name());
    sc.duration_s = END_S;
    sc.initial.speed_rpm = 0.0;
    let rpm = sc.rated_speed_rpm;
    sc.speed_ref_rpm = Profile::linear(vec![
        (0.0, 0.0),
        (RAMP_END_S, SPEED_FRACTION * rpm),
        (END_S, SPEED_FRACTION * rpm),
    ]);
    let w_rated = rpm / RPM_PER_RAD_S;
    let torque = sc.rated_torque_nm;
    sc.load = vec![
        LoadTerm::Fan {
            coefficient_nm_s2_rad2: FAN_LOAD_FRACTION * torque / (w_rated * w_rated),
        },
        LoadTerm::Step {
            time_s: STEP_S,
            before_nm: 0.0,
            after_nm: torque,
        },
    ];
    sc
}

/// The default EKF told a wrong motor, recording what the measure needs.
struct Told {
    case: Mismatch,
    /// With the start-up flux from the split filter's windows
    /// (`ParameterTracking::transient_flux`).
    transient: bool,
    obs: PmsmObserver<f64>,
    psi_true: f64,
    /// Per sample: `(t, true electrical speed, psi_f_hat / psi_f - 1, angle error deg,
    /// tracking)`.
    trace: Vec<(f64, f64, f64, f64, bool)>,
}

impl Observer for Told {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        Observer::step(&mut self.obs, u_prev, i_ab_a)
    }
}

impl SideObserver for Told {
    fn record(&mut self, s: &Sample, own: Result<ObserverSample, EkfError>) {
        let (psi, e, tracking) = match own {
            Ok(o) => (o.psi_f_wb, o.angle_error_deg, o.tracking),
            Err(_) => (f64::NAN, f64::NAN, false),
        };
        self.trace.push((
            s.t_s,
            s.truth.omega_e_rad_s,
            psi / self.psi_true - 1.0,
            e,
            tracking,
        ));
    }
}

/// Whether a case has converged, per sample, and from when.
struct Converged {
    /// Convergence time before the load step, s (`None`: not converged at the step).
    t_conv: Option<f64>,
    /// Largest flux error (%) and averaged angle error (deg) over `[t10 + GOAL_S, step)`.
    before: (f64, f64),
    /// The same from the end of the step's settling window to the end of the run.
    after: (f64, f64),
}

/// Trailing mean of `v` over `n` samples (`NaN` for the first `n - 1`).
fn trailing_mean(v: &[f64], n: usize) -> Vec<f64> {
    let mut mean = vec![f64::NAN; v.len()];
    let mut sum = 0.0;
    for k in 0..v.len() {
        sum += v[k];
        if k >= n {
            sum -= v[k - n];
        }
        if k + 1 >= n {
            mean[k] = sum / n as f64;
        }
    }
    mean
}

/// The measure (module docs) of the times `t`, flux errors `psi` (fractions) and averaged
/// angle errors `angle` (deg; `NaN` where not yet defined counts as not converged).
fn converged(t: &[f64], psi: &[f64], angle: &[f64], t10: f64) -> Converged {
    let good = |k: usize| psi[k].abs() <= PSI_TOL && angle[k].abs() <= ANGLE_TOL_DEG;
    let n_before = t.iter().take_while(|&&t| t < STEP_S).count();
    let t_conv = match (0..n_before).rev().find(|&k| !good(k)) {
        None => Some(t[0]),
        Some(k) if k + 1 < n_before => Some(t[k + 1]),
        Some(_) => None,
    };
    let worst = |from: f64, to: f64| {
        (0..t.len())
            .filter(|&k| t[k] >= from && t[k] < to)
            .fold((0.0f64, 0.0f64), |w, k| {
                // A NaN (failed step) makes the worst infinite.
                let p = psi[k].abs() * 100.0;
                let a = angle[k].abs();
                (
                    if p.is_nan() {
                        f64::INFINITY
                    } else {
                        w.0.max(p)
                    },
                    if a.is_nan() {
                        f64::INFINITY
                    } else {
                        w.1.max(a)
                    },
                )
            })
    };
    Converged {
        t_conv,
        before: worst(t10 + GOAL_S, STEP_S),
        after: worst(STEP_S + STEP_SETTLE_S, f64::INFINITY),
    }
}

/// One case's result.
struct Row {
    motor: &'static str,
    case: &'static str,
    /// With the start-up flux (`ParameterTracking::transient_flux`).
    transient: bool,
    t10: f64,
    /// The angle error against the truth.
    absolute: Converged,
    /// The angle error against the filter told the right motor in the same run.
    relative: Converged,
    /// Largest flux error from the start to the step, %.
    start_psi_pct: f64,
}

fn run(motor: SuiteMotor) -> Vec<Row> {
    let sc = scenario(motor);
    let ts = sc.ts_s();
    let truth = sc.observer_params();
    let right = Mismatch {
        name: "right motor",
        psi_f: 1.0,
        rs: 1.0,
        ls: 1.0,
    };
    let cases = std::iter::once(right).chain(
        MISMATCHES
            .iter()
            .filter(|m| m.is_psi_only() || m.name.starts_with("100 K"))
            .copied(),
    );
    let cases: Vec<Mismatch> = cases.collect();
    // The start-up flux is the default in host builds (the rows "on").
    assert!(
        ObserverConfig::new(truth, ts)
            .parameter_tracking
            .is_some_and(|t| t.transient_flux),
        "start-up flux on by default"
    );
    // Without the start-up flux first (the right motor at 0), then with it.
    let mut told: Vec<Told> = [false, true]
        .into_iter()
        .flat_map(|transient| cases.iter().map(move |m| (transient, *m)))
        .map(|(transient, m)| {
            let mut p = truth;
            p.psi_f_wb *= m.psi_f;
            p.rs_ohm *= m.rs;
            let mut cfg = ObserverConfig::new(p, ts);
            if let Some(t) = &mut cfg.parameter_tracking {
                t.transient_flux = transient;
            }
            let obs = PmsmObserver::new(&cfg).unwrap_or_else(|e| panic!("{}: {e}", m.name));
            Told {
                case: m,
                transient,
                obs,
                psi_true: truth.psi_f_wb,
                trace: Vec::new(),
            }
        })
        .collect();
    let mut cfg = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
    cfg.speed_slew_rad_s2 *= 100.0;
    let mut drive = FocDrive::new(&cfg, 0.0, None).unwrap_or_else(|e| panic!("{e}"));
    let out = {
        let mut side: Vec<&mut dyn SideObserver> = told
            .iter_mut()
            .map(|t| t as &mut dyn SideObserver)
            .collect();
        sim::run_with_side_observers(&sc, &mut drive, Default::default(), &mut side)
            .unwrap_or_else(|e| panic!("{}: {e}", sc.name))
    };
    assert!(out.end.is_completed(), "{}", out.end.describe());
    let w10 = 0.1 * sc.rated_speed_e_rad_s();
    let n_mean = ((ANGLE_MEAN_S / ts).round() as usize).max(1);
    let t: Vec<f64> = told[0].trace.iter().map(|r| r.0).collect();
    let t10 = told[0]
        .trace
        .iter()
        .find(|r| r.1.abs() >= w10)
        .map_or(f64::NAN, |r| r.0);
    // The reference of each set: its filter told the right motor.
    let e_right = |transient: bool| -> Vec<f64> {
        let i = if transient { cases.len() } else { 0 };
        told[i].trace.iter().map(|r| r.3).collect()
    };
    let (e_default, e_transient) = (e_right(false), e_right(true));
    told.iter()
        .map(|c| {
            let psi: Vec<f64> = c.trace.iter().map(|r| r.2).collect();
            let e: Vec<f64> = c.trace.iter().map(|r| r.3).collect();
            let e_ref = if c.transient {
                &e_transient
            } else {
                &e_default
            };
            let rel: Vec<f64> = e.iter().zip(e_ref).map(|(a, b)| a - b).collect();
            let start_psi_pct = (0..t.len())
                .filter(|&k| t[k] < STEP_S)
                .map(|k| psi[k].abs() * 100.0)
                .fold(0.0, f64::max);
            Row {
                motor: motor.name(),
                case: c.case.name,
                transient: c.transient,
                t10,
                absolute: converged(&t, &psi, &trailing_mean(&e, n_mean), t10),
                relative: converged(&t, &psi, &trailing_mean(&rel, n_mean), t10),
                start_psi_pct,
            }
        })
        .collect()
}

#[test]
fn tracked_flux_and_angle_converge_within_0_1_s_of_10_percent_speed() {
    let rows: Vec<Row> = SuiteMotor::SURFACE.into_iter().flat_map(run).collect();
    let f = |v: Option<f64>, t10: f64| v.map_or("never".to_string(), |v| format!("{:.3}", v - t10));
    println!(
        "| motor | told | start-up flux | t10 (s) | converged - t10 (s), angle against the right-motor filter | worst psi_f % / angle deg, t10 + 0.1 s to the step | the same after the step + {STEP_SETTLE_S} s | converged - t10 (s), angle against the truth | worst angle deg against the truth, t10 + 0.1 s to the step / after | largest psi_f % before the step |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {:.3} | {} | {:.2} / {:.3} | {:.2} / {:.3} | {} | {:.3} / {:.3} | {:.2} |",
            r.motor,
            r.case,
            if r.transient { "on" } else { "off" },
            r.t10,
            f(r.relative.t_conv, r.t10),
            r.relative.before.0,
            r.relative.before.1,
            r.relative.after.0,
            r.relative.after.1,
            f(r.absolute.t_conv, r.t10),
            r.absolute.before.1,
            r.absolute.after.1,
            r.start_psi_pct,
        );
    }
    // Without the start-up flux the goal is not met (module docs): the asserts hold
    // the measured bounds, with a small margin, so that a regression fails and an improvement
    // shows in the table.
    for r in rows.iter().filter(|r| !r.transient) {
        let name = format!("{} told {}", r.motor, r.case);
        let rel = r.relative.t_conv.map_or(f64::INFINITY, |t| t - r.t10);
        let abs = r.absolute.t_conv.map_or(f64::INFINITY, |t| t - r.t10);
        // Measured: 0.181 / 0.344 / 0.282 s (servo / 2.2 kW / small fast, worst of +-10 %).
        let bound = match r.motor {
            "servo" => 0.2,
            "industrial_2k2" => 0.36,
            _ => 0.3,
        };
        // After the load step the flux is within 1 % and the angle within 0.3 deg, but on the
        // 2.2 kW motor, where the resistance tracking's first loaded windows move `Rs` by a
        // few per cent before it settles and the lumped flux follows (measured 1.08 % and
        // 0.05 deg told psi_f +10 %, 0.47 % and 0.31 deg told -10 %, 1.47 % told the right
        // motor).
        let (after_psi_pct, after_deg) = if r.motor == "industrial_2k2" {
            (1.6, 0.35)
        } else {
            (PSI_TOL * 100.0, ANGLE_TOL_DEG)
        };
        if r.case.starts_with("psi_f") {
            assert!(
                rel <= bound,
                "{name}: converged {rel:.3} s after t10 (bound {bound} s)"
            );
            assert!(
                abs <= bound,
                "{name}: {abs:.3} s against the truth (bound {bound} s)"
            );
            // Once converged it holds, and again after the load step's settling window.
            assert!(
                r.relative.before.0 <= PSI_TOL * 100.0 || rel > GOAL_S,
                "{name}: {:?}",
                r.relative.before
            );
            assert!(
                r.relative.after.0 <= after_psi_pct && r.relative.after.1 <= after_deg,
                "{name}: after the step {:?}",
                r.relative.after
            );
            assert!(r.absolute.after.1 <= ANGLE_TOL_DEG, "{name}");
        }
        if r.case == "right motor" {
            // Told the right motor, the tracked flux leaves the truth where the tracking starts
            // late in the ramp (measured up to 10.7 %, 2.2 kW motor); after the step it is
            // within 1 % (1.6 % on the 2.2 kW motor, above).
            assert!(r.start_psi_pct <= 12.0, "{name}: {:.2} %", r.start_psi_pct);
            assert!(
                r.relative.after.0 <= after_psi_pct,
                "{name}: {:?}",
                r.relative.after
            );
        }
        // The thermal cases (Rs 39 % off as well) are reported, not held to the goal: under
        // the rated load the lumped flux carries the Rs error until the split filter has
        // told them apart (measured up to 4.6 deg after the step, small fast motor cold).
        assert!(r.absolute.after.1 <= 5.0, "{name}: {:?}", r.absolute.after);
    }
    // With the start-up flux the goal is met on the servo and, against the filter told
    // the right motor, on the small fast motor (measured 0.063 / 0.062 s and 0.020 / 0.069 s
    // after t10; against the truth 0.071 / 0.057 s and 0.124 / 0.107 s: told the right motor
    // the small fast motor's angle is within 0.3 deg of the truth only 0.107 s after t10).
    // Not on the 2.2 kW motor (0.272 / 0.272 s): told the right motor its flux too is 2.5 %
    // off between t10 + 0.1 s and the step (the EKF's own tracking, from the ramp's end);
    // after the step, told psi_f -10 %, the resistance tracking's first loaded windows move
    // the lumped flux by 1.08 % and the angle by 0.52 deg before they settle.
    for r in rows.iter().filter(|r| r.transient) {
        let name = format!("{} told {}, start-up flux", r.motor, r.case);
        let rel = r.relative.t_conv.map_or(f64::INFINITY, |t| t - r.t10);
        let abs = r.absolute.t_conv.map_or(f64::INFINITY, |t| t - r.t10);
        let (rel_bound, abs_bound, after_psi_pct, after_deg) = match r.motor {
            "servo" => (GOAL_S, GOAL_S, PSI_TOL * 100.0, ANGLE_TOL_DEG),
            "industrial_2k2" => (0.3, 0.36, 1.6, 0.6),
            _ => (GOAL_S, 0.15, PSI_TOL * 100.0, ANGLE_TOL_DEG),
        };
        if r.case.starts_with("psi_f") {
            assert!(rel <= rel_bound, "{name}: {rel:.3} s (bound {rel_bound} s)");
            assert!(abs <= abs_bound, "{name}: {abs:.3} s (bound {abs_bound} s)");
            assert!(
                r.relative.after.0 <= after_psi_pct && r.relative.after.1 <= after_deg,
                "{name}: after the step {:?}",
                r.relative.after
            );
        }
        if r.case == "right motor" {
            // Measured 0.93 / 2.62 / 0.81 % (servo / 2.2 kW / small fast).
            assert!(r.start_psi_pct <= 3.5, "{name}: {:.2} %", r.start_psi_pct);
        }
        assert!(r.absolute.after.1 <= 5.0, "{name}: {:?}", r.absolute.after);
    }
}
