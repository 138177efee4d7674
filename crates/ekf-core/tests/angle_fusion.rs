//! `PmsmObserver::correct_angle`: the scalar angle measurement (e.g. HFI's angle) against the
//! textbook Kalman update in the Joseph form, with the flux's augmented row when tracking is
//! active; refusals that leave the observer as it was; the wrap of the innovation.
mod common;
use common::*;

use ekf_core::nalgebra::{SMatrix, SVector, Vector4};
use ekf_core::{EkfError, MotorParams, ObserverConfig, PmsmObserver, wrap_angle};

/// An interior-motor observer after `n` steps on the salient test plant at `w` rad/s el. under
/// load (tracking as configured).
fn observer_after(cfg: &ObserverConfig<f64>, w: f64, n: usize) -> PmsmObserver<f64> {
    let (_, m, _, i_rated, noise) = interior_motors()[1];
    let sc = Scenario {
        motor: m,
        ts: cfg.ts_s,
        n,
        speed: &|_| w,
        iq_ref: &|_| 0.5 * i_rated,
        th0: 0.3,
        noise_a: noise,
        seed: 5,
    };
    let tr = simulate(&sc);
    let mut obs = PmsmObserver::new(cfg).expect("valid config");
    let mut u_prev = [0.0, 0.0];
    for (i, u) in tr.i_meas.iter().zip(&tr.u) {
        obs.step(u_prev, *i).expect("finite step");
        u_prev = *u;
    }
    obs
}

fn interior_cfg(tracking: bool) -> ObserverConfig<f64> {
    let (_, m, _, _, _) = interior_motors()[1];
    let mut cfg = ObserverConfig::new(m, 5e-5);
    if !tracking {
        cfg.parameter_tracking = None;
    }
    cfg
}

/// The Joseph-form update of the augmented state `[x, psi]` with `H = e_3`, variance `r`.
fn joseph(
    x: SVector<f64, 5>,
    p: SMatrix<f64, 5, 5>,
    z: f64,
    r: f64,
) -> (SVector<f64, 5>, SMatrix<f64, 5, 5>) {
    let mut h = SMatrix::<f64, 1, 5>::zeros();
    h[3] = 1.0;
    let s = (h * p * h.transpose())[0] + r;
    let k = p * h.transpose() / s;
    let y = wrap_angle(z - x[3]);
    let xn = x + k * y;
    let a = SMatrix::<f64, 5, 5>::identity() - k * h;
    let pn = a * p * a.transpose() + k * k.transpose() * r;
    (xn, pn)
}

fn augmented(obs: &PmsmObserver<f64>) -> (SVector<f64, 5>, SMatrix<f64, 5, 5>) {
    let x4 = obs.state();
    let p4 = obs.covariance();
    let (psi, _) = obs.parameters();
    let (xc, cpp) = obs.flux_covariance().unwrap_or((Vector4::zeros(), 0.0));
    let mut x = SVector::<f64, 5>::zeros();
    let mut p = SMatrix::<f64, 5, 5>::zeros();
    for i in 0..4 {
        x[i] = x4[i];
        p[(i, 4)] = xc[i];
        p[(4, i)] = xc[i];
        for j in 0..4 {
            p[(i, j)] = p4[(i, j)];
        }
    }
    x[4] = psi;
    p[(4, 4)] = cpp;
    (x, p)
}

fn check_against_joseph(mut obs: PmsmObserver<f64>, z: f64, r: f64) {
    let (x, p) = augmented(&obs);
    let (xe, pe) = joseph(x, p, z, r);
    obs.correct_angle(z, r).expect("accepted");
    let (xn, pn) = augmented(&obs);
    assert_eq!(obs.estimate().theta_rad, xn[3]);
    for i in 0..5 {
        let d = if i == 3 {
            wrap_angle(xn[i] - xe[i])
        } else {
            xn[i] - xe[i]
        };
        assert!(
            d.abs() <= 1e-9 * (1.0 + xe[i].abs()),
            "x[{i}]: {} vs {}",
            xn[i],
            xe[i]
        );
        for j in 0..5 {
            let scale = (pe[(i, i)] * pe[(j, j)]).sqrt().max(1e-30);
            assert!(
                (pn[(i, j)] - pe[(i, j)]).abs() <= 1e-9 * scale,
                "P[{i}][{j}]: {} vs {}",
                pn[(i, j)],
                pe[(i, j)]
            );
        }
    }
    // The angle variance falls, to `P33 r / (P33 + r)`.
    assert!(pn[(3, 3)] < p[(3, 3)]);
}

