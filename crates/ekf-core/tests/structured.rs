//! The observer's hand-scheduled update equals the generic nalgebra filter driven by the same
//! model, for both discretizations and both covariance updates, in f64 and f32.
mod common;
use common::*;
use ekf_core::nalgebra::{Matrix2, SMatrix, SVector, Vector2, Vector4};
use ekf_core::{
    CovarianceUpdate, Discretization, Ekf, Float, MeasurementModel, MotorParams, ObserverConfig,
    ObserverCounters, PmsmModel, PmsmObserver, ProcessModel, RsTracking,
};

fn trace() -> Trace {
    // Accelerating rotor with a current step: exercises every entry of P.
    servo_trace(MotorParams::servo(), &|t: f64| 200.0 + 8000.0 * t)
}

/// 3000 samples of `motor` at the electrical speed `speed(t)`, with a current step at 0.1 s.
fn servo_trace(motor: MotorParams<f64>, speed: &dyn Fn(f64) -> f64) -> Trace {
    let iq = |t: f64| if t < 0.1 { 1.0 } else { 4.0 };
    simulate(&Scenario {
        motor,
        ts: 1e-4,
        n: 3000,
        speed,
        iq_ref: &iq,
        th0: 1.0,
        noise_a: 0.05,
        seed: 5,
    })
}

