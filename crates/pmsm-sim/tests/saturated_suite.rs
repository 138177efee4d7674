//! The suite's saturated-motor rows (`pmsm_sim::analysis::suite`, module `saturated`), short
//! form: on the saturating PM-SyRM and interior motor, the EKF told the flux map meets its
//! goals (RMS at most half the flux baseline told the same map, no sample more than 45 deg
//! off, never `Tracking` while more than 45 deg off), the EKF told the small-signal constants
//! loses no lock (checked by the suite too), and no EKF row reports `Tracking` while more than
//! 45 deg off; the map EKFs converge on other sensor-noise seeds too. Opt-in: foc told the map too, at the default 500 Hz current bandwidth (the
//! small-signal drive runs at 150 Hz), meets the same goals.
//!
//! Run: `cargo test --release -p pmsm-sim --test saturated_suite -- --nocapture`.

use pmsm_sim::analysis::suite::{
    SatDrive, SuiteOptions, Told, saturated_rows, saturated_rows_with,
};

#[test]
fn map_ekf_meets_its_goals_on_the_saturated_motors() {
    let report = saturated_rows(&SuiteOptions {
        short: true,
        ..SuiteOptions::default()
    })
    .unwrap();
    print!("{}", report.to_markdown());
    assert_eq!(report.rows.len(), 10, "two motors, five observers");
    assert_eq!(report.checks.len(), 14, "two motors, seven checks");
    for c in &report.checks {
        assert!(
            c.pass,
            "{} ({}): {} > {}",
            c.name, c.motor, c.value, c.limit
        );
    }
    for r in report.rows.iter().filter(|r| r.told == Told::Map) {
        assert!(r.samples > 10_000 && r.failures == 0, "{r:?}");
    }
    // An honest status on every EKF row, also told the small-signal constants; and told
    // them (`ObserverConfig::saturating`), the EKF never loses the rotor.
    for r in report.rows.iter().filter(|r| r.observer == "EKF") {
        assert_eq!(r.tracking_while_lost, 0, "{r:?}");
        if r.told == Told::SmallSignal {
            assert_eq!(r.lost_pct, 0.0, "{r:?}");
        }
    }
    // The identified maps: measured at standstill within 5 s, the rotor held within a tenth
    // of a turn; the RMS ratio to the true map's row is reported against its goal (1.5).
    assert_eq!(report.identification.len(), 2);
    for i in &report.identification {
        assert!(i.duration_s <= 5.0, "{i:?}");
        assert!(
            i.rotor_moved_mech_rad < 0.1 * std::f64::consts::TAU,
            "{i:?}"
        );
        assert!(i.rms_ratio.is_finite(), "{i:?}");
    }
}

/// The map EKFs converge from the rows' start (zero speed and angle, the rotor 115 deg away
/// at 50 % speed, no load) on other sensor-noise seeds than the suite's default too: before
/// the isotropic response before the lock (module docs of `ekf_core::saturated`, "Before the
/// lock"), the PM-SyRM's map EKF settled on `th + pi` on these seeds and was lost after the
/// convergence phase (up to 8 % of the samples more than 45 deg off).
#[test]
fn saturated_rows_converge_on_every_seed() {
    for seed in 5..=9 {
        let report = saturated_rows(&SuiteOptions {
            short: true,
            seed,
            ..SuiteOptions::default()
        })
        .unwrap();
        for r in report.rows.iter().filter(|r| r.observer == "EKF") {
            assert_eq!(r.lost_pct, 0.0, "seed {seed}: {r:?}");
            assert_eq!(r.tracking_while_lost, 0, "seed {seed}: {r:?}");
        }
        for c in &report.checks {
            assert!(c.pass, "seed {seed}: {} ({}): {}", c.name, c.motor, c.value);
        }
    }
}

#[test]
fn foc_told_the_map_drives_the_saturated_motors_at_500_hz() {
    let report = saturated_rows_with(
        &SuiteOptions {
            short: true,
            ..SuiteOptions::default()
        },
        SatDrive::Map {
            current_bandwidth_hz: 500.0,
        },
    )
    .unwrap();
    print!("{}", report.to_markdown());
    assert_eq!(report.rows.len(), 10);
    for c in &report.checks {
        assert!(
            c.pass,
            "{} ({}): {} > {}",
            c.name, c.motor, c.value, c.limit
        );
    }
    for r in report.rows.iter().filter(|r| r.told == Told::Map) {
        assert!(r.samples > 10_000 && r.failures == 0, "{r:?}");
    }
}
