//! Property tests: whatever the inputs and commands, the duties are finite and in [0, 1], a
//! disabled or faulted output is the safe state, and nothing panics (with and without
//! dead-time compensation); arbitrary parameters are refused or run safely. Surface and
//! salient motors alike (`industrial_ipm` with MTPA and field weakening, `traction_ipm`).
//! `FUZZ_SECONDS=N` runs each target for `N` seconds instead of a fixed number of cases
//! (`ekf-core/tests/support/fuzz_harness.rs`).

use foc::ekf_core::MotorParams;
use foc::{Foc, FocConfig, Mode, PhaseCurrents, TickInput, TickOutput};
use proptest::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

#[path = "../../ekf-core/tests/support/fuzz_harness.rs"]
mod harness;

/// Ticks with the PWM on, over all cases (printed by `coverage`).
static RUNNING: AtomicUsize = AtomicUsize::new(0);
static TICKS: AtomicUsize = AtomicUsize::new(0);

fn check(out: &TickOutput) {
    for d in out.duties {
        assert!(d.is_finite() && (0.0..=1.0).contains(&d), "{out:?}");
    }
    if !out.pwm_enabled {
        assert_eq!(out.duties, [0.5; 3]);
    }
    if out.fault.is_some() {
        assert!(!out.pwm_enabled);
    }
    let t = &out.telemetry;
    assert!(
        t.u_ab.is_finite() && t.theta_rad.is_finite() && t.i_dq.is_finite() || !out.pwm_enabled
    );
}

/// Any f32 bit pattern, or (half the time) a plausible value so that the controller gets
/// past its input checks and into the running states.
fn value(plausible: f32) -> impl Strategy<Value = f32> {
    prop_oneof![
        any::<u32>().prop_map(f32::from_bits),
        (-1.0f32..1.0).prop_map(move |x| x * plausible),
    ]
}

/// Plausible values in every field (the controller runs).
fn plausible() -> impl Strategy<Value = (bool, f32, f32, f32, f32, Option<(f32, f32)>)> {
    (
        any::<bool>(),
        -5.0f32..5.0,
        -5.0f32..5.0,
        -5.0f32..5.0,
        250.0f32..350.0,
        (-4.0f32..4.0, -500.0f32..500.0).prop_map(Some),
    )
}

/// Arbitrary bit patterns or plausible values, field by field.
fn mixed() -> impl Strategy<Value = (bool, f32, f32, f32, f32, Option<(f32, f32)>)> {
    (
        any::<bool>(),
        value(5.0),
        value(5.0),
        value(5.0),
        prop_oneof![value(1.0), Just(0.0)].prop_map(|x| 300.0 + 50.0 * x),
        proptest::option::of((value(4.0), value(500.0))),
    )
}

fn input() -> impl Strategy<Value = TickInput> {
    prop_oneof![9 => plausible(), 1 => mixed()].prop_map(|(abc, a, b, c, u_dc, sensor)| {
        let mut t = TickInput {
            currents: if abc {
                PhaseCurrents::Abc(foc::Abc { a, b, c })
            } else {
                PhaseCurrents::AlphaBeta(foc::AlphaBeta { alpha: a, beta: b })
            },
            u_dc_v: u_dc,
            sensor: None,
        };
        if let Some((th, w)) = sensor {
            t = t.with_sensor(th, w);
        }
        t
    })
}

#[derive(Clone, Debug)]
enum Cmd {
    Tick(TickInput),
    Start,
    Stop,
    Disable,
    Speed(f32),
    Clear,
    Restart,
}

fn cmd() -> impl Strategy<Value = Cmd> {
    prop_oneof![
        30 => input().prop_map(Cmd::Tick),
        2 => Just(Cmd::Start),
        3 => Just(Cmd::Restart),
        1 => Just(Cmd::Stop),
        1 => Just(Cmd::Disable),
        1 => value(200.0).prop_map(Cmd::Speed),
        1 => Just(Cmd::Clear),
    ]
}

/// The motors fuzzed: surface, interior with field weakening, strongly salient.
fn motor_config(k: usize) -> FocConfig {
    match k % 3 {
        0 => FocConfig::new(MotorParams::servo(), 50e-6, 300.0),
        1 => FocConfig::new(MotorParams::industrial_ipm(), 50e-6, 300.0).with_field_weakening(2.0),
        _ => FocConfig::new(MotorParams::traction_ipm(), 50e-6, 300.0),
    }
}

