//! Unit tests of the identification: the numerical helpers, the settings, the faults.

use super::lsq::Lsq;
use super::*;
use crate::svpwm::SAFE_DUTIES;

#[test]
fn ln_matches_std() {
    for &x in &[
        1e-6f32, 0.01, 0.5, 0.9, 0.99, 0.999_9, 1.0, 1.000_1, 2.0, 10.0, 1e6,
    ] {
        let got = ln(x);
        let want = (x as f64).ln();
        assert!(
            ((got as f64) - want).abs() <= 2e-7 * want.abs().max(1e-3),
            "{x}: {got} vs {want}"
        );
    }
    assert!(ln(0.0).is_nan() && ln(-1.0).is_nan() && ln(f32::NAN).is_nan());
}

/// Givens least squares: recovers a model of nearly dependent columns (the inertia fit's
/// shape: 1, s, s^2 and a cubic) exactly from clean data, and the least-squares solution
/// (zero mean residual) from noisy data; a rank-deficient fit is `None`.
#[test]
fn givens_least_squares() {
    let beta = [0.3f32, -1.2, 0.7, 2.5];
    let row = |k: u32| {
        let s = k as f32 / 4000.0;
        [1.0, s, s * s, s * s * s]
    };
    let dot = |x: [f32; 4]| x.iter().zip(beta).map(|(a, b)| a * b).sum::<f32>();
    let mut fit = Lsq::<4>::new();
    for k in 0..4000 {
        fit.add(row(k), dot(row(k)));
    }
    let got = fit.solve().unwrap_or_else(|| panic!("singular"));
    for (g, b) in got.iter().zip(beta) {
        assert!((g - b).abs() < 2e-3 * b.abs(), "{got:?}");
    }
    // Alternating +-0.01 on y: the cubic coefficient moves by far less than the noise.
    let mut fit = Lsq::<4>::new();
    for k in 0..4000 {
        let n = if k % 2 == 0 { 0.01 } else { -0.01 };
        fit.add(row(k), dot(row(k)) + n);
    }
    let got = fit.solve().unwrap_or_else(|| panic!("singular"));
    assert!((got[3] - beta[3]).abs() < 0.01, "{got:?}");
    // Two equal columns: singular.
    let mut fit = Lsq::<2>::new();
    for k in 0..10 {
        fit.add([1.0, 1.0], k as f32);
    }
    assert_eq!(fit.solve(), None);
}

#[test]
fn bad_settings_are_typed_errors() {
    let ok = IdentifyConfig::new(1e-4, 300.0, 2.0).with_spin(200.0, 500.0);
    assert!(Identifier::new(&ok).is_ok());
    type Edit = fn(&mut IdentifyConfig);
    let cases: [(&str, Edit); 8] = [
        ("ts_s", |c| c.ts_s = f32::NAN),
        ("test_current_a", |c| c.test_current_a = -1.0),
        ("over_current_a", |c| c.over_current_a = 2.0),
        ("u_dc_max_v", |c| c.u_dc_max_v = 10.0),
        ("hf_frequency_hz", |c| c.hf_frequency_hz = 5000.0),
        ("spin_accel_rad_s2", |c| c.spin_accel_rad_s2 = 0.0),
        ("max_modulation", |c| c.max_modulation = 1.5),
        ("pole_pairs", |c| c.pole_pairs = 0),
    ];
    for (field, f) in cases {
        let mut c = ok;
        f(&mut c);
        match Identifier::new(&c) {
            Err(IdentifyError::Config(e)) => assert_eq!(e.field, field),
            other => panic!("{field}: {other:?}"),
        }
    }
    let mut c = IdentifyConfig::new(1e-4, 300.0, 2.0);
    c.measure_inertia = true;
    assert!(matches!(
        Identifier::new(&c),
        Err(IdentifyError::Config(IdentifyConfigError {
            field: "measure_inertia",
            ..
        }))
    ));
}

#[test]
fn non_finite_and_bus_faults_turn_the_pwm_off() {
    let cfg = IdentifyConfig::new(1e-4, 300.0, 2.0);
    let mut id = Identifier::new(&cfg).unwrap_or_else(|e| panic!("{e}"));
    let out = id.tick(&TickInput::abc(0.0, 0.0, 0.0, 100.0));
    assert!(!out.pwm_enabled);
    assert!(matches!(
        id.result(),
        Some(Err(IdentifyFailure {
            error: IdentifyError::BusUnderVoltage { .. },
            step: IdentifyStep::Offsets,
            ..
        }))
    ));
    let mut id = Identifier::new(&cfg).unwrap_or_else(|e| panic!("{e}"));
    let out = id.tick(&TickInput::abc(f32::NAN, 0.0, 0.0, 300.0));
    assert!(!out.pwm_enabled && out.duties == SAFE_DUTIES);
    assert!(matches!(
        id.result(),
        Some(Err(IdentifyFailure {
            error: IdentifyError::NonFiniteInput,
            ..
        }))
    ));
    // Finished: stays off.
    let out = id.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
    assert!(!out.pwm_enabled);
}

/// A motor that draws no current: the probe runs to the full voltage and reports it.
#[test]
fn no_current_is_no_motor() {
    let cfg = IdentifyConfig::new(1e-4, 300.0, 2.0);
    let mut id = Identifier::new(&cfg).unwrap_or_else(|e| panic!("{e}"));
    let mut on = false;
    for _ in 0..20_000 {
        let out = id.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
        on |= out.pwm_enabled;
        for d in out.duties {
            assert!((0.0..=1.0).contains(&d));
        }
        if id.is_done() {
            assert!(!out.pwm_enabled);
            break;
        }
    }
    assert!(on);
    assert!(
        matches!(
            id.result(),
            Some(Err(IdentifyFailure {
                error: IdentifyError::NoMotor,
                step: IdentifyStep::Probe,
                ..
            }))
        ),
        "{:?}",
        id.result()
    );
    assert!((id.ticks() as f32) * 1e-4 < id.max_duration_s());
}
