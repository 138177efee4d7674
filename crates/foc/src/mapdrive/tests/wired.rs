//! The tables wired into the controller (`FocConfig::flux_map`): the closed-loop references
//! come from them, the default configuration is unchanged.

use super::*;
use crate::{Foc, FocConfig, Mode, TickInput};

/// Sensored drive of the saturating IPM at 10 kHz on 540 V, current limit twice the rated
/// current, told the map or not; `fw`: field weakening up to 4x.
fn drive(c: &Case, map: bool, fw: bool) -> (FocConfig, MapTables) {
    let r = &c.m.reference;
    let mut cfg =
        FocConfig::new(r.params::<f32>(), r.ts_s as f32, r.u_dc_v as f32).with_mode(Mode::Sensored);
    if fw {
        cfg = cfg.with_field_weakening(4.0);
    }
    cfg.current_limit_a = (2.0 * c.i_r) as f32;
    cfg.over_current_a = 2.0 * cfg.current_limit_a;
    let tables = MapTables::from_map(
        &c.map,
        r.pole_pairs,
        cfg.torque_constant_nm_a(),
        cfg.current_limit_a,
        4.0,
    )
    .unwrap();
    if map {
        cfg.flux_map = Some(tables);
    }
    (cfg, tables)
}

/// The reference after `n` ticks at zero current with the rotor held by the sensor at the
/// speed `w` (rad/s el.) and a speed command far above it (the speed loop at its limit).
fn reference(cfg: &FocConfig, w: f32, n: usize) -> Dq {
    let mut foc = Foc::new(cfg).unwrap();
    foc.set_speed_ref_mech_rad_s(1e4).unwrap();
    foc.start().unwrap();
    let mut last = Dq::default();
    for _ in 0..n {
        let out =
            foc.tick(&TickInput::alpha_beta(0.0, 0.0, cfg.u_dc_min_v / 0.6).with_sensor(0.0, w));
        last = out.telemetry.i_dq_ref;
    }
    last
}

#[test]
fn a_drive_told_the_map_takes_its_references_from_it() {
    let c = case(SATURATED_IPM);
    let (with, t) = drive(&c, true, false);
    let (without, _) = drive(&c, false, false);
    assert_eq!(with.validate(), Ok(()));
    assert!(with.has_flux_map() && !without.has_flux_map());
    assert_eq!(with.torque_current_limit_a(), t.mtpa.torque_current_max());
    // The speed loop at its limit: the MTPA table's last point (the current limit).
    let i = reference(&with, 50.0, 3000);
    let want = t.mtpa.lookup(t.mtpa.torque_current_max()).i;
    println!("told the map: reference {i:?}, table {want:?}");
    assert!(
        (i.d - want.d).abs() < 1e-3 && (i.q - want.q).abs() < 1e-3,
        "{i:?} {want:?}"
    );
    let i0 = reference(&without, 50.0, 3000);
    println!("constant parameters: reference {i0:?}");
    assert!((i0.d - want.d).abs() > 0.1, "{i0:?}");
    // A table of another torque constant is refused.
    let mut bad = with;
    bad.motor.psi_f_wb *= 1.01;
    bad.observer.motor = bad.motor;
    assert!(bad.validate().is_err());
}

#[test]
fn a_drive_told_the_map_weakens_within_the_voltage_limit() {
    let c = case(SATURATED_IPM);
    let (cfg, _) = drive(&c, true, true);
    let r = &c.m.reference;
    let u_lim = f64::from(cfg.field_weakening.voltage_margin) * r.u_dc_v / 3f64.sqrt();
    for w in [300.0f32, 800.0, 1100.0] {
        let i = reference(&cfg, w, 3000);
        let (d, q) = (f64::from(i.d), f64::from(i.q));
        let u = f64::from(w) * c.flux(d, q) + r.rs_ohm * d.hypot(q);
        println!(
            "w {w} rad/s el.: reference {i:?}, |w psi| + Rs |i| = {u:.1} V (limit {u_lim:.1} V), \
             torque {:.2} N m",
            c.torque(d, q)
        );
        assert!(u <= 1.005 * u_lim, "{w}: {u} V");
        assert!(d.hypot(q) <= f64::from(cfg.current_limit_a) * 1.001);
    }
}
