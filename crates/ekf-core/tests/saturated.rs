//! The map observer (`ekf_core::saturated`) on a saturating PM-SyRM (the 5.6 kW machine of
//! `ekf_core::saturation::PM_SYRM_5K6`), against the constant-parameter observer told the
//! small-signal values a low-current commissioning measures, or the chord values at rated
//! current.
//!
//! The plant is independent of the observers' model: the stator flux in the rotor frame is
//! its state, the currents come from the algebraic current map (not from the sampled flux
//! map the map observer is told), RK4 with 8 sub-steps per period, the voltage held in the
//! stationary frame over each period. The speed is imposed (a stiff load): 0.25 s at
//! 1000 rpm with no load, rated current, a step to 150 %, a generating step to -100 %, then
//! a reversal to -600 rpm over 0.3 s at rated current. A sensored dq current loop on the true
//! angle sets the voltages; the observers see them one period late and the currents with
//! 20 mA of noise. They start 30 deg off at zero speed after 20 ms of running. The voltage is
//! limited to the linear range of a 540 V bus (311.8 V).
//!
//! The constant-parameter observer also runs in the mode for saturating motors
//! (`ObserverConfig::saturating`: its model `Lq` the midpoint of the told `Ld` and `Lq`). Each
//! constant observer's status is split into `Tracking` and `Uncertain`, within and beyond
//! 45 deg; none may read `Tracking` beyond (module docs of `ekf_core::observer`, "Model fit").
//!
//! Run: `cargo test --release -p ekf-core --test saturated -- --nocapture`.

#![allow(clippy::needless_range_loop)] // index-aligned traces

use ekf_core::saturated::{FluxMapObserver, FluxOffsetTracking, MapObserver};
use ekf_core::saturation::PM_SYRM_5K6;
use ekf_core::testing::Rng;
use ekf_core::{FluxObserver, FluxObserverConfig};
use ekf_core::{MotorParams, ObserverConfig, PmsmObserver, wrap_angle};

const TS: f64 = 1e-4;
const RS: f64 = 0.63;
const P: u32 = 2;
const RATED_A: f64 = 12.445; // 8.8 A rms
const U_MAX: f64 = 311.8;

struct Trace {
    u: Vec<[f64; 2]>,
    i: Vec<[f64; 2]>,
    th: Vec<f64>,
    w: Vec<f64>,
}

fn speed_and_iq(t: f64) -> (f64, f64) {
    let w1 = 1000.0 / 60.0 * std::f64::consts::TAU * f64::from(P);
    let w2 = -600.0 / 60.0 * std::f64::consts::TAU * f64::from(P);
    let w = if t < 1.0 {
        w1.min(w1 * t / 0.1)
    } else if t < 1.3 {
        w1 + (w2 - w1) * (t - 1.0) / 0.3
    } else {
        w2
    };
    let iq = match t {
        t if t < 0.25 => 0.0,
        t if t < 0.5 => RATED_A,
        t if t < 0.75 => 1.5 * RATED_A,
        t if t < 1.0 => -RATED_A,
        _ => RATED_A,
    };
    (w, iq)
}

