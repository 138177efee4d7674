//! MTPA and field weakening: the MTPA law against a brute-force search,
//! field weakening in closed loop on a salient dq plant (current and voltage limits held at
//! twice base speed), surface paths unchanged, bad settings refused.
//!
//! `cargo test -p foc --test mtpa_fw -- --nocapture` prints the numbers.

use foc::ekf_core::MotorParams;
use foc::{
    ComputationDelay, ConfigError, Field, Foc, FocConfig, Mode, Mtpa, Reversal, State, TickInput,
    TickOutput, duties_to_alpha_beta,
};

// ---------------------------------------------------------------------------------------
// MTPA against brute force
// ---------------------------------------------------------------------------------------

/// Torque of `(i_d, i_q)` without the `1.5 p` factor, f64.
fn torque(m: &MotorParams<f32>, i_d: f64, i_q: f64) -> f64 {
    let (ld, lq, psi) = (m.ld_h as f64, m.lq_h as f64, m.psi_f_wb as f64);
    (psi + (ld - lq) * i_d) * i_q
}

/// The largest torque a current of magnitude `i_s` makes, by a search over the current angle
/// (a fine grid, then a golden-section refinement), f64.
fn max_torque_brute(m: &MotorParams<f32>, i_s: f64) -> f64 {
    let t = |beta: f64| torque(m, -i_s * beta.sin(), i_s * beta.cos()); // beta: lead from q
    let n = 20_000;
    let (mut best, mut b_best) = (f64::NEG_INFINITY, 0.0);
    for k in 0..=n {
        let b = -0.5 * std::f64::consts::PI + std::f64::consts::PI * k as f64 / n as f64;
        if t(b) > best {
            best = t(b);
            b_best = b;
        }
    }
    let h = std::f64::consts::PI / n as f64;
    let (mut lo, mut hi) = (b_best - h, b_best + h);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..100 {
        let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if t(x1) > t(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    t(0.5 * (lo + hi)).max(best)
}

/// The smallest current magnitude that makes the torque `t` (bisection on
/// `max_torque_brute`), f64.
fn min_current_brute(m: &MotorParams<f32>, t: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    while max_torque_brute(m, hi) < t {
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if max_torque_brute(m, mid) >= t {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// Rated current of the tests' drives, A: the two IPMSM presets with a current limit that
/// lets them field-weaken (the defaults' `0.25 psi_f / Lq` is a start-up-sized limit).
fn rated_current(m: &MotorParams<f32>) -> f32 {
    if m.lq_h > 1e-3 { 12.0 } else { 200.0 }
}

#[test]
fn mtpa_torque_per_ampere_within_1_percent_of_brute_force() {
    for (name, m) in [
        ("industrial_ipm", MotorParams::industrial_ipm()),
        ("traction_ipm", MotorParams::traction_ipm()),
    ] {
        let law = Mtpa::new(&m);
        let i_rated = rated_current(&m);
        // Rated torque: the MTPA torque of the rated current (as a surface-equivalent current).
        let it_rated = law.torque_current_at_magnitude(i_rated);
        for frac in [0.1f32, 0.5, 1.0] {
            let it = frac * it_rated;
            // The controller's solution (converged iteration) and what it makes.
            let i = law.currents_for_torque(it);
            let mag = (i.d as f64).hypot(i.q as f64);
            let t_ctrl = torque(&m, i.d as f64, i.q as f64);
            let t_cmd = m.psi_f_wb as f64 * it as f64;
            let torque_err = t_ctrl / t_cmd - 1.0;
            // The optimum: the least current that makes the same torque.
            let i_opt = min_current_brute(&m, t_ctrl);
            let tpa_err = i_opt / mag - 1.0; // (T / I) / (T / I_opt) - 1
            // What i_d = 0 would need, for scale.
            let i_zero_d = t_ctrl / m.psi_f_wb as f64;
            println!(
                "{name} {:>4.0} % rated torque: i_dq = ({:.4}, {:.4}) A, |i| = {mag:.5} A, \
                 brute-force optimum {i_opt:.5} A: torque per ampere {:+.4} % of optimum \
                 (i_d = 0 needs {i_zero_d:.4} A, {:+.2} %); torque vs command {:+.2e}",
                100.0 * frac,
                i.d,
                i.q,
                100.0 * tpa_err,
                100.0 * (i_opt / i_zero_d - 1.0),
                torque_err
            );
            assert!(tpa_err.abs() < 0.01, "{name}: {tpa_err}");
            assert!(torque_err.abs() < 1e-4, "{name}: {torque_err}");
            // The analytic form of the issue at the same magnitude.
            let id_issue = law.id_for_magnitude(mag as f32);
            assert!(
                (id_issue - i.d).abs() < 1e-3 * i_rated,
                "{id_issue} vs {}",
                i.d
            );
        }
        // Warm-started single steps (one per tick in the controller) converge in a few ticks
        // from a torque step of the full range.
        let target = law.currents_for_torque(it_rated);
        let mut q = 0.0;
        let mut ticks = 0;
        while (q - target.q).abs() > 1e-3 * target.q.abs() {
            q = law.step(it_rated, q, 0.0).q;
            ticks += 1;
            assert!(ticks < 20, "{name}: no convergence");
        }
        println!("{name}: per-tick MTPA iteration within 0.1 % after {ticks} ticks");
    }
}

// ---------------------------------------------------------------------------------------
// A salient dq plant (RK4) with a mechanical load
// ---------------------------------------------------------------------------------------

struct Plant {
    rs: f64,
    ld: f64,
    lq: f64,
    psi: f64,
    p: f64,
    j: f64,
    /// Rotor-frame currents, A; mechanical speed, rad/s; electrical angle, rad.
    x: [f64; 4],
}

impl Plant {
    fn new(m: &MotorParams<f32>, j: f64) -> Self {
        Self {
            rs: m.rs_ohm as f64,
            ld: m.ld_h as f64,
            lq: m.lq_h as f64,
            psi: m.psi_f_wb as f64,
            p: m.pole_pairs as f64,
            j,
            x: [0.0; 4],
        }
    }

    fn f(&self, x: [f64; 4], u_ab: [f64; 2], t_load: f64) -> [f64; 4] {
        let [id, iq, wm, th] = x;
        let (s, c) = th.sin_cos();
        let ud = u_ab[0] * c + u_ab[1] * s;
        let uq = -u_ab[0] * s + u_ab[1] * c;
        let w = self.p * wm;
        let te = 1.5 * self.p * (self.psi + (self.ld - self.lq) * id) * iq;
        [
            (ud - self.rs * id + w * self.lq * iq) / self.ld,
            (uq - self.rs * iq - w * (self.ld * id + self.psi)) / self.lq,
            (te - t_load) / self.j,
            w,
        ]
    }

    /// One period `ts` with `u_ab` held (RK4, 8 sub-steps).
    fn step(&mut self, u_ab: [f64; 2], ts: f64, t_load: f64) {
        let n = 8;
        let h = ts / n as f64;
        let add = |a: [f64; 4], b: [f64; 4], k: f64| -> [f64; 4] {
            [
                a[0] + k * b[0],
                a[1] + k * b[1],
                a[2] + k * b[2],
                a[3] + k * b[3],
            ]
        };
        for _ in 0..n {
            let x = self.x;
            let k1 = self.f(x, u_ab, t_load);
            let k2 = self.f(add(x, k1, 0.5 * h), u_ab, t_load);
            let k3 = self.f(add(x, k2, 0.5 * h), u_ab, t_load);
            let k4 = self.f(add(x, k3, h), u_ab, t_load);
            for i in 0..4 {
                self.x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        self.x[3] = (self.x[3] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
    }

    fn i_ab(&self) -> [f64; 2] {
        let [id, iq, _, th] = self.x;
        let (s, c) = th.sin_cos();
        [id * c - iq * s, id * s + iq * c]
    }

    fn omega_e(&self) -> f64 {
        self.p * self.x[2]
    }

    fn torque(&self) -> f64 {
        let [id, iq, ..] = self.x;
        1.5 * self.p * (self.psi + (self.ld - self.lq) * id) * iq
    }
}

/// A drive of the tests: motor, PWM period, bus voltage, inertia.
#[derive(Clone, Copy)]
struct Drive {
    name: &'static str,
    m: MotorParams<f32>,
    ts: f32,
    u_dc: f32,
    j: f64,
}

fn drives() -> [Drive; 2] {
    [
        Drive {
            name: "industrial_ipm",
            m: MotorParams::industrial_ipm(),
            ts: 100e-6,
            u_dc: 540.0,
            j: 0.015,
        },
        Drive {
            name: "traction_ipm",
            m: MotorParams::traction_ipm(),
            ts: 50e-6,
            u_dc: 48.0,
            j: 2e-3,
        },
    ]
}

/// Sensored drive configuration (the angle from the plant: this file tests the current
/// references, not the observer), duties applied at once.
fn config(d: &Drive, fw_speed_ratio: Option<f32>) -> FocConfig {
    let lim = rated_current(&d.m);
    let mut cfg = FocConfig::new(d.m, d.ts, d.u_dc)
        .with_mode(Mode::Sensored)
        .with_delay(ComputationDelay::None);
    cfg.current_limit_a = lim;
    cfg.over_current_a = 2.0 * lim;
    cfg = cfg.with_inertia(d.j as f32);
    if let Some(r) = fw_speed_ratio {
        cfg = cfg.with_field_weakening(r);
    }
    cfg
}

/// What a closed-loop run records over a window.
#[derive(Debug, Default)]
struct Record {
    /// Largest measured |i| / current limit.
    max_i_ratio: f64,
    /// Largest |u_dq| asked for / u_max.
    max_u_ratio: f64,
    /// Mean |u_dq| / u_max.
    mean_u_ratio: f64,
    /// Mean speed / reference.
    speed_ratio: f64,
    /// Mean d and q current references, A.
    id_ref: f64,
    iq_ref: f64,
    /// Mean torque, N m.
    torque: f64,
    n: usize,
}

/// Runs `foc` on the plant for `t_s` with the load `load(w_mech)`; records over the last
/// `window_s`.
fn run(
    foc: &mut Foc,
    plant: &mut Plant,
    d: &Drive,
    t_s: f64,
    window_s: f64,
    load: &dyn Fn(f64) -> f64,
) -> Record {
    let cfg = *foc.config();
    let ts = d.ts as f64;
    let n = (t_s / ts) as usize;
    let n_win = (window_s / ts) as usize;
    let u_max = cfg.max_modulation as f64 * d.u_dc as f64 / 3f64.sqrt();
    let mut r = Record::default();
    for k in 0..n {
        let [a, b] = plant.i_ab();
        let input = TickInput::alpha_beta(a as f32, b as f32, d.u_dc)
            .with_sensor(plant.x[3] as f32, plant.omega_e() as f32);
        let out: TickOutput = foc.tick(&input);
        assert!(out.fault.is_none(), "{}: {:?}", d.name, foc.fault_info());
        let u = duties_to_alpha_beta(out.duties, d.u_dc);
        let t = &out.telemetry;
        if k + n_win >= n {
            let i_mag = plant.x[0].hypot(plant.x[1]);
            let u_mag = (t.u_dq.d as f64).hypot(t.u_dq.q as f64);
            r.max_i_ratio = r.max_i_ratio.max(i_mag / cfg.current_limit_a as f64);
            r.max_u_ratio = r.max_u_ratio.max(u_mag / u_max);
            r.mean_u_ratio += u_mag / u_max;
            r.speed_ratio += plant.x[2] / t.speed_ref_mech_rad_s as f64;
            r.id_ref += t.i_dq_ref.d as f64;
            r.iq_ref += t.i_dq_ref.q as f64;
            r.torque += plant.torque();
            r.n += 1;
        }
        plant.step([u.alpha as f64, u.beta as f64], ts, load(plant.x[2]));
    }
    let n = r.n.max(1) as f64;
    r.mean_u_ratio /= n;
    r.speed_ratio /= n;
    r.id_ref /= n;
    r.iq_ref /= n;
    r.torque /= n;
    r
}

/// Base speed: the top speed without field weakening (`FocConfig::new`'s `max_speed_rad_s`,
/// no-load back-EMF at 95 % of the linear voltage limit), rad/s mech.
fn base_speed_mech(d: &Drive) -> f64 {
    FocConfig::new(d.m, d.ts, d.u_dc).max_speed_rad_s as f64 / d.m.pole_pairs as f64
}

#[test]
fn field_weakening_reaches_twice_base_speed_within_both_limits() {
    for d in drives() {
        let cfg = config(&d, Some(2.2));
        let law = Mtpa::new(&d.m);
        let kt = 1.5 * d.m.pole_pairs as f64 * d.m.psi_f_wb as f64;
        let t_rated = kt * law.torque_current_at_magnitude(cfg.current_limit_a) as f64;
        let w_b = base_speed_mech(&d);
        // Load: a quarter of rated torque at 2x base (half the rated torque's power at
        // base speed), constant power above base speed, plus viscous friction below.
        let p_load = 0.25 * t_rated * 2.0 * w_b;
        let load = move |w: f64| p_load / w.abs().max(w_b) * w.signum();
        let mut foc = Foc::new(&cfg).unwrap();
        let mut plant = Plant::new(&d.m, d.j);
        foc.set_speed_ref_mech_rad_s((2.0 * w_b) as f32).unwrap();
        foc.start().unwrap();
        let rec = run(&mut foc, &mut plant, &d, 3.0, 0.3, &load);
        assert_eq!(foc.state(), State::ClosedLoop);
        println!(
            "{}: 2x base ({:.0} rpm), load {:.3} N m ({:.0} % of rated {:.3} N m): speed/ref {:.5}, \
             max |i|/limit {:.4}, max |u|/u_max {:.4}, mean {:.4}, i_dq_ref ({:.3}, {:.3}) A, torque {:.3} N m",
            d.name,
            2.0 * w_b * 60.0 / std::f64::consts::TAU,
            load(2.0 * w_b),
            100.0 * load(2.0 * w_b) / t_rated,
            t_rated,
            rec.speed_ratio,
            rec.max_i_ratio,
            rec.max_u_ratio,
            rec.mean_u_ratio,
            rec.id_ref,
            rec.iq_ref,
            rec.torque
        );
        assert!((rec.speed_ratio - 1.0).abs() < 0.01, "{}: {rec:?}", d.name);
        assert!(rec.max_i_ratio <= 1.02, "{}: {rec:?}", d.name);
        assert!(rec.max_u_ratio <= 1.0 + 1e-5, "{}: {rec:?}", d.name);
        // The loop holds the margin (0.95): the current loops have headroom.
        assert!(
            (rec.mean_u_ratio - 0.95).abs() < 0.02,
            "{}: {rec:?}",
            d.name
        );
        assert!(
            rec.id_ref < -0.3 * cfg.current_limit_a as f64,
            "{}: {rec:?}",
            d.name
        );

        // Back below base speed the correction fades out: the d reference returns to MTPA.
        foc.set_speed_ref_mech_rad_s((0.5 * w_b) as f32).unwrap();
        let rec = run(&mut foc, &mut plant, &d, 3.0, 0.2, &load);
        let it = rec.torque / kt;
        let mtpa = law.currents_for_torque(it as f32);
        println!(
            "{}: back at 0.5x base: i_d ref {:.4} A, MTPA {:.4} A, mean |u|/u_max {:.3}",
            d.name, rec.id_ref, mtpa.d, rec.mean_u_ratio
        );
        assert!((rec.speed_ratio - 1.0).abs() < 0.01, "{}: {rec:?}", d.name);
        assert!(
            (rec.id_ref - mtpa.d as f64).abs() < 0.02 * cfg.current_limit_a as f64,
            "{}: {rec:?}",
            d.name
        );

        // Without field weakening the same command stalls at the voltage limit.
        let mut cfg_off = cfg;
        cfg_off.field_weakening.enabled = false;
        let mut foc = Foc::new(&cfg_off).unwrap();
        let mut plant = Plant::new(&d.m, d.j);
        foc.set_speed_ref_mech_rad_s((2.0 * w_b) as f32).unwrap();
        foc.start().unwrap();
        let rec = run(&mut foc, &mut plant, &d, 3.0, 0.3, &load);
        println!(
            "{}: without field weakening: speed/ref {:.3}",
            d.name, rec.speed_ratio
        );
        assert!(rec.speed_ratio < 0.8, "{}: {rec:?}", d.name);
    }
}

/// Surface motor: field weakening enabled changes nothing below base speed (bit for bit), and
/// above base speed it holds the limits too.
#[test]
fn surface_motor_unchanged_below_base_speed_and_weakened_above() {
    let d = Drive {
        name: "servo",
        m: MotorParams::servo(),
        ts: 100e-6,
        u_dc: 300.0,
        j: 8e-4,
    };
    let lim = 10.0;
    let make = |fw: bool| {
        let mut cfg = FocConfig::new(d.m, d.ts, d.u_dc)
            .with_mode(Mode::Sensored)
            .with_delay(ComputationDelay::None);
        cfg.current_limit_a = lim;
        cfg.over_current_a = 2.0 * lim;
        cfg = cfg.with_inertia(d.j as f32);
        if fw {
            cfg = cfg.with_field_weakening(1.5);
        }
        cfg
    };
    let w_b = base_speed_mech(&d);
    let (mut a, mut b) = (
        Foc::new(&make(false)).unwrap(),
        Foc::new(&make(true)).unwrap(),
    );
    let mut plant = Plant::new(&d.m, d.j);
    for foc in [&mut a, &mut b] {
        foc.set_speed_ref_mech_rad_s((0.6 * w_b) as f32).unwrap();
        foc.start().unwrap();
    }
    for k in 0..20_000 {
        let [ia, ib] = plant.i_ab();
        let input = TickInput::alpha_beta(ia as f32, ib as f32, d.u_dc)
            .with_sensor(plant.x[3] as f32, plant.omega_e() as f32);
        let (oa, ob) = (a.tick(&input), b.tick(&input));
        assert_eq!(oa, ob, "tick {k}");
        let u = duties_to_alpha_beta(oa.duties, d.u_dc);
        let load = if k > 10_000 { 1.0 } else { 0.0 };
        plant.step([u.alpha as f64, u.beta as f64], d.ts as f64, load);
    }
    println!("servo: 20000 ticks to 0.6x base speed and a load step, FW on == FW off bit for bit");

    // Above base speed.
    let cfg = make(true);
    let mut foc = Foc::new(&cfg).unwrap();
    let mut plant = Plant::new(&d.m, d.j);
    foc.set_speed_ref_mech_rad_s((1.5 * w_b) as f32).unwrap();
    foc.start().unwrap();
    let rec = run(&mut foc, &mut plant, &d, 1.5, 0.2, &|w| 0.3 * w.signum());
    println!("servo at 1.5x base with 0.3 N m: {rec:?}");
    assert!((rec.speed_ratio - 1.0).abs() < 0.01, "{rec:?}");
    assert!(rec.max_i_ratio <= 1.02, "{rec:?}");
    assert!(rec.max_u_ratio <= 1.0 + 1e-5, "{rec:?}");
    assert!((rec.mean_u_ratio - 0.95).abs() < 0.02, "{rec:?}");
    assert!(rec.id_ref < 0.0);
}

#[test]
fn per_axis_gains_and_surface_gains() {
    let c = FocConfig::new(MotorParams::industrial_ipm(), 100e-6, 540.0);
    let (gd, gq) = (c.current_pi_gains_d(), c.current_pi_gains());
    let bw = c.current_bw_rad_s;
    assert!((gd.kp - 30e-3 * bw).abs() < 1e-4 * gd.kp);
    assert!((gq.kp - 42e-3 * bw).abs() < 1e-4 * gq.kp);
    assert_eq!(gd.ki, gq.ki);
    let c = FocConfig::new(MotorParams::servo(), 100e-6, 300.0);
    assert_eq!(c.current_pi_gains_d(), c.current_pi_gains());
    assert_eq!(c.torque_current_limit_a(), c.current_limit_a);
    assert_eq!(c.torque_current_of(0.7, 1.3), 1.3);
    // A salient motor's full current makes more torque than k_t I.
    let c = FocConfig::new(MotorParams::traction_ipm(), 50e-6, 48.0);
    assert!(c.torque_current_limit_a() > c.current_limit_a);
    let mut c2 = c;
    c2.mtpa = false;
    assert_eq!(c2.torque_current_limit_a(), c.current_limit_a);
}

#[test]
fn bad_field_weakening_settings_are_refused() {
    let base =
        FocConfig::new(MotorParams::industrial_ipm(), 100e-6, 540.0).with_field_weakening(2.0);
    assert_eq!(base.validate(), Ok(()));
    type Case = (fn(&mut FocConfig), ConfigError);
    let cases: [Case; 8] = [
        (
            |c| c.field_weakening.voltage_margin = 0.3,
            ConfigError::OutOfRange(Field::FwVoltageMargin),
        ),
        (
            |c| c.field_weakening.voltage_margin = 1.2,
            ConfigError::OutOfRange(Field::FwVoltageMargin),
        ),
        (
            |c| c.field_weakening.voltage_margin = f32::NAN,
            ConfigError::NonFinite(Field::FwVoltageMargin),
        ),
        (
            |c| c.field_weakening.bandwidth_rad_s = 0.0,
            ConfigError::NotPositive(Field::FwBandwidth),
        ),
        (
            |c| c.field_weakening.bandwidth_rad_s = 2.0 * c.current_bw_rad_s,
            ConfigError::OutOfRange(Field::FwBandwidth),
        ),
        (
            |c| c.field_weakening.max_negative_id_a = Some(-1.0),
            ConfigError::NotPositive(Field::FwMaxNegativeId),
        ),
        (
            |c| c.field_weakening.max_negative_id_a = Some(2.0 * c.current_limit_a),
            ConfigError::OutOfRange(Field::FwMaxNegativeId),
        ),
        (
            |c| c.field_weakening.max_negative_id_a = Some(f32::INFINITY),
            ConfigError::NonFinite(Field::FwMaxNegativeId),
        ),
    ];
    for (set, err) in cases {
        let mut c = base;
        set(&mut c);
        assert_eq!(c.validate(), Err(err));
        assert_eq!(Foc::new(&c).err(), Some(err));
    }
    // The disabled loop's settings are checked too (they are used when it is turned on).
    let mut c = FocConfig::new(MotorParams::servo(), 100e-6, 300.0);
    c.field_weakening.voltage_margin = 0.0;
    assert!(c.validate().is_err());
}

/// Sensorless start-up, hand-over and reversal of both IPMSMs (the salient observer of
/// ekf-core, MTPA on) from a rotor at rest at 1 rad, with a friction load; the reversal
/// through I/f (a second hand-over) and in closed loop (none, foc's default).
#[test]
fn salient_motors_start_hand_over_and_reverse_sensorless() {
    for (d, delay, reversal) in drives().into_iter().flat_map(|d| {
        [
            (ComputationDelay::None, Reversal::OpenLoop),
            (ComputationDelay::OnePeriod, Reversal::OpenLoop),
            (ComputationDelay::None, Reversal::ClosedLoop),
            (ComputationDelay::OnePeriod, Reversal::ClosedLoop),
        ]
        .map(|(x, r)| (d, x, r))
    }) {
        let mut cfg = FocConfig::new(d.m, d.ts, d.u_dc).with_delay(delay);
        cfg.startup.reversal = reversal;
        let mut pending = [0.5f32; 3];
        let lim = rated_current(&d.m);
        cfg.current_limit_a = lim;
        cfg.over_current_a = 2.0 * lim;
        cfg = cfg.with_inertia(d.j as f32);
        let mut foc = Foc::new(&cfg).unwrap();
        let mut plant = Plant::new(&d.m, d.j);
        plant.x[3] = 1.0;
        let w_b = base_speed_mech(&d);
        let kt = 1.5 * d.m.pole_pairs as f64 * d.m.psi_f_wb as f64;
        // Viscous friction: 10 % of k_t I_lim at base speed.
        let b = 0.1 * kt * lim as f64 / w_b;
        foc.set_speed_ref_mech_rad_s((0.5 * w_b) as f32).unwrap();
        foc.start().unwrap();
        let ts = d.ts as f64;
        let mut states = vec![];
        let (mut err_fwd, mut err_rev, mut n_fwd, mut n_rev) = (0.0, 0.0, 0, 0);
        let mut worst_angle = 0.0f64;
        let t_end = 4.0;
        let n = (t_end / ts) as usize;
        for k in 0..n {
            let t = k as f64 * ts;
            if (t - 2.0).abs() < 0.5 * ts {
                foc.set_speed_ref_mech_rad_s((-0.3 * w_b) as f32).unwrap();
            }
            let [ia, ib] = plant.i_ab();
            let out = foc.tick(&TickInput::alpha_beta(ia as f32, ib as f32, d.u_dc));
            assert!(
                out.fault.is_none(),
                "{}: {:?} at {t}",
                d.name,
                foc.fault_info()
            );
            if states.last() != Some(&out.state) {
                states.push(out.state);
            }
            let w = plant.x[2];
            if (1.5..2.0).contains(&t) {
                err_fwd += (w / (0.5 * w_b) - 1.0).abs();
                n_fwd += 1;
            }
            if (3.5..4.0).contains(&t) {
                err_rev += (w / (-0.3 * w_b) - 1.0).abs();
                n_rev += 1;
            }
            if out.state == State::ClosedLoop && (1.5..2.0).contains(&t) {
                let e = (out.telemetry.estimate.theta_rad as f64 - plant.x[3]
                    + 3.0 * std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                worst_angle = worst_angle.max(e.abs().to_degrees());
            }
            // With the one-period delay the duties of tick k act over [t_k+1, t_k+2).
            let duties = match delay {
                ComputationDelay::None => out.duties,
                ComputationDelay::OnePeriod => core::mem::replace(&mut pending, out.duties),
            };
            let u = duties_to_alpha_beta(duties, d.u_dc);
            plant.step([u.alpha as f64, u.beta as f64], ts, b * w);
        }
        let (e1, e2) = (err_fwd / n_fwd as f64, err_rev / n_rev as f64);
        println!(
            "{} ({delay:?}, {reversal:?}): states {states:?}; mean |speed error| {:.3} % at 0.5x base, {:.3} % after the reversal to -0.3x base; observer angle error in closed loop up to {worst_angle:.4} deg",
            d.name,
            100.0 * e1,
            100.0 * e2
        );
        let visits = |s: State| states.iter().filter(|x| **x == s).count();
        match reversal {
            Reversal::OpenLoop => assert!(visits(State::Handover) >= 2, "{}: {states:?}", d.name),
            Reversal::ClosedLoop => assert_eq!(
                states,
                [
                    State::Align,
                    State::OpenLoop,
                    State::Handover,
                    State::ClosedLoop
                ],
                "{}",
                d.name
            ),
        }
        assert_eq!(states.last(), Some(&State::ClosedLoop), "{}", d.name);
        assert!(e1 < 0.01 && e2 < 0.01, "{}: {e1} {e2}", d.name);
        assert!(worst_angle < 5.0, "{}: {worst_angle}", d.name);
    }
}

/// Field weakening to twice base speed sensorless (start-up on the observer, then the same
/// load as the sensored test), the observer's angle checked at 2x base.
#[test]
fn field_weakening_sensorless_to_twice_base_speed() {
    for d in drives() {
        let cfg = config(&d, Some(2.2)).with_mode(Mode::Sensorless);
        let law = Mtpa::new(&d.m);
        let kt = 1.5 * d.m.pole_pairs as f64 * d.m.psi_f_wb as f64;
        let t_rated = kt * law.torque_current_at_magnitude(cfg.current_limit_a) as f64;
        let w_b = base_speed_mech(&d);
        // Constant power above base speed, rising linearly with speed below (no break-away
        // torque for the I/f start).
        let p_load = 0.25 * t_rated * 2.0 * w_b;
        let load =
            move |w: f64| p_load / w_b * (w / w_b).clamp(-1.0, 1.0) * (w_b / w.abs().max(w_b));
        let mut foc = Foc::new(&cfg).unwrap();
        let mut plant = Plant::new(&d.m, d.j);
        foc.set_speed_ref_mech_rad_s((2.0 * w_b) as f32).unwrap();
        foc.start().unwrap();
        let rec = run(&mut foc, &mut plant, &d, 3.5, 0.3, &load);
        let est = foc.observer().estimate();
        // The estimate is of the last tick's sample time, one period before the plant's state.
        let theta_k = plant.x[3] - plant.omega_e() * d.ts as f64;
        let e = (est.theta_rad as f64 - theta_k + 3.0 * std::f64::consts::PI)
            .rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        println!(
            "{} sensorless at 2x base: speed/ref {:.5}, max |i|/limit {:.4}, max |u|/u_max {:.4}, \
             mean {:.4}, i_dq_ref ({:.2}, {:.2}) A, final observer angle error {:.3} deg",
            d.name,
            rec.speed_ratio,
            rec.max_i_ratio,
            rec.max_u_ratio,
            rec.mean_u_ratio,
            rec.id_ref,
            rec.iq_ref,
            e.to_degrees()
        );
        assert_eq!(foc.state(), State::ClosedLoop);
        assert!((rec.speed_ratio - 1.0).abs() < 0.01, "{}: {rec:?}", d.name);
        assert!(rec.max_i_ratio <= 1.02, "{}: {rec:?}", d.name);
        assert!(rec.max_u_ratio <= 1.0 + 1e-5, "{}: {rec:?}", d.name);
        assert!(e.to_degrees().abs() < 0.5, "{}: {e}", d.name);
    }
}
