//! The scenario suite (`pmsm_sim::analysis::suite`, `pmsm-sim suite`) on its short run: the goals and
//! limits that hold are asserted; the ones the default EKF misses on realistic sensing are
//! named, with the weaker statement that holds there. (Debug profile: about 0.2 s per run.)

use pmsm_sim::analysis::suite::{
    self, GOAL_IPM_CONVERGENCE_S, GOAL_MEAN_DEG, GOAL_MISMATCH_LOW_SPEED_RMS_DEG,
    GOAL_MISMATCH_PSI_PCT, GOAL_MISMATCH_RMS_DEG, GOAL_RMS_RATIO, KNOWN_LIMIT_LS,
    LIMIT_LOAD_STEP_DEG, MISMATCHES, ObserverKind, SuiteMotor, SuiteOptions, SuiteReport,
    run_suite_motors, suite_scenario,
};

fn opts(ideal: bool) -> SuiteOptions {
    SuiteOptions {
        short: true,
        seed: 1,
        ideal,
    }
}

/// The short run on the surface motors (their rows are those of the whole suite: each motor
/// keeps its seed).
fn short(ideal: bool) -> SuiteReport {
    run_suite_motors(&opts(ideal), &SuiteMotor::SURFACE).unwrap_or_else(|e| panic!("suite: {e}"))
}

/// The short run on the interior motors.
fn short_interior(ideal: bool) -> SuiteReport {
    run_suite_motors(&opts(ideal), &SuiteMotor::INTERIOR).unwrap_or_else(|e| panic!("suite: {e}"))
}

/// Goals the default EKF misses on the realistic short run (measured, seed 1): the RMS ratio
/// on the small fast motor at 10 % (0.64) and 50 % (0.59) of rated speed.
const RMS_GOAL_MISSES: [(SuiteMotor, &str); 2] = [
    (SuiteMotor::SmallFast, "10 %"),
    (SuiteMotor::SmallFast, "50 %"),
];