fn simulate(duration_s: f64, seed: u64) -> Trace {
    let m = PM_SYRM_5K6;
    let n = (duration_s / TS) as usize;
    let mut rng = Rng::new(seed);
    let (mut pd, mut pq) = m.flux(0.0, 0.0, (0.4, 0.0)).unwrap();
    let mut th: f64 = 0.3;
    let mut tr = Trace {
        u: vec![],
        i: vec![],
        th: vec![],
        w: vec![],
    };
    let (mut int_d, mut int_q) = (0.0, 0.0);
    let mut u_ab = [0.0f64; 2];
    // Current-loop gains for about 300 Hz on the small-signal inductances.
    let (kp_d, kp_q, ki) = (
        2.0 * 300.0 * 0.03 * std::f64::consts::TAU,
        2.0 * 300.0 * 0.08 * std::f64::consts::TAU,
        RS * 600.0,
    );
    for k in 0..n {
        let t = k as f64 * TS;
        let (w, iq_ref) = speed_and_iq(t);
        // Sample: currents now.
        let (id, iq) = m.currents(pd, pq);
        let (s, c) = th.sin_cos();
        let ia = c * id - s * iq;
        let ib = s * id + c * iq;
        tr.i.push([ia + 0.02 * rng.gauss(), ib + 0.02 * rng.gauss()]);
        tr.th.push(th);
        tr.w.push(w);
        tr.u.push(u_ab);
        // Controller on the true angle (its output applies over the coming period).
        let (ed, eq) = (0.0 - id, iq_ref - iq);
        let (mut ud, mut uq) = (
            kp_d * ed + int_d + ki * ed * TS - w * pq,
            kp_q * eq + int_q + ki * eq * TS + w * pd,
        );
        // The inverter's linear range, u_dc / sqrt 3 on a 540 V bus; no integration while
        // limited.
        let mag = ud.hypot(uq);
        if mag > U_MAX {
            ud *= U_MAX / mag;
            uq *= U_MAX / mag;
        } else {
            int_d += ki * ed * TS;
            int_q += ki * eq * TS;
        }
        u_ab = [c * ud - s * uq, s * ud + c * uq];
        // Plant over the period: RK4 on (psi_d, psi_q, th) with u held in alpha-beta.
        let h = TS / 8.0;
        let f = |pd: f64, pq: f64, th: f64| {
            let (s, c) = th.sin_cos();
            let (ud, uq) = (c * u_ab[0] + s * u_ab[1], -s * u_ab[0] + c * u_ab[1]);
            let (id, iq) = m.currents(pd, pq);
            (ud - RS * id + w * pq, uq - RS * iq - w * pd, w)
        };
        for _ in 0..8 {
            let k1 = f(pd, pq, th);
            let k2 = f(
                pd + 0.5 * h * k1.0,
                pq + 0.5 * h * k1.1,
                th + 0.5 * h * k1.2,
            );
            let k3 = f(
                pd + 0.5 * h * k2.0,
                pq + 0.5 * h * k2.1,
                th + 0.5 * h * k2.2,
            );
            let k4 = f(pd + h * k3.0, pq + h * k3.1, th + h * k3.2);
            pd += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            pq += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
            th += h / 6.0 * (k1.2 + 2.0 * k2.2 + 2.0 * k3.2 + k4.2);
        }
        th = wrap_angle(th);
    }
    tr
}

/// RMS and max angle error (deg) from 0.2 s on, where |w| is above 10 % of 1000 rpm, and the
/// share of those samples more than 45 deg off.
fn score(tr: &Trace, theta: &[f64]) -> (f64, f64, f64) {
    let w_min = 0.1 * 1000.0 / 60.0 * std::f64::consts::TAU * 2.0;
    let (mut ss, mut n, mut max, mut lost) = (0.0, 0usize, 0.0f64, 0usize);
    for k in (0.2 / TS) as usize..theta.len() {
        if tr.w[k].abs() < w_min {
            continue;
        }
        let e = wrap_angle(theta[k] - tr.th[k]).to_degrees();
        ss += e * e;
        n += 1;
        max = max.max(e.abs());
        lost += usize::from(e.abs() > 45.0);
    }
    ((ss / n as f64).sqrt(), max, lost as f64 / n as f64)
}

const START: usize = 200;

fn sampled_map() -> ekf_core::FluxMap<f64, 16> {
    let i_d: Vec<f64> = (0..12).map(|k| -20.0 + 30.0 * k as f64 / 11.0).collect();
    let i_q: Vec<f64> = (0..16).map(|k| -30.0 + 60.0 * k as f64 / 15.0).collect();
    PM_SYRM_5K6.flux_map::<f64, 16>(&i_d, &i_q).unwrap()
}

