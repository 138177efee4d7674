//! The self-commissioning (`foc::Identifier`) on the PM-assisted synchronous reluctance
//! reference motor `pm_syrm`, which it does not commission (docs/identify.md, "Why `pm_syrm`
//! fails"): on the saturated suite row's realistic drive it must fail with a typed error,
//! the bridge off and the current within the trip, never with parameters.
//!
//! And the plant's own numbers that make it fail, from the motor's saturation model (the
//! plant's): the current at which a d-axis current stops holding the rotor, where the rotor
//! rests against a larger current, how stiff and slow the hold is below that limit, and the
//! incremental inductances a standstill measurement sees there.
//!
//! Run: `cargo test --release -p pmsm-sim --test identify_pm_syrm -- --nocapture`.

use ekf_core::saturation::{PM_SYRM, SaturationModel};
use pmsm_sim::analysis::identify::{IdentifyOptions, identify};
use pmsm_sim::analysis::suite::identified::saturated_scenario;

/// The sequence on the saturated row's drive (sensor seed 2), with the current limit scaled by
/// `limit`: `(ok, error kind, failed step, time, peak current, trip)`.
fn run(
    limit: f64,
) -> (
    bool,
    Option<&'static str>,
    Option<&'static str>,
    f64,
    f64,
    f64,
) {
    let (mut sc, _) = saturated_scenario(&PM_SYRM, 2);
    sc.controller.current_limit_a *= limit;
    let r = identify(&sc, &IdentifyOptions::default()).expect("runs");
    println!(
        "current limit {:.2} A (test current {:.2} A): ok {}, {:?}, {:.3} s, peak {:.2} A",
        sc.controller.current_limit_a,
        0.5 * sc.controller.current_limit_a,
        r.ok,
        r.error,
        r.total_time_s,
        r.peak_current_a
    );
    assert!(r.pwm_off_at_end);
    assert!(r.identified.is_none() || r.ok);
    (
        r.ok,
        r.error_kind,
        r.failed_step,
        r.total_time_s,
        r.peak_current_a,
        2.0 * sc.controller.current_limit_a,
    )
}

/// The suite's drive (test current 11.9 A, half the limit): the rotor does not follow the
/// spin. At 0.3 x the limit (test current 3.6 A, below the d-axis limit): the rotor, held
/// only weakly, still turns when the injections run and the q injection's fit fails.
#[test]
fn the_identification_fails_safely_on_pm_syrm() {
    let (ok, kind, step, t, peak, trip) = run(1.0);
    assert!(!ok);
    assert_eq!((kind, step), (Some("lost_sync"), Some("spin")));
    assert!(t < 2.5 && peak < trip, "{t} s, {peak} A");
    let (ok, kind, step, _, peak, trip) = run(0.3);
    assert!(!ok);
    assert_eq!((kind, step), (Some("implausible"), Some("inductance_q")));
    assert!(peak < trip, "{peak} A");
}

/// Torque, N m, of the model at the current `i` A, `g` rad from the rotor's d axis.
fn torque(m: &SaturationModel, p: f64, i: f64, g: f64) -> f64 {
    let (i_d, i_q) = (i * g.cos(), i * g.sin());
    let (psi_d, psi_q) = m.flux(i_d, i_q, (0.45, 0.0)).expect("flux");
    1.5 * p * (psi_d * i_q - psi_q * i_d)
}

/// The incremental inductance matrix `d psi / d i` at `(i_d, i_q)`, H.
fn incremental(m: &SaturationModel, i_d: f64, i_q: f64) -> [[f64; 2]; 2] {
    let psi = m.flux(i_d, i_q, (0.45, 0.0)).expect("flux");
    let h = 1e-6;
    let col = |dd: f64, dq: f64| {
        let a = m.currents(psi.0 + dd, psi.1 + dq);
        let b = m.currents(psi.0 - dd, psi.1 - dq);
        ((a.0 - b.0) / (2.0 * h), (a.1 - b.1) / (2.0 * h))
    };
    // d i / d psi, inverted.
    let (a, c) = col(h, 0.0);
    let (b, d) = col(0.0, h);
    let det = a * d - b * c;
    [[d / det, -b / det], [-c / det, a / det]]
}

