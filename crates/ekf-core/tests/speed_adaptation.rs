//! Speed noise adaptation: the default observer through a hard acceleration, against the same
//! observer with the speed's process noise fixed.
//!
//! The plant (surface servo, RK4 over 20 substeps a period) turns at `w Ts = 0.02`, then
//! accelerates to `w Ts = 0.25` in 30 periods (a recorded ESC's duty step: 150 to 4000 rad/s
//! in 25 ms is `0.0076` rad of `w Ts` per period, per period; here `0.0077`), then holds that
//! speed. The voltage is the feed-forward for a constant `i_q`; the currents carry 20 mA of
//! Gaussian noise. Measured (`cargo test --release -p ekf-core --test speed_adaptation --
//! --nocapture`): max error through the ramp 2.8-3.0 deg adaptive, 6.8-6.9 deg with `Q` fixed;
//! steady RMS 0.046 deg both.
use ekf_core::testing::Rng;
use ekf_core::{MotorParams, ObserverConfig, PmsmObserver, wrap_angle};

struct Record {
    u: Vec<[f64; 2]>,
    i: Vec<[f64; 2]>,
    th: Vec<f64>,
}

fn record(motor: &MotorParams<f64>, ts: f64, ramp: usize, seed: u64) -> Record {
    let (rs, ls, psi) = (motor.rs_ohm, motor.lq_h, motor.psi_f_wb);
    let iq = 2.0;
    let (w0, w1) = (0.02 / ts, 0.25 / ts);
    let (start, n) = (3000, 5000);
    let speed = |k: f64| {
        if k < start as f64 {
            w0
        } else if k < (start + ramp) as f64 {
            w0 + (w1 - w0) * (k - start as f64) / ramp as f64
        } else {
            w1
        }
    };
    let (mut ia, mut ib, mut th) = (0.0f64, 0.0f64, 0.3f64);
    let mut rng = Rng::new(seed);
    let mut rec = Record {
        u: vec![],
        i: vec![],
        th: vec![],
    };
    let sub = 20;
    for k in 0..n {
        rec.i
            .push([ia + 0.02 * rng.gauss(), ib + 0.02 * rng.gauss()]);
        rec.th.push(wrap_angle(th));
        let w = speed(k as f64 + 0.5);
        let (sm, cm) = (th + 0.5 * w * ts).sin_cos();
        let (ud, uq) = (-w * ls * iq, rs * iq + w * psi);
        let u = [ud * cm - uq * sm, ud * sm + uq * cm];
        rec.u.push(u);
        let h = ts / sub as f64;
        for j in 0..sub {
            let t0 = k as f64 + j as f64 / sub as f64;
            let f = |a: f64, b: f64, t: f64, w: f64| {
                (
                    (-rs * a + w * psi * t.sin() + u[0]) / ls,
                    (-rs * b - w * psi * t.cos() + u[1]) / ls,
                )
            };
            let (wa, wm, wb) = (
                speed(t0),
                speed(t0 + 0.5 / sub as f64),
                speed(t0 + 1.0 / sub as f64),
            );
            let (k1a, k1b) = f(ia, ib, th, wa);
            let (k2a, k2b) = f(
                ia + 0.5 * h * k1a,
                ib + 0.5 * h * k1b,
                th + 0.5 * h * wa,
                wm,
            );
            let (k3a, k3b) = f(
                ia + 0.5 * h * k2a,
                ib + 0.5 * h * k2b,
                th + 0.5 * h * wm,
                wm,
            );
            let (k4a, k4b) = f(ia + h * k3a, ib + h * k3b, th + h * wm, wb);
            ia += h / 6.0 * (k1a + 2.0 * k2a + 2.0 * k3a + k4a);
            ib += h / 6.0 * (k1b + 2.0 * k2b + 2.0 * k3b + k4b);
            th += h * (wa + 4.0 * wm + wb) / 6.0;
        }
    }
    rec
}

/// Max angle error (deg) from the ramp on, RMS over the steady part before it.
fn errors(rec: &Record, cfg: &ObserverConfig<f64>) -> (f64, f64) {
    let mut obs = PmsmObserver::new(cfg).unwrap();
    let mut u_prev = [0.0; 2];
    let (mut s2, mut cnt, mut mx) = (0.0, 0.0, 0.0f64);
    for k in 0..rec.i.len() {
        let e = obs.step(u_prev, rec.i[k]).unwrap();
        u_prev = rec.u[k];
        let d = wrap_angle(e.theta_rad - rec.th[k]).to_degrees();
        if (1000..3000).contains(&k) {
            s2 += d * d;
            cnt += 1.0;
        } else if k >= 3000 {
            mx = mx.max(d.abs());
        }
    }
    ((s2 / cnt).sqrt(), mx)
}

#[test]
fn adaptation_follows_a_hard_acceleration_and_leaves_steady_state_alone() {
    let motor = MotorParams::servo();
    let ts = 1e-4;
    let adaptive = ObserverConfig::new(motor, ts);
    let fixed = ObserverConfig {
        speed_noise_adaptation: None,
        ..adaptive
    };
    for seed in 1..=3 {
        let rec = record(&motor, ts, 30, seed);
        let (steady_a, max_a) = errors(&rec, &adaptive);
        let (steady_f, max_f) = errors(&rec, &fixed);
        println!(
            "seed {seed}: adaptive steady rms {steady_a:.4} deg, max through the ramp {max_a:.2} deg; \
             fixed Q steady rms {steady_f:.4} deg, max {max_f:.2} deg"
        );
        assert!(max_a < 10.0, "adaptive: {max_a} deg through the ramp");
        assert!(
            max_f > 2.0 * max_a,
            "fixed Q: {max_f} deg, adaptive {max_a}"
        );
        assert!(
            (steady_a - steady_f).abs() <= 0.02 * steady_f,
            "steady state changed: {steady_a} vs {steady_f}"
        );
    }
}