fn run(mode: Mode, delay: foc::ComputationDelay, dead_time_s: f32, cmds: &[Cmd]) {
    run_motor(0, mode, delay, dead_time_s, cmds);
}

fn run_motor(
    motor: usize,
    mode: Mode,
    delay: foc::ComputationDelay,
    dead_time_s: f32,
    cmds: &[Cmd],
) {
    let mut cfg = motor_config(motor).with_mode(mode).with_delay(delay);
    cfg.dead_time_s = dead_time_s;
    let mut foc = Foc::new(&cfg).unwrap();
    for c in cmds {
        match c {
            Cmd::Tick(t) => {
                let out = foc.tick(t);
                check(&out);
                TICKS.fetch_add(1, Ordering::Relaxed);
                if out.pwm_enabled {
                    RUNNING.fetch_add(1, Ordering::Relaxed);
                }
            }
            Cmd::Start => {
                let _ = foc.start();
            }
            Cmd::Stop => foc.stop(),
            Cmd::Disable => foc.disable(),
            Cmd::Speed(w) => {
                let _ = foc.set_speed_ref_mech_rad_s(*w);
            }
            Cmd::Clear => {
                foc.clear_fault();
            }
            Cmd::Restart => {
                foc.clear_fault();
                let _ = foc.start();
            }
        }
    }
}

/// The tick counters, for the harness's report.
fn stats() -> String {
    format!(
        "totals so far: {} ticks, {} with the bridge on; configs {} accepted / {} refused",
        TICKS.load(Ordering::Relaxed),
        RUNNING.load(Ordering::Relaxed),
        CONFIGS_OK.load(Ordering::Relaxed),
        CONFIGS_REFUSED.load(Ordering::Relaxed),
    )
}

#[test]
fn tick_sequences_stay_safe() {
    harness::fuzz(
        "tick sequences",
        512,
        proptest::collection::vec(cmd(), 1..300),
        |cmds| {
            run(
                Mode::Sensorless,
                foc::ComputationDelay::OnePeriod,
                0.0,
                &cmds,
            );
            run(Mode::Sensored, foc::ComputationDelay::None, 0.0, &cmds);
            // Dead-time compensation on (1.5 us: 3 % of the period).
            run(
                Mode::Sensorless,
                foc::ComputationDelay::OnePeriod,
                1.5e-6,
                &cmds,
            );
            // Salient motors: MTPA, field weakening (interior), both modes.
            let k = cmds.len();
            run_motor(
                1 + k % 2,
                Mode::Sensorless,
                foc::ComputationDelay::OnePeriod,
                0.0,
                &cmds,
            );
            run_motor(
                2 - k % 2,
                Mode::Sensored,
                foc::ComputationDelay::None,
                0.0,
                &cmds,
            );
            let (r, t) = (
                RUNNING.load(Ordering::Relaxed),
                TICKS.load(Ordering::Relaxed),
            );
            // Not a property of one case: a guard that the strategy reaches the running states.
            prop_assert!(
                t < 20_000 || r * 10 > t,
                "only {r} of {t} ticks ran the bridge"
            );
            Ok(())
        },
        stats,
    );
}

#[test]
fn running_controller_with_arbitrary_bits() {
    harness::fuzz(
        "raw bits into a running controller",
        512,
        proptest::collection::vec(
            (any::<u32>(), any::<u32>(), any::<u32>(), any::<u32>()),
            1..64,
        ),
        |bits| {
            // Started, then fed raw bit patterns in every field; restarted after each fault.
            // Dead-time compensation on; surface or salient motor.
            let mut cfg = motor_config(bits.len());
            cfg.dead_time_s = 1e-6;
            let mut foc = Foc::new(&cfg).unwrap();
            foc.set_speed_ref_mech_rad_s(100.0).unwrap();
            foc.start().unwrap();
            for (a, b, c, u) in bits {
                let out = foc.tick(&TickInput::abc(
                    f32::from_bits(a),
                    f32::from_bits(b),
                    f32::from_bits(c),
                    f32::from_bits(u),
                ));
                check(&out);
                if out.fault.is_some() {
                    foc.clear_fault();
                    foc.start().unwrap();
                }
            }
            Ok(())
        },
        stats,
    );
}