#[test]
fn short_run_goals_and_limits() {
    let r = short(false);
    assert_eq!(r.motors.len(), 3);
    assert_eq!(r.steady.len(), 3 * 3 * 4);
    assert_eq!(r.transients.len(), 3 * 3);
    for m in &r.motors {
        assert_eq!(m.end, "completed", "{:?}", m.motor);
    }
    // w_e Ts at rated speed: servo 2000 rpm x 4, industrial 1500 rpm x 3, small fast 400 Hz.
    let wts = |m: SuiteMotor| {
        r.motors
            .iter()
            .find(|x| x.motor == m)
            .map_or(f64::NAN, |x| x.rated_w_ts_rad)
    };
    assert!((wts(SuiteMotor::Servo) - 0.0838).abs() < 1e-3);
    assert!((wts(SuiteMotor::Industrial2k2) - 0.0471).abs() < 1e-3);
    assert!((wts(SuiteMotor::SmallFast) - 0.2513).abs() < 1e-3);

    // Every absolute limit of the default EKF holds (RMS <= 1 deg, max <= 5 deg, speed RMS
    // <= 1 % of rated, converged from every start angle, load step <= 5 deg).
    let limits: Vec<_> = r
        .checks
        .iter()
        .filter(|c| c.name.starts_with("limit"))
        .collect();
    assert_eq!(limits.len(), 3 * 4 * 3 + 3 * 2);
    for c in &limits {
        assert!(
            c.pass,
            "{} {:?} {}: {} > {}",
            c.name, c.motor, c.row, c.value, c.limit
        );
    }

    for ekf in r
        .steady
        .iter()
        .filter(|x| x.observer == ObserverKind::DefaultEkf)
    {
        let base = r
            .steady_row(ObserverKind::FluxBaseline, ekf.motor, &ekf.condition)
            .unwrap_or_else(|| panic!("no baseline row"));
        let what = format!("{:?} {}", ekf.motor, ekf.condition);
        assert_eq!(ekf.failures + base.failures, 0, "{what}");
        assert!(ekf.samples > 1000 && ekf.samples == base.samples, "{what}");
        let ratio = ekf.angle_rms_deg / base.angle_rms_deg;
        if RMS_GOAL_MISSES.contains(&(ekf.motor, ekf.condition.as_str())) {
            // Missed goal: still better than the baseline.
            assert!(ratio < 0.8, "{what}: RMS ratio {ratio}");
        } else {
            assert!(ratio <= GOAL_RMS_RATIO, "{what}: RMS ratio {ratio}");
        }
        if ekf.speed_fraction >= 0.5 {
            assert!(ekf.w_ts_rad <= 0.3);
            assert!(
                ekf.angle_mean_deg.abs() <= GOAL_MEAN_DEG,
                "{what}: mean {}",
                ekf.angle_mean_deg
            );
        } else {
            // At 10 % of rated speed the sensing errors (offsets, the residual of the dead-time
            // compensation at small currents) bias both observers; the goal is missed on the
            // industrial (0.107 deg) and small fast (0.35 deg) motors. The EKF's bias stays
            // below the baseline's.
            assert!(
                ekf.angle_mean_deg.abs() < 0.8 * base.angle_mean_deg.abs(),
                "{what}: mean {} vs baseline {}",
                ekf.angle_mean_deg,
                base.angle_mean_deg
            );
        }
        // The baseline itself works (a fair comparison): within 2 deg RMS everywhere.
        assert!(
            base.angle_rms_deg < 2.0,
            "{what}: baseline RMS {}",
            base.angle_rms_deg
        );
    }
    for m in SuiteMotor::SURFACE {
        let base = r.transient_row(ObserverKind::FluxBaseline, m).expect("row");
        assert_eq!(base.converged_starts, base.start_angles_deg.len(), "{m:?}");
        let ekf = r.transient_row(ObserverKind::DefaultEkf, m).expect("row");
        assert_eq!(ekf.converged_starts, ekf.start_angles_deg.len(), "{m:?}");
        // An honest status: never Tracking while more than 45 deg off, start included.
        assert_eq!(ekf.tracking_while_lost, 0, "{m:?}");
        assert!(ekf.tracking_pct > 95.0, "{m:?} {}", ekf.tracking_pct);
        // Through the load step the EKF's worst error is below the baseline's.
        assert!(ekf.load_step_max_deg < base.load_step_max_deg, "{m:?}");
    }
}

/// With ideal sensing and switches every goal and limit holds but the wrong-`Ls` goal
/// (`mismatch_rows`) and the RMS ratio on the small fast motor at 10 % of rated
/// speed: 0.509 (EKF 0.027 deg against the baseline's 0.054; the online flux tracking costs
/// about 0.002 deg here and removes most of the realistic runs' low-speed bias).
#[test]
fn short_run_with_ideal_sensing_meets_every_goal() {
    let r = short(true);
    for c in &r.checks {
        // Ls is not tracked: its goal's misses are the physical bias (`mismatch_rows`).
        let ls_at_load = c.name.contains("wrong Ls");
        let known = c.name == "goal: EKF RMS / baseline RMS"
            && c.motor == SuiteMotor::SmallFast
            && c.row == "10 %"
            && c.value < 0.55;
        // The reversal's Ls rows: the same physical bias (a documented known limit).
        let ls_known = c.known_limit == Some(KNOWN_LIMIT_LS);
        assert!(
            c.pass || ls_at_load || known || ls_known,
            "{} {:?} {}: {} > {}",
            c.name,
            c.motor,
            c.row,
            c.value,
            c.limit
        );
    }
    // 12 rows x (ratio, mean, RMS, max, speed) + 3 x (convergence, load step), and per motor
    // 3 rows at >= 50 % speed x 8 cases (RMS) + 3 x 2 psi_f cases (tracked flux), and the
    // 10 % rows: the steady one x 8 cases + the reversal x (8 cases + the exact motor); the
    // status of every EKF mismatch row: 4 windows x 8 cases + the reversal's 8 + 1.
    assert_eq!(
        r.checks.len(),
        12 * 5 + 3 * 2 + 3 * (3 * 8 + 3 * 2) + 3 * (8 + 8 + 1) + 3 * (4 * 8 + 8 + 1)
    );
}

