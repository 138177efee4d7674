//! The d-axis excitation (`FocConfig::d_excitation`, feature `d-excitation`): off by default,
//! refused settings, and in sensored closed loop the d reference steps by `+-a` with the sign
//! `DExcitation::sign(tick_count)`.
#![cfg(feature = "d-excitation")]

use foc::config::DExcitation;
use foc::ekf_core::MotorParams;
use foc::{ConfigError, Field, Foc, FocConfig, Mode, TickInput};

const TS: f32 = 1e-4;
const U_DC: f32 = 300.0;

fn cfg() -> FocConfig {
    FocConfig::new(MotorParams::servo(), TS, U_DC).with_inertia(8e-4)
}

#[test]
fn off_by_default_and_checked() {
    let c = cfg();
    assert_eq!(c.d_excitation, None);
    for (amplitude_a, half_period_ticks, min_speed_rad_s, err) in [
        (0.0, 10, 0.0, ConfigError::NotPositive(Field::DExcitation)),
        (
            f32::NAN,
            10,
            0.0,
            ConfigError::NonFinite(Field::DExcitation),
        ),
        (1e3, 10, 0.0, ConfigError::OutOfRange(Field::DExcitation)),
        (0.1, 1, 0.0, ConfigError::OutOfRange(Field::DExcitation)),
        (0.1, 10, -1.0, ConfigError::OutOfRange(Field::DExcitation)),
        (
            0.1,
            10,
            f32::NAN,
            ConfigError::OutOfRange(Field::DExcitation),
        ),
    ] {
        let mut bad = c;
        bad.d_excitation = Some(DExcitation {
            amplitude_a,
            half_period_ticks,
            min_speed_rad_s,
        });
        assert_eq!(bad.validate(), Err(err));
    }
}

#[test]
fn square_wave_on_the_d_reference() {
    let a = 0.2;
    let n = 7;
    let x = DExcitation {
        amplitude_a: a,
        half_period_ticks: n,
        min_speed_rad_s: 10.0,
    };
    let mut with = cfg().with_mode(Mode::Sensored);
    with.d_excitation = Some(x);
    let mut plain = Foc::new(&cfg().with_mode(Mode::Sensored)).unwrap();
    let mut foc = Foc::new(&with).unwrap();
    for f in [&mut foc, &mut plain] {
        f.set_speed_ref_mech_rad_s(50.0).unwrap();
        f.start().unwrap();
    }
    let mut seen = [false; 2];
    let mut skipped = 0;
    for k in 0..200 {
        let input = TickInput::abc(1.0, -0.3, -0.7, U_DC).with_sensor(0.01 * k as f32, 20.0);
        let o = foc.tick(&input);
        let p = plain.tick(&input);
        let d = o.telemetry.i_dq_ref.d - p.telemetry.i_dq_ref.d;
        // (Before the closed loop's frame: no excitation.)
        if d == 0.0 {
            skipped += 1;
            continue;
        }
        let expected = if x.sign(foc.tick_count()) { a } else { -a };
        assert!((d - expected).abs() < 1e-6, "tick {k}: {d} vs {expected}");
        assert_eq!(
            x.sign(foc.tick_count()),
            foc::ekf_core::excitation_sign(foc.tick_count(), n)
        );
        seen[usize::from(d > 0.0)] = true;
        assert_eq!(o.telemetry.i_dq_ref.q, p.telemetry.i_dq_ref.q);
    }
    assert_eq!(seen, [true, true]);
    assert!(skipped < 10, "{skipped} ticks without the excitation");
    // Below the minimum speed: off.
    let mut slow = cfg().with_mode(Mode::Sensored);
    slow.d_excitation = Some(DExcitation {
        min_speed_rad_s: 30.0,
        ..x
    });
    let mut foc = Foc::new(&slow).unwrap();
    let mut plain = Foc::new(&cfg().with_mode(Mode::Sensored)).unwrap();
    for f in [&mut foc, &mut plain] {
        f.set_speed_ref_mech_rad_s(50.0).unwrap();
        f.start().unwrap();
    }
    for k in 0..100 {
        let input = TickInput::abc(1.0, -0.3, -0.7, U_DC).with_sensor(0.01 * k as f32, 20.0);
        let (o, p) = (foc.tick(&input), plain.tick(&input));
        assert_eq!(o.telemetry.i_dq_ref, p.telemetry.i_dq_ref);
    }
}
