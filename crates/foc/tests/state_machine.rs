//! Every state-machine transition, on the self-written plant of tests/common.
mod common;

use common::{Plant, Rig};
use foc::ekf_core::MotorParams;
use foc::{
    CommandError, Fault, Foc, FocConfig, Mode, ObserverLossPolicy, Reversal, State, TickInput,
};

/// States visited (deduplicated) while running `seconds`.
fn visit(rig: &mut Rig, seconds: f64) -> Vec<State> {
    let mut v: Vec<State> = vec![];
    rig.run(seconds, |_, o| {
        if v.last() != Some(&o.state) {
            v.push(o.state);
        }
    });
    v
}

fn rig() -> Rig {
    let (_cfg, mut rig) = Rig::servo_default();
    rig.noise_a = 0.04;
    rig.plant.x[3] = -2.0;
    rig
}

/// Starts `rig` at `speed` rad/s mech. and runs it into closed loop (within 1.5 s).
fn start_closed_loop(rig: &mut Rig, speed: f32) {
    rig.foc.set_speed_ref_mech_rad_s(speed).unwrap();
    rig.foc.start().unwrap();
    assert!(rig.run_until(State::ClosedLoop, 1.5).is_some());
}

/// [`rig`] started at `speed` rad/s mech., in closed loop.
fn closed_loop_at(speed: f32) -> Rig {
    let mut rig = rig();
    start_closed_loop(&mut rig, speed);
    rig
}

#[test]
fn idle_align_openloop_handover_closedloop_stop_idle() {
    let mut rig = rig();
    // Idle: PWM off until started.
    let out = rig.step();
    assert_eq!(
        (out.state, out.pwm_enabled, out.duties),
        (State::Idle, false, [0.5; 3])
    );
    rig.foc.set_speed_ref_mech_rad_s(80.0).unwrap();
    rig.foc.start().unwrap();
    let seen = visit(&mut rig, 1.2);
    assert_eq!(
        seen,
        [
            State::Align,
            State::OpenLoop,
            State::Handover,
            State::ClosedLoop
        ]
    );
    let out = rig.last.unwrap();
    assert!(
        (rig.plant.omega_mech() - 80.0).abs() < 3.0,
        "{}",
        rig.plant.omega_mech()
    );
    assert!(out.pwm_enabled && out.fault.is_none());
    // Controlled stop: closed loop down to the exit speed, I/f to zero, PWM off.
    rig.foc.stop();
    let seen = visit(&mut rig, 2.0);
    assert_eq!(seen, [State::ClosedLoop, State::OpenLoop, State::Idle]);
    assert!(
        rig.plant.omega_mech().abs() < 3.0,
        "{}",
        rig.plant.omega_mech()
    );
    assert!(!rig.last.unwrap().pwm_enabled);
}

#[test]
fn start_without_alignment_goes_straight_to_open_loop() {
    let (mut cfg, _) = Rig::servo_default();
    cfg.startup.align_time_s = 0.0;
    let mut rig = Rig::new(&cfg, Plant::servo(), 300.0);
    rig.foc.set_speed_ref_mech_rad_s(60.0).unwrap();
    rig.foc.start().unwrap();
    assert_eq!(rig.foc.state(), State::OpenLoop);
    let seen = visit(&mut rig, 1.2);
    assert_eq!(seen, [State::OpenLoop, State::Handover, State::ClosedLoop]);
}

#[test]
fn reversal_through_zero_speed() {
    // The classic reversal: I/f through zero, a second hand-over.
    let (mut cfg, _) = Rig::servo_default();
    cfg.startup.reversal = Reversal::OpenLoop;
    let mut rig = Rig::new(&cfg, Plant::servo(), 300.0);
    rig.noise_a = 0.04;
    rig.plant.x[3] = -2.0;
    start_closed_loop(&mut rig, 100.0);
    rig.run(0.2, |_, _| {});
    rig.foc.set_speed_ref_mech_rad_s(-100.0).unwrap();
    let seen = visit(&mut rig, 2.5);
    assert_eq!(
        seen,
        [
            State::ClosedLoop,
            State::OpenLoop,
            State::Handover,
            State::ClosedLoop
        ]
    );
    assert!(
        (rig.plant.omega_mech() + 100.0).abs() < 3.0,
        "{}",
        rig.plant.omega_mech()
    );
}

#[test]
fn reversal_in_closed_loop_through_zero_speed() {
    // foc's default: the reversal stays on the observer through zero.
    let mut rig = closed_loop_at(100.0);
    rig.run(0.2, |_, _| {});
    rig.foc.set_speed_ref_mech_rad_s(-100.0).unwrap();
    let mut worst = 0.0f64;
    let mut seen: Vec<State> = vec![];
    rig.run(1.0, |r, o| {
        if seen.last() != Some(&o.state) {
            seen.push(o.state);
        }
        let e = f64::from(o.telemetry.speed_ref_mech_rad_s) - r.plant.omega_mech();
        worst = worst.max(e.abs());
    });
    assert_eq!(seen, [State::ClosedLoop]);
    assert!(
        (rig.plant.omega_mech() + 100.0).abs() < 3.0,
        "{}",
        rig.plant.omega_mech()
    );
    // The step command is slewed at the full closed-loop rate (0.5 k_t I_lim / J); the speed
    // loop's own lag on that ramp is the largest error (measured 12.4 rad/s, no stumble at
    // zero).
    assert!(worst < 15.0, "worst |ref - speed| {worst} rad/s");
}

