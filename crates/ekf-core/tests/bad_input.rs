//! Every rejection: invalid configurations give a typed error; non-finite samples are refused
//! and leave the filter exactly as it was.
use ekf_core::nalgebra::{Matrix2, Matrix4, SMatrix, Vector2, Vector4};
use ekf_core::{
    ConfigError, CovarianceUpdate, Ekf, EkfError, Matrix, MeasurementModel, MotorParams,
    ObserverConfig, Param, PmsmObserver,
};

fn base() -> ObserverConfig<f64> {
    ObserverConfig::new(MotorParams::servo(), 1e-4)
}

/// Sets one scalar field of a configuration.
type Setter = fn(&mut ObserverConfig<f64>, f64);

fn refused(cfg: ObserverConfig<f64>, expected: ConfigError) {
    assert_eq!(PmsmObserver::new(&cfg).err(), Some(expected));
    // The message names the problem.
    assert!(!expected.to_string().is_empty());
}

#[test]
fn default_and_seed_configurations_are_valid() {
    assert!(PmsmObserver::new(&base()).is_ok());
    assert!(
        PmsmObserver::new(&ObserverConfig::seed(
            MotorParams::<f32>::small_fast(),
            1e-4
        ))
        .is_ok()
    );
}

#[test]
fn motor_parameters_and_ts() {
    let cases: [(Setter, Param); 4] = [
        (|c, v| c.motor.rs_ohm = v, Param::Rs),
        (|c, v| c.motor.lq_h = v, Param::Lq),
        (|c, v| c.motor.psi_f_wb = v, Param::PsiF),
        (|c, v| c.ts_s = v, Param::Ts),
    ];
    for (set, param) in cases {
        for v in [0.0, -1.0, -0.0] {
            let mut cfg = base();
            set(&mut cfg, v);
            refused(cfg, ConfigError::NotPositive(param));
        }
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut cfg = base();
            set(&mut cfg, v);
            refused(cfg, ConfigError::NonFinite(param));
        }
    }
    let mut cfg = base();
    cfg.motor.pole_pairs = 0;
    refused(cfg, ConfigError::ZeroPolePairs);
    let mut cfg = base();
    cfg.angle_sigma_limit_rad = 0.0;
    refused(cfg, ConfigError::NotPositive(Param::AngleSigmaLimit));
    assert_eq!(
        ConfigError::NotPositive(Param::Lq).to_string(),
        "lq_h must be positive"
    );
}

#[test]
fn covariance_matrices() {
    // Q not symmetric.
    let mut cfg = base();
    cfg.noise.q[(0, 2)] = 1.0;
    refused(cfg, ConfigError::NotSymmetric(Matrix::Q));
    // Q with a negative variance.
    let mut cfg = base();
    cfg.noise.q[(2, 2)] = -1.0;
    refused(cfg, ConfigError::NotPositiveSemiDefinite(Matrix::Q));
    // Symmetric, positive diagonal, but indefinite (correlation > 1).
    let mut cfg = base();
    cfg.noise.q[(0, 1)] = 1.0;
    cfg.noise.q[(1, 0)] = 1.0;
    refused(cfg, ConfigError::NotPositiveSemiDefinite(Matrix::Q));
    // R with a NaN, R indefinite.
    let mut cfg = base();
    cfg.noise.r[(1, 1)] = f64::NAN;
    refused(cfg, ConfigError::NonFiniteMatrix(Matrix::R));
    let mut cfg = base();
    cfg.noise.r = Matrix2::new(1.0, 2.0, 2.0, 1.0);
    refused(cfg, ConfigError::NotPositiveSemiDefinite(Matrix::R));
    let mut cfg = base();
    cfg.noise.r = Matrix2::new(1.0, 0.5, 0.4, 1.0);
    refused(cfg, ConfigError::NotSymmetric(Matrix::R));
    // P0 and x0.
    let mut cfg = base();
    cfg.p0[(3, 3)] = -1e-3;
    refused(cfg, ConfigError::NotPositiveSemiDefinite(Matrix::P0));
    let mut cfg = base();
    cfg.p0[(0, 0)] = f64::INFINITY;
    refused(cfg, ConfigError::NonFiniteMatrix(Matrix::P0));
    let mut cfg = base();
    cfg.x0[2] = f64::NAN;
    refused(cfg, ConfigError::NonFiniteInitialState);
    // Zero matrices are positive semi-definite: allowed (R = 0 is caught at run time if S is
    // singular).
    let mut cfg = base();
    cfg.noise.q = Matrix4::zeros();
    assert!(PmsmObserver::new(&cfg).is_ok());
}

/// Runs 200 good steps so the filter holds a non-trivial state.
fn spun_up() -> PmsmObserver<f64> {
    let mut obs = PmsmObserver::new(&base()).expect("valid");
    for k in 0..200 {
        let th = k as f64 * 0.05;
        obs.step([10.0 * th.cos(), 10.0 * th.sin()], [th.sin(), -th.cos()])
            .expect("finite");
    }
    obs
}

