//! The scenario suite (`pmsm_sim::suite`, `pmsm-sim suite`) on its short run: the goals and
//! limits that hold are asserted; the ones the default EKF misses on realistic sensing are
//! named, with the weaker statement that holds there. (Debug profile: about 0.2 s per run.)

use pmsm_sim::suite::{
    GOAL_MEAN_DEG, GOAL_RMS_RATIO, ObserverKind, SuiteMotor, SuiteOptions, SuiteReport, run_suite,
};

fn short(ideal: bool) -> SuiteReport {
    run_suite(&SuiteOptions {
        short: true,
        seed: 1,
        ideal,
    })
    .unwrap_or_else(|e| panic!("suite: {e}"))
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
    for m in SuiteMotor::ALL {
        let base = r.transient_row(ObserverKind::FluxBaseline, m).expect("row");
        assert_eq!(base.converged_starts, base.start_angles_deg.len(), "{m:?}");
        let ekf = r.transient_row(ObserverKind::DefaultEkf, m).expect("row");
        assert_eq!(ekf.converged_starts, ekf.start_angles_deg.len(), "{m:?}");
        // Through the load step the EKF's worst error is below the baseline's.
        assert!(ekf.load_step_max_deg < base.load_step_max_deg, "{m:?}");
    }
}

/// With ideal sensing and switches every goal and limit holds: what the EKF misses on the
/// realistic run comes from the sensing, not from the filter.
#[test]
fn short_run_with_ideal_sensing_meets_every_goal() {
    let r = short(true);
    for c in &r.checks {
        assert!(
            c.pass,
            "{} {:?} {}: {} > {}",
            c.name, c.motor, c.row, c.value, c.limit
        );
    }
    assert!(r.all_pass());
    // 12 rows x (ratio, mean, RMS, max, speed) + 3 x (convergence, load step).
    assert_eq!(r.checks.len(), 12 * 5 + 3 * 2);
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
