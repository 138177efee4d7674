//! The host's dispatched step (`PmsmObserver::step`: on x86-64 with AVX2 and FMA, the step
//! compiled for them) gives bit for bit the portable step's results, for every configuration
//! kind, in f64 and f32, through convergence, glitches (gate rejections, a health reset) and
//! a reversal (branch check). On a machine without those extensions both are the portable
//! step and the test says so.
mod common;
use common::*;
use ekf_core::{Float, MotorParams, ObserverConfig, PmsmObserver};

/// Both observers over `tr` (converted to `T`), with glitches at a few samples; every
/// estimate, state and covariance compared bit for bit.
fn same_results<T: Float>(name: &str, cfg: &ObserverConfig<T>, tr: &Trace, conv: fn(f64) -> T) {
    let mut a = PmsmObserver::new(cfg).expect("valid config");
    let mut b = PmsmObserver::new(cfg).expect("valid config");
    let mut u_prev = [T::zero(); 2];
    let mut events = 0usize;
    for (k, (i, u)) in tr.i_meas.iter().zip(&tr.u).enumerate() {
        let mut z = [conv(i[0]), conv(i[1])];
        // Outliers (gate), one absurd sample (health), one non-finite sample (refusal).
        if k % 997 == 500 {
            z[0] += conv(40.0);
        }
        if k == 2200 {
            z = [conv(1e12), conv(-1e12)];
        }
        if k == 2600 {
            z[1] = conv(f64::NAN);
        }
        let ea = a.step(u_prev, z);
        let eb = b.step_portable(u_prev, z);
        assert_eq!(ea, eb, "{name}: sample {k}");
        if let Ok(e) = ea {
            events += usize::from(e.rejected || e.covariance_reset || e.branch_flipped);
        }
        assert_eq!(a.state(), b.state(), "{name}: state at {k}");
        assert_eq!(a.covariance(), b.covariance(), "{name}: covariance at {k}");
        u_prev = [conv(u[0]), conv(u[1])];
    }
    assert_eq!(a.counters(), b.counters(), "{name}");
    assert!(events > 0, "{name}: no safeguard acted");
}

#[test]
fn dispatched_step_equals_portable_step() {
    #[cfg(target_arch = "x86_64")]
    println!(
        "AVX2 and FMA: {}",
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    );
    let rev = |t: f64| 1500.0 - 9000.0 * t;
    let surface = simulate(&Scenario {
        motor: MotorParams::servo(),
        ts: 1e-4,
        n: 3000,
        speed: &rev,
        iq_ref: &|t: f64| if t < 0.1 { 1.0 } else { 4.0 },
        th0: 1.0,
        noise_a: 0.05,
        seed: 7,
    });
    let (_, ipm, w_rated, iq_rated, noise) = interior_motors()[0];
    let salient = simulate(&Scenario {
        motor: ipm,
        ts: 1e-4,
        n: 3000,
        speed: &|_| 0.5 * w_rated,
        iq_ref: &|t: f64| if t < 0.15 { 0.3 * iq_rated } else { iq_rated },
        th0: -2.0,
        noise_a: noise,
        seed: 9,
    });
    let f32c = |v: f64| v as f32;
    let f64c = |v: f64| v;
    let ts = 1e-4;
    for (name, tr, motor) in [
        ("surface", &surface, MotorParams::servo()),
        ("salient", &salient, ipm),
    ] {
        let untracked = |c: ObserverConfig<f64>| ObserverConfig {
            parameter_tracking: None,
            ..c
        };
        same_results(
            &format!("{name} f64 default"),
            &ObserverConfig::new(motor, ts),
            tr,
            f64c,
        );
        same_results(
            &format!("{name} f64 untracked"),
            &untracked(ObserverConfig::new(motor, ts)),
            tr,
            f64c,
        );
        let m32 = common::motor_f32(&motor);
        same_results(
            &format!("{name} f32 default"),
            &ObserverConfig::new(m32, ts as f32),
            tr,
            f32c,
        );
    }
    // The seed's configuration has no safeguards: compare without requiring events.
    let cfg = ObserverConfig::seed(MotorParams::<f64>::servo(), ts);
    let mut a = PmsmObserver::new(&cfg).expect("valid config");
    let mut b = PmsmObserver::new(&cfg).expect("valid config");
    let mut u_prev = [0.0; 2];
    for (i, u) in surface.i_meas.iter().zip(&surface.u) {
        assert_eq!(a.step(u_prev, *i), b.step_portable(u_prev, *i));
        assert_eq!(a.state(), b.state());
        u_prev = *u;
    }
}