#[test]
fn low_speed_command_stays_in_open_loop_and_returns_up() {
    let mut rig = closed_loop_at(100.0);
    // Below the exit speed (1.5 % of the base speed, 0.015 * 940 / 4 = 3.5 rad/s mech):
    // back to I/f, held there.
    let c = *rig.foc.config();
    let exit_mech =
        c.startup.exit_speed_ratio * c.startup.handover_speed_rad_s / c.motor.pole_pairs as f32;
    assert!((exit_mech - 3.53).abs() < 0.05, "{exit_mech}");
    rig.foc.set_speed_ref_mech_rad_s(2.5).unwrap();
    let seen = visit(&mut rig, 1.0);
    assert_eq!(seen, [State::ClosedLoop, State::OpenLoop]);
    let mut mean = 0.0;
    rig.run(0.5, |r, _| mean += r.plant.omega_mech() / 10_000.0);
    assert!((mean - 2.5).abs() < 1.0, "I/f mean speed {mean}");
    // And up again.
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    let seen = visit(&mut rig, 1.0);
    assert_eq!(seen, [State::OpenLoop, State::Handover, State::ClosedLoop]);
}

/// A trip latches until cleared; cleared, the drive is idle and restarts from standstill
/// through the whole sequence. The restart's duration depends on where the rotor coasted
/// to, a function of the noise realization: over noise seeds 1-16 (`FOC_TEST_SEED`) the
/// rotor stopped 21 to 173 deg el. from the alignment angle, and the restart reached closed
/// loop after 0.72 to 1.26 s, the longer the larger that angle (from near 180 deg the rotor
/// still swings when the ramp begins, and the hand-over waits; the 1.2 s allowed before
/// held for the former generator's seed 7 only). It gets the start-up budget of
/// [`start_closed_loop`], 1.5 s.
#[test]
fn fault_clear_restart() {
    let mut rig = closed_loop_at(80.0);
    // Bus over-voltage for one sample.
    rig.u_dc = 400.0;
    let out = rig.step();
    assert_eq!(
        (out.state, out.fault),
        (State::Fault, Some(Fault::BusOverVoltage))
    );
    assert_eq!(
        rig.foc.start(),
        Err(CommandError::Faulted(Fault::BusOverVoltage))
    );
    rig.u_dc = 300.0;
    // Latched although the cause is gone.
    let out = rig.step();
    assert_eq!((out.state, out.pwm_enabled), (State::Fault, false));
    let info = rig.foc.clear_fault().unwrap();
    assert_eq!(
        (info.fault, info.state, info.value),
        (Fault::BusOverVoltage, State::ClosedLoop, 400.0)
    );
    assert_eq!(rig.foc.state(), State::Idle);
    // Let the rotor coast down, then restart from standstill.
    rig.run(3.0, |_, _| {});
    rig.plant.x[2] = 0.0;
    rig.foc.start().unwrap();
    let seen = visit(&mut rig, 1.5);
    assert_eq!(
        seen,
        [
            State::Align,
            State::OpenLoop,
            State::Handover,
            State::ClosedLoop
        ]
    );
}

#[test]
fn observer_loss_falls_back_and_reacquires() {
    let mut rig = closed_loop_at(100.0);
    rig.run(0.2, |_, _| {});
    // A burst of current-sensor noise 12x the observer's R: the NIS flags the loss.
    rig.noise_a = 0.5;
    let seen = visit(&mut rig, 0.05);
    assert_eq!(seen, [State::ClosedLoop, State::OpenLoop]);
    assert_eq!(rig.foc.health_report().lost, None, "loss is acted on once");
    rig.noise_a = 0.04;
    let seen = visit(&mut rig, 1.0);
    assert_eq!(seen, [State::OpenLoop, State::Handover, State::ClosedLoop]);
    assert!(rig.foc.fault().is_none());
    assert!((rig.plant.omega_mech() - 100.0).abs() < 3.0);
}

/// Safety of the closed-loop reversal: a loss while the reference passes through the exit
/// band (where the drive now stays on the observer) still falls back to I/f, and the drive
/// re-acquires in the new direction.
#[test]
fn observer_loss_near_zero_in_a_closed_loop_reversal_falls_back() {
    let mut rig = closed_loop_at(100.0);
    rig.run(0.2, |_, _| {});
    let cfg = *rig.foc.config();
    let exit_mech = cfg.startup.exit_speed_ratio * cfg.startup.handover_speed_rad_s
        / cfg.motor.pole_pairs as f32;
    rig.foc.set_speed_ref_mech_rad_s(-100.0).unwrap();
    // Into the band, still in closed loop.
    let mut k = 0;
    loop {
        let out = rig.step();
        assert_eq!(out.state, State::ClosedLoop);
        if out.telemetry.speed_ref_mech_rad_s.abs() < 0.5 * exit_mech {
            break;
        }
        k += 1;
        assert!(k < 20_000, "never reached the band");
    }
    rig.noise_a = 0.5;
    let seen = visit(&mut rig, 0.05);
    assert_eq!(seen, [State::ClosedLoop, State::OpenLoop]);
    rig.noise_a = 0.04;
    let seen = visit(&mut rig, 2.0);
    assert_eq!(seen, [State::OpenLoop, State::Handover, State::ClosedLoop]);
    assert!(rig.foc.fault().is_none());
    assert!(
        (rig.plant.omega_mech() + 100.0).abs() < 3.0,
        "{}",
        rig.plant.omega_mech()
    );
}

