//! Measurement glitches at unit level (the test rig's own plant, servo motor, 20 kHz): single
//! missing (NaN) and wild (ten times the rated current) current samples are ridden through
//! with the estimate within 5 deg el. of the truth; persistent ones trip with their reason;
//! the software over-current trip is debounced but a persistent over-current trips.
mod common;

use common::Rig;
use foc::ekf_core::MotorParams;
use foc::{
    Abc, ConfigError, Fault, Field, Foc, FocConfig, PhaseCurrents, SampleCheckConfig, State,
    TickInput, TickOutput,
};

/// Rated current of the rig's servo (1.5 N m / k_t, k_t = 1.05 N m/A), A.
const RATED_A: f32 = 1.43;

/// The rig in closed loop at 100 rad/s mech. under 1 N m of load, settled.
fn running_rig() -> Rig {
    let (_cfg, mut rig) = Rig::servo_default();
    rig.noise_a = 0.02;
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    rig.foc.start().unwrap();
    assert!(rig.run_until(State::ClosedLoop, 2.0).is_some());
    rig.plant.load_nm = 1.0;
    rig.run(0.3, |_, _| {});
    rig
}

fn assert_driving(out: &TickOutput) {
    assert!(out.pwm_enabled, "{out:?}");
    assert_eq!(out.fault, None, "{out:?}");
    assert_eq!(out.state, State::ClosedLoop, "{out:?}");
    assert!(
        out.duties
            .iter()
            .all(|d| d.is_finite() && (0.0..=1.0).contains(d)),
        "{out:?}"
    );
    let t = &out.telemetry;
    assert!(t.u_ab.is_finite() && t.i_dq.is_finite() && t.theta_rad.is_finite());
}

/// The rig's next input with phase `phase` (0 a, 1 b, 2 c) replaced by `value`.
fn corrupted_input(rig: &mut Rig, phase: usize, value: f32) -> TickInput {
    let mut inp = rig.input();
    if let PhaseCurrents::Abc(x) = &mut inp.currents {
        match phase {
            0 => x.a = value,
            1 => x.b = value,
            _ => x.c = value,
        }
    }
    inp
}

/// Ticks with phase `phase` reading `value` (`corrupted_input`) for at most `ticks` ticks,
/// the drive running until then: the tick (from 1) of the first fault and the fault, with the
/// PWM off; `None` if nothing tripped.
fn first_trip(rig: &mut Rig, ticks: usize, phase: usize, value: f32) -> Option<(usize, Fault)> {
    for k in 1..=ticks {
        let inp = corrupted_input(rig, phase, value);
        let out = rig.step_with(&inp);
        if let Some(fault) = out.fault {
            assert!(!out.pwm_enabled && out.duties == [0.5; 3]);
            return Some((k, fault));
        }
        assert_driving(&out);
    }
    None
}

/// Injects a single bad sample every 20 ms (ten times, cycling through the phases given) and
/// returns the largest angle error seen from the first glitch on, deg el.
fn ride_through(value: f32, phases: &[usize]) -> f64 {
    let mut rig = running_rig();
    let mut worst: f64 = 0.0;
    for g in 0..10 {
        let before = rig.step();
        assert_driving(&before);
        let inp = corrupted_input(&mut rig, phases[g % phases.len()], value);
        let out = rig.step_with(&inp);
        assert_driving(&out);
        worst = worst.max(rig.angle_error_deg(&out).abs());
        if phases[g % phases.len()] < 2 {
            // a or b: the sample is not used; the loops hold the last voltage.
            assert!(!out.telemetry.sample_ok, "glitch {g}: {out:?}");
            assert_eq!(out.telemetry.u_dq, before.telemetry.u_dq);
        }
        let after = rig.run(0.02, |r, o| {
            assert_driving(o);
            worst = worst.max(r.angle_error_deg(o).abs());
        });
        assert!(after.telemetry.sample_ok);
    }
    worst
}

#[test]
fn single_missing_samples_are_ridden_through() {
    let worst = ride_through(f32::NAN, &[0, 1, 2]);
    println!("NaN samples: worst angle error {worst:.3} deg");
    assert!(worst < 5.0, "{worst} deg");
    let worst = ride_through(f32::INFINITY, &[1]);
    assert!(worst < 5.0, "{worst} deg");
}

#[test]
fn single_wild_samples_are_rejected_not_tripped() {
    // Ten times the rated current on one phase: above the over-current level (10.3 A here),
    // and a jump no inductive current can make in one period.
    let rig = running_rig();
    let oc = rig.foc.config().over_current_a;
    assert!(10.0 * RATED_A > oc);
    assert!(10.0 * RATED_A > 2.0 * rig.foc.config().max_current_step());
    for v in [10.0 * RATED_A, -10.0 * RATED_A] {
        let worst = ride_through(v, &[0, 1]);
        println!("{v} A samples: worst angle error {worst:.3} deg");
        assert!(worst < 5.0, "{v}: {worst} deg");
    }
    // On phase c (used for the over-current check only) a single sample above the level is
    // accepted but does not trip: the check is debounced.
    let worst = ride_through(10.0 * RATED_A, &[2]);
    assert!(worst < 5.0, "{worst} deg");
}