/// Largest difference over the run, relative to the largest magnitude, of state and covariance.
/// `salient` runs the interior industrial motor (active-flux model) instead of the servo.
fn compare<T: Float + Into<f64>>(
    conv: impl Fn(f64) -> T,
    disc: Discretization,
    update: CovarianceUpdate,
    salient: bool,
) -> (f64, f64, f64) {
    let (tr, motor) = if salient {
        (
            servo_trace(MotorParams::industrial_ipm(), &|t: f64| 150.0 + 3000.0 * t),
            MotorParams::<T>::industrial_ipm(),
        )
    } else {
        (trace(), MotorParams::<T>::servo())
    };
    let mut cfg = ObserverConfig::new(motor, conv(1e-4));
    // The 4-state filter; the tracking's augmented filter is compared in
    // `tracking_equals_generic_5_state`.
    cfg.parameter_tracking = None;
    // The speed noise adaptation changes `Q` from step to step; the generic filter's `Q` is
    // fixed.
    cfg.speed_noise_adaptation = None;
    if salient {
        // The trace's sensor noise (0.05 A) is large against the default R of this motor
        // (scaled by its smaller `psi_f / Lq`): the gate rejects two 4-sigma samples. The
        // comparison is of the filter's arithmetic, so the gate is off here.
        cfg.innovation_gate = None;
        // Start on the truth with a tracked angle, so that the observer locks at once.
        cfg.x0[3] = conv(1.0);
        cfg.p0[(3, 3)] = conv(1e-4);
    }
    cfg.discretization = disc;
    cfg.covariance_update = update;
    cfg.x0[2] = conv(150.0);
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let model = PmsmModel::new(&cfg);
    let mut ekf = Ekf::<T, 4, 2>::new(cfg.x0, cfg.p0, update);
    let (mut dx, mut mx, mut dp, mut mp) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut dn, mut mn) = (0.0f64, 0.0f64);
    let mut u_prev = [conv(0.0), conv(0.0)];
    let mut samples = tr.u.iter().zip(&tr.i_meas);
    if salient {
        // The observer applies the d-axis transient correction once locked (after its first
        // correction here), the generic model always: compare from the second sample on.
        let (u, i) = samples.next().expect("samples");
        obs.step(u_prev, [conv(i[0]), conv(i[1])]).expect("finite");
        ekf = Ekf::<T, 4, 2>::new(*obs.state(), obs.covariance(), update);
        u_prev = [conv(u[0]), conv(u[1])];
    }
    for (u, i) in samples {
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
            for salient in [false, true] {
                let (ex, ep, en) = compare::<f64>(|v| v, disc, update, salient);
                println!(
                    "f64 {disc:?} {update:?} salient {salient}: state {ex:.2e}, \
                     covariance {ep:.2e}, nis {en:.2e}"
                );
                assert!(
                    ex < 1e-12 && ep < 1e-12 && en < 1e-9,
                    "{disc:?} {update:?} {salient}: {ex:e} {ep:e} {en:e}"
                );
            }
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
            for salient in [false, true] {
                let (ex, ep, en) = compare::<f32>(|v| v as f32, disc, update, salient);
                println!(
                    "f32 {disc:?} {update:?} salient {salient}: state {ex:.2e}, \
                     covariance {ep:.2e}, nis {en:.2e}"
                );
                assert!(
                    ex < 1e-4 && ep < 1e-3 && en < 1e-2,
                    "{disc:?} {update:?} {salient}: {ex:e} {ep:e} {en:e}"
                );
            }
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

/// The tracking's augmented model `[i_a, i_b, w, th, psi_f]` for the generic filter, built
/// from the public 4-state model at the flux of the state: prediction, the exact Jacobian
/// (the flux's column is the EMF term per weber), `Q` with the flux's random walk while
/// active.
struct Augmented {
    cfg: ObserverConfig<f64>,
    q: SMatrix<f64, 5, 5>,
    r: Matrix2<f64>,
    active: bool,
}

impl ProcessModel<f64, 5, 2> for Augmented {
    fn transition(
        &self,
        x: &SVector<f64, 5>,
        u: &SVector<f64, 2>,
    ) -> (SVector<f64, 5>, SMatrix<f64, 5, 5>) {
        let mut c = self.cfg;
        c.motor.psi_f_wb = x[4];
        let m = PmsmModel::new(&c);
        let x4 = Vector4::new(x[0], x[1], x[2], x[3]);
        let (xn4, phi4) = m.transition(&x4, u);
        let mut xn = SVector::<f64, 5>::zeros();
        let mut phi = SMatrix::<f64, 5, 5>::identity();
        for r in 0..4 {
            xn[r] = xn4[r];
            for col in 0..4 {
                phi[(r, col)] = phi4[(r, col)];
            }
        }
        xn[4] = x[4];
        if self.active {
            for r in 0..2 {
                let emf = xn4[r] - (m.decay() * x[r] + m.input_gain() * u[r]);
                phi[(r, 4)] = emf / x[4];
            }
        }
        (xn, phi)
    }

    fn process_noise(&self) -> &SMatrix<f64, 5, 5> {
        &self.q
    }

    fn normalize(&self, x: &mut SVector<f64, 5>) {
        x[3] = ekf_core::wrap_angle(x[3]);
    }
}

impl MeasurementModel<f64, 5, 2> for Augmented {
    fn observe(&self, x: &SVector<f64, 5>) -> (SVector<f64, 2>, SMatrix<f64, 2, 5>) {
        let mut h = SMatrix::<f64, 2, 5>::zeros();
        h[(0, 0)] = 1.0;
        h[(1, 1)] = 1.0;
        (Vector2::new(x[0], x[1]), h)
    }

    fn measurement_noise(&self) -> &Matrix2<f64> {
        &self.r
    }

    fn normalize(&self, x: &mut SVector<f64, 5>) {
        x[3] = ekf_core::wrap_angle(x[3]);
    }
}

/// With flux tracking on (Rs fixed), the observer's block-wise augmented update equals the
/// generic 5-state filter, told the same active/frozen schedule, on a trace where the motor's
/// flux is 10 % below the configured one.
#[test]
fn tracking_equals_generic_5_state() {
    let tr = trace_with_flux(0.9);
    let motor = MotorParams::<f64>::servo();
    let mut cfg = ObserverConfig::new(motor, 1e-4);
    let mut tracking = cfg.parameter_tracking.expect("on by default");
    tracking.rs = RsTracking::Fixed;
    cfg.parameter_tracking = Some(tracking);
    cfg.speed_noise_adaptation = None;
    cfg.x0[2] = 700.0;
    let mut obs = PmsmObserver::new(&cfg).expect("valid");
    let psi0 = motor.psi_f_wb;
    let var0 = (tracking.psi_f_sigma0 * psi0).powi(2);
    let q_psi = (tracking.psi_f_walk_per_sqrt_s * psi0).powi(2) * 1e-4;
    let mut x0 = SVector::<f64, 5>::zeros();
    let mut p0 = SMatrix::<f64, 5, 5>::zeros();
    for r in 0..4 {
        x0[r] = cfg.x0[r];
        for c in 0..4 {
            p0[(r, c)] = cfg.p0[(r, c)];
        }
    }
    x0[4] = psi0;
    p0[(4, 4)] = var0;
    let mut ekf = Ekf::<f64, 5, 2>::new(x0, p0, cfg.covariance_update);
    let (mut dx, mut dp, mut dpsi) = (0.0f64, 0.0f64, 0.0f64);
    let mut u_prev = [0.0, 0.0];
    let mut active_steps = 0;
    for (u, i) in tr.u.iter().zip(&tr.i_meas) {
        let est = obs.step(u_prev, *i).expect("finite");
        let active = est.parameters_tracking;
        active_steps += usize::from(active);
        let mut p = *ekf.covariance();
        let mut q = SMatrix::<f64, 5, 5>::zeros();
        for r in 0..4 {
            for c in 0..4 {
                q[(r, c)] = cfg.noise.q[(r, c)];
            }
        }
        if active {
            if p[(4, 4)] < var0 {
                q[(4, 4)] = q_psi;
            }
        } else {
            // Frozen: the flux is a constant for the step, its correlations dropped.
            for r in 0..4 {
                p[(r, 4)] = 0.0;
                p[(4, r)] = 0.0;
            }
        }
        let x = *ekf.state();
        ekf.reset(x, p).expect("finite");
        let model = Augmented {
            cfg,
            q,
            r: cfg.noise.r,
            active,
        };
        ekf.predict(&model, &Vector2::from(u_prev)).expect("finite");
        ekf.correct(&model, &Vector2::from(*i)).expect("finite");
        let xs = obs.state();
        for r in 0..4 {
            let d = xs[r] - ekf.state()[r];
            let d = if r == 3 { ekf_core::wrap_angle(d) } else { d };
            dx = dx.max(d.abs() / (1.0 + ekf.state()[r].abs()));
        }
        dpsi = dpsi.max((est.psi_f_wb - ekf.state()[4]).abs() / psi0);
        let pc = obs.covariance();
        for r in 0..4 {
            for c in 0..4 {
                dp = dp.max(
                    (pc[(r, c)] - ekf.covariance()[(r, c)]).abs()
                        / (1.0 + ekf.covariance()[(r, c)].abs()),
                );
            }
        }
        u_prev = *u;
    }
    println!(
        "tracking vs generic 5-state: state {dx:.2e}, covariance {dp:.2e}, psi {dpsi:.2e}, \
         {active_steps} active steps, final psi {:.4} (truth {:.4})",
        obs.parameters().0,
        0.9 * psi0
    );
    assert!(active_steps > 1000, "tracking never became active");
    assert!(
        dx < 1e-9 && dp < 1e-9 && dpsi < 1e-9,
        "{dx:e} {dp:e} {dpsi:e}"
    );
    assert!((obs.parameters().0 / (0.9 * psi0) - 1.0).abs() < 0.01);
}

/// A servo whose flux is `psi_scale` times the nominal one, at a steady 800 rad/s el. (the
/// tracking is frozen during fast accelerations) with a current step.
fn trace_with_flux(psi_scale: f64) -> Trace {
    let base = MotorParams::servo();
    let motor = MotorParams {
        psi_f_wb: base.psi_f_wb * psi_scale,
        ..base
    };
    servo_trace(motor, &|_t: f64| 800.0)
}
