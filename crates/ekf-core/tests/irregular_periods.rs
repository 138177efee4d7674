//! Irregular periods: `PmsmObserver::step_dt` on a record with skipped control cycles.
//!
//! The plant (surface servo, exact integration by RK4 over 40 substeps a period) turns at a
//! constant speed under a feed-forward voltage. Every 37th period the controller skips a
//! cycle: it keeps its voltage for a second period and no current is sampled in between, so
//! the record has a row whose period is `2 Ts`.
use ekf_core::{EkfError, MotorParams, ObserverConfig, PmsmObserver, wrap_angle};

struct Record {
    u: Vec<[f64; 2]>,
    i: Vec<[f64; 2]>,
    dt: Vec<f64>,
    th: Vec<f64>,
}

fn record(motor: &MotorParams<f64>, ts: f64, w: f64, n: usize) -> Record {
    let (rs, ls, psi) = (motor.rs_ohm, motor.lq_h, motor.psi_f_wb);
    let iq = 2.0;
    let (mut ia, mut ib, mut th) = (0.0f64, 0.0f64, 0.4f64);
    let mut rec = Record {
        u: vec![],
        i: vec![],
        dt: vec![],
        th: vec![],
    };
    let sub = 40;
    let mut k = 0;
    let mut period = ts;
    while rec.i.len() < n {
        rec.i.push([ia, ib]);
        rec.th.push(wrap_angle(th));
        rec.dt.push(period);
        let skip = k % 37 == 36;
        period = if skip { 2.0 * ts } else { ts };
        // Feed-forward voltage for (0, iq), rotated at the mid-period angle.
        let (sm, cm) = (th + 0.5 * w * ts).sin_cos();
        let (ud, uq) = (-w * ls * iq, rs * iq + w * psi);
        let u = [ud * cm - uq * sm, ud * sm + uq * cm];
        rec.u.push(u);
        let h = period / sub as f64;
        for _ in 0..sub {
            let f = |a: f64, b: f64, t: f64| {
                (
                    (-rs * a + w * psi * t.sin() + u[0]) / ls,
                    (-rs * b - w * psi * t.cos() + u[1]) / ls,
                )
            };
            let (k1a, k1b) = f(ia, ib, th);
            let (k2a, k2b) = f(ia + 0.5 * h * k1a, ib + 0.5 * h * k1b, th + 0.5 * h * w);
            let (k3a, k3b) = f(ia + 0.5 * h * k2a, ib + 0.5 * h * k2b, th + 0.5 * h * w);
            let (k4a, k4b) = f(ia + h * k3a, ib + h * k3b, th + h * w);
            ia += h / 6.0 * (k1a + 2.0 * k2a + 2.0 * k3a + k4a);
            ib += h / 6.0 * (k1b + 2.0 * k2b + 2.0 * k3b + k4b);
            th += h * w;
        }
        k += 1;
    }
    rec
}

/// RMS and max angle error (deg) over the second half, with and without the periods.
fn errors(rec: &Record, cfg: &ObserverConfig<f64>, use_dt: bool) -> (f64, f64) {
    let mut obs = PmsmObserver::new(cfg).unwrap();
    let mut u_prev = [0.0; 2];
    let n = rec.i.len();
    let (mut s2, mut mx, mut cnt) = (0.0, 0.0f64, 0.0);
    for k in 0..n {
        let e = if use_dt {
            obs.step_dt(u_prev, rec.i[k], rec.dt[k]).unwrap()
        } else {
            obs.step(u_prev, rec.i[k]).unwrap()
        };
        u_prev = rec.u[k];
        if k >= n / 2 {
            let d = wrap_angle(e.theta_rad - rec.th[k]).to_degrees();
            s2 += d * d;
            mx = mx.max(d.abs());
            cnt += 1.0;
        }
    }
    ((s2 / cnt).sqrt(), mx)
}

#[test]
fn skipped_cycles_are_predicted_over_their_period() {
    let motor = MotorParams::servo();
    let ts = 1e-4;
    let w = 0.2 / ts;
    let rec = record(&motor, ts, w, 4000);
    let cfg = ObserverConfig::new(motor, ts);
    let (rms_dt, max_dt) = errors(&rec, &cfg, true);
    let (rms_fixed, max_fixed) = errors(&rec, &cfg, false);
    println!(
        "skipped cycles every 37 periods at w Ts = 0.2: step_dt rms {rms_dt:.4} max {max_dt:.4} deg; \
         fixed-period step rms {rms_fixed:.3} max {max_fixed:.3} deg"
    );
    assert!(
        rms_dt < 0.05 && max_dt < 0.2,
        "step_dt {rms_dt} / {max_dt} deg"
    );
    assert!(
        max_fixed > 5.0,
        "ignoring the long periods costs {max_fixed} deg"
    );
}

#[test]
fn step_dt_at_ts_is_step_bit_for_bit_and_bad_periods_are_refused() {
    let motor = MotorParams::servo();
    let ts = 1e-4;
    let rec = record(&motor, ts, 0.1 / ts, 600);
    let cfg = ObserverConfig::new(motor, ts);
    let mut a = PmsmObserver::new(&cfg).unwrap();
    let mut b = PmsmObserver::new(&cfg).unwrap();
    let mut u_prev = [0.0; 2];
    for k in 0..rec.i.len() {
        let ea = a.step(u_prev, rec.i[k]).unwrap();
        let eb = b.step_dt(u_prev, rec.i[k], ts).unwrap();
        assert_eq!(ea, eb);
        u_prev = rec.u[k];
    }
    let before = b.clone();
    for dt in [0.0, -ts, f64::NAN, f64::INFINITY, 65.0 * ts] {
        assert_eq!(
            b.step_dt(u_prev, [0.1, 0.2], dt),
            Err(EkfError::InvalidPeriod),
            "{dt}"
        );
        assert_eq!(b, before, "a refused period leaves the observer as it was");
    }
    // A long but valid gap still steps.
    assert!(b.step_dt(u_prev, [0.1, 0.2], 3.0 * ts).is_ok());
}
