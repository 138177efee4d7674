//! PI anti-windup: the integrator stops growing under saturation and the output recovers at
//! once when the error reverses.

use foc::{Pi, PiGains};

#[test]
fn integrator_holds_under_saturation_and_recovers_immediately() {
    let gains = PiGains { kp: 0.5, ki: 200.0 };
    let ts = 1e-3;
    let mut pi = Pi::new(gains, ts);
    // Error 10 with a limit of 1: saturates at once.
    let mut held = None;
    for k in 0..1000 {
        let u = pi.step(10.0, 0.0, -1.0, 1.0);
        assert_eq!(u, 1.0);
        if k == 5 {
            held = Some(pi.integrator());
        }
        if k > 5 {
            assert_eq!(Some(pi.integrator()), held, "integrator grew at step {k}");
        }
    }
    assert!(pi.integrator() <= 1.0);
    // Error reverses: the output leaves the limit on the first sample.
    let u = pi.step(-0.5, 0.0, -1.0, 1.0);
    assert!(u < 1.0, "still saturated: {u}");

    // Without anti-windup the integrator would have reached 200 * 1e-3 * 10 * 1000 = 2000
    // and needed thousands of samples of reversed error to come back. Here: count samples.
    let mut pi = Pi::new(gains, ts);
    for _ in 0..1000 {
        pi.step(10.0, 0.0, -1.0, 1.0);
    }
    let mut k_out = None;
    for k in 0..100 {
        if pi.step(-0.2, 0.0, -1.0, 1.0) < 1.0 {
            k_out = Some(k);
            break;
        }
    }
    assert_eq!(k_out, Some(0));
}

#[test]
fn saturation_by_feed_forward_and_negative_side() {
    let mut pi = Pi::new(PiGains { kp: 1.0, ki: 100.0 }, 1e-3);
    // Feed-forward alone beyond the lower limit, error pushing further down: no windup.
    for _ in 0..500 {
        assert_eq!(pi.step(-1.0, -5.0, -2.0, 2.0), -2.0);
    }
    assert!(pi.integrator() >= -2.0);
    // An error toward the inside of the range still integrates while saturated.
    let before = pi.integrator();
    pi.step(1.0, -5.0, -2.0, 2.0);
    assert!(pi.integrator() > before);
}

/// Samples until a first-order plant `y' = (u - y) / tau` under `step` settles within
/// 1 % of 0.5 after 0.5 s of an unreachable setpoint (100 with the output limited to +-1).
fn settle_samples(mut step: impl FnMut(f32) -> f32) -> usize {
    let ts = 1e-4;
    let tau = 1e-2;
    let mut y = 0.0_f32;
    for _ in 0..5000 {
        let u = step(100.0 - y);
        y += ts * (u - y) / tau;
    }
    assert!((y - 1.0).abs() < 1e-3);
    let mut last_out = 0;
    for k in 0..50_000 {
        let u = step(0.5 - y);
        y += ts * (u - y) / tau;
        if (y - 0.5).abs() > 0.005 {
            last_out = k;
        }
    }
    last_out
}

#[test]
fn recovers_from_saturation_much_faster_than_a_wound_up_pi() {
    let gains = PiGains { kp: 2.0, ki: 200.0 };
    let ts = 1e-4;
    let mut pi = Pi::new(gains, ts);
    let ours = settle_samples(|e| pi.step(e, 0.0, -1.0, 1.0));
    // The same PI without anti-windup: unbounded integrator, clamped output.
    let mut integ = 0.0_f32;
    let naive = settle_samples(|e| {
        integ += gains.ki * ts * e;
        (gains.kp * e + integ).clamp(-1.0, 1.0)
    });
    // Measured: 528 samples (the held integrator starts at 0 and must build up 0.5, through
    // the plant's 10 ms time constant) against 10 000+ for the wound-up integrator (~100 V s
    // to unwind).
    assert!(ours < 600, "anti-windup PI settled after {ours} samples");
    assert!(naive > 10 * ours, "naive PI settled after {naive} samples");
}
