//! The real-drive effects of the simulator do what they say: the longer voltage update delay
//! shifts the applied voltage by the set number of periods, the back-EMF harmonics show in
//! the open-circuit EMF at 5 and 7 times the fundamental with the set amplitude and phase,
//! and skipped control cycles happen at the set rate, hold the duties and leave the run
//! finite. Debug build, a few seconds.

use core::f64::consts::{PI, TAU};

use pmsm_sim::plant::frames::clarke;
use pmsm_sim::plant::{EmfHarmonics, MotorModel, Plant, PlantState};
use pmsm_sim::scenario::Scenario;
use pmsm_sim::sim::{self, RunOptions};

fn default_cut(duration_s: f64) -> Scenario {
    let mut sc = Scenario::preset("default")
        .unwrap_or_else(|e| panic!("{e}"))
        .with_duration(duration_s);
    sc.observer.reference_filter = false;
    sc
}

fn traced(sc: &Scenario) -> sim::RunOutput {
    let out = sim::run_with(
        sc,
        RunOptions {
            record_trace: true,
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(out.end.is_completed(), "{}", out.end.describe());
    out
}

#[test]
fn voltage_delay_shifts_the_applied_voltage_by_the_set_periods() {
    // No dead time: the applied voltage is the duties' ideal one, comparable exactly.
    for (dp, n, f) in [(1.5, 1usize, 0.5), (2.0, 2, 0.0), (0.25, 0, 0.25)] {
        let mut sc = default_cut(0.4);
        sc.inverter.dead_time_s = 0.0;
        sc.inverter.delay_periods = Some(dp);
        let out = traced(&sc);
        let s = &out.trace.samples;
        let ideal = |k: usize| {
            let u = clarke(s[k].control.duties);
            [u[0] * s[k].measured.u_dc_v, u[1] * s[k].measured.u_dc_v]
        };
        let mut checked = 0;
        let mut worst = 0.0f64;
        for k in (n + 2)..s.len() {
            let pwm = (k - n - 1..=k).all(|j| s[j].inverter.pwm_enabled);
            if !pwm {
                continue;
            }
            // Period k: tick k-n-1's voltage over its first f, tick k-n's over the rest.
            let (a, b) = (ideal(k - n - 1), ideal(k - n));
            let want = [f * a[0] + (1.0 - f) * b[0], f * a[1] + (1.0 - f) * b[1]];
            let got = s[k].inverter.u_ab_v;
            worst = worst.max((got[0] - want[0]).abs().max((got[1] - want[1]).abs()));
            // What the controller is told is the one period it compensates.
            let told = ideal(k - 1);
            let c = s[k].inverter.u_ab_commanded_v;
            assert!((c[0] - told[0]).abs() < 1e-9 && (c[1] - told[1]).abs() < 1e-9);
            checked += 1;
        }
        println!("delay {dp} periods: {checked} periods, worst |u - expected| {worst:.2e} V");
        assert!(checked > 1000, "{checked}");
        assert!(worst < 1e-9, "delay {dp}: {worst} V");
    }
    // A bad value names the key.
    let text = Scenario::preset_text("default")
        .unwrap_or_default()
        .replace("delay = true", "delay = true\ndelay_periods = 4.0");
    match Scenario::from_toml_str(&text, "t.toml") {
        Err(pmsm_sim::SimError::Scenario { field, .. }) => {
            assert_eq!(field, "inverter.delay_periods")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn emf_harmonics_show_at_5x_and_7x_with_the_set_amplitude() {
    let h = EmfHarmonics {
        h5: 0.02,
        h5_phase_rad: 0.4,
        h7: 0.01,
        h7_phase_rad: -1.1,
    };
    let motor = MotorModel {
        emf_harmonics: h,
        j_kg_m2: 1e9, // constant speed
        ..MotorModel::servo()
    };
    let w_mech = 100.0;
    let w = w_mech * motor.p();
    // The open-circuit EMF from the plant's dynamics: at i = 0, L di/dt = u - e, so a tiny
    // step with u = 0 gives e = -L di / dt (not the plant's own EMF function).
    let n = 720;
    let dt = 1e-9;
    let mut ea = Vec::with_capacity(n);
    for j in 0..n {
        let th = -PI + TAU * j as f64 / n as f64;
        let mut p = Plant::new(
            motor.clone(),
            PlantState {
                theta_e_rad: th,
                omega_mech_rad_s: w_mech,
                ..PlantState::default()
            },
        );
        let emf = p.emf_ab_v();
        p.step([0.0, 0.0], 0.0, dt);
        let i = p.i_ab_a();
        let e = [-motor.ld_h * i[0] / dt, -motor.ld_h * i[1] / dt];
        assert!(
            (e[0] - emf[0]).abs() < 1e-4 * w * motor.psi_f_wb,
            "{e:?} {emf:?}"
        );
        ea.push((th, e[0]));
    }
    // Fourier coefficients of phase a's EMF (alpha = a, amplitude-invariant).
    let coef = |m: f64| {
        let (mut re, mut im) = (0.0, 0.0);
        for &(th, e) in &ea {
            re += e * (m * th).cos();
            im -= e * (m * th).sin();
        }
        (2.0 * re / n as f64, 2.0 * im / n as f64)
    };
    let c1 = coef(1.0);
    let a1 = c1.0.hypot(c1.1);
    assert!((a1 / (w * motor.psi_f_wb) - 1.0).abs() < 1e-5, "{a1}");
    for (m, k, phi) in [(5.0, h.h5, h.h5_phase_rad), (7.0, h.h7, h.h7_phase_rad)] {
        let c = coef(m);
        let am = c.0.hypot(c.1);
        // e_a = -w psi_f (sin th + 5 k5 sin(5 th + phi5) + 7 k7 sin(7 th + phi7)).
        let ratio = am / a1;
        let phase = (c.1.atan2(c.0) - c1.1.atan2(c1.0) - phi + PI).rem_euclid(TAU) - PI;
        println!(
            "EMF harmonic {m}: {:.4} % of the fundamental (set {:.4} %: {m} x {k} of psi_f), phase error {phase:.2e} rad",
            100.0 * ratio,
            100.0 * m * k
        );
        assert!((ratio / (m * k) - 1.0).abs() < 1e-4, "{m}: {ratio}");
        assert!(phase.abs() < 1e-4, "{m}: {phase}");
    }
    for m in [2.0, 3.0, 4.0, 6.0, 8.0, 11.0] {
        let c = coef(m);
        assert!(c.0.hypot(c.1) < 1e-6 * a1, "harmonic {m}");
    }
    // Out of range: the error names the key.
    let text = format!(
        "{}\n[motor.emf_harmonics]\nh5 = 0.5\n",
        Scenario::preset_text("default").unwrap_or_default()
    );
    match Scenario::from_toml_str(&text, "t.toml") {
        Err(pmsm_sim::SimError::Scenario { field, .. }) => {
            assert_eq!(field, "motor.emf_harmonics.h5")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn emf_harmonics_in_closed_loop_ripple_the_torque_at_6x() {
    // The default drive with harmonics runs, and its torque at rated speed ripples.
    let mut sc = default_cut(0.8);
    sc.motor.emf_harmonics = EmfHarmonics {
        h5: 0.006,
        h7: 0.003,
        ..EmfHarmonics::NONE
    };
    let out = traced(&sc);
    let s = &out.trace.samples;
    let last: Vec<f64> = s[s.len() - 500..]
        .iter()
        .map(|x| x.truth.torque_nm)
        .collect();
    let mean = last.iter().sum::<f64>() / last.len() as f64;
    let span = last.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - last.iter().copied().fold(f64::INFINITY, f64::min);
    println!("torque at the end: mean {mean:.3} N m, peak to peak {span:.3} N m");
    assert!(span.is_finite() && span > 0.01, "{span}");
}

#[test]
fn skipped_cycles_happen_at_the_set_rate_and_the_run_stays_finite() {
    let mut sc = default_cut(0.6);
    sc.skipped_cycles.probability = 0.02;
    sc.skipped_cycles.times_s = vec![0.45];
    let out = traced(&sc);
    let n = out.metrics.periods;
    let skipped = out.metrics.skipped_control_periods;
    // Binomial(6000, 0.02): mean 120, sd 11; plus the timed one.
    println!("skipped {skipped} of {n} periods (set 2 % + 1)");
    assert!((80..=160).contains(&skipped), "{skipped}");
    let s = &out.trace.samples;
    // A skipped period has no estimate of the controller's observer and holds the duties.
    let held: Vec<usize> = (1..s.len())
        .filter(|&k| s[k].controller_observer.is_none() && s[k - 1].controller_observer.is_some())
        .collect();
    for &k in &held {
        assert_eq!(s[k].control.duties, s[k - 1].control.duties, "period {k}");
    }
    let k45 = (0.45f64 / sc.ts_s()).round() as usize;
    assert!(s[k45].controller_observer.is_none(), "the timed skip");
    assert!(held.len() as u64 <= skipped);
    assert!(held.len() as u64 > skipped / 2);
    for x in s {
        assert!(x.truth.i_ab_a.iter().all(|v| v.is_finite()));
        assert!(x.control.duties.iter().all(|d| (0.0..=1.0).contains(d)));
    }
    assert!(
        out.metrics.drive.fault.is_none(),
        "{:?}",
        out.metrics.drive.fault
    );
    // Deterministic: the same scenario, the same periods.
    let again = traced(&sc);
    assert_eq!(again.metrics.skipped_control_periods, skipped);
    // Bad settings name the key.
    sc.skipped_cycles.probability = 0.7;
    assert_eq!(
        sc.validate().map_err(|e| e.field),
        Err("skipped_cycles.probability".to_string())
    );
    sc.skipped_cycles.probability = 0.0;
    sc.skipped_cycles.times_s = vec![0.1, -1.0];
    assert_eq!(
        sc.validate().map_err(|e| e.field),
        Err("skipped_cycles.times_s[1]".to_string())
    );
}