#[test]
fn persistent_missing_samples_trip_after_the_configured_count() {
    for n in [1u16, 3, 5] {
        let mut rig = running_rig();
        let mut cfg = *rig.foc.config();
        cfg.samples.missing_trip_ticks = n;
        // The same controller state with a different limit: rebuild and re-run.
        rig = {
            let mut r = Rig::new(&cfg, common::Plant::servo(), 300.0);
            r.noise_a = 0.02;
            r.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
            r.foc.start().unwrap();
            assert!(r.run_until(State::ClosedLoop, 2.0).is_some());
            r.plant.load_nm = 1.0;
            r.run(0.1, |_, _| {});
            r
        };
        for k in 1..=n {
            let inp = corrupted_input(&mut rig, 0, f32::NAN);
            let out = rig.step_with(&inp);
            if k < n {
                assert_driving(&out);
            } else {
                assert!(!out.pwm_enabled && out.duties == [0.5; 3], "{out:?}");
                assert_eq!(out.fault, Some(Fault::NonFiniteInput));
                assert!(rig.foc.fault_info().unwrap().value.is_nan());
            }
        }
    }
}

#[test]
fn a_good_sample_resets_the_count() {
    let mut rig = running_rig();
    let n = rig.foc.config().samples.missing_trip_ticks;
    assert_eq!(n, 5);
    // n - 1 bad, one good, n - 1 bad: never n in a row.
    for _ in 0..3 {
        for _ in 0..n - 1 {
            let inp = corrupted_input(&mut rig, 1, f32::NAN);
            assert_driving(&rig.step_with(&inp));
        }
        assert_driving(&rig.step());
    }
    let out = rig.step();
    let worst = rig.angle_error_deg(&out);
    assert!(worst.abs() < 5.0, "{worst}");
}

#[test]
fn a_persistent_wild_reading_trips_over_current() {
    // A jump to 14.3 A that stays: rejected sample by sample while the allowed step grows
    // with the samples missed (`(n + 1) max_step_a`); once the reading is within reach it is
    // accepted, and the debounced over-current check trips. Either way the trip comes within
    // `missing_trip_ticks + over_current_trip_ticks` ticks, never at the first.
    let mut rig = running_rig();
    let s = rig.foc.config().samples;
    let limit = s.missing_trip_ticks + s.over_current_trip_ticks;
    let (k, fault) = first_trip(&mut rig, usize::from(limit), 0, 10.0 * RATED_A).expect("no trip");
    assert_eq!(fault, Fault::OverCurrent);
    assert!(k >= 3, "tripped at tick {k}");
    println!("persistent 14.3 A reading: over-current trip at tick {k}");
}

#[test]
fn over_current_is_debounced_but_a_persistent_one_trips() {
    let cfg = FocConfig::new(MotorParams::servo(), 50e-6, 300.0);
    let oc = cfg.over_current_a;
    let step = cfg.max_current_step();
    assert!(step > 2.0 && step < 4.0, "{step}");
    let mut foc = Foc::new(&cfg).unwrap();
    foc.set_speed_ref_mech_rad_s(50.0).unwrap();
    foc.start().unwrap();
    let tick = |foc: &mut Foc, a: f32| foc.tick(&TickInput::abc(a, -0.5 * a, -0.5 * a, 300.0));
    // Rising at a physically possible rate (accepted samples) to above the trip level.
    let mut a = 0.0;
    while a < oc - 0.5 * step {
        a += 0.5 * step;
        assert_eq!(tick(&mut foc, a).fault, None);
    }
    // One sample above the level, then back below: no trip.
    assert_eq!(tick(&mut foc, oc + 0.2).fault, None);
    assert!(foc.tick_count() > 0);
    assert_eq!(tick(&mut foc, oc - 0.2).fault, None);
    // Two in a row: trip, with the value.
    assert_eq!(tick(&mut foc, oc + 0.2).fault, None);
    let out = tick(&mut foc, oc + 0.3);
    assert_eq!(out.fault, Some(Fault::OverCurrent));
    assert!(!out.pwm_enabled);
    assert!((foc.fault_info().unwrap().value - (oc + 0.3)).abs() < 1e-3);
}

