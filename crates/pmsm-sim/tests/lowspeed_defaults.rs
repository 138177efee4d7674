//! The default drive at 3 % of rated speed under rated load (module
//! `pmsm_sim::analysis::low_speed`, "The default drive"): on the three surface reference
//! motors `foc` sensorless with pmsm-sim's defaults (damped start handing over at 3 % of
//! rated speed, closed loop left below 1.5 % of rated) stays in closed loop and draws at most
//! 1.15 times the rated-torque current; with foc's classic start (no damping, no kick: its
//! own hand-over rule, 9.8 % of rated on the servo) the exit at 1.5 % of rated keeps the
//! servo and small_fast there too. The interior motors keep foc's rule for the hand-over
//! (18.3 % of rated on industrial_ipm: this job's rated load, at 0.8 s, finds it still in
//! I/f and the observer is lost); docs/startup.md, "Hand-over and exit speed".
//!
//! Goals asserted over the window (5 s held at 3 % of rated after the ramp down from 20 %
//! under rated load): no fault, closed loop in every period (no exit, no fall-back), mean
//! speed within 25 % of the test speed, RMS current / rated-torque current <= 1.15, RMS
//! angle error of foc's observer <= 3 deg el.
//!
//! Measured (`cargo test --release -p pmsm-sim --test lowspeed_defaults -- --nocapture`
//! prints the rows): current ratio 1.000-1.005, angle error RMS 0.24 (small_fast) to 1.09
//! deg (servo), in closed loop throughout (classic start: servo 1.004 / 0.90 deg, small_fast
//! 1.000 / 0.25 deg); with the previous defaults (the hand-over by foc's classic rule,
//! exit at 0.7 of it: 6.9 % of rated on the servo) the servo ran I/f in the whole window at
//! 1.75 times the rated-torque current, which the last test asserts still fails the goals.

use pmsm_sim::analysis::low_speed::{LowSpeedRun, default_drive_scenario, run_scenario, scenario};
use pmsm_sim::analysis::suite::SuiteMotor;

/// Test speed, % of rated.
const SPEED_PCT: f64 = 3.0;
/// Time held at the test speed, s.
const HOLD_S: f64 = 5.0;
/// Goals: RMS current / rated-torque current, and the observer's RMS angle error (deg el.).
const CURRENT_RATIO_MAX: f64 = 1.15;
const ANGLE_RMS_MAX_DEG: f64 = 3.0;

fn print(motor: &str, start: &str, r: &LowSpeedRun) {
    println!(
        "| {motor} | {start} | {:.1} | {} | {:.2} | {:.3} | {:.2} | {} |",
        r.closed_loop_pct,
        r.exits,
        r.mean_speed_rpm,
        r.current_ratio,
        r.angle_error_rms_deg,
        r.fault.as_deref().unwrap_or("none")
    );
}

fn assert_goals(motor: &str, r: &LowSpeedRun) {
    assert!(r.fault.is_none(), "{motor}: {r:?}");
    assert!(
        r.pass && r.exits == 0 && r.closed_loop_pct == 100.0,
        "{motor}: not closed loop throughout: {r:?}"
    );
    assert!(r.current_ratio <= CURRENT_RATIO_MAX, "{motor}: {r:?}");
    assert!(r.angle_error_rms_deg <= ANGLE_RMS_MAX_DEG, "{motor}: {r:?}");
}

#[test]
fn default_drive_stays_closed_loop_at_three_percent_of_rated_under_rated_load() {
    println!(
        "| motor | start | closed loop (% window) | exits | mean speed (rpm) | current ratio | angle error RMS (deg) | fault |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for motor in SuiteMotor::SURFACE {
        let sc = default_drive_scenario(motor, SPEED_PCT, HOLD_S)
            .unwrap_or_else(|e| panic!("{}: {e}", motor.name()));
        // The defaults under test: the damped start hands over at 3 % of rated speed and
        // closed loop is left below 1.5 % of rated.
        let cfg = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        let rated_e = sc.rated_speed_e_rad_s();
        let st = cfg.startup;
        assert!(st.damping_ratio > 0.0, "{}", motor.name());
        let handover = f64::from(st.handover_speed_rad_s) / rated_e;
        let exit = f64::from(st.exit_speed_ratio * st.handover_speed_rad_s) / rated_e;
        assert!(
            (handover - 0.03).abs() < 1e-6,
            "{}: {handover}",
            motor.name()
        );
        assert!((exit - 0.015).abs() < 1e-6, "{}: {exit}", motor.name());
        let r = run_scenario(&sc, SPEED_PCT).unwrap_or_else(|e| panic!("{e}"));
        print(motor.name(), "damped (default)", &r);
        assert_goals(motor.name(), &r);
    }
}

/// foc's classic start (no damping, no kick; `FocConfig::new`'s own start-up): the hand-over
/// by foc's rule `max(2 Rs I_f / psi_f, 0.02 w_max)` (9.8 % of rated on the servo, 11.9 % on
/// small_fast), the exit still at 1.5 % of rated speed. Not industrial_2k2: its classic start
/// is still in I/f when the rated load steps in at 0.8 s and loses the observer at 0.98 s
/// (`observer_lost`), with the exit at 1.5 % of rated as with the previous 0.7 of the
/// hand-over speed: a limit of the classic start, not of the exit.
#[test]
fn classic_start_also_stays_closed_loop_at_three_percent_of_rated() {
    for motor in [SuiteMotor::Servo, SuiteMotor::SmallFast] {
        let mut sc = default_drive_scenario(motor, SPEED_PCT, HOLD_S)
            .unwrap_or_else(|e| panic!("{}: {e}", motor.name()));
        let mut foc = sc.controller.foc.unwrap_or_default();
        foc.startup_damping_ratio = Some(0.0);
        foc.startup_kick_speed_ratio = Some(0.0);
        sc.controller.foc = Some(foc);
        let cfg = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        let st = cfg.startup;
        let rated_e = sc.rated_speed_e_rad_s();
        assert!(
            f64::from(st.handover_speed_rad_s) / rated_e > 0.09,
            "{}",
            motor.name()
        );
        let exit = f64::from(st.exit_speed_ratio * st.handover_speed_rad_s) / rated_e;
        assert!((exit - 0.015).abs() < 1e-6, "{}: {exit}", motor.name());
        let r = run_scenario(&sc, SPEED_PCT).unwrap_or_else(|e| panic!("{e}"));
        print(motor.name(), "classic", &r);
        assert_goals(motor.name(), &r);
    }
}

/// The check can fail: with the previous defaults (exit at 0.7 of the classic rule's
/// hand-over speed, 6.9 % of rated on the servo) the servo at 3 % of rated runs I/f with
/// about 1.75 times the rated-torque current.
#[test]
fn the_previous_defaults_miss_the_goals() {
    let mut sc = scenario(SuiteMotor::Servo, SPEED_PCT, HOLD_S).unwrap_or_else(|e| panic!("{e}"));
    let mut foc = sc.controller.foc.unwrap_or_default();
    foc.handover_speed_rpm = Some(0.098 * sc.rated_speed_rpm);
    foc.exit_speed_ratio = Some(0.7);
    sc.controller.foc = Some(foc);
    let r = run_scenario(&sc, SPEED_PCT).unwrap_or_else(|e| panic!("{e}"));
    print("servo", "previous defaults", &r);
    assert!(!r.pass && r.closed_loop_pct < 50.0, "{r:?}");
    assert!(r.current_ratio > 1.5, "{r:?}");
}
