//! MTPA in the simulator's closed loop: `foc` (sensored, with the true
//! angle, and sensorless, on its own observer from the preset's start-up) drives each interior
//! preset at half its rated speed against its rated torque, on the full plant, inverter (delay, dead
//! time compensated by foc) and current sensing (noise, ADC). In steady state the torque per
//! ampere the plant makes must be within 1 % of the analytic optimum: the smallest current
//! magnitude that makes the measured torque, found by brute force over the current angle with
//! the plant's `Ld`, `Lq`, `psi_f`, for the torque of the mean current vector. A sensored run
//! with `[controller.foc] mtpa = false` (`i_d = 0`) is checked to miss it (0.71 on the traction
//! motor).
//!
//! `cargo test -p pmsm-sim --test mtpa -- --nocapture` prints the numbers.

use pmsm_sim::output::record::Sample;
use pmsm_sim::plant::load::{LoadTerm, Profile};
use pmsm_sim::scenario::{ControllerKind, Scenario};
use pmsm_sim::sim::{RunOptions, SampleSink, run_with};

/// The averaging window, s (from, to).
const WINDOW_S: (f64, f64) = (0.9, 1.3);

/// Means over the window of the plant's `i_d`, `i_q`, `|i|` and torque.
#[derive(Default)]
struct Means {
    n: u64,
    sums: [f64; 5],
    speed_rpm: f64,
}

impl SampleSink for Means {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        if s.t_s >= WINDOW_S.0 && s.t_s < WINDOW_S.1 {
            let [d, q] = s.truth.i_dq_a;
            let [rd, _] = s.control.telemetry.i_dq_ref_a;
            for (acc, v) in self
                .sums
                .iter_mut()
                .zip([d, q, d.hypot(q), s.truth.torque_nm, rd])
            {
                *acc += v;
            }
            self.speed_rpm += s.truth.speed_rpm;
            self.n += 1;
        }
        Ok(())
    }
}

/// Torque of `(i_d, i_q)`, N m.
fn torque(p: f64, ld: f64, lq: f64, psi: f64, i_d: f64, i_q: f64) -> f64 {
    1.5 * p * (psi + (ld - lq) * i_d) * i_q
}