/// The flux baseline told the map (`map`) or told constants (`motor`).
fn run_flux(tr: &Trace, motor: MotorParams<f64>, map: bool) -> Vec<f64> {
    let cfg = FluxObserverConfig::new(motor, TS);
    let mut out = vec![0.0; tr.th.len()];
    if map {
        let mut obs = FluxMapObserver::new(&cfg, sampled_map()).unwrap();
        for k in START..tr.th.len() {
            out[k] = obs.step(tr.u[k], tr.i[k]).unwrap().theta_rad;
        }
    } else {
        let mut obs = FluxObserver::new(&cfg).unwrap();
        for k in START..tr.th.len() {
            out[k] = obs.step(tr.u[k], tr.i[k]).unwrap().theta_rad;
        }
    }
    out
}

fn run_map(tr: &Trace) -> Vec<f64> {
    let map = sampled_map();
    let cfg = MapObserver::default_config(&map, RS, P, TS);
    let mut obs = MapObserver::new(&cfg, map).unwrap();
    let x0 = ekf_core::nalgebra::Vector4::new(0.0, 0.0, 0.0, tr.th[START] + 30f64.to_radians());
    obs.reset(x0, cfg.p0).unwrap();
    let mut out = vec![0.0; tr.th.len()];
    for k in START..tr.th.len() {
        out[k] = obs.step(tr.u[k], tr.i[k]).unwrap().theta_rad;
    }
    out
}

/// A constant-parameter observer's run: its angle, and how its status split the samples from
/// its start on.
struct Constant {
    theta: Vec<f64>,
    /// Samples `Tracking` while more than 45 deg off.
    tracking_lost: usize,
    /// Shares of the samples, %: `Tracking` within 45 deg, `Tracking` beyond (0 when the
    /// status is honest), `Uncertain` within 45 deg, `Uncertain` beyond.
    shares: [f64; 4],
}

impl Constant {
    fn status_line(&self) -> String {
        let [t, tl, u, ul] = self.shares;
        format!(
            "status: Tracking {:.1} % ({t:.1} within 45 deg, {tl:.1} beyond), Uncertain {:.1} % \
             ({u:.1} within, {ul:.1} beyond)",
            t + tl,
            u + ul
        )
    }
}

fn run_constant(tr: &Trace, cfg: ObserverConfig<f64>) -> Constant {
    let mut obs = PmsmObserver::new(&cfg).unwrap();
    let x0 = ekf_core::nalgebra::Vector4::new(0.0, 0.0, 0.0, tr.th[START] + 30f64.to_radians());
    obs.reset(x0, cfg.p0).unwrap();
    let mut out = vec![0.0; tr.th.len()];
    let mut counts = [0usize; 4];
    for k in START..tr.th.len() {
        let e = obs.step(tr.u[k], tr.i[k]).unwrap();
        out[k] = e.theta_rad;
        let off = wrap_angle(e.theta_rad - tr.th[k]).abs() > 45f64.to_radians();
        let uncertain = e.status != ekf_core::Status::Tracking;
        counts[2 * usize::from(uncertain) + usize::from(off)] += 1;
    }
    let n = (tr.th.len() - START) as f64;
    Constant {
        theta: out,
        tracking_lost: counts[1],
        shares: counts.map(|c| 100.0 * c as f64 / n),
    }
}

