//! Fuzzing of the public step functions, on stable, driven by proptest.
//!
//! Arbitrary `f32`/`f64` bit patterns (NaN, infinities, subnormals, huge values) for the
//! measurements, the inputs and the parameters. Properties, after every call:
//! - nothing panics;
//! - a constructor either refuses the configuration with an error or gives an observer;
//! - a refused step leaves the state and the covariance bit for bit as they were;
//! - an accepted step leaves a finite state, a finite covariance, an angle in `[-pi, pi]`
//!   and a finite estimate.
//!
//! By default each target runs a fixed number of cases (part of `cargo test`). With
//! `FUZZ_SECONDS=N` each target runs fresh random cases for `N` seconds instead and prints how
//! many it ran: `FUZZ_SECONDS=600 cargo test --release -p ekf-core --test fuzz -- --nocapture`.

use ekf_core::nalgebra::Vector2;
use ekf_core::nalgebra::{Matrix4, Vector4};
use ekf_core::{
    CovarianceUpdate, Discretization, Ekf, Float, MotorParams, NoiseCovariances, ObserverConfig,
    PmsmModel, PmsmObserver, RsTracking, observer::MAX_REFUSALS,
};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

#[path = "support/fuzz_harness.rs"]
mod harness;

/// Counters printed after each target, so a run shows it reached the accepting paths.
static CONFIGS_OK: AtomicU64 = AtomicU64::new(0);
static CONFIGS_REFUSED: AtomicU64 = AtomicU64::new(0);
static CALLS_OK: AtomicU64 = AtomicU64::new(0);
static CALLS_REFUSED: AtomicU64 = AtomicU64::new(0);

/// Any bit pattern of an `f64`, or (most of the time) a plausible value of scale `scale`.
fn any_f64(scale: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        1 => any::<u64>().prop_map(f64::from_bits),
        1 => prop_oneof![
            Just(0.0), Just(-0.0), Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY),
            Just(f64::MAX), Just(f64::MIN_POSITIVE), Just(-f64::MAX), Just(1e-300),
        ],
        4 => (-1.0f64..1.0).prop_map(move |x| x * scale),
    ]
}

/// A parameter: any bit pattern, a boundary value, or (mostly) a plausible positive value
/// around `nominal` (from 1e-3x to 1e3x).
fn param(nominal: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        1 => any_f64(nominal),
        12 => (-3.0f64..3.0).prop_map(move |e| nominal * 10f64.powf(e)),
    ]
}

/// One call on the observer.
#[derive(Clone, Debug)]
enum Call {
    Step([f64; 2], [f64; 2]),
    Predict([f64; 2]),
    Correct([f64; 2]),
    Reset([f64; 4], f64),
}

fn call(u: f64, i: f64) -> impl Strategy<Value = Call> {
    let pair = move |s| [any_f64(s), any_f64(s)];
    let plausible = move |s: f64| [(-s..s), (-s..s)];
    prop_oneof![
        30 => (plausible(u), plausible(i)).prop_map(|(u, i)| Call::Step(u, i)),
        10 => (pair(u), pair(i)).prop_map(|(u, i)| Call::Step(u, i)),
        2 => pair(u).prop_map(Call::Predict),
        2 => pair(i).prop_map(Call::Correct),
        1 => ([any_f64(i), any_f64(i), any_f64(1e3), any_f64(4.0)], param(1.0))
            .prop_map(|(x, p)| Call::Reset(x, p)),
    ]
}

/// A configuration with every parameter fuzzed: motor, Ts, Q, R, P0, x0, angle limit.
#[derive(Clone, Debug)]
struct Params {
    motor: (f64, f64, f64, u32),
    /// `Lq / Ld`: 1 (surface) half of the time, else any ratio (mostly 0.1..10, so some are
    /// refused as absurd).
    saliency: f64,
    ts: f64,
    q: [f64; 4],
    r: [f64; 2],
    p0: [f64; 4],
    x0: [f64; 4],
    sigma_limit: f64,
    lag_free: bool,
    joseph: bool,
    seed_noise: bool,
    /// Parameter tracking: 0 off, 1 flux only (`Rs` fixed), 2 the default (flux and the split
    /// filter for `Rs`).
    tracking: u8,
}

