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

/// The controller's tick on the map plant (flux as state, rotor held at `w` el.), sensored,
/// current limit `I_r` and the speed loop asking for more torque than that: the current
/// references rise to the limit. Returns the largest `i_q` beyond its reference while it
/// rises (A), the last tick's `i_dq` and reference, and the plant's torque at the end (N m).
fn run_on_map_plant(c: &Case, map: bool) -> (f64, Dq, Dq, f64) {
    let r = &c.m.reference;
    let mut cfg =
        FocConfig::new(r.params::<f32>(), r.ts_s as f32, r.u_dc_v as f32).with_mode(Mode::Sensored);
    cfg.current_limit_a = c.i_r as f32;
    cfg.over_current_a = 3.0 * cfg.current_limit_a;
    cfg.samples.max_step_a = Some(f32::INFINITY);
    if map {
        cfg.flux_map = Some(
            MapTables::from_map(
                &c.map,
                r.pole_pairs,
                cfg.torque_constant_nm_a(),
                cfg.current_limit_a,
                4.0,
            )
            .unwrap(),
        );
    }
    let w = 0.2 * r.rated_omega_e_rad_s();
    let mut foc = Foc::new(&cfg).unwrap();
    foc.set_speed_ref_mech_rad_s((3.0 * w / f64::from(r.pole_pairs)) as f32)
        .unwrap();
    foc.start().unwrap();
    let e0 = c.map.eval(0.0, 0.0);
    let (mut pd, mut pq, mut id, mut iq) = (e0.psi_d, e0.psi_q, 0.0f64, 0.0f64);
    let mut u_prev = [0.0f64; 2];
    let mut over = 0.0f64;
    let (mut i_last, mut ref_last) = (Dq::default(), Dq::default());
    let ts = r.ts_s;
    for k in 0..3000 {
        let th = w * ts * k as f64;
        let (s, co) = th.sin_cos();
        let (ia, ib) = (co * id - s * iq, s * id + co * iq);
        let out = foc.tick(
            &TickInput::alpha_beta(ia as f32, ib as f32, r.u_dc_v as f32)
                .with_sensor(crate::trig::wrap(th as f32), w as f32),
        );
        assert!(out.fault.is_none(), "{:?}", out.fault);
        let t = out.telemetry;
        over = over.max(f64::from(t.i_dq.q - t.i_dq_ref.q));
        (i_last, ref_last) = (t.i_dq, t.i_dq_ref);
        let h = ts / 20.0;
        for m in 0..20 {
            let (s, co) = (th + w * h * m as f64).sin_cos();
            let (ud, uq) = (
                co * u_prev[0] + s * u_prev[1],
                co * u_prev[1] - s * u_prev[0],
            );
            pd += h * (ud - r.rs_ohm * id + w * pq);
            pq += h * (uq - r.rs_ohm * iq - w * pd);
            (id, iq) = c.map.currents(pd, pq, (id, iq), 30, 1e-12).unwrap();
        }
        u_prev = [f64::from(t.u_ab.alpha), f64::from(t.u_ab.beta)];
    }
    (over, i_last, ref_last, c.torque(id, iq))
}

#[test]
fn the_tick_told_the_map_tracks_its_references_on_the_map_plant() {
    for m in [PM_SYRM, SATURATED_IPM] {
        let c = case(m);
        let (over, i, r, t) = run_on_map_plant(&c, true);
        let (over0, i0, r0, t0) = run_on_map_plant(&c, false);
        let best = c.best_torque(c.i_r);
        println!(
            "{}: told the map: i {i:?} ref {r:?}, torque {t:.2} N m (map's best at I_r \
             {best:.2}), largest i_q above its reference {over:.3} A; constant parameters: i \
             {i0:?} ref {r0:?}, torque {t0:.2} N m, largest i_q above its reference {over0:.3} A",
            m.reference.name
        );
        assert!((i.d - r.d).abs() < 0.01 * c.i_r as f32 && (i.q - r.q).abs() < 0.01 * c.i_r as f32);
        assert!((t / best - 1.0).abs() < 0.01, "{t} vs {best}");
        assert!(over < 0.1 * c.i_r, "{over}");
    }
}