#[test]
fn map_observer_holds_the_angle_of_a_saturating_pm_syrm() {
    let tr = simulate(1.6, 1);
    let map = score(&tr, &run_map(&tr));
    let m = PM_SYRM_5K6;
    // Small-signal constants (zero current) and rated-current chord values.
    let (pd0, _) = m.flux(0.0, 0.0, (0.4, 0.0)).unwrap();
    let h = 1e-4;
    let ld0 = (m.flux(h, 0.0, (pd0, 0.0)).unwrap().0 - pd0) / h;
    let lq0 = m.flux(0.0, h, (pd0, 0.0)).unwrap().1 / h;
    let small = MotorParams::salient_from_f64(RS, ld0, lq0, pd0, P);
    let (pdr, pqr) = m.flux(0.0, RATED_A, (pd0, 0.5)).unwrap();
    let ldr = (m.flux(h, RATED_A, (pdr, pqr)).unwrap().0 - pdr) / h;
    let rated = MotorParams::salient_from_f64(RS, ldr, pqr / RATED_A, pdr, P);
    let small_c = run_constant(&tr, ObserverConfig::new(small, TS));
    let sat_c = run_constant(&tr, ObserverConfig::saturating(small, TS));
    let rated_c = run_constant(&tr, ObserverConfig::new(rated, TS));
    let small_s = score(&tr, &small_c.theta);
    let sat_s = score(&tr, &sat_c.theta);
    let rated_s = score(&tr, &rated_c.theta);
    println!(
        "constant, small-signal, ObserverConfig::saturating (model Lq {:.1} mH): RMS {:.2}, \
         max {:.2}, > 45 deg {:.2} %, Tracking while > 45 deg off {}\n  {}",
        ekf_core::observer::saturating_lq(&small) * 1e3,
        sat_s.0,
        sat_s.1,
        100.0 * sat_s.2,
        sat_c.tracking_lost,
        sat_c.status_line()
    );
    let flux_map = score(&tr, &run_flux(&tr, small, true));
    let flux_small = score(&tr, &run_flux(&tr, small, false));
    println!(
        "flux baseline told the map: RMS {:.2} deg, max {:.2}, > 45 deg {:.2} %\n\
         flux baseline told the small-signal constants: RMS {:.2}, max {:.2}, > 45 deg {:.2} %",
        flux_map.0,
        flux_map.1,
        100.0 * flux_map.2,
        flux_small.0,
        flux_small.1,
        100.0 * flux_small.2
    );
    println!(
        "saturated PM-SyRM, 1000 rpm, 0/100/150/-100 % current steps, reversal to -600 rpm:\n\
         map observer (told the sampled map): RMS {:.2} deg, max {:.2}, > 45 deg {:.2} %\n\
         constant, small-signal (Ld {:.1} mH, Lq {:.1} mH, psi_f {:.3}): RMS {:.2}, max {:.2}, \
         > 45 deg {:.2} %, Tracking while > 45 deg off {}\n  {}\n\
         constant, rated chord (Ld {:.1} mH, Lq {:.1} mH, psi_f {:.3}): RMS {:.2}, max {:.2}, \
         > 45 deg {:.2} %, Tracking while > 45 deg off {}\n  {}",
        map.0,
        map.1,
        100.0 * map.2,
        ld0 * 1e3,
        lq0 * 1e3,
        pd0,
        small_s.0,
        small_s.1,
        100.0 * small_s.2,
        small_c.tracking_lost,
        small_c.status_line(),
        ldr * 1e3,
        pqr / RATED_A * 1e3,
        pdr,
        rated_s.0,
        rated_s.1,
        100.0 * rated_s.2,
        rated_c.tracking_lost,
        rated_c.status_line(),
    );
    assert!(map.2 == 0.0, "map observer lost lock: {map:?}");
    assert!(map.0 < 1.0, "map observer RMS {map:?}");
    assert!(
        map.0 < 0.5 * small_s.0.min(rated_s.0),
        "{map:?} {small_s:?} {rated_s:?}"
    );
    // The mode for saturating motors (`ObserverConfig::saturating`) told the same constants
    // is closer than `ObserverConfig::new` (on this plant, driven at `i_d = 0` up to 150 %
    // `i_q`, no constant `Lq` stays within 45 deg: docs/saturation.md).
    assert!(sat_s.0 < 0.7 * small_s.0, "{sat_s:?} {small_s:?}");
    // An honest status (module docs of `ekf_core::observer`, "Model fit"): none of the three
    // reads `Tracking` while more than 45 deg off (1719 / 8369 / 65 samples without the model
    // fit), and each still reads it where it holds the angle.
    for (name, c) in [
        ("saturating, small-signal", &sat_c),
        ("new, small-signal", &small_c),
        ("new, rated chord", &rated_c),
    ] {
        assert_eq!(c.tracking_lost, 0, "{name}: {}", c.status_line());
        assert!(c.shares[0] > 5.0, "{name}: {}", c.status_line());
    }
    // The goal: at most half the flux baseline told the same map.
    assert!(map.0 <= 0.5 * flux_map.0, "{map:?} {flux_map:?}");
}

