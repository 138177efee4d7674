//! The observer's hand-scheduled update equals the generic nalgebra filter driven by the same
//! model, for both discretizations and both covariance updates, in f64 and f32.
mod common;
use common::*;
use ekf_core::nalgebra::Vector2;
use ekf_core::{
    CovarianceUpdate, Discretization, Ekf, Float, MotorParams, ObserverConfig, ObserverCounters,
    PmsmModel, PmsmObserver,
};

fn trace() -> Trace {
    let motor = MotorParams::servo();
    // Accelerating rotor with a current step: exercises every entry of P.
    let speed = |t: f64| 200.0 + 8000.0 * t;
    let iq = |t: f64| if t < 0.1 { 1.0 } else { 4.0 };
    let sc = Scenario {
        motor,
        ts: 1e-4,
        n: 3000,
        speed: &speed,
        iq_ref: &iq,
        th0: 1.0,
        noise_a: 0.05,
        seed: 5,
    };
    simulate(&sc)
}

/// Largest difference over the run, relative to the largest magnitude, of state and covariance.
fn compare<T: Float + Into<f64>>(
    conv: impl Fn(f64) -> T,
    disc: Discretization,
    update: CovarianceUpdate,
) -> (f64, f64, f64) {
    let tr = trace();
    let mut cfg = ObserverConfig::new(MotorParams::<T>::servo(), conv(1e-4));
    cfg.discretization = disc;
    cfg.covariance_update = update;
    cfg.x0[2] = conv(150.0);
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let model = PmsmModel::new(&cfg);
    let mut ekf = Ekf::<T, 4, 2>::new(cfg.x0, cfg.p0, update);
    let (mut dx, mut mx, mut dp, mut mp) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut dn, mut mn) = (0.0f64, 0.0f64);
    let mut u_prev = [conv(0.0), conv(0.0)];
    for (u, i) in tr.u.iter().zip(&tr.i_meas) {
        let z = [conv(i[0]), conv(i[1])];
        let est = obs.step(u_prev, z).expect("finite");
        ekf.predict(&model, &Vector2::from(u_prev)).expect("finite");
        let c = ekf.correct(&model, &Vector2::from(z)).expect("finite");
        let (na, nb): (f64, f64) = (est.nis.into(), c.nis.into());
        dn = dn.max((na - nb).abs());
        mn = mn.max(nb.abs());
        for r in 0..4 {
            let a: f64 = obs.state()[r].into();
            let b: f64 = ekf.state()[r].into();
            let d = if r == 3 {
                ekf_core::wrap_angle(a - b)
            } else {
                a - b
            };
            dx = dx.max(d.abs());
            mx = mx.max(b.abs());
            for col in 0..4 {
                let a: f64 = obs.covariance()[(r, col)].into();
                let b: f64 = ekf.covariance()[(r, col)].into();
                dp = dp.max((a - b).abs());
                mp = mp.max(b.abs());
            }
        }
        u_prev = [conv(u[0]), conv(u[1])];
    }
    // The safeguards of the default configuration (branch check, innovation gate, covariance
    // health) have no counterpart in the generic filter: the comparison is valid only if none
    // of them acted on this trace.
    assert_eq!(
        *obs.counters(),
        ObserverCounters::default(),
        "a safeguard acted; the comparison would be meaningless"
    );
    (dx / mx, dp / mp, dn / mn)
}

#[test]
fn structured_equals_generic_f64() {
    for disc in [Discretization::LagFree, Discretization::ForwardEuler] {
        for update in [
            CovarianceUpdate::Joseph,
            CovarianceUpdate::StandardSymmetrized,
        ] {
            let (ex, ep, en) = compare::<f64>(|v| v, disc, update);
            println!("f64 {disc:?} {update:?}: state {ex:.2e}, covariance {ep:.2e}, nis {en:.2e}");
            assert!(
                ex < 1e-12 && ep < 1e-12 && en < 1e-9,
                "{disc:?} {update:?}: {ex:e} {ep:e} {en:e}"
            );
        }
    }
}

#[test]
fn structured_equals_generic_f32() {
    for disc in [Discretization::LagFree, Discretization::ForwardEuler] {
        for update in [
            CovarianceUpdate::Joseph,
            CovarianceUpdate::StandardSymmetrized,
        ] {
            let (ex, ep, en) = compare::<f32>(|v| v as f32, disc, update);
            println!("f32 {disc:?} {update:?}: state {ex:.2e}, covariance {ep:.2e}, nis {en:.2e}");
            assert!(
                ex < 1e-4 && ep < 1e-3 && en < 1e-2,
                "{disc:?} {update:?}: {ex:e} {ep:e} {en:e}"
            );
        }
    }
}

#[test]
fn separate_predict_and_correct_equal_step() {
    let tr = trace();
    let cfg = ObserverConfig::new(MotorParams::<f64>::servo(), 1e-4);
    let mut a = PmsmObserver::new(&cfg).expect("valid");
    let mut b = a.clone();
    let mut u_prev = [0.0, 0.0];
    for (u, i) in tr.u.iter().zip(&tr.i_meas).take(500) {
        let ea = a.step(u_prev, *i).expect("finite");
        b.predict(u_prev).expect("finite");
        let eb = b.correct(*i).expect("finite");
        assert_eq!(ea, eb);
        u_prev = *u;
    }
}