#[test]
fn observer_loss_trips_with_trip_policy() {
    let (mut cfg, _) = Rig::servo_default();
    cfg.health.policy = ObserverLossPolicy::Trip;
    let mut rig = Rig::new(&cfg, Plant::servo(), 300.0);
    rig.noise_a = 0.04;
    start_closed_loop(&mut rig, 100.0);
    rig.noise_a = 0.5;
    assert!(rig.run_until(State::Fault, 0.1).is_some());
    let info = rig.foc.fault_info().unwrap();
    assert_eq!(
        (info.fault, info.state),
        (Fault::ObserverLost, State::ClosedLoop)
    );
}

#[test]
fn persistent_loss_exhausts_reacquisitions() {
    let mut rig = closed_loop_at(100.0);
    rig.noise_a = 0.5;
    assert!(rig.run_until(State::Fault, 8.0).is_some());
    assert_eq!(rig.foc.fault(), Some(Fault::ObserverLost));
}

#[test]
fn commands_outside_their_states() {
    let cfg = FocConfig::new(MotorParams::servo(), 50e-6, 300.0);
    let mut foc = Foc::new(&cfg).unwrap();
    assert_eq!(
        foc.set_speed_ref_mech_rad_s(f32::NAN),
        Err(CommandError::NonFinite)
    );
    // Clamped to the maximum speed.
    foc.set_speed_ref_mech_rad_s(1e9).unwrap();
    assert_eq!(foc.speed_target_mech_rad_s(), cfg.max_speed_rad_s / 4.0);
    foc.set_mode(Mode::Sensored).unwrap();
    foc.set_mode(Mode::Sensorless).unwrap();
    assert_eq!(foc.clear_fault(), None);
    foc.start().unwrap();
    assert_eq!(foc.state(), State::Align);
    assert_eq!(foc.set_mode(Mode::Sensored), Err(CommandError::NotIdle));
    // start() while running is a no-op; stop() during alignment stops at once.
    foc.start().unwrap();
    foc.stop();
    assert_eq!(foc.state(), State::Idle);
    foc.start().unwrap();
    let out = foc.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
    assert!(out.pwm_enabled);
    foc.disable();
    let out = foc.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
    assert_eq!((out.state, out.pwm_enabled), (State::Idle, false));
}

#[test]
fn sensored_mode_idle_closedloop_stop() {
    let (cfg, _) = Rig::servo_default();
    let cfg = cfg.with_mode(Mode::Sensored);
    let mut rig = Rig::new(&cfg, Plant::servo(), 300.0);
    rig.noise_a = 0.04;
    rig.foc.set_speed_ref_mech_rad_s(100.0).unwrap();
    rig.foc.start().unwrap();
    assert_eq!(rig.foc.state(), State::ClosedLoop);
    let seen = visit(&mut rig, 0.3);
    assert_eq!(seen, [State::ClosedLoop]);
    assert!(
        (rig.plant.omega_mech() - 100.0).abs() < 2.0,
        "{}",
        rig.plant.omega_mech()
    );
    // Reversal with the true angle: straight through zero in closed loop.
    rig.foc.set_speed_ref_mech_rad_s(-100.0).unwrap();
    let seen = visit(&mut rig, 0.3);
    assert_eq!(seen, [State::ClosedLoop]);
    assert!(
        (rig.plant.omega_mech() + 100.0).abs() < 2.0,
        "{}",
        rig.plant.omega_mech()
    );
    // The observer ran alongside and agrees.
    let out = rig.last.unwrap();
    assert!(rig.angle_error_deg(&out).abs() < 2.0);
    rig.foc.stop();
    let seen = visit(&mut rig, 0.5);
    assert_eq!(seen, [State::ClosedLoop, State::Idle]);
}

#[test]
fn no_delay_configuration_runs_a_delay_free_plant() {
    let (cfg, _) = Rig::servo_default();
    let cfg = cfg.with_delay(foc::ComputationDelay::None);
    assert_eq!(cfg.angle_advance_periods, 0.5);
    let mut rig = Rig::new(&cfg, Plant::servo(), 300.0);
    assert!(!rig.delay);
    rig.noise_a = 0.04;
    start_closed_loop(&mut rig, 100.0);
    let mut worst: f64 = 0.0;
    rig.run(0.3, |r, o| worst = worst.max(r.angle_error_deg(o).abs()));
    assert!(worst < 2.0, "angle error {worst} deg");
}
