//! Exploration (ignored): tracking on mismatched motors.
mod common;
use common::*;
use ekf_core::{MotorParams, ObserverConfig, ParameterTracking};

fn told(m: MotorParams<f64>, psi: f64, rs: f64, ls: f64) -> MotorParams<f64> {
    MotorParams {
        psi_f_wb: m.psi_f_wb * psi,
        rs_ohm: m.rs_ohm * rs,
        ls_h: m.ls_h * ls,
        ..m
    }
}

#[test]
#[ignore]
fn explore() {
    let ts = 1e-4;
    let walk: f64 = std::env::var("WALK")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0);
    let sig: f64 = std::env::var("SIG")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0);
    let n: usize = std::env::var("N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20000);
    for (name, motor, rated, noise) in reference_motors() {
        let ic = motor.characteristic_current_a();
        for frac in [0.1, 0.5, 1.0] {
            let w = rated * frac;
            let speed = move |_t: f64| w;
            let iq = move |t: f64| if t < 0.1 { 0.05 * ic } else { 0.15 * ic };
            let sc = Scenario {
                motor,
                ts,
                n,
                speed: &speed,
                iq_ref: &iq,
                th0: -0.3,
                noise_a: noise,
                seed: 3,
            };
            let tr = simulate(&sc);
            let cases = [
                ("exact", 1.0, 1.0, 1.0),
                ("psi+10", 1.1, 1.0, 1.0),
                ("psi-10", 0.9, 1.0, 1.0),
                ("rs+30", 1.0, 1.3, 1.0),
                ("hot", 1.0 / 0.88, 1.0 / 1.393, 1.0),
                ("ls+20", 1.0, 1.0, 1.2),
            ];
            let ncase: usize = std::env::var("NCASE")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(6);
            for &(case, p, r, l) in &cases[..ncase] {
                let m = told(motor, p, r, l);
                let mut cfg = ObserverConfig::new(m, ts);
                let mut t = ParameterTracking::default_for(ts);
                t.psi_f_walk_per_sqrt_s *= walk;
                t.rs_walk_per_sqrt_s *= walk;
                t.psi_f_sigma0 *= sig;
                t.rs_sigma0 *= sig;
                if let Ok("fixed") = std::env::var("MODE").as_deref() {
                    t.rs = ekf_core::RsTracking::Fixed
                }
                let ps: f64 = std::env::var("PSIG")
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(1.0);
                let rsg: f64 = std::env::var("RSIG")
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(1.0);
                t.psi_f_sigma0 *= ps;
                t.psi_f_walk_per_sqrt_s *= ps;
                t.rs_sigma0 *= rsg;
                t.rs_walk_per_sqrt_s *= rsg;
                cfg.parameter_tracking = Some(t);
                let est = run_observer(&cfg, &tr);
                let err = angle_errors_deg(&tr, &est);
                let (mean, rms, max) = stats(&err[n / 2..]);
                let e = est.last().unwrap();
                let act = est.iter().filter(|e| e.parameters_tracking).count();
                let off = ObserverConfig {
                    parameter_tracking: None,
                    ..cfg
                };
                let (_, rms_off, _) =
                    stats(&angle_errors_deg(&tr, &run_observer(&off, &tr))[n / 2..]);
                println!(
                    "{name:10} {:>4.0}% {case:7} rms {rms:6.3} mean {mean:7.3} max {max:6.3} (off {rms_off:6.3}) psi {:+6.2}% rs {:+6.1}% act {act}",
                    frac * 100.0,
                    (e.psi_f_wb / motor.psi_f_wb - 1.0) * 100.0,
                    (e.rs_ohm / motor.rs_ohm - 1.0) * 100.0
                );
            }
        }
    }
}

#[test]
#[ignore]
fn explore_time() {
    let ts = 1e-4;
    let n = 60000;
    let (name, motor, rated, noise) = reference_motors()[0];
    let ic = motor.characteristic_current_a();
    let w = rated * 0.5;
    let speed = move |_t: f64| w;
    let iq = move |t: f64| if t < 0.1 { 0.05 * ic } else { 0.15 * ic };
    let nz: f64 = std::env::var("NOISE")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0);
    let sc = Scenario {
        motor,
        ts,
        n,
        speed: &speed,
        iq_ref: &iq,
        th0: -0.3,
        noise_a: noise * nz,
        seed: 3,
    };
    let tr = simulate(&sc);
    let cfg = ObserverConfig::new(motor, ts);
    let est = run_observer(&cfg, &tr);
    for k in (0..n).step_by(2500) {
        let e = &est[k];
        println!(
            "{name} t {:.2} psi {:+.3}% ({:.3}%) rs {:+.2}% ({:.2}%) active {}",
            k as f64 * ts,
            (e.psi_f_wb / motor.psi_f_wb - 1.0) * 100.0,
            e.psi_f_sigma_wb / motor.psi_f_wb * 100.0,
            (e.rs_ohm / motor.rs_ohm - 1.0) * 100.0,
            e.rs_sigma_ohm / motor.rs_ohm * 100.0,
            e.parameters_tracking
        );
    }
}

#[test]
#[ignore]
fn explore_reversal() {
    let ts = 1e-4;
    let (name, motor, rated, noise) = reference_motors()[2];
    let n = 4000;
    let slow = move |t: f64| rated * (2.0 * std::f64::consts::PI * t / 0.2).cos();
    let iq = |_t: f64| 2.0;
    let tr = simulate(&Scenario {
        motor,
        ts,
        n,
        speed: &slow,
        iq_ref: &iq,
        th0: 0.3,
        noise_a: noise,
        seed: 9,
    });
    let mut cfg = ObserverConfig::new(motor, ts);
    cfg.x0[2] = tr.w[0];
    cfg.x0[3] = tr.th[0];
    let est = run_observer(&cfg, &tr);
    for k in (0..n).step_by(100) {
        let e = &est[k];
        println!(
            "{name} t {:.3} w {:7.1} west {:7.1} err {:7.2} psi {:+.3}% rs {:+.2}% active {}",
            k as f64 * ts,
            tr.w[k],
            e.omega_e_rad_s,
            ekf_core::wrap_angle(e.theta_rad - tr.th[k]).to_degrees(),
            (e.psi_f_wb / motor.psi_f_wb - 1.0) * 100.0,
            (e.rs_ohm / motor.rs_ohm - 1.0) * 100.0,
            e.parameters_tracking
        );
    }
}