#[test]
fn sample_check_settings_are_validated() {
    let base = FocConfig::new(MotorParams::servo(), 50e-6, 300.0);
    let mut c = base;
    c.samples.missing_trip_ticks = 0;
    assert_eq!(
        c.validate(),
        Err(ConfigError::NotPositive(Field::MissingTripTicks))
    );
    let mut c = base;
    c.samples.over_current_trip_ticks = 0;
    assert_eq!(
        c.validate(),
        Err(ConfigError::NotPositive(Field::OverCurrentTripTicks))
    );
    let mut c = base;
    c.samples.max_step_a = Some(f32::NAN);
    assert_eq!(
        c.validate(),
        Err(ConfigError::NonFinite(Field::MaxCurrentStep))
    );
    let mut c = base;
    c.samples.max_step_a = Some(-1.0);
    assert_eq!(
        c.validate(),
        Err(ConfigError::NotPositive(Field::MaxCurrentStep))
    );
    let mut c = base;
    c.samples = SampleCheckConfig::strict();
    assert_eq!(c.validate(), Ok(()));
    // The derived step limit: (u_dc_max + Rs I_oc) Ts / Ls + 0.1 I_oc.
    let want = (base.u_dc_max_v + base.motor.rs_ohm * base.over_current_a) * base.ts_s
        / base.motor.lq_h
        + 0.1 * base.over_current_a;
    assert!((base.max_current_step() - want).abs() < 1e-5);
}

#[test]
fn bad_samples_while_idle_do_not_disturb_a_later_start() {
    let cfg = FocConfig::new(MotorParams::servo(), 50e-6, 300.0);
    let mut foc = Foc::new(&cfg).unwrap();
    let nan = TickInput {
        currents: PhaseCurrents::Abc(Abc {
            a: f32::NAN,
            b: 0.0,
            c: 0.0,
        }),
        u_dc_v: 300.0,
        sensor: None,
    };
    let out = foc.tick(&nan);
    assert_eq!((out.state, out.fault), (State::Idle, None));
    assert!(!out.telemetry.sample_ok);
    foc.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
    foc.set_speed_ref_mech_rad_s(50.0).unwrap();
    foc.start().unwrap();
    let out = foc.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
    assert_eq!((out.state, out.pwm_enabled), (State::Align, true));
}

/// A frozen phase reading is diagnosed as such (`CurrentSensor`) within an eighth of a
/// period. Measured over noise seeds 1-16 (`FOC_TEST_SEED`): trips after 35-50 ticks (an
/// eighth period is 40); the real current peaks at 1.8-5.9 A with phase a frozen, below the
/// 10.3 A over-current level, but at 4.2-12.2 A with phase b frozen (above the level for
/// seeds 2 and 16): the misled loops can outrun an eighth-turn check, whose time grows as
/// the speed falls. Only phase a's peak is asserted; the over-current comparator of the
/// bridge remains the protection.
#[test]
fn a_stuck_channel_trips_within_an_eighth_turn() {
    for phase in [0usize, 1] {
        let mut rig = running_rig();
        let frozen = match rig.input().currents {
            PhaseCurrents::Abc(x) => [x.a, x.b][phase],
            _ => unreachable!(),
        };
        // An eighth of an electrical period at 400 rad/s el., 20 kHz: 39.3 ticks.
        let w = f64::from(rig.foc.observer().estimate().omega_e_rad_s).abs();
        let eighth = (std::f64::consts::FRAC_PI_4 / w / rig.ts).ceil() as usize;
        // The real current's peak while the channel is frozen (the bridge opens at the trip).
        let mut peak: f64 = 0.0;
        let mut tripped = None;
        for k in 1..=2 * eighth {
            let inp = corrupted_input(&mut rig, phase, frozen);
            peak = peak.max(rig.plant.x[0].hypot(rig.plant.x[1]));
            let out = rig.step_with(&inp);
            if let Some(fault) = out.fault {
                assert!(!out.pwm_enabled && out.duties == [0.5; 3]);
                tripped = Some((k, fault));
                break;
            }
            assert_driving(&out);
        }
        let (k, fault) = tripped.expect("stuck channel not detected");
        assert_eq!(
            fault,
            Fault::CurrentSensor,
            "phase {phase}, peak {peak:.2} A"
        );
        // The angle accrues at least at the speed at the onset; the frame's speed moves as
        // the frozen reading misleads the loops, so the trip comes within 3/4 to 3/2 of an
        // eighth period.
        assert!(
            4 * k >= 3 * eighth && 2 * k <= 3 * eighth,
            "{k} ticks, eighth {eighth}"
        );
        println!(
            "phase {phase} stuck: trip after {k} ticks (eighth period {eighth}), peak {peak:.2} A"
        );
        if phase == 0 {
            assert!(peak < rig.foc.config().over_current_a.into(), "{peak} A");
        }
    }
}

#[test]
fn repeated_readings_at_standstill_do_not_trip() {
    // Alignment: a constant current vector, noise-free readings repeat every tick; the
    // vector does not turn, so nothing trips.
    let (_cfg, mut rig) = Rig::servo_default();
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    rig.foc.start().unwrap();
    let inp = TickInput::abc(1.0, -0.5, -0.5, 300.0);
    for _ in 0..2000 {
        let out = rig.foc.tick(&inp);
        assert_eq!(out.fault, None);
        if out.state != State::Align {
            break;
        }
    }
}