fn params() -> impl Strategy<Value = Params> {
    (
        (param(1.0), param(2e-3), param(0.05), 0u32..64),
        param(1e-4),
        (
            [param(1e-6), param(1e-6), param(1.0), param(1e-8)],
            [param(1e-4), param(1e-4)],
        ),
        (
            [param(1e-2), param(1e-2), param(1e4), param(10.0)],
            [any_f64(1.0), any_f64(1.0), any_f64(1e3), any_f64(4.0)],
        ),
        (param(0.2), 0u8..3),
        (any::<bool>(), any::<bool>(), prop::bool::weighted(0.2)),
        prop_oneof![
            4 => Just(1.0),
            3 => (-1.0f64..1.0).prop_map(|e| 10f64.powf(e)),
            1 => param(1.5),
        ],
    )
        .prop_map(
            |(
                motor,
                ts,
                (q, r),
                (p0, x0),
                (sigma_limit, tracking),
                (lag_free, joseph, seed_noise),
                saliency,
            )| Params {
                tracking,
                motor,
                saliency,
                ts,
                q,
                r,
                p0,
                x0,
                sigma_limit,
                lag_free,
                joseph,
                seed_noise,
            },
        )
}

fn config<T: Float>(p: &Params) -> ObserverConfig<T> {
    let t = |v: f64| T::from_subset(&v);
    let motor = MotorParams {
        rs_ohm: t(p.motor.0),
        ld_h: t(p.motor.1),
        lq_h: t(p.motor.1 * p.saliency),
        psi_f_wb: t(p.motor.2),
        pole_pairs: p.motor.3,
    };
    let mut cfg = ObserverConfig::new(motor, t(p.ts));
    cfg.discretization = if p.lag_free {
        Discretization::LagFree
    } else {
        Discretization::ForwardEuler
    };
    cfg.covariance_update = if p.joseph {
        CovarianceUpdate::Joseph
    } else {
        CovarianceUpdate::StandardSymmetrized
    };
    cfg.noise = if p.seed_noise {
        NoiseCovariances::seed()
    } else {
        NoiseCovariances::from_diagonals(p.q.map(t), p.r.map(t))
    };
    cfg.p0 = Matrix4::from_diagonal(&Vector4::from(p.p0.map(t)));
    cfg.x0 = Vector4::from(p.x0.map(t));
    cfg.angle_sigma_limit_rad = t(p.sigma_limit);
    match p.tracking {
        0 => cfg.parameter_tracking = None,
        1 => {
            if let Some(tr) = &mut cfg.parameter_tracking {
                tr.rs = RsTracking::Fixed;
            }
        }
        _ => {}
    }
    cfg
}

fn is_nan<T: Float>(x: T) -> bool {
    x.partial_cmp(&x).is_none()
}

