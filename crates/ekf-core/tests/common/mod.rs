//! Test plant, independent of the filter's discretization: the alpha-beta current equations of
//! a surface PMSM integrated with RK4 over 40 substeps per period, the voltage held over each
//! period, the rotor following a prescribed electrical speed profile. Currents are sampled at
//! `t_k` with Gaussian noise from a seeded generator.
#![allow(dead_code)]

use core::f64::consts::PI;
use ekf_core::{Estimate, MotorParams, ObserverConfig, PmsmObserver, wrap_angle};

/// The three reference motors of `docs/design.md` section 6 as the tests use them: name, motor,
/// rated electrical speed (rad/s), current-sensor noise standard deviation (A).
pub fn reference_motors() -> [(&'static str, MotorParams<f64>, f64, f64); 3] {
    [
        (
            "servo",
            MotorParams::servo(),
            3000.0 / 60.0 * 2.0 * PI * 4.0,
            0.02,
        ),
        (
            "industrial 2.2 kW",
            MotorParams::industrial_2k2(),
            1500.0 / 60.0 * 2.0 * PI * 3.0,
            0.02,
        ),
        (
            "small fast",
            MotorParams::small_fast(),
            400.0 * 2.0 * PI,
            0.1,
        ),
    ]
}

/// Samples aligned on k: `u[k]` held over `[t_k, t_k+1)`, `i_meas[k]`, `th[k]`, `w[k]` at `t_k`.
pub struct Trace {
    pub ts: f64,
    pub u: Vec<[f64; 2]>,
    pub i_meas: Vec<[f64; 2]>,
    pub th: Vec<f64>,
    pub w: Vec<f64>,
}

/// The workspace's seeded test generator (xorshift64* with Box-Muller), shared with foc's
/// tests.
pub use ekf_core::testing::Rng;

/// Scenario of the prescribed-speed plant.
pub struct Scenario<'a> {
    pub motor: MotorParams<f64>,
    pub ts: f64,
    pub n: usize,
    /// Electrical speed (rad/s) as a function of time.
    pub speed: &'a dyn Fn(f64) -> f64,
    /// q-axis current reference (A) as a function of time; d-axis reference is 0.
    pub iq_ref: &'a dyn Fn(f64) -> f64,
    pub th0: f64,
    pub noise_a: f64,
    pub seed: u64,
}

/// The same motor in `f32` (every parameter rounded once).
pub fn motor_f32(m: &MotorParams<f64>) -> MotorParams<f32> {
    MotorParams::<f32>::salient_from_f64(m.rs_ohm, m.ld_h, m.lq_h, m.psi_f_wb, m.pole_pairs)
}

/// The MTPA d-axis current for a current magnitude `i` (A) of a motor with `Lq > Ld`
/// (`docs/design.md` section 7); 0 for a surface or inversely salient motor.
pub fn mtpa_id(m: &MotorParams<f64>, i: f64) -> f64 {
    let dl = m.lq_h - m.ld_h;
    if dl <= 0.0 {
        return 0.0;
    }
    let psi = m.psi_f_wb;
    (psi - (psi * psi + 8.0 * dl * dl * i * i).sqrt()) / (4.0 * dl)
}

