//! Every fault path, and NaN / infinite / absurd values in every input field: the outputs go
//! safe (PWM off, duties 0.5), the fault is latched with its reason, nothing panics.
//!
//! These tests run the strict sample checks (`SampleCheckConfig::strict`: every bad or
//! over-current sample trips at once); the default ride-through of single bad samples is
//! tested in `glitches.rs`.
mod common;

use common::{Plant, Rig};
use foc::ekf_core::MotorParams;
use foc::{
    Fault, Foc, FocConfig, Mode, PhaseCurrents, SampleCheckConfig, State, TickInput, TickOutput,
};

fn cfg() -> FocConfig {
    let mut c = FocConfig::new(MotorParams::servo(), 50e-6, 300.0);
    c.samples = SampleCheckConfig::strict();
    c
}

fn assert_safe(out: &TickOutput) {
    assert!(!out.pwm_enabled, "{out:?}");
    assert_eq!(out.duties, [0.5; 3]);
    assert_eq!(out.state, State::Fault);
    assert!(out.fault.is_some());
}

fn ok_input() -> TickInput {
    TickInput::abc(0.1, -0.05, -0.05, 300.0)
}

/// A controller driven into `state` (Idle, Align, OpenLoop, or sensored ClosedLoop).
fn in_state(state: State) -> Foc {
    let mut c = cfg();
    match state {
        State::OpenLoop => c.startup.align_time_s = 0.0,
        State::ClosedLoop => c.mode = Mode::Sensored,
        _ => {}
    }
    let mut foc = Foc::new(&c).unwrap();
    foc.set_speed_ref_mech_rad_s(50.0).unwrap();
    if state != State::Idle {
        foc.start().unwrap();
        let out = foc.tick(&ok_input().with_sensor(0.0, 0.0));
        assert_eq!(out.state, state);
        assert!(out.pwm_enabled);
    }
    foc
}

/// Bad values for one field of the input.
fn corrupted(field: usize, v: f32) -> TickInput {
    let base = ok_input().with_sensor(0.3, 10.0);
    let mut t = base;
    match field {
        0..=2 => {
            let mut abc = [0.1_f32, -0.05, -0.05];
            abc[field] = v;
            t.currents = PhaseCurrents::Abc(foc::Abc {
                a: abc[0],
                b: abc[1],
                c: abc[2],
            });
        }
        3 => {
            t.currents = PhaseCurrents::AlphaBeta(foc::AlphaBeta {
                alpha: v,
                beta: 0.0,
            })
        }
        4 => {
            t.currents = PhaseCurrents::AlphaBeta(foc::AlphaBeta {
                alpha: 0.0,
                beta: v,
            })
        }
        5 => t.u_dc_v = v,
        6 => {
            t.sensor = Some(foc::RotorSensor {
                theta_e_rad: v,
                omega_e_rad_s: 0.0,
            })
        }
        _ => {
            t.sensor = Some(foc::RotorSensor {
                theta_e_rad: 0.0,
                omega_e_rad_s: v,
            })
        }
    }
    t
}

#[test]
fn non_finite_in_every_field_and_every_state() {
    for state in [
        State::Idle,
        State::Align,
        State::OpenLoop,
        State::ClosedLoop,
    ] {
        for field in 0..8 {
            for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
                let mut foc = in_state(state);
                let out = foc.tick(&corrupted(field, v));
                assert_safe(&out);
                assert_eq!(
                    out.fault,
                    Some(Fault::NonFiniteInput),
                    "{state:?} field {field} {v}"
                );
                let info = foc.fault_info().unwrap();
                assert_eq!(info.state, state);
                assert!(info.value.is_nan() || info.value.is_infinite());
                // Stays latched with good inputs; start refused until cleared.
                let out = foc.tick(&ok_input());
                assert_safe(&out);
                assert!(foc.start().is_err());
                assert!(foc.clear_fault().is_some());
                assert_eq!(foc.state(), State::Idle);
                assert!(foc.start().is_ok());
            }
        }
    }
}

#[test]
fn absurd_values_in_every_field_and_every_state() {
    // (field, value, expected fault); None: acceptable in that state.
    let cases: [(usize, f32, Option<Fault>); 12] = [
        (0, 1e30, Some(Fault::OverCurrent)),
        (1, -1e30, Some(Fault::OverCurrent)),
        (2, 3e38, Some(Fault::OverCurrent)),
        (3, f32::MAX, Some(Fault::OverCurrent)),
        (4, -f32::MAX, Some(Fault::OverCurrent)),
        (5, 1e30, Some(Fault::BusOverVoltage)),
        (5, f32::MAX, Some(Fault::BusOverVoltage)),
        (5, -1e30, Some(Fault::BusUnderVoltage)),
        (5, 0.0, Some(Fault::BusUnderVoltage)),
        (6, 1e6, Some(Fault::NonFiniteInput)),
        (7, -1e9, Some(Fault::NonFiniteInput)),
        (7, f32::MIN_POSITIVE, None),
    ];
    for state in [
        State::Idle,
        State::Align,
        State::OpenLoop,
        State::ClosedLoop,
    ] {
        for (field, v, want) in cases {
            let mut foc = in_state(state);
            let out = foc.tick(&corrupted(field, v));
            assert!(
                out.duties
                    .iter()
                    .all(|d| d.is_finite() && (0.0..=1.0).contains(d))
            );
            // Under-voltage only counts while the bridge is driven.
            let want = if state == State::Idle && want == Some(Fault::BusUnderVoltage) {
                None
            } else {
                want
            };
            match want {
                Some(f) => {
                    assert_safe(&out);
                    assert_eq!(out.fault, Some(f), "{state:?} field {field} = {v}");
                }
                None => assert!(
                    out.fault.is_none(),
                    "{state:?} field {field} = {v}: {out:?}"
                ),
            }
        }
    }
}