fn finite<T: Float>(v: &[T]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Applies `calls` and checks the properties of the module docs after each.
fn drive<T: Float>(obs: &mut PmsmObserver<T>, calls: &[Call]) -> Result<(), TestCaseError> {
    let t = |v: f64| T::from_subset(&v);
    let pi = T::pi();
    for c in calls {
        let (x0, p0) = (*obs.state(), obs.covariance());
        let (par0, fc0) = (obs.parameters(), obs.flux_covariance());
        let (ok, est) = match *c {
            Call::Step(u, i) => match obs.step(u.map(t), i.map(t)) {
                Ok(e) => (true, Some(e)),
                Err(_) => (false, None),
            },
            Call::Predict(u) => (obs.predict(u.map(t)).is_ok(), None),
            Call::Correct(i) => match obs.correct(i.map(t)) {
                Ok(e) => (true, Some(e)),
                Err(_) => (false, None),
            },
            Call::Reset(x, p) => {
                let p = Matrix4::identity() * t(p);
                (obs.reset(Vector4::from(x.map(t)), p).is_ok(), None)
            }
        };
        let (x, p) = (*obs.state(), obs.covariance());
        if ok { &CALLS_OK } else { &CALLS_REFUSED }.fetch_add(1, Relaxed);
        if !ok {
            // Refused: nothing changed, bit for bit (NaN-safe comparison).
            let same = |a: &[T], b: &[T]| {
                a.iter()
                    .zip(b)
                    .all(|(a, b)| a == b || (is_nan(*a) && is_nan(*b)))
            };
            prop_assert!(same(x.as_slice(), x0.as_slice()), "{c:?} changed x");
            prop_assert!(same(p.as_slice(), p0.as_slice()), "{c:?} changed P");
            let (par, fc) = (obs.parameters(), obs.flux_covariance());
            prop_assert!(
                same(&[par.0, par.1], &[par0.0, par0.1]),
                "{c:?} changed psi_f, Rs"
            );
            if let (Some((xa, ca)), Some((xb, cb))) = (fc, fc0) {
                prop_assert!(
                    same(xa.as_slice(), xb.as_slice()) && same(&[ca], &[cb]),
                    "{c:?} changed the flux covariance"
                );
            }
            continue;
        }
        let (psi, rs) = obs.parameters();
        prop_assert!(
            psi.is_finite() && rs.is_finite() && psi > T::zero() && rs > T::zero(),
            "{c:?}: tracked psi_f {psi:?}, Rs {rs:?}"
        );
        if let Some((xc, cc)) = obs.flux_covariance() {
            prop_assert!(
                finite(xc.as_slice()) && cc.is_finite() && cc > T::zero(),
                "{c:?}: flux covariance {xc:?} {cc:?}"
            );
        }
        prop_assert!(finite(x.as_slice()), "{c:?}: state {x:?}");
        prop_assert!(finite(p.as_slice()), "{c:?}: P {p:?}");
        prop_assert!(x[3] >= -pi && x[3] <= pi, "{c:?}: angle {}", x[3]);
        if let Some(e) = est {
            prop_assert!(
                finite(&[e.theta_rad, e.omega_e_rad_s, e.omega_mech_rad_s])
                    && finite(&[e.i_alpha_a, e.i_beta_a]),
                "{c:?}: estimate {e:?}"
            );
            prop_assert!(!is_nan(e.nis), "{c:?}: NIS {:?}", e.nis);
            prop_assert!(
                finite(&[e.psi_f_wb, e.psi_f_sigma_wb, e.rs_ohm, e.rs_sigma_ohm])
                    && e.winding_temperature_c.is_finite(),
                "{c:?}: tracked parameters {e:?}"
            );
        }
    }
    Ok(())
}

/// With the covariance health check on, the observer is never stuck: whatever absurd (but
/// finite) data it accepted before, a step on plain data (no voltage, no current) returns an
/// estimate at least every `MAX_REFUSALS` steps (a refused step is followed by a self-reset
/// at the latest on the `MAX_REFUSALS`-th). On a reference motor (`settles`), plain data is
/// moreover accepted for good within 20 steps.
fn recovers<T: Float>(obs: &mut PmsmObserver<T>, settles: bool) -> Result<(), TestCaseError> {
    let zero = [T::zero(), T::zero()];
    let (mut run, mut longest, mut accepted) = (0u32, 0u32, 0);
    for _ in 0..20 {
        if obs.step(zero, zero).is_ok() {
            run = 0;
            accepted += 1;
        } else {
            run += 1;
            longest = longest.max(run);
        }
    }
    prop_assert!(
        longest < MAX_REFUSALS,
        "stuck: {longest} refusals in a row; x = {:?}, counters {:?}",
        obs.state(),
        obs.counters()
    );
    if settles {
        prop_assert!(
            obs.step(zero, zero).is_ok(),
            "not settled: {accepted} of 20 plain steps accepted; x = {:?}, counters {:?}",
            obs.state(),
            obs.counters()
        );
    }
    Ok(())
}

/// The counters, for the harness's report.
fn stats() -> String {
    format!(
        "totals so far: configs {} accepted / {} refused, calls {} accepted / {} refused",
        CONFIGS_OK.load(Relaxed),
        CONFIGS_REFUSED.load(Relaxed),
        CALLS_OK.load(Relaxed),
        CALLS_REFUSED.load(Relaxed),
    )
}

fn fuzz_params<T: Float>(name: &str, cases: u32) {
    harness::fuzz(
        name,
        cases,
        (params(), prop::collection::vec(call(50.0, 5.0), 0..64)),
        |(p, calls)| {
            let cfg = config::<T>(&p);
            match PmsmObserver::new(&cfg) {
                // A refused configuration must have been refused by `validate` too.
                Err(_) => {
                    CONFIGS_REFUSED.fetch_add(1, Relaxed);
                    prop_assert!(cfg.validate().is_err());
                }
                Ok(mut obs) => {
                    CONFIGS_OK.fetch_add(1, Relaxed);
                    drive(&mut obs, &calls)?;
                    if cfg.covariance_health.is_some() {
                        recovers(&mut obs, false)?;
                    }
                }
            }
            Ok(())
        },
        stats,
    );
}

fn fuzz_inputs<T: Float>(name: &str, cases: u32) {
    let motors = [
        MotorParams::<T>::servo(),
        MotorParams::industrial_2k2(),
        MotorParams::small_fast(),
        MotorParams::industrial_ipm(),
        MotorParams::traction_ipm(),
    ];
    harness::fuzz(
        name,
        cases,
        (
            0usize..5,
            any::<bool>(),
            prop::collection::vec(call(100.0, 10.0), 1..256),
        ),
        |(m, seed, calls)| {
            let ts = T::from_subset(&1e-4);
            let cfg = if seed {
                ObserverConfig::seed(motors[m], ts)
            } else {
                ObserverConfig::new(motors[m], ts)
            };
            let mut obs = PmsmObserver::new(&cfg).expect("preset is valid");
            drive(&mut obs, &calls)?;
            if cfg.covariance_health.is_some() {
                recovers(&mut obs, true)?;
            }
            Ok(())
        },
        stats,
    );
}

#[test]
fn fuzz_inputs_f32() {
    fuzz_inputs::<f32>("inputs f32", 256);
}

#[test]
fn fuzz_inputs_f64() {
    fuzz_inputs::<f64>("inputs f64", 256);
}

#[test]
fn fuzz_parameters_f32() {
    fuzz_params::<f32>("parameters f32", 512);
}

#[test]
fn fuzz_parameters_f64() {
    fuzz_params::<f64>("parameters f64", 512);
}

/// The generic filter driven by the PMSM model, with fuzzed parameters and calls: a refused
/// call changes nothing, an accepted one leaves everything finite.
fn fuzz_generic<T: Float>(name: &str, cases: u32) {
    harness::fuzz(
        name,
        cases,
        (params(), prop::collection::vec(call(50.0, 5.0), 0..64)),
        |(p, calls)| {
            let cfg = config::<T>(&p);
            if cfg.validate().is_err() {
                CONFIGS_REFUSED.fetch_add(1, Relaxed);
                return Ok(());
            }
            CONFIGS_OK.fetch_add(1, Relaxed);
            let model = PmsmModel::new(&cfg);
            let mut ekf = Ekf::<T, 4, 2>::new(cfg.x0, cfg.p0, cfg.covariance_update);
            let t = |v: f64| T::from_subset(&v);
            for c in &calls {
                let (x0, p0) = (*ekf.state(), *ekf.covariance());
                let ok = match *c {
                    Call::Step(u, i) => {
                        ekf.predict(&model, &Vector2::from(u.map(t))).is_ok()
                            && ekf.correct(&model, &Vector2::from(i.map(t))).is_ok()
                    }
                    Call::Predict(u) => ekf.predict(&model, &Vector2::from(u.map(t))).is_ok(),
                    Call::Correct(i) => ekf.correct(&model, &Vector2::from(i.map(t))).is_ok(),
                    Call::Reset(x, p) => ekf
                        .reset(Vector4::from(x.map(t)), Matrix4::identity() * t(p))
                        .is_ok(),
                };
                if ok { &CALLS_OK } else { &CALLS_REFUSED }.fetch_add(1, Relaxed);
                let (x, p) = (ekf.state(), ekf.covariance());
                if ok {
                    prop_assert!(finite(x.as_slice()) && finite(p.as_slice()), "{c:?}");
                } else if !matches!(c, Call::Step(..)) {
                    // (A step is predict then correct; a refused correct keeps the prediction.)
                    prop_assert!(
                        x.iter().zip(x0.iter()).all(|(a, b)| a == b || is_nan(*b))
                            && p.iter().zip(p0.iter()).all(|(a, b)| a == b || is_nan(*b)),
                        "{c:?} changed the filter"
                    );
                }
            }
            Ok(())
        },
        stats,
    );
}

#[test]
fn fuzz_generic_f32() {
    fuzz_generic::<f32>("generic Ekf f32", 256);
}

#[test]
fn fuzz_generic_f64() {
    fuzz_generic::<f64>("generic Ekf f64", 256);
}

/// The flux-observer baseline: fuzzed parameters (motor, Ts, gains, timing, angle output) and
/// inputs; a refused configuration is refused by `validate` too, a refused step changes
/// nothing, an accepted one gives a finite estimate with the angle in `[-pi, pi]`.
fn fuzz_flux<T: Float>(name: &str, cases: u32) {
    use ekf_core::{FluxAngleOutput, FluxObserver, FluxObserverConfig, FluxTiming};
    harness::fuzz(
        name,
        cases,
        (
            params(),
            (param(1e3), param(1e3), any::<bool>(), any::<bool>()),
            prop::collection::vec(call(50.0, 5.0), 0..64),
        ),
        |(p, (gain, bw, centred, pll), calls)| {
            let t = |v: f64| T::from_subset(&v);
            let base = config::<T>(&p);
            let mut cfg = FluxObserverConfig::new(base.motor, base.ts_s);
            // Fuzz the gains too, except now and then (`seed_noise`): the derived defaults.
            if !p.seed_noise {
                cfg.observer_gain_rad_s = t(gain);
                cfg.pll_bandwidth_rad_s = t(bw);
            }
            if centred {
                cfg.timing = FluxTiming::Centred;
            }
            if pll {
                cfg.angle_output = FluxAngleOutput::Pll;
            }
            let Ok(mut obs) = FluxObserver::new(&cfg) else {
                CONFIGS_REFUSED.fetch_add(1, Relaxed);
                prop_assert!(cfg.validate().is_err());
                return Ok(());
            };
            CONFIGS_OK.fetch_add(1, Relaxed);
            let pi = T::pi();
            for c in &calls {
                let (u, i) = match *c {
                    Call::Step(u, i) => (u, i),
                    Call::Predict(u) => (u, [0.0; 2]),
                    Call::Correct(i) => ([0.0; 2], i),
                    Call::Reset(x, _) => ([x[0], x[1]], [x[2], x[3]]),
                };
                let before = obs.estimate();
                match obs.step(u.map(t), i.map(t)) {
                    Ok(e) => {
                        CALLS_OK.fetch_add(1, Relaxed);
                        prop_assert!(
                            finite(&[e.theta_rad, e.omega_e_rad_s, e.theta_pll_rad])
                                && finite(&e.eta_wb)
                                && e.theta_rad >= -pi
                                && e.theta_rad <= pi,
                            "{c:?}: {e:?}"
                        );
                    }
                    Err(_) => {
                        CALLS_REFUSED.fetch_add(1, Relaxed);
                        prop_assert_eq!(obs.estimate(), before, "{:?} changed the observer", c);
                    }
                }
            }
            Ok(())
        },
        stats,
    );
}

#[test]
fn fuzz_flux_f32() {
    fuzz_flux::<f32>("flux observer f32", 256);
}

#[test]
fn fuzz_flux_f64() {
    fuzz_flux::<f64>("flux observer f64", 256);
}
