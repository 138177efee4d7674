//! The standstill flux-map measurement (`foc::identify::saturation::SaturationProbe`) on the
//! saturating plants `pm_syrm` and `saturating_ipm`: the rotor free with the motor's inertia
//! at an arbitrary aligned angle, the probe told `Rs`, `psi_f` and the small-signal
//! inductances (what the identification measures), the voltages applied one period late
//! (ideal switches), the currents sampled exactly.
//!
//! The grid spans `+-1.5` times the rated current on both axes (the suite's identified-map
//! rows: `+-PROBE_CURRENT`, 1.7, checked against the flux goal too). Goals: the identified flux within 2 % of the true flux (error
//! over the stator flux magnitude `|psi|`) at the grid's nodes with `|i| <= rated`; the `FluxMap` built from them
//! within 1 % (points) of the true model sampled on the same grid, over `|i| <= rated` (the
//! grid's own interpolation error is the motor's, not the probe's); the rotor moves less than
//! 0.2 mechanical rad (it is followed from the torque and `J`); the probe ends within 5 s.
//!
//! Run: `cargo test --release -p pmsm-sim --test saturated_flux_probe -- --nocapture`.

use ekf_core::FluxMap;
use ekf_core::saturation::{PM_SYRM, SATURATED_IPM, SaturatedMotor};
use pmsm_sim::analysis::suite::identified::{
    PROBE_CURRENT, ProbeRun, ProbeTold as Told, probe_plant, probe_realistic,
};