#[test]
fn over_current_from_any_phase() {
    let mut foc = in_state(State::OpenLoop);
    let out = foc.tick(&TickInput::abc(1.0, 1.0, -11.0, 300.0));
    assert_safe(&out);
    assert_eq!(out.fault, Some(Fault::OverCurrent));
    assert_eq!(foc.fault_info().unwrap().value, 11.0);
    // The vector magnitude: alpha-beta input of 10.4 A against the 10.3 A trip level.
    let mut foc = in_state(State::Align);
    assert_eq!(
        foc.config().over_current_a,
        2.0 * foc.config().current_limit_a
    );
    let out = foc.tick(&TickInput::alpha_beta(8.0, -6.7, 300.0));
    assert_eq!(out.fault, Some(Fault::OverCurrent));
    // Just below: no trip.
    let mut foc = in_state(State::Align);
    let out = foc.tick(&TickInput::alpha_beta(7.0, -6.7, 300.0));
    assert_eq!(out.fault, None);
}

#[test]
fn bus_voltage_limits() {
    let c = cfg();
    let mut foc = in_state(State::Idle);
    // Under-voltage is allowed while idle (bus not yet charged) ...
    let out = foc.tick(&TickInput::abc(0.0, 0.0, 0.0, 10.0));
    assert_eq!((out.state, out.fault), (State::Idle, None));
    // ... and trips at the first tick of a start.
    foc.start().unwrap();
    let out = foc.tick(&TickInput::abc(0.0, 0.0, 0.0, c.u_dc_min_v - 1.0));
    assert_safe(&out);
    assert_eq!(out.fault, Some(Fault::BusUnderVoltage));
    assert_eq!(foc.fault_info().unwrap().value, c.u_dc_min_v - 1.0);
    // Over-voltage in any state.
    let mut foc = in_state(State::Idle);
    let out = foc.tick(&TickInput::abc(0.0, 0.0, 0.0, c.u_dc_max_v + 1.0));
    assert_safe(&out);
    assert_eq!(out.fault, Some(Fault::BusOverVoltage));
}

#[test]
fn first_fault_stays_latched() {
    let mut foc = in_state(State::Align);
    foc.tick(&TickInput::abc(50.0, 0.0, -50.0, 300.0));
    foc.tick(&TickInput::abc(f32::NAN, 0.0, 0.0, 1e9));
    assert_eq!(foc.fault(), Some(Fault::OverCurrent));
    let info = foc.clear_fault().unwrap();
    assert_eq!(info.fault, Fault::OverCurrent);
    assert_eq!(foc.fault(), None);
}

#[test]
fn sensored_mode_without_sensor_trips() {
    let mut foc = in_state(State::ClosedLoop);
    let out = foc.tick(&ok_input());
    assert_safe(&out);
    assert_eq!(out.fault, Some(Fault::NonFiniteInput));
}

#[test]
fn stall_with_locked_rotor_under_if() {
    let (_cfg, mut rig) = Rig::servo_default();
    rig.plant.locked = true;
    rig.noise_a = 0.04;
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    rig.foc.start().unwrap();
    // Ramp 0.7 s, then the acquisition timeout of 1 s at the hand-over speed.
    let t = rig.run_until(State::Fault, 3.0).expect("no trip");
    assert!((1.6..1.8).contains(&t), "tripped at {t}");
    let info = rig.foc.fault_info().unwrap();
    assert_eq!((info.fault, info.state), (Fault::Stall, State::OpenLoop));
}

#[test]
fn stall_with_rotor_jammed_in_closed_loop() {
    let (_cfg, mut rig) = Rig::servo_default();
    rig.noise_a = 0.04;
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    rig.foc.start().unwrap();
    assert!(rig.run_until(State::ClosedLoop, 1.5).is_some());
    rig.run(0.2, |_, _| {});
    rig.plant.locked = true;
    rig.plant.x[2] = 0.0;
    let t = rig.run_until(State::Fault, 2.0).expect("no trip");
    // Stall time 0.5 s after the speed loop saturates.
    assert!((0.45..0.7).contains(&t), "tripped after {t}");
    let info = rig.foc.fault_info().unwrap();
    assert_eq!((info.fault, info.state), (Fault::Stall, State::ClosedLoop));
    assert!(info.value.abs() < 0.5 * rig.foc.config().startup.handover_speed_rad_s);
}

#[test]
fn stall_in_sensored_mode() {
    let (cfg, _) = Rig::servo_default();
    let mut plant = Plant::servo();
    plant.locked = true;
    let mut rig = Rig::new(&cfg.with_mode(Mode::Sensored), plant, 300.0);
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    rig.foc.start().unwrap();
    assert!(rig.run_until(State::Fault, 1.0).is_some());
    assert_eq!(rig.foc.fault(), Some(Fault::Stall));
}