/// The observers told a wrong motor (module docs of `suite`, realistic short run): the EKF
/// with online tracking keeps its angle within 0.5 deg RMS told a wrong psi_f, Rs or
/// temperature at >= 50 % speed, finds a wrong psi_f to 1 %, and beats the baseline told the
/// same. Told a wrong Ls (not tracked), its bias at rated load is the physical one, `atan(dLs
/// i_q / psi_f)`, within 30 % (the goal of 1 deg is missed there; measured 1.0-3.8 deg).
#[test]
fn mismatch_rows() {
    let r = short(false);
    // 4 windows of the main run and the reversal, x 2 observers; the reversal also told the
    // true motor.
    assert_eq!(r.mismatch.len(), 3 * (MISMATCHES.len() * 2 * 5 + 2));
    reversal_rows(&r);
    let opts = SuiteOptions {
        short: true,
        seed: 1,
        ideal: false,
    };
    for m in SuiteMotor::SURFACE {
        let told = suite_scenario(m, &opts).observer_params();
        let torque = r
            .motors
            .iter()
            .find(|x| x.motor == m)
            .map_or(f64::NAN, |x| x.rated_torque_nm);
        let iq = torque / (1.5 * f64::from(told.pole_pairs) * told.psi_f_wb);
        for case in MISMATCHES {
            for ekf in r.mismatch.iter().filter(|x| {
                x.motor == m
                    && x.case == case.name
                    && x.observer == ObserverKind::DefaultEkf
                    && x.speed_fraction >= 0.5
            }) {
                let base = r
                    .mismatch
                    .iter()
                    .find(|b| {
                        b.motor == m
                            && b.case == case.name
                            && b.condition == ekf.condition
                            && b.observer == ObserverKind::FluxBaseline
                    })
                    .expect("baseline row");
                let what = format!("{m:?} {} {}", case.name, ekf.condition);
                assert_eq!(ekf.tracking_while_lost, 0, "{what}: Tracking while lost");
                if case.is_ls() {
                    let physical = ((case.ls - 1.0).abs() * told.lq_h * iq / told.psi_f_wb)
                        .atan()
                        .to_degrees();
                    if ekf.condition.contains("rated load") {
                        // Measured 1.2-1.4 x the first-order estimate.
                        assert!(
                            ekf.angle_mean_deg.abs() > 0.7 * physical
                                && ekf.angle_mean_deg.abs() < 1.6 * physical,
                            "{what}: {} vs {physical}",
                            ekf.angle_mean_deg
                        );
                    } else {
                        // Fan load only: within 1.1 deg (the industrial motor at 50 %: 1.07).
                        assert!(ekf.angle_rms_deg < 1.1, "{what}: {}", ekf.angle_rms_deg);
                    }
                    continue;
                }
                assert!(
                    ekf.angle_rms_deg <= GOAL_MISMATCH_RMS_DEG,
                    "{what}: {}",
                    ekf.angle_rms_deg
                );
                assert!(ekf.angle_rms_deg < base.angle_rms_deg, "{what}");
                if case.is_psi_only() {
                    let e = ekf.psi_f_error_pct.expect("EKF tracks psi_f");
                    assert!(e.abs() <= GOAL_MISMATCH_PSI_PCT, "{what}: psi {e}");
                }
            }
        }
    }
}

#[test]
fn report_is_deterministic_and_serializes() {
    let mut a = short(false);
    let mut b = short(false);
    a.wall_time_s = 0.0;
    b.wall_time_s = 0.0;
    assert_eq!(a, b);
    let json = serde_json::to_string(&a).unwrap_or_else(|e| panic!("{e}"));
    for key in [
        "\"steady\"",
        "\"transients\"",
        "\"checks\"",
        "\"angle_rms_deg\"",
        "\"small_fast\"",
    ] {
        assert!(json.contains(key), "{key}");
    }
    let md = a.to_markdown();
    for needle in [
        "## Steady state: default EKF",
        "## Steady state: baseline",
        "## Steady state: seed's filter",
        "| servo | 10 % | 0.008 |",
        "| small_fast | 100 %, rated load | 0.251 |",
        "## Goals and limits",
    ] {
        assert!(md.contains(needle), "{needle}\n{md}");
    }
}

