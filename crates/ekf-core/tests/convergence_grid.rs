//! Convergence from any initial angle error with the rotor spinning and the speed estimate 0
//! (docs/design.md, "The reference filter", "theta+pi lock"): the three reference motors at +-10 %, +-50 % and
//! +-100 % of their rated speed, initial angle errors every 30 deg (every 10 deg with
//! `EKF_GRID_FULL=1`). A cell passes when the wrapped angle error is below 5 deg el. from some
//! time before 50 ms to the end of the 100 ms run.
//!
//! The default ([`ObserverConfig::new`], branch check on) passes every cell; the seed
//! ([`ObserverConfig::seed`]) settles on the `(-w, th + pi)` branch in some cells and stays
//! there. Run with `--nocapture` to see the grids.
mod common;
use common::*;
use core::f64::consts::PI;
use ekf_core::{MotorParams, ObserverConfig, PmsmObserver, wrap_angle};

const TS: f64 = 1e-4;
/// Samples per run (100 ms).
const N: usize = 1000;
/// Lock deadline, samples (50 ms).
const DEADLINE: usize = 500;
const LOCK_DEG: f64 = 5.0;

/// A motor of the grid: name, motor, rated electrical speed (rad/s), sensor noise (A), q
/// current as a fraction of the characteristic current `psi_f / Lq`.
type GridMotor = (&'static str, MotorParams<f64>, f64, f64, f64);

fn surface_motors() -> Vec<GridMotor> {
    reference_motors()
        .into_iter()
        .map(|(n, m, r, s)| (n, m, r, s, 0.1))
        .collect()
}

/// The interior motors at their rated q current (MTPA d current in the plant).
fn interior_grid_motors() -> Vec<GridMotor> {
    interior_motors()
        .into_iter()
        .map(|(n, m, r, iq, s)| (n, m, r, s, iq / m.characteristic_current_a()))
        .collect()
}

const SPEED_FRACTIONS: [f64; 6] = [-1.0, -0.5, -0.1, 0.1, 0.5, 1.0];

fn angle_grid_deg() -> Vec<f64> {
    let step = if std::env::var_os("EKF_GRID_FULL").is_some() {
        10
    } else {
        30
    };
    (0..360).step_by(step).map(f64::from).collect()
}

/// Outcome of one cell.
#[derive(Clone, Copy)]
struct Cell {
    /// Time to lock, samples, if locked before the deadline and held to the end.
    lock: Option<usize>,
    flips: u32,
    /// Flips after which the speed estimate had the wrong sign.
    wrong_flips: u32,
}

/// Runs one observer over a trace from the initial angle error `err0_deg`, speed estimate 0.
fn run_cell(mut cfg: ObserverConfig<f64>, tr: &Trace, err0_deg: f64) -> Cell {
    cfg.x0[3] = wrap_angle(tr.th[0] + err0_deg.to_radians());
    cfg.x0[2] = 0.0;
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let mut u_prev = [0.0, 0.0];
    let mut err = Vec::with_capacity(tr.th.len());
    let mut wrong_flips = 0;
    for (((i, u), th), w) in tr.i_meas.iter().zip(&tr.u).zip(&tr.th).zip(&tr.w) {
        let e = obs.step(u_prev, *i).expect("finite step");
        if e.branch_flipped && e.omega_e_rad_s * w <= 0.0 {
            wrong_flips += 1;
        }
        err.push(wrap_angle(e.theta_rad - th).to_degrees());
        u_prev = *u;
    }
    let lock = convergence_index(&err, LOCK_DEG).filter(|&k| k <= DEADLINE);
    Cell {
        lock,
        flips: obs.counters().branch_flips,
        wrong_flips,
    }
}

/// Runs the grid for one configuration maker; prints it; returns (cells, failures, flips that
/// left the speed estimate with the wrong sign).
fn grid(
    name: &str,
    motors: &[GridMotor],
    make: fn(MotorParams<f64>, f64) -> ObserverConfig<f64>,
) -> (usize, usize, u32) {
    let angles = angle_grid_deg();
    let (mut cells, mut failures, mut wrong) = (0, 0, 0);
    println!("\n=== {name}: time to lock (ms) or FAIL; '*' = branch flip(s) ===");
    for &(mname, motor, rated, noise, iq_frac) in motors {
        let ic = motor.characteristic_current_a();
        println!("{mname} (rated {rated:.0} rad/s el.)");
        print!("{:>8}", "err0\\w");
        for f in SPEED_FRACTIONS {
            print!("{:>9}", format!("{:+.0}%", f * 100.0));
        }
        println!();
        let traces: Vec<Trace> = SPEED_FRACTIONS
            .iter()
            .enumerate()
            .map(|(j, &f)| {
                let w = f * rated;
                let speed = move |_t: f64| w;
                let iq = move |_t: f64| iq_frac * ic;
                simulate(&Scenario {
                    motor,
                    ts: TS,
                    n: N,
                    speed: &speed,
                    iq_ref: &iq,
                    th0: 0.3,
                    noise_a: noise,
                    seed: 100 + j as u64,
                })
            })
            .collect();
        for &a in &angles {
            print!("{a:>7.0}°");
            for tr in &traces {
                let c = run_cell(make(motor, TS), tr, a);
                cells += 1;
                wrong += c.wrong_flips;
                let mark = if c.flips > 0 { "*" } else { " " };
                match c.lock {
                    Some(k) => print!("{:>8.1}{mark}", k as f64 * TS * 1e3),
                    None => {
                        failures += 1;
                        print!("{:>8}{mark}", "FAIL")
                    }
                }
            }
            println!();
        }
    }
    println!("{name}: {failures} of {cells} cells fail; {wrong} flips to the wrong branch");
    (cells, failures, wrong)
}

#[test]
fn default_locks_from_any_angle_and_seed_does_not() {
    let motors = surface_motors();
    let (cells, fail_default, wrong) = grid(
        "ObserverConfig::new (default)",
        &motors,
        ObserverConfig::new,
    );
    let (_, fail_seed, _) = grid("ObserverConfig::seed", &motors, ObserverConfig::seed);
    assert_eq!(
        fail_default, 0,
        "default: {fail_default} of {cells} cells fail"
    );
    assert_eq!(wrong, 0, "default: flips to the wrong branch");
    // The seed's filter has no branch check: some cells settle on the theta + pi branch.
    assert!(fail_seed > 0, "the seed was expected to fail some cells");
}

/// The interior motors (active-flux model) at rated q current with the MTPA d current: the
/// default passes every cell of the grid within 50 ms too (the goal; measured: all
/// 144 cells lock within 25 ms: worst 23 ms industrial, 25 ms traction). At this load (the traction motor's `Lq i_q` exceeds
/// `psi_f`) the convergence transients sometimes trip the branch check the wrong way
/// (measured 5 of 144 cells); the check then undoes it within the same run (every cell still
/// locks), so those flips are bounded here rather than forbidden.
#[test]
fn interior_motors_lock_from_any_angle() {
    let (cells, fail, wrong) = grid(
        "ObserverConfig::new, interior motors at rated current",
        &interior_grid_motors(),
        ObserverConfig::new,
    );
    assert_eq!(fail, 0, "interior: {fail} of {cells} cells fail");
    assert!(
        wrong as usize * 20 <= cells,
        "interior: {wrong} flips to the wrong branch in {cells} cells (bound 5 %)"
    );
}

/// Runs the default observer started on the truth over a speed profile; returns the branch
/// flips and the largest angle error (deg) where `|w| > 10 %` of rated after the first 20 ms.
fn run_profile(
    motor: MotorParams<f64>,
    rated: f64,
    noise: f64,
    speed: &dyn Fn(f64) -> f64,
    n: usize,
) -> (u32, f64) {
    let ic = motor.characteristic_current_a();
    let iq = move |_t: f64| 0.1 * ic;
    let tr = simulate(&Scenario {
        motor,
        ts: TS,
        n,
        speed,
        iq_ref: &iq,
        th0: 0.3,
        noise_a: noise,
        seed: 9,
    });
    let mut cfg = ObserverConfig::new(motor, TS);
    cfg.x0[2] = tr.w[0];
    cfg.x0[3] = tr.th[0];
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let mut u_prev = [0.0, 0.0];
    let mut max_err = 0.0f64;
    for (k, ((i, u), (th, w))) in tr
        .i_meas
        .iter()
        .zip(&tr.u)
        .zip(tr.th.iter().zip(&tr.w))
        .enumerate()
    {
        let e = obs.step(u_prev, *i).expect("finite");
        if k >= 200 && w.abs() >= 0.099 * rated {
            max_err = max_err.max(wrap_angle(e.theta_rad - th).to_degrees().abs());
        }
        u_prev = *u;
    }
    (obs.counters().branch_flips, max_err)
}

/// No false flips: steady state at every grid speed, slow and fast reversals through zero,
/// and a rotor rocking around standstill (where the back-EMF is unobservable).
#[test]
fn no_false_flips() {
    for (mname, motor, rated, noise) in reference_motors() {
        let mut report = Vec::new();
        for f in SPEED_FRACTIONS {
            let w = f * rated;
            let (flips, err) = run_profile(motor, rated, noise, &move |_| w, 2000);
            report.push((format!("steady {:+.0}%", f * 100.0), flips, err));
        }
        // Sinusoidal reversal, period 0.2 s, through +-rated.
        let slow = move |t: f64| rated * (2.0 * PI * t / 0.2).cos();
        let (flips, err) = run_profile(motor, rated, noise, &slow, 4000);
        report.push(("reversal 0.2 s period".into(), flips, err));
        // Linear reversal from +rated to -rated in 50 ms, and back.
        let fast = move |t: f64| {
            let r = (t - 0.02) / 0.05;
            if t < 0.1 {
                rated * (1.0 - 2.0 * r.clamp(0.0, 1.0))
            } else {
                -rated * (1.0 - 2.0 * ((t - 0.12) / 0.05).clamp(0.0, 1.0))
            }
        };
        let (flips, err) = run_profile(motor, rated, noise, &fast, 2000);
        report.push(("reversal +-rated in 50 ms".into(), flips, err));
        // Rocking around standstill: +-3 % of rated at 5 Hz.
        let rock = move |t: f64| 0.03 * rated * (2.0 * PI * 5.0 * t).sin();
        let (flips, _) = run_profile(motor, rated, noise, &rock, 4000);
        report.push(("rocking +-3% at 5 Hz".into(), flips, 0.0));
        for (name, flips, err) in &report {
            println!("{mname:18} {name:28} flips {flips}  max |angle error| {err:6.2} deg");
        }
        for (name, flips, err) in &report {
            assert_eq!(*flips, 0, "{mname} {name}: false branch flip");
            assert!(*err < 5.0, "{mname} {name}: angle error {err} deg");
        }
    }
}