#[test]
fn equals_the_joseph_form_without_tracking() {
    let obs = observer_after(&interior_cfg(false), 300.0, 4000);
    assert!(obs.flux_covariance().is_none());
    // An angle 10 deg off the estimate, and one across the +-pi seam.
    let th = obs.state()[3];
    check_against_joseph(obs.clone(), th + 0.17, 0.03 * 0.03);
    check_against_joseph(obs.clone(), th - 0.5, 1.0);
    let mut o = obs;
    let mut x = *o.state();
    x[3] = 3.1;
    o.reset(x, o.covariance()).expect("finite");
    check_against_joseph(o, -3.1, 0.01);
}

#[test]
fn equals_the_joseph_form_with_the_flux_tracked() {
    // Fast enough for the tracking to be active: the flux's cross-covariance is not zero.
    let obs = observer_after(&interior_cfg(true), 1500.0, 20000);
    let (xc, _) = obs.flux_covariance().expect("tracking on");
    assert!(xc[3] != 0.0, "tracking frozen: {xc:?}");
    let th = obs.state()[3];
    check_against_joseph(obs, th + 0.1, 0.05 * 0.05);
}

#[test]
fn frozen_tracking_keeps_the_flux() {
    // At standstill the tracking is frozen: the flux and its variance do not move.
    let mut obs = observer_after(&interior_cfg(true), 0.0, 2000);
    let before = (obs.parameters(), obs.flux_covariance());
    assert_eq!(before.1.map(|(x, _)| x), Some(Vector4::zeros()));
    let th = obs.state()[3];
    obs.correct_angle(th + 0.3, 0.01).expect("accepted");
    assert_eq!((obs.parameters(), obs.flux_covariance()), before);
    assert!(wrap_angle(obs.state()[3] - th) > 0.0);
}

#[test]
fn a_tight_measurement_pulls_angle_and_speed() {
    // Repeated every period, HFI-like: the angle follows the measurement and the speed the
    // measurement's motion (through the angle-speed covariance of the prediction).
    let cfg = interior_cfg(false);
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let (w, ts) = (60.0, cfg.ts_s);
    let mut th = 1.0;
    for _ in 0..4000 {
        obs.predict([0.0, 0.0]).expect("finite");
        th = wrap_angle(th + w * ts);
        obs.correct_angle(th, 0.03 * 0.03).expect("accepted");
    }
    let e = obs.estimate();
    assert!(wrap_angle(e.theta_rad - th).abs() < 0.01, "{e:?}");
    assert!((e.omega_e_rad_s - w).abs() < 0.05 * w, "{e:?}");
}

#[test]
fn bad_input_is_refused_and_changes_nothing() {
    let obs = observer_after(&interior_cfg(true), 300.0, 2000);
    for (z, r) in [
        (f64::NAN, 0.01),
        (f64::INFINITY, 0.01),
        (0.1, f64::NAN),
        (0.1, f64::INFINITY),
        (0.1, 0.0),
        (0.1, -1.0),
    ] {
        let mut o = obs.clone();
        assert_eq!(
            o.correct_angle(z, r),
            Err(EkfError::NonFiniteMeasurement),
            "{z} {r}"
        );
        assert_eq!(o, obs);
    }
}

#[test]
fn works_in_f32() {
    let m = MotorParams::<f32>::traction_ipm();
    let mut obs = PmsmObserver::new(&ObserverConfig::new(m, 5e-5)).expect("valid");
    obs.step([0.0, 0.0], [0.0, 0.0]).expect("finite");
    let p33 = obs.covariance()[(3, 3)];
    obs.correct_angle(1.0, 1e-4).expect("accepted");
    let e = obs.estimate();
    assert!(obs.covariance()[(3, 3)] < p33);
    assert!(e.theta_rad.is_finite() && e.omega_e_rad_s.is_finite());
}
