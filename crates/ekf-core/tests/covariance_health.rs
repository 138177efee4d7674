//! Covariance health.
//!
//! - Long run: `P` of the default `f32` observer, augmented by the tracked flux (5 x 5), stays symmetric positive definite over many
//!   steps on the three reference motors, the speed sweeping through +-rated with reversals,
//!   the current reference varying, with sensor noise. The short version (1e6 steps in all)
//!   runs with every `cargo test`; the long one (1e8 steps in all) on demand:
//!   `cargo test --release -p ekf-core --test covariance_health -- --ignored --nocapture`.
//! - Self-reset: a covariance forced bad through `reset` (huge, negative diagonal) is caught
//!   by the next step, which resets the observer to its documented state and reports it.
mod common;
use common::{Rng, reference_motors};
use core::f64::consts::PI;
use ekf_core::nalgebra::{Cholesky, Matrix4, Matrix5, Vector4};
use ekf_core::{MotorParams, ObserverConfig, ObserverCounters, PmsmObserver, default_p0};

const TS: f64 = 1e-4;

fn motors() -> [(&'static str, MotorParams<f64>, f64, f64); 3] {
    reference_motors()
}

struct Outcome {
    checks: u64,
    not_pd: u64,
    min_eig_ratio: f64,
    counters: ObserverCounters,
    failed_steps: u64,
    /// Branch flips that left the speed estimate with the wrong sign.
    wrong_flips: u64,
}

/// Runs `steps` steps of the f32 default observer on a plant in f64 (4 midpoint substeps per
/// period): speed `rated sin(2 pi t / 1.5 s)` (through +-rated, reversing every 0.75 s),
/// `i_q` reference `0.1 I_c (1 + sin(2 pi t / 0.37 s))`, a dq controller on the true angle.
/// Checks `P` for symmetry and positive definiteness (Cholesky, in f64) every 16 steps.
fn run(motor: MotorParams<f64>, rated: f64, noise: f64, steps: u64, seed: u64) -> Outcome {
    let cfg = ObserverConfig::new(
        MotorParams::<f32>::from_f64(motor.rs_ohm, motor.lq_h, motor.psi_f_wb, motor.pole_pairs),
        TS as f32,
    );
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let (rs, ls, psi) = (motor.rs_ohm, motor.lq_h, motor.psi_f_wb);
    let ic = psi / ls;
    let mut rng = Rng::new(seed);
    let (mut ia, mut ib, mut th) = (0.0f64, 0.0f64, 0.3f64);
    let mut u_prev = [0.0f32; 2];
    let sub = 4;
    let h = TS / sub as f64;
    let mut out = Outcome {
        checks: 0,
        not_pd: 0,
        min_eig_ratio: f64::INFINITY,
        counters: ObserverCounters::default(),
        failed_steps: 0,
        wrong_flips: 0,
    };
    for k in 0..steps {
        let t = k as f64 * TS;
        let w = rated * (2.0 * PI * t / 1.5).sin();
        let z = [
            (ia + noise * rng.gauss()) as f32,
            (ib + noise * rng.gauss()) as f32,
        ];
        match obs.step(u_prev, z) {
            Ok(e) if e.branch_flipped => {
                // A flip must land on the right branch (speed of the right sign).
                if f64::from(e.omega_e_rad_s) * w <= 0.0 {
                    out.wrong_flips += 1;
                }
            }
            Ok(_) => {}
            Err(_) => out.failed_steps += 1,
        }
        if k % 16 == 0 {
            out.checks += 1;
            let p4: Matrix4<f64> = obs.covariance().map(f64::from);
            assert_eq!(p4, p4.transpose(), "P not symmetric at step {k}");
            // The augmented covariance of [i_a, i_b, w, th, psi_f] (the tracked flux's rows).
            let (xc, cc) = obs.flux_covariance().expect("tracking is on by default");
            let mut p = Matrix5::<f64>::zeros();
            p.fixed_view_mut::<4, 4>(0, 0).copy_from(&p4);
            for r in 0..4 {
                p[(r, 4)] = f64::from(xc[r]);
                p[(4, r)] = f64::from(xc[r]);
            }
            p[(4, 4)] = f64::from(cc);
            let d = p.diagonal();
            if d.iter().any(|v| *v <= 0.0) {
                out.not_pd += 1;
            } else {
                // Correlation matrix: its smallest eigenvalue says how close P is to singular.
                let s = d.map(|v| 1.0 / v.sqrt());
                let corr = Matrix5::from_diagonal(&s) * p * Matrix5::from_diagonal(&s);
                if Cholesky::new(corr).is_none() {
                    out.not_pd += 1;
                } else if k % 4096 == 0 {
                    let ev = corr.symmetric_eigenvalues().min();
                    out.min_eig_ratio = out.min_eig_ratio.min(ev);
                }
            }
        }
        // Voltage over [t_k, t_k+1): feed-forward plus P term in dq, at the mid-period angle.
        let iq_ref = 0.1 * ic * (1.0 + (2.0 * PI * t / 0.37).sin());
        let (s, c) = th.sin_cos();
        let (id, iq) = (ia * c + ib * s, -ia * s + ib * c);
        let kp = 0.3 * ls / TS;
        let ud = -w * ls * iq_ref - kp * id;
        let uq = rs * iq_ref + w * psi + kp * (iq_ref - iq);
        let (sm, cm) = (th + 0.5 * w * TS).sin_cos();
        let (ua, ub) = (ud * cm - uq * sm, ud * sm + uq * cm);
        for _ in 0..sub {
            // Midpoint rule; the speed is constant over the period.
            let f = |ia: f64, ib: f64, th: f64| {
                let (s, c) = th.sin_cos();
                (
                    (-rs * ia + w * psi * s + ua) / ls,
                    (-rs * ib - w * psi * c + ub) / ls,
                )
            };
            let (da, db) = f(ia, ib, th);
            let (da, db) = f(ia + 0.5 * h * da, ib + 0.5 * h * db, th + 0.5 * h * w);
            ia += h * da;
            ib += h * db;
            th += h * w;
        }
        th = ekf_core::wrap_angle(th);
        u_prev = [ua as f32, ub as f32];
    }
    out.counters = *obs.counters();
    out
}

fn long_run(total_steps: u64) {
    let per_motor = total_steps / 3;
    let start = std::time::Instant::now();
    for (j, (name, motor, rated, noise)) in motors().into_iter().enumerate() {
        let t0 = std::time::Instant::now();
        let o = run(motor, rated, noise, per_motor, 1000 + j as u64);
        println!(
            "{name:18} {per_motor} f32 steps in {:.1} s: {} checks, {} not positive definite, \
             smallest correlation eigenvalue {:.2e}, {} failed steps, {} flips to the wrong branch, \
             counters {:?}",
            t0.elapsed().as_secs_f64(),
            o.checks,
            o.not_pd,
            o.min_eig_ratio,
            o.failed_steps,
            o.wrong_flips,
            o.counters
        );
        assert_eq!(o.not_pd, 0, "{name}: P lost positive definiteness");
        assert_eq!(o.failed_steps, 0, "{name}: steps failed");
        assert_eq!(o.counters.covariance_resets, 0, "{name}: health resets");
        assert!(o.min_eig_ratio > 0.0);
        assert_eq!(o.wrong_flips, 0, "{name}: flips to the wrong branch");
    }
    println!(
        "total {total_steps} steps in {:.1} s",
        start.elapsed().as_secs_f64()
    );
}

#[test]
fn covariance_stays_positive_definite_short() {
    long_run(1_000_000);
}

#[test]
#[ignore = "1e8 steps: run with --release -- --ignored"]
fn covariance_stays_positive_definite_1e8() {
    long_run(100_000_000);
}

/// A spun-up default observer (f64, servo) fed with consistent data.
fn spun_up() -> (PmsmObserver<f64>, ObserverConfig<f64>) {
    let cfg = ObserverConfig::new(MotorParams::servo(), TS);
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    for k in 0..200 {
        let th = k as f64 * 0.05;
        obs.step([10.0 * th.cos(), 10.0 * th.sin()], [th.sin(), -th.cos()])
            .expect("finite");
    }
    (obs, cfg)
}

#[test]
fn huge_covariance_triggers_a_self_reset() {
    let (mut obs, cfg) = spun_up();
    let x = *obs.state();
    obs.reset(x, Matrix4::identity() * 1e20).expect("finite");
    let z = [0.7, -0.2];
    let e = obs.step([1.0, 2.0], z).expect("recovers");
    assert!(e.covariance_reset, "reset reported in the estimate");
    assert_eq!(obs.counters().covariance_resets, 1);
    // Documented state: currents = the measured currents, speed and angle kept, P = P0.
    assert_eq!(obs.covariance(), cfg.p0);
    assert_eq!((obs.state()[0], obs.state()[1]), (z[0], z[1]));
    assert!(obs.state()[2].is_finite() && obs.state()[3].is_finite());
    // The next step is an ordinary one.
    let e = obs.step([1.0, 2.0], z).expect("finite");
    assert!(!e.covariance_reset);
    assert_eq!(obs.counters().covariance_resets, 1);
}

#[test]
fn negative_variance_triggers_a_self_reset() {
    let (mut obs, cfg) = spun_up();
    let x = *obs.state();
    let mut p = obs.covariance();
    p[(3, 3)] = -1.0;
    obs.reset(x, p).expect("finite");
    let e = obs.step([0.0, 0.0], [0.1, 0.1]).expect("recovers");
    assert!(e.covariance_reset);
    assert_eq!(obs.covariance(), cfg.p0);
    // Through predict alone: the currents are kept, the rest as above.
    let mut p = obs.covariance();
    p[(3, 3)] = -1.0;
    let x = *obs.state();
    obs.reset(x, p).expect("finite");
    obs.predict([0.0, 0.0]).expect("recovers");
    assert!(obs.estimate().covariance_reset);
    assert_eq!(obs.counters().covariance_resets, 2);
    assert_eq!(obs.covariance(), cfg.p0);
}

#[test]
fn seed_configuration_has_no_health_check() {
    let cfg = ObserverConfig::seed(MotorParams::<f64>::servo(), TS);
    assert!(cfg.covariance_health.is_none());
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    obs.reset(Vector4::zeros(), Matrix4::identity() * 1e20)
        .expect("finite");
    let e = obs.step([0.0, 0.0], [0.1, 0.1]).expect("finite");
    assert!(!e.covariance_reset);
    assert_eq!(obs.counters().covariance_resets, 0);
    assert!(obs.covariance()[(2, 2)] > 1e19, "the huge P is kept");
}

#[test]
fn health_bound_is_a_multiple_of_trace_p0() {
    let motor = MotorParams::<f64>::servo();
    let p0 = default_p0(&motor, TS);
    let (mut obs, cfg) = spun_up();
    let factor = cfg.covariance_health.expect("on by default").trace_factor;
    let bound = factor * p0.trace();
    let x = *obs.state();
    // Checked after a prediction (no correction to shrink P): a speed variance that keeps the
    // trace under the bound passes ...
    obs.reset(
        x,
        Matrix4::from_diagonal(&Vector4::new(1e-3, 1e-3, 0.9 * bound, 1e-3)),
    )
    .expect("finite");
    obs.predict([0.0, 0.0]).expect("finite");
    assert!(!obs.estimate().covariance_reset);
    assert!(obs.covariance().trace() > 0.9 * bound);
    // ... one above it does not.
    obs.reset(
        x,
        Matrix4::from_diagonal(&Vector4::new(1e-3, 1e-3, 1.1 * bound, 1e-3)),
    )
    .expect("finite");
    obs.predict([0.0, 0.0]).expect("finite");
    assert!(obs.estimate().covariance_reset);
    assert_eq!(obs.covariance(), cfg.p0);
}