#[test]
fn non_finite_samples_are_refused_and_state_is_kept() {
    let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
    for v in bad {
        let mut obs = spun_up();
        let reference = obs.clone();
        assert_eq!(
            obs.step([v, 1.0], [0.1, 0.2]),
            Err(EkfError::NonFiniteInput)
        );
        assert_eq!(
            obs.step([1.0, v], [0.1, 0.2]),
            Err(EkfError::NonFiniteInput)
        );
        assert_eq!(
            obs.step([1.0, 1.0], [v, 0.2]),
            Err(EkfError::NonFiniteMeasurement)
        );
        assert_eq!(
            obs.step([1.0, 1.0], [0.1, v]),
            Err(EkfError::NonFiniteMeasurement)
        );
        assert_eq!(obs.predict([v, v]), Err(EkfError::NonFiniteInput));
        assert_eq!(
            obs.correct([v, 0.0]).err(),
            Some(EkfError::NonFiniteMeasurement)
        );
        assert_eq!(
            obs, reference,
            "state, covariance and diagnostics unchanged"
        );
        // The next good sample gives exactly what it would have given without the bad ones.
        let mut twin = reference.clone();
        assert_eq!(
            obs.step([1.0, 1.0], [0.1, 0.2]),
            twin.step([1.0, 1.0], [0.1, 0.2])
        );
    }
}

#[test]
fn absurd_finite_samples_never_leave_a_non_finite_state() {
    for (u, i) in [
        ([f64::MAX, f64::MAX], [0.0, 0.0]),
        ([0.0, 0.0], [f64::MAX, -f64::MAX]),
        ([1e300, -1e300], [1e300, 1e300]),
        ([f64::MIN_POSITIVE, 0.0], [5e-324, 0.0]),
    ] {
        let mut obs = spun_up();
        let before = obs.clone();
        match obs.step(u, i) {
            Ok(e) => assert!(e.theta_rad.is_finite() && e.omega_e_rad_s.is_finite()),
            Err(err) => {
                assert!(
                    matches!(
                        err,
                        EkfError::NonFiniteResult
                            | EkfError::ImplausibleInput
                            | EkfError::ImplausibleMeasurement
                    ),
                    "u {u:?} i {i:?}: {err:?}"
                );
                // Estimate, covariance and diagnostics unchanged; only the health check's
                // count of refusals in a row moved (it resets the filter at the third).
                assert_eq!(obs.state(), before.state());
                assert_eq!(obs.covariance(), before.covariance());
                assert_eq!(obs.last_correction(), before.last_correction());
                assert_eq!(obs.estimate(), before.estimate());
            }
        }
        assert!(obs.state().iter().all(|v| v.is_finite()));
        assert!(obs.covariance().iter().all(|v| v.is_finite()));
    }
}

#[test]
fn reset_refuses_non_finite() {
    let mut obs = spun_up();
    let before = obs.clone();
    assert!(
        obs.reset(Vector4::new(0.0, 0.0, f64::NAN, 0.0), Matrix4::identity())
            .is_err()
    );
    assert!(
        obs.reset(Vector4::zeros(), Matrix4::identity() * f64::INFINITY)
            .is_err()
    );
    assert_eq!(obs, before);
    obs.reset(Vector4::new(0.0, 0.0, 100.0, 7.0), Matrix4::identity())
        .expect("finite");
    assert!(
        (obs.state()[3] - (7.0 - 2.0 * core::f64::consts::PI)).abs() < 1e-12,
        "angle wrapped"
    );
}

/// A measurement with no noise on a state with no uncertainty: `S = 0` cannot be inverted.
struct Exact;
impl MeasurementModel<f64, 2, 2> for Exact {
    fn observe(&self, x: &Vector2<f64>) -> (Vector2<f64>, SMatrix<f64, 2, 2>) {
        (*x, SMatrix::identity())
    }
    fn measurement_noise(&self) -> &Matrix2<f64> {
        const R: Matrix2<f64> = Matrix2::new(0.0, 0.0, 0.0, 0.0);
        &R
    }
}

#[test]
fn singular_innovation_covariance_is_an_error() {
    for update in [
        CovarianceUpdate::Joseph,
        CovarianceUpdate::StandardSymmetrized,
    ] {
        let mut ekf = Ekf::<f64, 2, 2>::new(Vector2::new(1.0, 2.0), Matrix2::zeros(), update);
        let before = ekf.clone();
        assert_eq!(
            ekf.correct(&Exact, &Vector2::new(1.5, 2.5)),
            Err(EkfError::SingularInnovation)
        );
        assert_eq!(ekf, before);
    }
}

