//! Plug and spin on the identified flux map (`pmsm-sim run SCENARIO --identify --flux-map`,
//! `pmsm_sim::analysis::plug_map`) on the saturating reference motors, on the saturated
//! suite rows' realistic drive (dead time, delay, ADC, noise, gain and offset errors; load
//! steps 100/150/-100/100 % and a reversal under rated load at 50 % rated speed, a flying
//! start): the identification with the flux-map step, then foc told the identified map (MTPA
//! and gains from it) with its angle from the EKF on the identified map. Asserted: no fault,
//! no scored sample more than 45 deg off, the angle RMS at most 1.5 deg and the torque per
//! ampere within 0.5 % of the same drive's told the plant's true map. The goal of 1.5 x the
//! true-map run's angle RMS is printed, not asserted: it is missed (0.92 / 0.17 deg, 5.5 x;
//! the identified map's 1-2 % flux errors, a +6 mWb offset in `psi_d`, set the angle bias).
//!
//! Run: `cargo test --release -p pmsm-sim --test plug_flux_map -- --nocapture`.

use ekf_core::saturation::{SATURATED_IPM, SaturatedMotor};
use pmsm_sim::analysis::plug_map::{compare, plug_and_spin_map};
use pmsm_sim::analysis::suite::identified::saturated_scenario;

fn check(m: &SaturatedMotor) {
    let name = m.reference.name;
    let (sc, i_rated) = saturated_scenario(m, 2);
    let (plug, report, map) =
        plug_and_spin_map(&sc, 1.7 * i_rated).unwrap_or_else(|e| panic!("{name}: {e}"));
    let rs = report.identified.as_ref().map_or(f64::NAN, |v| v.rs_ohm);
    let c = compare(&sc, &plug, &map, rs, 0.5).unwrap_or_else(|e| panic!("{name}: {e}"));
    println!(
        "{name}: identification with the flux-map step {:.3} s\n{}",
        report.total_time_s,
        c.table()
    );
    for r in [&c.identified, &c.truth] {
        assert!(r.samples > 1000, "{name}: {r:?}");
        assert_eq!(r.fault, None, "{name}: {r:?}");
        assert!(r.angle_max_deg < 45.0, "{name}: {r:?}");
    }
    assert!(
        c.identified.angle_rms_deg <= 1.5,
        "{name}: {:?}",
        c.identified
    );
    let tpa = c.torque_per_ampere_ratio();
    assert!((tpa - 1.0).abs() <= 0.005, "{name}: {tpa:.4}");
    println!(
        "{name}: goal angle RMS <= 1.5 x the true-map run's: {:.2} x ({})",
        c.rms_ratio(),
        if c.rms_ratio() <= 1.5 {
            "met"
        } else {
            "missed"
        }
    );
}

#[test]
fn saturating_ipm_plug_and_spin_on_the_identified_map() {
    check(&SATURATED_IPM);
}