/// Peak rated current: the smallest current magnitude whose best angle (MTPA, searched in
/// 0.5 deg steps) gives the rated torque.
fn rated_current(m: &SaturatedMotor) -> f64 {
    let p = f64::from(m.reference.pole_pairs);
    let torque = |i: f64| {
        (0..=180)
            .map(|k| {
                let g = f64::from(k) * 0.5_f64.to_radians();
                let (id, iq) = (-i * g.sin(), i * g.cos());
                let (pd, pq) = m.model.flux(id, iq, (m.reference.psi_f_wb, 0.0)).unwrap();
                1.5 * p * (pd * iq - pq * id)
            })
            .fold(f64::MIN, f64::max)
    };
    let (mut lo, mut hi) = (0.0, 100.0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if torque(mid) < m.reference.rated_torque_nm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Runs the probe (`pmsm_sim::analysis::suite::identified::probe_plant`).
fn probe(m: &SaturatedMotor, i_max: f64, theta0: f64, told: Told) -> ProbeRun {
    probe_plant(m, i_max, theta0, &told)
        .unwrap_or_else(|e| panic!("{}: probe did not finish: {e}", m.reference.name))
}

/// Largest error of `(psi_d, psi_q)` over `|psi|` at the points `f` gives, `%`.
fn max_errors(
    m: &SaturatedMotor,
    points: &[(f64, f64)],
    f: impl Fn(f64, f64) -> (f64, f64),
) -> (f64, f64) {
    let (mut ed, mut eq) = (0.0f64, 0.0f64);
    for &(id, iq) in points {
        let (td, tq) = m.model.flux(id, iq, (m.reference.psi_f_wb, 0.0)).unwrap();
        let (gd, gq) = f(id, iq);
        let mag = td.hypot(tq);
        ed = ed.max(100.0 * (gd - td).abs() / mag);
        eq = eq.max(100.0 * (gq - tq).abs() / mag);
    }
    (ed, eq)
}

fn check(m: &SaturatedMotor, theta0: f64) {
    check_told(m, theta0, Told::EXACT, 2.0, 1.0, 1.5);
}

/// Runs the probe told `told` on a grid to `k_max` times the rated current and checks the
/// nodes within `node_pct`, the map within `map_pct` of the true model on the same grid, the
/// rotor's motion (0.2 mech rad on the 1.5 grid, a tenth of a turn on a wider one), time and
/// peak current.
fn check_told(
    m: &SaturatedMotor,
    theta0: f64,
    told: Told,
    node_pct: f64,
    map_pct: f64,
    k_max: f64,
) {
    let name = m.reference.name;
    let i_r = rated_current(m);
    let i_max = k_max * i_r;
    let o = probe(m, i_max, theta0, told);
    let s = &o.samples;
    // Nodes inside the rated circle: the measurement itself.
    let mut nodes = Vec::new();
    for d in 0..s.n_d {
        for q in 0..s.n_q {
            let (id, iq) = (f64::from(s.i_d[d]), f64::from(s.i_q[q]));
            if id.hypot(iq) <= i_r * 1.0001 {
                nodes.push((d, q, id, iq));
            }
        }
    }
    let pts: Vec<(f64, f64)> = nodes.iter().map(|n| (n.2, n.3)).collect();
    let (nd, nq) = max_errors(m, &pts, |id, iq| {
        let n = nodes.iter().find(|n| n.2 == id && n.3 == iq).unwrap();
        (f64::from(s.psi_d[n.0][n.1]), f64::from(s.psi_q[n.0][n.1]))
    });
    println!("{name}: measured psi_d / psi_q (rows i_d, columns i_q), Wb; true in brackets");
    for d in 0..s.n_d {
        let mut line = format!("{:7.2} A:", s.i_d[d]);
        for q in 0..s.n_q {
            let (id, iq) = (f64::from(s.i_d[d]), f64::from(s.i_q[q]));
            let (td, tq) = m.model.flux(id, iq, (m.reference.psi_f_wb, 0.0)).unwrap();
            line += &format!(
                " {:.4}/{:.4} ({td:.4}/{tq:.4})",
                s.psi_d[d][q], s.psi_q[d][q]
            );
        }
        println!("{line}");
    }
    // The map built from the samples, on a fine grid inside the rated circle.
    let map: FluxMap<f32, 9> = s.flux_map().unwrap_or_else(|e| panic!("{name}: {e}"));
    let mut fine = Vec::new();
    for a in -20..=20 {
        for b in -20..=20 {
            let (id, iq) = (i_r * f64::from(a) / 20.0, i_r * f64::from(b) / 20.0);
            if id.hypot(iq) <= i_r {
                fine.push((id, iq));
            }
        }
    }
    let (md, mq) = max_errors(m, &fine, |id, iq| {
        let p = map.eval(id as f32, iq as f32);
        (f64::from(p.psi_d), f64::from(p.psi_q))
    });
    // The true model sampled on the same grid: the interpolation's own share.
    let true_map: FluxMap<f32, 9> = m
        .model
        .flux_map(
            &s.i_d[..s.n_d]
                .iter()
                .map(|&x| f64::from(x))
                .collect::<Vec<_>>(),
            &s.i_q[..s.n_q]
                .iter()
                .map(|&x| f64::from(x))
                .collect::<Vec<_>>(),
        )
        .unwrap();
    let (gd, gq) = max_errors(m, &fine, |id, iq| {
        let p = true_map.eval(id as f32, iq as f32);
        (f64::from(p.psi_d), f64::from(p.psi_q))
    });
    println!(
        "{name}: the true model on the same grid, interpolated: psi_d {gd:.3} %, psi_q {gq:.3} %"
    );
    println!(
        "{name}: rated {i_r:.2} A, grid {}x{} to {i_max:.2} A; nodes |i|<=rated: psi_d {nd:.3} %, \
         psi_q {nq:.3} %; map over |i|<=rated: psi_d {md:.3} %, psi_q {mq:.3} %; duration \
         {:.3} s; rotor moved {:.2e} mech rad; peak {:.2} A; q closure {:.2e} Wb",
        s.n_d, s.n_q, o.duration_s, o.rotor_moved_mech_rad, o.peak_a, s.q_closure_wb
    );
    assert!(
        nd < node_pct && nq < node_pct,
        "{name}: node errors {nd} {nq} %"
    );
    assert!(
        md < gd + map_pct && mq < gq + map_pct,
        "{name}: map errors {md} {mq} % (the true model on the grid: {gd} {gq} %)"
    );
    // The rotor drifts slowly between the pulses (followed by the probe): bounded here.
    let moved_max = if k_max <= 1.5 {
        0.2
    } else {
        0.1 * std::f64::consts::TAU
    };
    assert!(o.rotor_moved_mech_rad < moved_max, "{name}: rotor moved");
    // The probe's own estimate of the motion agrees with the plant's (electrical rad).
    let est = f64::from(s.rotor_angle_max_rad) / f64::from(m.reference.pole_pairs);
    println!("{name}: the probe's estimate of the rotor's largest angle: {est:.2e} mech rad");
    assert!(
        (est - o.rotor_moved_mech_rad).abs() < 0.1 * o.rotor_moved_mech_rad + 1e-4,
        "{name}: estimated {est}, true {}",
        o.rotor_moved_mech_rad
    );
    assert!(o.duration_s < 5.0, "{name}: {} s", o.duration_s);
    assert!(o.peak_a < 2.0 * i_max, "{name}: peak {} A", o.peak_a);
}

#[test]
fn pm_syrm_flux_map_at_standstill() {
    check(&PM_SYRM, 0.7);
}

#[test]
fn saturating_ipm_flux_map_at_standstill() {
    check(&SATURATED_IPM, -2.1);
}

/// Told what the identification measures, with its typical errors (`Rs` +2 %, `Ld`, `Lq`
/// +3 %, `psi_f` +1 %, `J` +5 %) and 50 mA of current noise: the nodes within 3 %, the map
/// within 2 % of the true model on the grid.
#[test]
fn the_identifications_errors_and_noise_cost_little() {
    let told = Told {
        rs: 1.02,
        l: 1.03,
        psi_f: 1.01,
        j: 1.05,
        noise_a: 0.05,
    };
    check_told(&PM_SYRM, 0.7, told, 3.0, 2.0, 1.5);
    check_told(&SATURATED_IPM, -2.1, told, 3.0, 2.0, 1.5);
}

/// The grid of the suite's identified-map rows (`+-PROBE_CURRENT` times rated), the probe
/// told the motor's own values: the identified flux within 2 % over the rated current range
/// on both motors (the nodes inside the rated circle), the map within 1 % of the true model
/// on the same grid.
#[test]
fn the_suites_grid_meets_the_flux_goal() {
    check_told(&PM_SYRM, 0.7, Told::EXACT, 2.0, 1.0, PROBE_CURRENT);
    check_told(&SATURATED_IPM, -2.1, Told::EXACT, 2.0, 1.0, PROBE_CURRENT);
}

/// The probe on the suite's realistic drive (`probe_realistic`: dead time, one period of
/// delay, 12-bit ADC over four times rated, noise, gain and offset errors; the offsets and
/// the dead-time voltage as the identification measures them), on the suite's grid, told
/// the motor's own values: prints the flux errors and asserts the 2 % goal on the nodes
/// inside the rated circle.
#[test]
fn realistic_sensing_meets_the_flux_goal() {
    for (m, theta0) in [(&PM_SYRM, 0.7), (&SATURATED_IPM, -2.1)] {
        let name = m.reference.name;
        let i_r = rated_current(m);
        let o = probe_realistic(m, i_r, PROBE_CURRENT * i_r, theta0, &Told::EXACT, 1)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = &o.samples;
        let mut pts = Vec::new();
        let mut got = Vec::new();
        for d in 0..s.n_d {
            for q in 0..s.n_q {
                let (id, iq) = (f64::from(s.i_d[d]), f64::from(s.i_q[q]));
                if id.hypot(iq) <= i_r * 1.0001 {
                    pts.push((id, iq));
                    got.push((f64::from(s.psi_d[d][q]), f64::from(s.psi_q[d][q])));
                }
            }
        }
        let (nd, nq) = max_errors(m, &pts, |id, iq| {
            let k = pts.iter().position(|p| *p == (id, iq)).unwrap();
            got[k]
        });
        println!(
            "{name} realistic sensing, grid to {:.2} A: nodes |i|<=rated psi_d {nd:.3} %, \
             psi_q {nq:.3} %; duration {:.3} s; rotor moved {:.3} mech rad; peak {:.2} A; \
             q closure {:.2e} Wb",
            PROBE_CURRENT * i_r,
            o.duration_s,
            o.rotor_moved_mech_rad,
            o.peak_a,
            s.q_closure_wb
        );
        assert!(nd < 2.0 && nq < 2.0, "{name}: {nd} {nq} %");
        assert!(o.duration_s < 5.0);
    }
}

/// The probe on the identification's realistic drive with each error source on its own:
/// the node errors (measured minus the plant's flux at the node), RMS over the grid and
/// per node, in mWb. Diagnostic (about 5 s in release):
/// `cargo test --release -p pmsm-sim --test saturated_flux_probe error_sources -- --ignored --nocapture`.
#[test]
#[ignore]
fn error_sources() {
    use pmsm_sim::analysis::suite::identified::{probe_on_drive, saturated_scenario};
    use pmsm_sim::plant::sensors::SensorConfig;
    let m = &SATURATED_IPM;
    let r = &m.reference;
    let variants: [(&str, bool, u8, bool); 8] = [
        ("realistic", true, 0, true),
        ("ideal sensors", true, 1, true),
        ("no noise", true, 2, true),
        ("noise only", true, 3, true),
        ("gain only", true, 4, true),
        ("offset only", true, 5, true),
        ("adc only", true, 6, true),
        ("ideal sensors, no dead time", false, 1, true),
    ];
    for theta0 in [0.0f64, -2.1] {
        for (name, dead, sensors, delay) in variants {
            let (mut sc, i_r) = saturated_scenario(m, 2);
            if !dead {
                sc.inverter.dead_time_s = 0.0;
            }
            match sensors {
                1 => sc.sensors = SensorConfig::default(),
                2 => sc.sensors.current_noise_std_a = 0.0,
                3 => {
                    sc.sensors = SensorConfig {
                        current_noise_std_a: sc.sensors.current_noise_std_a,
                        ..SensorConfig::default()
                    }
                }
                4 => {
                    sc.sensors = SensorConfig {
                        gain_error: sc.sensors.gain_error,
                        ..SensorConfig::default()
                    }
                }
                5 => {
                    sc.sensors = SensorConfig {
                        offset_a: sc.sensors.offset_a,
                        ..SensorConfig::default()
                    }
                }
                6 => {
                    sc.sensors = SensorConfig {
                        adc_bits: sc.sensors.adc_bits,
                        adc_full_scale_a: sc.sensors.adc_full_scale_a,
                        ..SensorConfig::default()
                    }
                }
                _ => {}
            }

            sc.inverter.delay = delay;
            let s = probe_on_drive(m, &sc, PROBE_CURRENT * i_r, theta0, &Told::EXACT)
                .unwrap_or_else(|e| panic!("{name}: {e}"))
                .samples;
            let (mut sd, mut sq, mut n) = (0.0, 0.0, 0.0);
            let mut lines = String::new();
            for d in 0..s.n_d {
                lines += &format!("{:7.2} A:", s.i_d[d]);
                for q in 0..s.n_q {
                    let (id, iq) = (f64::from(s.i_d[d]), f64::from(s.i_q[q]));
                    let (td, tq) = m.model.flux(id, iq, (r.psi_f_wb, 0.0)).unwrap();
                    let ed = 1e3 * (f64::from(s.psi_d[d][q]) - td);
                    let eq = 1e3 * (f64::from(s.psi_q[d][q]) - tq);
                    sd += ed * ed;
                    sq += eq * eq;
                    n += 1.0;
                    lines += &format!(" {ed:+5.2}/{eq:+5.2}");
                }
                lines += "\n";
            }
            println!(
                "theta0 {theta0}, {name}: RMS node error psi_d {:.2} mWb, psi_q {:.2} mWb \
                 (d/q per node, rows i_d, columns i_q)\n{lines}",
                (sd / n).sqrt(),
                (sq / n).sqrt()
            );
        }
    }
}