/// Finite but absurd motors are refused, naming the parameter and its accepted range.
#[test]
fn implausible_motors_are_refused_with_their_range() {
    use ekf_core::MotorParams;
    let servo = MotorParams::<f64>::servo();
    let cases = [
        (
            MotorParams {
                rs_ohm: 1e300,
                ..servo
            },
            Param::Rs,
            "rs_ohm",
            "(0, 1000] ohm",
        ),
        (
            MotorParams {
                ld_h: 1e-12,
                ..servo
            },
            Param::Ld,
            "ld_h",
            "[1e-8, 10] H",
        ),
        (
            MotorParams {
                lq_h: 50.0,
                ..servo
            },
            Param::Lq,
            "lq_h",
            "[1e-8, 10] H",
        ),
        (
            MotorParams {
                psi_f_wb: 1e5,
                ..servo
            },
            Param::PsiF,
            "psi_f_wb",
            "(0, 100] Wb",
        ),
        (
            MotorParams {
                pole_pairs: 1 << 31,
                ..servo
            },
            Param::PolePairs,
            "pole_pairs",
            "1..=1000",
        ),
    ];
    for (m, p, name, range) in cases {
        let e = m.validate().unwrap_err();
        assert_eq!(e, ConfigError::OutOfRange(p));
        let text = e.to_string();
        assert!(text.contains(name) && text.contains(range), "{text}");
    }
    // The reference motors are all inside.
    for m in ekf_core::catalog::ALL {
        assert!(m.params::<f32>().validate().is_ok(), "{}", m.name);
    }
}

/// A sample time outside [1e-7, 1] s and covariances with absurd entries are refused before
/// anything is derived from them (the scaled Q of ts = 1e-300 would overflow).
#[test]
fn absurd_sample_time_and_covariances_are_refused() {
    use ekf_core::{Matrix, MotorParams, ObserverConfig, PmsmObserver};
    let servo = MotorParams::<f64>::servo();
    for ts in [1e-300, 1e-9, 10.0] {
        let e = PmsmObserver::new(&ObserverConfig::new(servo, ts)).unwrap_err();
        assert_eq!(e, ConfigError::OutOfRange(Param::Ts), "{ts}");
        assert!(e.to_string().contains("[1e-7, 1] s"), "{e}");
    }
    let mut cfg = ObserverConfig::new(servo, 1e-4);
    cfg.noise.q = Matrix4::identity() * 1e300;
    assert_eq!(
        PmsmObserver::new(&cfg).unwrap_err(),
        ConfigError::TooLargeMatrix(Matrix::Q)
    );
    let mut cfg = ObserverConfig::new(servo, 1e-4);
    cfg.p0 = Matrix4::identity() * 1e19;
    assert_eq!(
        PmsmObserver::new(&cfg).unwrap_err(),
        ConfigError::TooLargeMatrix(Matrix::P0)
    );
    // The check a caller applies before a reset.
    assert!(ekf_core::observer::check_covariance(&(-Matrix4::<f64>::identity())).is_err());
    assert!(ekf_core::observer::check_covariance(&Matrix4::<f64>::identity()).is_ok());
}

/// A corrupted sample (module docs of `ekf_core::observer`, "Implausible input"): a voltage
/// beyond `MAX_INPUT_FLUX_RATIO` magnet fluxes per sample time, or a current beyond
/// `MAX_CURRENT_RATIO` characteristic currents, is refused with its own error and leaves the
/// observer exactly as it was; one just inside the bounds is filtered.
#[test]
fn implausible_samples_are_refused_and_plausible_large_ones_filtered() {
    let obs0 = spun_up();
    let m = MotorParams::<f64>::servo();
    let (u_max, i_max) = (
        ekf_core::observer::MAX_INPUT_FLUX_RATIO * m.psi_f_wb / 1e-4,
        ekf_core::observer::MAX_CURRENT_RATIO * m.characteristic_current_a(),
    );
    for (u, i, err) in [
        ([1.01 * u_max, 0.0], [0.1, 0.2], EkfError::ImplausibleInput),
        ([0.0, -1.01 * u_max], [0.1, 0.2], EkfError::ImplausibleInput),
        (
            [1.0, 1.0],
            [1.01 * i_max, 0.0],
            EkfError::ImplausibleMeasurement,
        ),
        ([1.0, 1.0], [0.0, 1.4e17], EkfError::ImplausibleMeasurement),
        ([6.7e5, 7.6], [0.1, 0.2], EkfError::ImplausibleInput),
    ] {
        let mut obs = obs0.clone();
        assert_eq!(obs.step(u, i).err(), Some(err), "u {u:?} i {i:?}");
        assert_eq!(obs, obs0, "unchanged");
        if err == EkfError::ImplausibleInput {
            assert_eq!(obs.predict(u), Err(err));
        } else {
            assert_eq!(obs.correct(i).err(), Some(err));
        }
        assert_eq!(obs, obs0, "unchanged");
    }
    let mut obs = obs0.clone();
    assert!(obs.step([0.99 * u_max, 0.0], [0.1, 0.2]).is_ok());
    let mut obs = obs0.clone();
    assert!(obs.step([1.0, 1.0], [0.0, 0.99 * i_max]).is_ok());
}