/// Runs the plant. The voltage is an ideal dead-beat-ish dq controller that knows the true
/// angle: steady-state feed-forward plus a proportional term on the current error, rotated at
/// the mid-period angle. It only has to make the currents plausible. A salient motor
/// (`Ld != Lq`) is integrated in the rotor frame ([`simulate_salient`]).
pub fn simulate(sc: &Scenario) -> Trace {
    if sc.motor.is_salient() {
        return simulate_salient(sc);
    }
    let m = &sc.motor;
    let (rs, ls, psi) = (m.rs_ohm, m.lq_h, m.psi_f_wb);
    let sub = 40;
    let h = sc.ts / sub as f64;
    let mut rng = Rng::new(sc.seed);
    let (mut ia, mut ib, mut th) = (0.0f64, 0.0f64, sc.th0);
    let mut tr = Trace {
        ts: sc.ts,
        u: Vec::with_capacity(sc.n),
        i_meas: Vec::with_capacity(sc.n),
        th: Vec::with_capacity(sc.n),
        w: Vec::with_capacity(sc.n),
    };
    let deriv = |t: f64, ia: f64, ib: f64, th: f64, ua: f64, ub: f64| {
        let w = (sc.speed)(t);
        (
            (-rs * ia + w * psi * th.sin() + ua) / ls,
            (-rs * ib - w * psi * th.cos() + ub) / ls,
            w,
        )
    };
    for k in 0..sc.n {
        let t = k as f64 * sc.ts;
        let w = (sc.speed)(t);
        tr.th.push(wrap_angle(th));
        tr.w.push(w);
        tr.i_meas
            .push([ia + sc.noise_a * rng.gauss(), ib + sc.noise_a * rng.gauss()]);
        // dq voltage: feed-forward for (0, iq) plus a P term, rotated at the mid-period angle.
        let iq = (sc.iq_ref)(t);
        let (s, c) = th.sin_cos();
        let id_meas = ia * c + ib * s;
        let iq_meas = -ia * s + ib * c;
        let kp = 0.3 * ls / sc.ts;
        let ud = -w * ls * iq + kp * (0.0 - id_meas);
        let uq = rs * iq + w * psi + kp * (iq - iq_meas);
        let (sm, cm) = (th + 0.5 * w * sc.ts).sin_cos();
        let (ua, ub) = (ud * cm - uq * sm, ud * sm + uq * cm);
        tr.u.push([ua, ub]);
        (ia, ib, th) = rk4_period(
            |t, a, b, th| deriv(t, a, b, th, ua, ub),
            t,
            h,
            sub,
            (ia, ib, th),
        );
    }
    tr
}

/// The salient plant: the rotor-frame equations (`docs/design.md` section 7)
///
/// ```text
/// Ld di_d/dt = u_d - Rs i_d + w Lq i_q,    Lq di_q/dt = u_q - Rs i_q - w (Ld i_d + psi_f)
/// ```
///
/// integrated with RK4 over 40 substeps per period, the alpha-beta voltage held over each
/// period (so `u_dq` turns with the rotor within the period). The d-axis reference is the
/// MTPA current for `|i_q ref|` ([`mtpa_id`]).
pub fn simulate_salient(sc: &Scenario) -> Trace {
    let m = &sc.motor;
    let (rs, ld, lq, psi) = (m.rs_ohm, m.ld_h, m.lq_h, m.psi_f_wb);
    let sub = 40;
    let h = sc.ts / sub as f64;
    let mut rng = Rng::new(sc.seed);
    let (mut id, mut iq, mut th) = (0.0f64, 0.0f64, sc.th0);
    let mut tr = Trace {
        ts: sc.ts,
        u: Vec::with_capacity(sc.n),
        i_meas: Vec::with_capacity(sc.n),
        th: Vec::with_capacity(sc.n),
        w: Vec::with_capacity(sc.n),
    };
    let deriv = |t: f64, id: f64, iq: f64, th: f64, ua: f64, ub: f64| {
        let w = (sc.speed)(t);
        let (s, c) = th.sin_cos();
        let (ud, uq) = (ua * c + ub * s, -ua * s + ub * c);
        (
            (ud - rs * id + w * lq * iq) / ld,
            (uq - rs * iq - w * (ld * id + psi)) / lq,
            w,
        )
    };
    for k in 0..sc.n {
        let t = k as f64 * sc.ts;
        let w = (sc.speed)(t);
        let (s, c) = th.sin_cos();
        let (ia, ib) = (id * c - iq * s, id * s + iq * c);
        tr.th.push(wrap_angle(th));
        tr.w.push(w);
        tr.i_meas
            .push([ia + sc.noise_a * rng.gauss(), ib + sc.noise_a * rng.gauss()]);
        let iq_ref = (sc.iq_ref)(t);
        let id_ref = mtpa_id(m, iq_ref.abs());
        let (kd, kq) = (0.3 * ld / sc.ts, 0.3 * lq / sc.ts);
        let ud = rs * id_ref - w * lq * iq_ref + kd * (id_ref - id);
        let uq = rs * iq_ref + w * (ld * id_ref + psi) + kq * (iq_ref - iq);
        let (sm, cm) = (th + 0.5 * w * sc.ts).sin_cos();
        let (ua, ub) = (ud * cm - uq * sm, ud * sm + uq * cm);
        tr.u.push([ua, ub]);
        (id, iq, th) = rk4_period(
            |t, a, b, th| deriv(t, a, b, th, ua, ub),
            t,
            h,
            sub,
            (id, iq, th),
        );
    }
    tr
}