#[test]
fn saturating_mode_models_the_midpoint_inductance() {
    let interior = MotorParams::salient_from_f64(RS, 0.03, 0.15, 0.477, P);
    let cfg = ObserverConfig::saturating(interior, TS);
    assert!((cfg.motor.lq_h - 0.09).abs() < 1e-12, "{}", cfg.motor.lq_h);
    assert_eq!(cfg.motor.ld_h, 0.03);
    let mut told = interior;
    told.lq_h = cfg.motor.lq_h;
    assert_eq!(cfg, ObserverConfig::new(told, TS));
    // Surface and inverse-salient motors: the default configuration itself.
    for m in [
        MotorParams::salient_from_f64(RS, 0.05, 0.05, 0.477, P),
        MotorParams::salient_from_f64(RS, 0.06, 0.04, 0.477, P),
    ] {
        assert_eq!(
            ObserverConfig::saturating(m, TS),
            ObserverConfig::new(m, TS)
        );
    }
}

/// `MapObserver::shift_psi_d` moves the map's `psi_d` (and so the prediction) by the offset,
/// keeps the state, and refuses a non-finite offset without changing anything.
#[test]
fn a_psi_d_shift_moves_the_map_and_a_bad_one_is_refused() {
    let map = sampled_map();
    let cfg = MapObserver::default_config(&map, RS, P, TS);
    let mut obs = MapObserver::new(&cfg, map).unwrap();
    let before = obs.map().eval(-3.0, 7.0);
    let x = *obs.observer().state();
    obs.shift_psi_d(0.004).unwrap();
    let after = obs.map().eval(-3.0, 7.0);
    assert!((after.psi_d - before.psi_d - 0.004).abs() < 1e-12);
    assert_eq!(after.psi_q, before.psi_q);
    assert_eq!(*obs.observer().state(), x);
    for bad in [f64::NAN, f64::INFINITY] {
        assert!(obs.shift_psi_d(bad).is_err());
        assert_eq!(obs.map().eval(-3.0, 7.0), after);
    }
}

/// The map observer on `map` with the flux-offset tracking on or off: its angles and the
/// offset it learnt.
fn run_map_tracking(tr: &Trace, map: ekf_core::FluxMap<f64, 16>, on: bool) -> (Vec<f64>, f64) {
    let cfg = MapObserver::default_config(&map, RS, P, TS);
    let mut obs = MapObserver::new(&cfg, map).unwrap();
    if on {
        obs.set_flux_offset_tracking(Some(FluxOffsetTracking::new()))
            .unwrap();
    }
    let x0 = ekf_core::nalgebra::Vector4::new(0.0, 0.0, 0.0, tr.th[START] + 30f64.to_radians());
    obs.reset(x0, cfg.p0).unwrap();
    let mut out = vec![0.0; tr.th.len()];
    for k in START..tr.th.len() {
        out[k] = obs.step(tr.u[k], tr.i[k]).unwrap().theta_rad;
    }
    (out, obs.flux_offset_wb())
}