/// Where the rotor rests against a current `i` (its electrical angle from the rotor's d
/// axis, rad): the first angle from 0 at which the torque turns from pulling the rotor
/// forward (a rotor behind the current) to zero.
fn rest_angle(m: &SaturationModel, p: f64, i: f64) -> f64 {
    let step = 0.05f64.to_radians();
    let mut g = 0.0;
    // dT/dg > 0 at 0 (a stable equilibrium): the rotor rests on the current.
    if torque(m, p, i, step) > 0.0 {
        return 0.0;
    }
    while g < 1.5 {
        g += step;
        if torque(m, p, i, g) >= 0.0 {
            return g;
        }
    }
    f64::NAN
}

#[test]
fn why_the_d_axis_does_not_hold() {
    let m = &PM_SYRM.model;
    let r = &PM_SYRM.reference;
    let p = f64::from(r.pole_pairs);
    let linear_limit = r.psi_f_wb / (r.lq_h - r.ld_h);
    println!("psi_f / (Lq - Ld) with the small-signal values: {linear_limit:.2} A");
    println!(
        "| current (A) | rest angle (deg) | d-axis stiffness (N m / mech rad) | swing period (s) | \
         incremental Ld at +I / -I on d (mH) | incremental L at the rest, min / max (mH) | \
         its min axis from the rotor's d (deg) |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut limit = f64::NAN;
    let mut prev_k = f64::NAN;
    for i in [1.0, 2.0, 3.0, 3.5, 4.0, 5.0, 6.0, 8.0, 11.88] {
        let h = 1e-4;
        // Per mechanical radian: the electrical angle is p times it.
        let k = p * (torque(m, p, i, h) - torque(m, p, i, -h)) / (2.0 * h);
        if prev_k > 0.0 && k <= 0.0 {
            limit = i;
        }
        prev_k = k;
        let period = if k > 0.0 {
            std::f64::consts::TAU / (k / r.j_kg_m2).sqrt()
        } else {
            f64::NAN
        };
        let lp = incremental(m, i, 0.0)[0][0];
        let lm = incremental(m, -i, 0.0)[0][0];
        let g = rest_angle(m, p, i);
        let l = incremental(m, i * g.cos(), -i * g.sin());
        // Eigen decomposition of the symmetric 2 x 2 matrix.
        let (a, b, d) = (l[0][0], 0.5 * (l[0][1] + l[1][0]), l[1][1]);
        let mean = 0.5 * (a + d);
        let rad = (0.25 * (a - d) * (a - d) + b * b).sqrt();
        let axis = 0.5 * (2.0 * b).atan2(a - d);
        // The min-inductance axis is perpendicular to the max one.
        let min_axis = axis + std::f64::consts::FRAC_PI_2;
        let min_axis = (min_axis + std::f64::consts::FRAC_PI_2).rem_euclid(std::f64::consts::PI)
            - std::f64::consts::FRAC_PI_2;
        println!(
            "| {i:.2} | {:.1} | {k:.2} | {period:.2} | {:.1} / {:.1} | {:.1} / {:.1} | {:+.1} |",
            g.to_degrees(),
            1e3 * lp,
            1e3 * lm,
            1e3 * (mean - rad),
            1e3 * (mean + rad),
            min_axis.to_degrees()
        );
        if i >= 11.0 {
            // At the suite's test current the rotor rests far off the current.
            assert!((50.0..62.0).contains(&g.to_degrees()), "{}", g.to_degrees());
        }
        if i <= 3.0 {
            assert!(g == 0.0 && k > 0.0 && period > 0.5, "{i}: {g} {k} {period}");
        }
    }
    println!("the d-axis current stops holding the rotor between 3.5 A and {limit:.1} A");
    assert_eq!(limit, 4.0);
}