/// The two interior reference motors as the tests use them: name, motor, rated electrical
/// speed (rad/s), rated q current (A), current-sensor noise standard deviation (A).
pub fn interior_motors() -> [(&'static str, MotorParams<f64>, f64, f64, f64); 2] {
    [
        (
            "industrial IPM",
            MotorParams::industrial_ipm(),
            1500.0 / 60.0 * 2.0 * PI * 3.0,
            6.7,
            0.02,
        ),
        (
            "traction IPM",
            MotorParams::traction_ipm(),
            3000.0 / 60.0 * 2.0 * PI * 4.0,
            125.0,
            0.3,
        ),
    ]
}

/// One period of `sub` RK4 steps of `h` from `t` of the three states `y` (two currents and the
/// angle) with the derivative `f(t, y0, y1, y2)` (the voltage held, captured by `f`).
fn rk4_period(
    f: impl Fn(f64, f64, f64, f64) -> (f64, f64, f64),
    t: f64,
    h: f64,
    sub: usize,
    y: (f64, f64, f64),
) -> (f64, f64, f64) {
    let (mut a, mut b, mut th) = y;
    for j in 0..sub {
        let t0 = t + j as f64 * h;
        let k1 = f(t0, a, b, th);
        let k2 = f(
            t0 + h / 2.0,
            a + h / 2.0 * k1.0,
            b + h / 2.0 * k1.1,
            th + h / 2.0 * k1.2,
        );
        let k3 = f(
            t0 + h / 2.0,
            a + h / 2.0 * k2.0,
            b + h / 2.0 * k2.1,
            th + h / 2.0 * k2.2,
        );
        let k4 = f(t0 + h, a + h * k3.0, b + h * k3.1, th + h * k3.2);
        a += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        b += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        th += h / 6.0 * (k1.2 + 2.0 * k2.2 + 2.0 * k3.2 + k4.2);
    }
    (a, b, th)
}

/// Runs an observer over a trace with the project's timing: row k predicts with `u[k-1]`
/// (zero for k = 0) and corrects with `i_meas[k]`.
pub fn run_observer(cfg: &ObserverConfig<f64>, tr: &Trace) -> Vec<Estimate<f64>> {
    let mut obs = PmsmObserver::new(cfg).expect("valid config");
    let mut u_prev = [0.0, 0.0];
    tr.i_meas
        .iter()
        .zip(&tr.u)
        .map(|(i, u)| {
            let e = obs.step(u_prev, *i).expect("finite step");
            u_prev = *u;
            e
        })
        .collect()
}

/// Wrapped angle errors, electrical degrees.
pub fn angle_errors_deg(tr: &Trace, est: &[Estimate<f64>]) -> Vec<f64> {
    est.iter()
        .zip(&tr.th)
        .map(|(e, th)| wrap_angle(e.theta_rad - th).to_degrees())
        .collect()
}

/// (mean, rms, max |.|) of a slice.
pub fn stats(v: &[f64]) -> (f64, f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let max = v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    (mean, rms, max)
}

/// First time index after which `|e| < limit` holds to the end; `None` if never.
pub fn convergence_index(err_deg: &[f64], limit: f64) -> Option<usize> {
    match err_deg.iter().rposition(|e| e.abs() >= limit) {
        None => Some(0),
        Some(last) if last + 1 < err_deg.len() => Some(last + 1),
        Some(_) => None,
    }
}