/// The RMS ratio of the traction motor at 10 % of rated speed on the *short* run: 0.573
/// (realistic sensing, seed 1; EKF 0.284 deg, baseline 0.496 deg), over the goal of 0.5 which
/// the full suite meets (0.372: EKF 0.377 deg, baseline 1.015 deg). The EKF's error there is
/// noise (mean 0.02 deg); the baseline's is mostly a bias that differs between the two runs'
/// windows. Asserted against this bound (measured + about 15 %) on the short run only.
const TRACTION_10_PCT_SHORT_RATIO_BOUND: f64 = 0.66;

/// The interior motors on the short run: the goals (EKF RMS at most half the salient
/// baseline's in every steady row, |mean| < 0.1 deg at >= 50 % speed, every start of the
/// convergence grid, 180 deg included, converged within 50 ms) and the suite's limits hold,
/// but the traction motor's RMS ratio at 10 % on this short run (bounded by
/// [`TRACTION_10_PCT_SHORT_RATIO_BOUND`]; the full suite meets the goal).
#[test]
fn interior_motors_goals_and_limits() {
    for ideal in [false, true] {
        let r = short_interior(ideal);
        assert_eq!(r.motors.len(), 2);
        assert_eq!(r.steady.len(), 2 * 3 * 4);
        assert_eq!(r.transients.len(), 2 * 3);
        assert!(r.mismatch.is_empty(), "mismatch rows are surface-only");
        let info = |m: SuiteMotor| r.motors.iter().find(|x| x.motor == m).expect("motor");
        // 1500 rpm x 3 at 10 kHz; 3000 rpm x 4 at 20 kHz.
        assert!((info(SuiteMotor::IndustrialIpm).rated_w_ts_rad - 0.0471).abs() < 1e-3);
        assert!((info(SuiteMotor::TractionIpm).rated_w_ts_rad - 0.0628).abs() < 1e-3);
        assert_eq!(info(SuiteMotor::TractionIpm).ts_s, 5e-5);
        for m in &r.motors {
            assert_eq!(m.end, "completed", "{:?}", m.motor);
            assert_eq!(m.drive, "foc sensored, MTPA");
        }
        for ekf in r
            .steady
            .iter()
            .filter(|x| x.observer == ObserverKind::DefaultEkf)
        {
            let base = r
                .steady_row(ObserverKind::FluxBaseline, ekf.motor, &ekf.condition)
                .expect("baseline row");
            let what = format!("{:?} {} ideal={ideal}", ekf.motor, ekf.condition);
            assert_eq!(ekf.failures + base.failures, 0, "{what}");
            assert!(ekf.samples > 1000 && ekf.samples == base.samples, "{what}");
            let ratio = ekf.angle_rms_deg / base.angle_rms_deg;
            let bound = if ekf.motor == SuiteMotor::TractionIpm && ekf.speed_fraction < 0.5 {
                TRACTION_10_PCT_SHORT_RATIO_BOUND
            } else {
                GOAL_RMS_RATIO
            };
            assert!(ratio <= bound, "{what}: RMS ratio {ratio}");
            if ekf.speed_fraction >= 0.5 {
                assert!(
                    ekf.angle_mean_deg.abs() < GOAL_MEAN_DEG,
                    "{what}: mean {}",
                    ekf.angle_mean_deg
                );
            } else {
                // 10 %: the industrial motor's realistic bias is 0.111 deg (as on the surface
                // motors, sensing errors at small currents); below the baseline's.
                assert!(
                    ekf.angle_mean_deg.abs() < 0.8 * base.angle_mean_deg.abs(),
                    "{what}: mean {} vs baseline {}",
                    ekf.angle_mean_deg,
                    base.angle_mean_deg
                );
            }
        }
        for m in SuiteMotor::INTERIOR {
            let ekf = r.transient_row(ObserverKind::DefaultEkf, m).expect("row");
            let base = r.transient_row(ObserverKind::FluxBaseline, m).expect("row");
            let what = format!("{m:?} ideal={ideal}");
            // The convergence grid: the standard starts and the theta+pi cell.
            assert_eq!(ekf.start_angles_deg.len(), 5, "{what}");
            assert!(ekf.start_angles_deg.contains(&180.0), "{what}");
            assert_eq!(ekf.converged_starts, 5, "{what}");
            let worst = ekf.convergence_worst_s.unwrap_or(f64::INFINITY);
            assert!(worst <= GOAL_IPM_CONVERGENCE_S, "{what}: {worst} s");
            assert_eq!(base.converged_starts, 5, "{what}");
            // Through the load step: below the baseline's worst error.
            assert!(
                ekf.load_step_max_deg < base.load_step_max_deg,
                "{what}: {} vs {}",
                ekf.load_step_max_deg,
                base.load_step_max_deg
            );
            assert!(ekf.load_step_max_deg <= LIMIT_LOAD_STEP_DEG, "{what}");
        }
        // Every check passes but the traction motor's RMS ratio at 10 % on this short run (see
        // above) and, on realistic sensing, the industrial motor's bias at 10 % of rated speed
        // (0.111 deg; the bias goal is at >= 50 % speed, the suite checks it wherever
        // w_e Ts <= 0.3).
        for c in &r.checks {
            let known = (c.motor == SuiteMotor::TractionIpm
                && c.row == "10 %"
                && c.name == "goal: EKF RMS / baseline RMS"
                && c.value <= TRACTION_10_PCT_SHORT_RATIO_BOUND)
                || (!ideal
                    && c.motor == SuiteMotor::IndustrialIpm
                    && c.name == "goal: EKF |mean| (deg)"
                    && c.row == "10 %"
                    && c.value < 0.13);
            assert!(
                c.pass || known,
                "{} {:?} {} ideal={ideal}: {} > {}",
                c.name,
                c.motor,
                c.row,
                c.value,
                c.limit
            );
        }
        // 8 rows x (ratio, mean, RMS, max, speed) + 2 x (convergence, load step, 50 ms goal).
        assert_eq!(r.checks.len(), 8 * 5 + 2 * 3);
        let md = r.to_markdown();
        for needle in [
            "| traction_ipm | foc sensored, MTPA | 20 |",
            "| industrial_ipm | 100 %, rated load | 0.047 |",
            "theta+pi included",
        ] {
            assert!(md.contains(needle), "{needle}\n{md}");
        }
    }
}