/// A parameter: any bit pattern, or (mostly) the default scaled by 1e-3 .. 1e3 or negated.
fn param() -> impl Strategy<Value = Option<f32>> {
    prop_oneof![
        2 => any::<u32>().prop_map(|b| Some(f32::from_bits(b))),
        1 => prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(0.0), Just(-1.0)].prop_map(Some),
        6 => (-3.0f32..3.0).prop_map(|e| Some(10f32.powf(e))),
        1 => Just(None),
    ]
}

/// Sets field `k` (of the list below) of `cfg` to `v` times its default (or to `v` itself
/// for bit patterns and special values, which come as `absolute`).
fn set_field(cfg: &mut FocConfig, k: usize, v: f32, absolute: bool) {
    let f: &mut f32 = match k % FIELDS {
        0 => &mut cfg.motor.rs_ohm,
        1 => &mut cfg.motor.lq_h,
        2 => &mut cfg.motor.psi_f_wb,
        3 => &mut cfg.ts_s,
        4 => &mut cfg.angle_advance_periods,
        5 => &mut cfg.current_bw_rad_s,
        6 => &mut cfg.speed_bw_rad_s,
        7 => &mut cfg.current_limit_a,
        8 => &mut cfg.over_current_a,
        9 => &mut cfg.u_dc_min_v,
        10 => &mut cfg.u_dc_max_v,
        11 => &mut cfg.max_speed_rad_s,
        12 => &mut cfg.max_modulation,
        13 => &mut cfg.dead_time_s,
        14 => &mut cfg.startup.align_current_a,
        15 => &mut cfg.startup.align_time_s,
        16 => &mut cfg.startup.if_current_a,
        17 => &mut cfg.startup.accel_rad_s2,
        18 => &mut cfg.startup.handover_speed_rad_s,
        19 => &mut cfg.health.window_s,
        20 => &mut cfg.health.nis_limit,
        21 => &mut cfg.observer.ts_s,
        22 => &mut cfg.observer.motor.lq_h,
        23 => &mut cfg.motor.ld_h,
        24 => &mut cfg.observer.motor.ld_h,
        25 => &mut cfg.field_weakening.voltage_margin,
        26 => &mut cfg.field_weakening.bandwidth_rad_s,
        27 => cfg.field_weakening.max_negative_id_a.get_or_insert(1.0),
        _ => &mut cfg.observer.angle_sigma_limit_rad,
    };
    *f = if absolute { v } else { *f * v };
}

/// Number of fields `set_field` reaches.
const FIELDS: usize = 29;

static CONFIGS_OK: AtomicUsize = AtomicUsize::new(0);
static CONFIGS_REFUSED: AtomicUsize = AtomicUsize::new(0);

#[test]
fn arbitrary_parameters_are_refused_or_run_safely() {
    harness::fuzz(
        "parameters",
        1024,
        (
            proptest::collection::vec((0usize..FIELDS, param(), any::<bool>()), 1..4),
            any::<u32>().prop_map(|p| p % 64),
            proptest::collection::vec(input(), 1..200),
            0usize..3,
        ),
        |(fields, pole_pairs, inputs, motor)| {
            let mut cfg = motor_config(motor);
            cfg.dead_time_s = 0.5e-6;
            for (k, v, absolute) in fields {
                match v {
                    Some(v) => set_field(&mut cfg, k, v, absolute || !v.is_finite()),
                    None => cfg.motor.pole_pairs = pole_pairs,
                }
            }
            let Ok(mut foc) = Foc::new(&cfg) else {
                CONFIGS_REFUSED.fetch_add(1, Ordering::Relaxed);
                prop_assert!(cfg.validate().is_err());
                return Ok(());
            };
            CONFIGS_OK.fetch_add(1, Ordering::Relaxed);
            let _ = foc.set_speed_ref_mech_rad_s(100.0);
            let _ = foc.start();
            for t in &inputs {
                let out = foc.tick(t);
                check(&out);
                TICKS.fetch_add(1, Ordering::Relaxed);
                if out.pwm_enabled {
                    RUNNING.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(())
        },
        stats,
    );
}