/// Largest torque of the current magnitude `i_s` over the current angle (lead from q, a
/// 20 000-point grid and a golden-section refinement), and that angle.
fn max_torque(p: f64, ld: f64, lq: f64, psi: f64, i_s: f64) -> (f64, f64) {
    let t = |b: f64| torque(p, ld, lq, psi, -i_s * b.sin(), i_s * b.cos());
    let n = 20_000;
    let (mut best, mut b_best) = (f64::NEG_INFINITY, 0.0);
    for k in 0..=n {
        let b = 0.5 * std::f64::consts::PI * f64::from(k) / f64::from(n);
        if t(b) > best {
            (best, b_best) = (t(b), b);
        }
    }
    let h = 0.5 * std::f64::consts::PI / f64::from(n);
    let (mut lo, mut hi) = (b_best - h, b_best + h);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..80 {
        let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if t(x1) > t(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    let b = 0.5 * (lo + hi);
    if t(b) >= best {
        (t(b), b)
    } else {
        (best, b_best)
    }
}

/// The smallest current magnitude that makes torque `t_nm` (bisection), and its angle.
fn min_current(p: f64, ld: f64, lq: f64, psi: f64, t_nm: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (0.0, 1.0);
    while max_torque(p, ld, lq, psi, hi).0 < t_nm {
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if max_torque(p, ld, lq, psi, mid).0 >= t_nm {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (hi, max_torque(p, ld, lq, psi, hi).1)
}

#[test]
fn mtpa_torque_per_ampere_within_1_percent_of_the_optimum_at_rated_torque() {
    println!(
        "\n| motor | speed (rpm) | torque (N m) | i_d / i_q (A) | abs(i) (A) | angle (deg, lead from q) | \
         optimum abs(i) (A) | optimum angle (deg) | torque per ampere / optimum | with i_d = 0: abs(i) (A) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    // The last row, MTPA off (`i_d = 0`), shows that the check can fail.
    for (name, kind, mtpa) in [
        ("industrial-ipm", ControllerKind::FocSensored, true),
        ("traction-ipm", ControllerKind::FocSensored, true),
        ("industrial-ipm", ControllerKind::Foc, true),
        ("traction-ipm", ControllerKind::Foc, true),
        ("traction-ipm", ControllerKind::FocSensored, false),
    ] {
        let mut sc = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
        sc.controller.kind = kind;
        let mode = match (kind == ControllerKind::Foc, mtpa) {
            (true, _) => "sensorless",
            (false, true) => "sensored",
            (false, false) => "sensored, MTPA off",
        };
        let f = sc.controller.foc.get_or_insert_default();
        f.mtpa = Some(mtpa);
        // foc's classic align / I/f start (this test is about MTPA, and its timing is the
        // classic start's hand-over at 0.32-0.38 s; the damped start hands over later).
        f.startup_damping_ratio = Some(0.0);
        f.startup_kick_speed_ratio = Some(0.0);
        // From 0.5 rad off the alignment angle, where the classic start hands the traction
        // motor over (its grid: -0.52, 0 and 0.52 rad of 12 angles; the preset's own start
        // angle suits the damped start).
        sc.initial.theta_e_rad = 0.5;
        sc.duration_s = WINDOW_S.1;
        let half = 0.5 * sc.rated_speed_rpm;
        sc.speed_ref_rpm = Profile::linear(vec![(0.0, 0.0), (0.3, half)]);
        // Rated torque in all (the motor's own friction on top is part of what it makes).
        // (after the sensorless hand-over, at 0.32-0.38 s)
        sc.load = vec![LoadTerm::Ramp {
            start_s: 0.6,
            end_s: 0.8,
            from_nm: 0.0,
            to_nm: sc.rated_torque_nm,
        }];
        sc.faults.clear();
        sc.validate().unwrap_or_else(|e| panic!("{name}: {e:?}"));
        let mut m = Means::default();
        let out = run_with(
            &sc,
            RunOptions {
                sinks: vec![&mut m],
                ..RunOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(out.end.is_completed(), "{name}: {}", out.end.describe());
        let n = m.n as f64;
        let [i_d, i_q, i_abs, t_nm, _] = m.sums.map(|x| x / n);
        let speed = m.speed_rpm / n;
        let mo = sc.motor;
        let (p, ld, lq, psi) = (mo.p(), mo.ld_h, mo.lq_h, mo.psi_f_wb);
        // The mean current vector and the torque the plant's model gives for it (the ripple of
        // noise and PWM is not MTPA's business; the mean magnitude and the plant's mean torque,
        // which differs by the ripple's share, are printed too).
        let i_vec = i_d.hypot(i_q);
        let t_op = torque(p, ld, lq, psi, i_d, i_q);
        let (i_opt, b_opt) = min_current(p, ld, lq, psi, t_op);
        let ratio = i_opt / i_vec;
        let i_surface = t_op / (1.5 * p * psi);
        println!(
            "| {name}, {mode} | {speed:.1} | {t_op:.3} (plant's mean {t_nm:.3}) | {i_d:.3} / {i_q:.3} | {i_vec:.3} (mean abs {i_abs:.3}) | {:.2} | \
             {i_opt:.3} | {:.2} | {ratio:.6} | {i_surface:.3} |",
            (-i_d).atan2(i_q).to_degrees(),
            b_opt.to_degrees(),
        );
        assert!((speed - half).abs() < 0.01 * half, "{name}: {speed} rpm");
        assert!(
            (t_nm - sc.rated_torque_nm).abs() < 0.05 * sc.rated_torque_nm,
            "{name}: {t_nm} N m"
        );
        // The optimum is the least current for the torque: the ratio cannot exceed 1 beyond
        // the search's precision.
        assert!(ratio < 1.0 + 1e-9, "{name}: {ratio}");
        if mtpa {
            assert!(ratio > 0.99, "{name}, {mode}: {ratio}");
        } else {
            assert!(ratio < 0.9, "{name}, {mode}: {ratio}");
        }
    }
}