/// The whole suite runs every motor, the surface ones first, each with the rows of its own
/// run (the seed offset is the motor's place in `SuiteMotor::ALL`).
#[test]
fn the_full_suite_lists_all_five_motors() {
    assert_eq!(SuiteMotor::ALL.len(), 5);
    assert_eq!(
        SuiteMotor::ALL[..3],
        SuiteMotor::SURFACE,
        "the surface motors keep their seeds"
    );
    for m in SuiteMotor::ALL {
        assert_eq!(SuiteMotor::from_name(m.name()), Some(m));
        assert_eq!(m.is_interior(), SuiteMotor::INTERIOR.contains(&m));
        let sc = suite_scenario(m, &opts(false));
        assert_eq!(sc.validate(), Ok(()), "{m:?}");
        assert_eq!(sc.motor.lq_h > sc.motor.ld_h, m.is_interior(), "{m:?}");
    }
}

/// The reversal under rated load at 10 % speed (module docs of `suite`, "Mismatch through a
/// reversal"; realistic short run). Measured (`pmsm-sim suite --short`): told the true motor
/// 0.32 / 0.61 / 0.35 deg RMS (servo / industrial / small fast); told a wrong psi_f, Rs or
/// temperature 0.26-0.84 deg (the windows of the resistance tracking find `Rs` at the loaded
/// low speed before the reversal), against 16-75 deg for the baseline told the same; told a
/// wrong Ls the physical bias (0.8-3.0 deg). Told they are 100 K colder (told `Rs` 64 % high;
/// the drop error 36-37 % of the back-EMF at the load step): the small fast motor 0.36 deg (it
/// loses the angle in the load step's speed dip, and the windows of a filter in trouble find
/// `Rs` again: module docs of `ekf_core::observer::tracking`; without them 56 deg), the 2.2 kW
/// motor 0.61 deg here and 0.70 deg in the full run (its braking ramp to 10 % finds `Rs`
/// before the load step; where it has not, after the step its speed state and its angle's
/// advance conflict, and the windows of a filter in trouble find `Rs`: 0.95 / 0.80 deg
/// without the braking ramp's windows, 2.3 deg in the full run without either, 11-16 deg off
/// for 0.2 s with consistent innovations).
fn reversal_rows(r: &SuiteReport) {
    let rows: Vec<_> = r
        .mismatch
        .iter()
        .filter(|x| x.condition == suite::reversal::CONDITION)
        .collect();
    assert_eq!(rows.len(), 3 * (MISMATCHES.len() * 2 + 2));
    for ekf in rows
        .iter()
        .filter(|x| x.observer == ObserverKind::DefaultEkf)
    {
        let what = format!("{:?} {}", ekf.motor, ekf.case);
        // An honest status in every case, the misses included: never `Tracking` while more
        // than 45 deg off, in the window and over the whole run.
        assert_eq!(
            (ekf.tracking_while_lost, ekf.run_tracking_while_lost),
            (0, 0),
            "{what}: Tracking while lost"
        );
        let case = MISMATCHES.iter().find(|m| m.name == ekf.case);
        if case.is_some_and(|c| c.is_ls()) {
            assert!(ekf.angle_rms_deg < 3.5, "{what}: {}", ekf.angle_rms_deg);
            continue;
        }
        assert!(
            ekf.angle_rms_deg <= GOAL_MISMATCH_LOW_SPEED_RMS_DEG,
            "{what}: {}",
            ekf.angle_rms_deg
        );
        if case.is_some_and(|c| c.rs != 1.0) {
            let base = rows
                .iter()
                .find(|b| {
                    b.motor == ekf.motor
                        && b.case == ekf.case
                        && b.observer == ObserverKind::FluxBaseline
                })
                .expect("baseline row");
            assert!(ekf.angle_rms_deg < 0.1 * base.angle_rms_deg, "{what}");
        }
    }
}