/// Told a map whose `psi_d` is 8 % of `psi_f` high (the magnets warmer than when it was
/// measured), the flux-offset tracking learns the offset and removes most of the angle bias
/// it causes; told the right map, it costs (almost) nothing (module docs of
/// `ekf_core::saturated`, "The flux offset").
#[test]
fn the_map_observer_learns_a_psi_d_offset() {
    let tr = simulate(1.6, 1);
    let psi0 = sampled_map().eval(0.0, 0.0).psi_d;
    let offset = 0.08 * psi0;
    let mut told = sampled_map();
    told.shift_psi_d(offset);
    let (off_th, _) = run_map_tracking(&tr, told.clone(), false);
    let (on_th, learnt) = run_map_tracking(&tr, told, true);
    let (right_off, _) = run_map_tracking(&tr, sampled_map(), false);
    let (right_on, right_learnt) = run_map_tracking(&tr, sampled_map(), true);
    let (s_off, s_on) = (score(&tr, &off_th), score(&tr, &on_th));
    let (r_off, r_on) = (score(&tr, &right_off), score(&tr, &right_on));
    println!(
        "map psi_d +{:.1} mWb (8 % of psi_f): angle RMS {:.2} deg (max {:.2}) without the \
         tracking, {:.2} (max {:.2}) with it; learnt {:+.2} mWb ({:.1} % of the offset)\n\
         the right map: {:.3} deg without, {:.3} with; learnt {:+.2} mWb",
        offset * 1e3,
        s_off.0,
        s_off.1,
        s_on.0,
        s_on.1,
        learnt * 1e3,
        100.0 * (-learnt / offset),
        r_off.0,
        r_on.0,
        right_learnt * 1e3
    );
    assert!(s_on.0 < 0.5 * s_off.0, "{s_on:?} vs {s_off:?}");
    assert!(
        (learnt + offset).abs() < 0.1 * offset,
        "learnt {learnt}, offset {offset}"
    );
    assert!(r_on.0 < 1.1 * r_off.0, "{r_on:?} vs {r_off:?}");
    assert!(right_learnt.abs() < 0.01 * psi0, "{right_learnt}");
}

/// A flux-offset setting out of range is refused, naming the field, and leaves the observer
/// as it was; non-finite inputs to a tracking observer are refused without moving the map.
#[test]
fn a_bad_flux_offset_setting_or_input_is_refused() {
    let map = sampled_map();
    let cfg = MapObserver::default_config(&map, RS, P, TS);
    let mut obs = MapObserver::new(&cfg, map).unwrap();
    let fine = FluxOffsetTracking::<f64>::new();
    for bad in [
        FluxOffsetTracking { gain: 0.0, ..fine },
        FluxOffsetTracking { gain: 1.5, ..fine },
        FluxOffsetTracking {
            window_rad: 4.0,
            ..fine
        },
        FluxOffsetTracking {
            min_speed_rad_s: -1.0,
            ..fine
        },
        FluxOffsetTracking {
            max_drop_ratio: f64::NAN,
            ..fine
        },
        FluxOffsetTracking {
            max_window_s: 0.0,
            ..fine
        },
        FluxOffsetTracking {
            max_offset_fraction: f64::INFINITY,
            ..fine
        },
    ] {
        let e = obs.set_flux_offset_tracking(Some(bad)).unwrap_err();
        assert!(e.to_string().contains("flux_offset."), "{e}");
        assert_eq!(obs.flux_offset_wb(), 0.0);
    }
    obs.set_flux_offset_tracking(Some(fine)).unwrap();
    let before = obs.map().eval(1.0, 2.0);
    let x = *obs.observer().state();
    assert!(obs.step([f64::NAN, 0.0], [0.0, 0.0]).is_err());
    assert!(obs.step([0.0, 0.0], [f64::INFINITY, 0.0]).is_err());
    // Corrupted samples (module docs of `ekf_core::observer`, "Implausible input").
    assert_eq!(
        obs.step([6.7e5 * 1e3, 0.0], [0.0, 0.0]).err(),
        Some(ekf_core::EkfError::ImplausibleInput)
    );
    assert_eq!(
        obs.step([0.0, 0.0], [1.4e17, 0.0]).err(),
        Some(ekf_core::EkfError::ImplausibleMeasurement)
    );
    assert_eq!(*obs.observer().state(), x);
    assert_eq!(obs.map().eval(1.0, 2.0), before);
}