/// The 2.2 kW motor told 100 K cold (`Rs` +65 %) through the reversal at 10 % speed under rated
/// load, on a sensor seed where no active window had moved `Rs` before the braking ramp: the
/// ramp's windows find `Rs` (module docs of `ekf_core::observer::tracking`, "Resistance on a
/// braking ramp"); without them the filter slipped from the load step on (50.5 deg RMS on this
/// short run).
#[test]
fn braking_ramp_finds_rs_before_the_load_step() {
    let r = run_suite_motors(
        &SuiteOptions {
            short: true,
            seed: 14,
            ideal: false,
        },
        &[SuiteMotor::Industrial2k2],
    )
    .unwrap_or_else(|e| panic!("suite: {e}"));
    let row = r
        .mismatch
        .iter()
        .find(|x| {
            x.condition == suite::reversal::CONDITION
                && x.case == "100 K cold"
                && x.observer == ObserverKind::DefaultEkf
        })
        .expect("the reversal row told 100 K cold");
    assert!(
        row.angle_rms_deg <= GOAL_MISMATCH_LOW_SPEED_RMS_DEG,
        "{}",
        row.angle_rms_deg
    );
    assert_eq!(
        (row.tracking_while_lost, row.run_tracking_while_lost),
        (0, 0)
    );
    // Measured: -0.3 %.
    assert!(row.rs_error_pct.abs() < 5.0, "Rs {} %", row.rs_error_pct);
}
