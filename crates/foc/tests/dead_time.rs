//! Dead-time compensation (`FocConfig::dead_time_s`, module `foc::deadtime`): the duty
//! offsets per phase (sign, magnitude, the linear band, the current prediction), clamping,
//! off by default, the observer fed the voltage net of the compensation, refused settings,
//! and a closed loop on the self-written plant of tests/common with a dead-time bridge.
mod common;

use common::{Plant, Rig};
use foc::deadtime::{DeadTimeCompensation, compensate, smooth_sign};
use foc::ekf_core::MotorParams;
use foc::{
    Abc, AlphaBeta, ConfigError, Dq, Field, Foc, FocConfig, Mode, State, TickInput, TickOutput,
    duties_to_alpha_beta,
};

const TS: f32 = 1e-4;
const U_DC: f32 = 300.0;
/// 1 us at 100 us: 1 % of the period.
const DEAD: f32 = 1e-6;
const FRAC: f32 = 0.01;
const BAND: f32 = 0.1;

fn cfg() -> FocConfig {
    FocConfig::new(MotorParams::servo(), TS, U_DC).with_inertia(8e-4)
}

fn with_dead_time(mut c: FocConfig) -> FocConfig {
    c.dead_time_s = DEAD;
    c.dead_time_band_a = Some(BAND);
    c
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

/// Phase currents of the alpha-beta vector `i`.
fn abc(i: AlphaBeta) -> Abc {
    i.to_abc()
}

#[test]
fn off_by_default() {
    let c = cfg();
    assert_eq!(c.dead_time_s, 0.0);
    assert_eq!(c.dead_time_band_a, None);
    // The default band: 2 % of the current limit.
    assert!(close(c.dead_time_band(), 0.02 * c.current_limit_a, 1e-6));
    assert!(!DeadTimeCompensation::new(c.dead_time_s, c.ts_s, c.dead_time_band()).is_active());
    // Duties are the plain SVPWM of the voltage the telemetry reports.
    let mut foc = Foc::new(&c.with_mode(Mode::Sensored)).unwrap();
    foc.set_speed_ref_mech_rad_s(50.0).unwrap();
    foc.start().unwrap();
    for k in 0..50 {
        let out =
            foc.tick(&TickInput::abc(1.0, -0.3, -0.7, U_DC).with_sensor(0.1 * k as f32, 20.0));
        let m = foc::svpwm(out.telemetry.u_ab, U_DC);
        for x in 0..3 {
            assert!(close(out.duties[x], m.duties[x], 1e-6), "{out:?}");
        }
    }
}

#[test]
fn smooth_sign_and_offsets() {
    assert_eq!(smooth_sign(0.0, 0.1), 0.0);
    assert!(close(smooth_sign(0.05, 0.1), 0.5, 1e-6));
    assert!(close(smooth_sign(-0.025, 0.1), -0.25, 1e-6));
    assert_eq!(smooth_sign(0.3, 0.1), 1.0);
    assert_eq!(smooth_sign(-7.0, 0.1), -1.0);
    let c = DeadTimeCompensation::new(DEAD, TS, BAND);
    assert!(c.is_active());
    assert!(close(c.dead_fraction(), FRAC, 1e-7));
    // Positive current gains the dead time, negative loses it (the bridge's error is the
    // opposite); proportional within the band.
    let o = c.offsets(Abc {
        a: 2.0,
        b: -1.95,
        c: -0.05,
    });
    assert!(close(o[0], FRAC, 1e-7), "{o:?}");
    assert!(close(o[1], -FRAC, 1e-7), "{o:?}");
    assert!(close(o[2], -0.5 * FRAC, 1e-7), "{o:?}");
}

#[test]
fn compensate_adds_offsets_and_reports_the_realized_duties() {
    let d = [0.7, 0.4, 0.2];
    let delta = [0.01, -0.01, 0.005];
    let r = compensate(d, delta);
    for x in 0..3 {
        assert!(close(r.duties[x], d[x] + delta[x], 1e-7), "{r:?}");
        assert!(close(r.effective[x], d[x], 1e-7), "{r:?}");
    }
    // Clamping: the duty stops at 1 (or 0) and the bridge then realizes 1 - delta (delta);
    // an offset towards the inside is not clamped.
    let r = compensate([1.0, 0.0, 0.995], [0.01, -0.01, 0.01]);
    assert_eq!(r.duties, [1.0, 0.0, 1.0]);
    assert!(close(r.effective[0], 0.99, 1e-7), "{r:?}");
    assert!(close(r.effective[1], 0.01, 1e-7), "{r:?}");
    assert!(close(r.effective[2], 0.99, 1e-7), "{r:?}");
    let r = compensate([1.0, 0.0, 0.5], [-0.01, 0.01, 0.0]);
    assert!(close(r.duties[0], 0.99, 1e-7) && close(r.duties[1], 0.01, 1e-7));
    assert_eq!(r.effective, [1.0, 0.0, 0.5]);
}

/// Two controllers on `base`, one compensating 1 us with a 0.1 A band, started: with the
/// same inputs they run the same loops (and, the observer being fed the same realized
/// voltage, the same state machine), so their duties differ only by the compensation.
fn pair(mut base: FocConfig) -> (Foc, Foc) {
    // The loops' feed-forward takes the observer's tracked psi_f and Rs, which follow the
    // (rounding-level) differences of the realized voltages: compare with them fixed.
    base.observer.parameter_tracking = None;
    let mut off = Foc::new(&base).unwrap();
    let mut on = Foc::new(&with_dead_time(base)).unwrap();
    for f in [&mut off, &mut on] {
        f.set_speed_ref_mech_rad_s(30.0).unwrap();
        f.start().unwrap();
    }
    (off, on)
}

/// Duty offsets of `on` over `off`, per phase.
fn offsets(off: &TickOutput, on: &TickOutput) -> [f32; 3] {
    [0, 1, 2].map(|x| on.duties[x] - off.duties[x])
}

/// Ticks both controllers with the same input; checks that the loops agree.
fn tick2(off: &mut Foc, on: &mut Foc, inp: &TickInput) -> (TickOutput, TickOutput) {
    let (o0, o1) = (off.tick(inp), on.tick(inp));
    assert_eq!(o0.state, o1.state);
    assert_eq!(o0.telemetry.u_dq, o1.telemetry.u_dq);
    (o0, o1)
}

/// Input with the phase currents of the alpha-beta vector `i`.
fn input(i: AlphaBeta) -> TickInput {
    let m = abc(i);
    TickInput::abc(m.a, m.b, m.c, U_DC)
}

#[test]
fn offsets_per_phase_follow_the_current_sign_and_magnitude() {
    // Alignment (speed 0, so no prediction): the reference is `align_current_a` along
    // `align_angle_rad`; the measured current tracks it.
    let i_ref = 2.0_f32;
    for (angle, expect) in [
        // Phase currents 2 cos(angle - k 120 deg); expected offsets in units of t_dead / Ts
        // (the band is 0.1 A).
        (0.0, [1.0, -1.0, -1.0]),
        (core::f32::consts::PI, [-1.0, 1.0, 1.0]),
        (core::f32::consts::FRAC_PI_2, [0.0, 1.0, -1.0]),
        // Phase a at 2 sin(0.02) = 0.040 A: within the band, 0.40 of the offset.
        (core::f32::consts::FRAC_PI_2 - 0.02, [0.39997, 1.0, -1.0]),
        // Phase b at -0.025 A.
        (core::f32::consts::FRAC_PI_6 - 0.0125, [1.0, -0.25, -1.0]),
    ] {
        let mut base = cfg();
        base.startup.align_angle_rad = angle;
        base.startup.align_current_a = i_ref;
        let (mut off, mut on) = pair(base);
        let (s, c) = angle.sin_cos();
        // The reference ramps up over the first half of the alignment (0.1 s): past it.
        let mut last = None;
        for k in 0..1200 {
            let r = (k as f32 / 1000.0).min(1.0) * i_ref;
            let inp = input(AlphaBeta {
                alpha: r * c,
                beta: r * s,
            });
            last = Some(tick2(&mut off, &mut on, &inp));
        }
        let (o0, o1) = last.unwrap();
        assert_eq!(o1.state, State::Align);
        let got = offsets(&o0, &o1);
        for x in 0..3 {
            assert!(
                close(got[x], expect[x] * FRAC, 2e-6),
                "angle {angle}: offsets {got:?}, expected {expect:?} x {FRAC}"
            );
        }
    }
}

/// The offsets of every tick are those of the current reference turned to the middle of the
/// application interval, `theta + 1.5 w Ts`: checked over the I/f ramp.
#[test]
fn offsets_use_the_current_predicted_for_the_application_interval() {
    let mut base = cfg();
    base.startup.align_time_s = 0.0; // straight into the I/f ramp
    let (mut off, mut on) = pair(base);
    let comp = DeadTimeCompensation::new(DEAD, TS, BAND);
    let mut inp = input(AlphaBeta::default());
    let (mut turned, mut n) = (0.0_f32, 0);
    for _ in 0..5000 {
        let (o0, o1) = tick2(&mut off, &mut on, &inp);
        assert_eq!(o1.state, State::OpenLoop);
        let t = o1.telemetry;
        let at = |advance: f32| {
            comp.offsets(abc(t
                .i_dq_ref
                .to_alpha_beta_angle(t.theta_rad + advance * t.omega_rad_s * TS)))
        };
        let (expect, unturned) = (at(1.5), at(0.0));
        let got = offsets(&o0, &o1);
        for x in 0..3 {
            assert!(close(got[x], expect[x], 2e-5), "{got:?} vs {expect:?}");
            turned = turned.max((expect[x] - unturned[x]).abs());
        }
        // The motor follows the reference: the next measured current is this one.
        inp = input(t.i_dq_ref.to_alpha_beta_angle(t.theta_rad));
        n += 1;
    }
    // The ramp reaches 60 rad/s el.: the turn moves a phase crossing zero by up to
    // 1.5 w Ts I_f = 0.023 A, a quarter of the band.
    assert!(n == 5000 && turned > 0.15 * FRAC, "{turned}");
}

#[test]
fn observer_is_fed_the_voltage_net_of_the_compensation() {
    let (mut off, mut on) = pair(cfg().with_mode(Mode::Sensored));
    let (mut max_duty_diff, mut max_u_diff) = (0.0_f32, 0.0_f32);
    for k in 0..400 {
        let th = 0.01 * k as f32;
        let i = AlphaBeta {
            alpha: 1.5 * (th + 1.6).cos(),
            beta: 1.5 * (th + 1.6).sin(),
        };
        let m = abc(i);
        let inp = TickInput::abc(m.a, m.b, m.c, U_DC).with_sensor(th, 100.0);
        let (o0, o1) = tick2(&mut off, &mut on, &inp);
        assert_eq!(o1.state, State::ClosedLoop);
        for x in 0..3 {
            max_duty_diff = max_duty_diff.max((o1.duties[x] - o0.duties[x]).abs());
        }
        // The realized voltage is the intended one (no clamping here) ...
        let (u0, u1) = (o0.telemetry.u_ab, o1.telemetry.u_ab);
        assert!(
            close(u0.alpha, u1.alpha, 1e-3) && close(u0.beta, u1.beta, 1e-3),
            "{u0:?} vs {u1:?}"
        );
        // ... while the duties carry the compensation.
        let commanded = duties_to_alpha_beta(o1.duties, U_DC);
        max_u_diff = max_u_diff.max((commanded - u1).norm_squared().sqrt());
    }
    // Up to 4/3 t_dead / Ts u_dc = 4 V.
    assert!(max_u_diff > 3.0, "{max_u_diff}");
    assert!(
        max_duty_diff > 0.5 * FRAC && max_duty_diff <= FRAC * 1.0001,
        "{max_duty_diff}"
    );
    // So both observers saw the same voltages and currents: the same estimate.
    let (x0, x1) = (off.observer().state(), on.observer().state());
    for n in 0..4 {
        assert!(
            (x0[n] - x1[n]).abs() < 1e-3 * (1.0 + x0[n].abs()),
            "{x0:?} vs {x1:?}"
        );
    }
}

/// At the voltage limit the current loops do not reach their reference; the sign then comes
/// from the measured current, and offsets cut at 0 or 1 are reported to the observer.
#[test]
fn clamped_compensation_at_the_voltage_limit() {
    // Alignment towards 30 deg with the measured current well below the reference: the
    // d-axis PI saturates on the inscribed circle, which touches the hexagon at 30 deg, so
    // the duties of phases a and c sit at 1 and 0, and the current's sign pushes them out.
    let mut base = cfg();
    let th = core::f32::consts::FRAC_PI_6;
    base.startup.align_angle_rad = th;
    let (mut off, mut on) = pair(base);
    // Measured: 0.5 A along 30 deg and -0.3 A across it (reference: 2.55 A along).
    let i = Dq { d: 0.5, q: -0.3 }.to_alpha_beta_angle(th);
    let inp = input(i);
    let mut last = None;
    for _ in 0..1500 {
        last = Some(tick2(&mut off, &mut on, &inp));
    }
    let (o0, o1) = last.unwrap();
    assert_eq!(o1.state, State::Align);
    let u = o0.telemetry.u_dq;
    assert!(
        close(u.d * u.d + u.q * u.q, U_DC * U_DC / 3.0, 1.0),
        "{u:?}"
    );
    assert!(
        o0.duties[0] > 0.999 && o0.duties[2] < 0.001,
        "{:?}",
        o0.duties
    );
    // The measured current sets the sign: phase b carries -0.30 A (the reference none).
    let delta = DeadTimeCompensation::new(DEAD, TS, BAND).offsets(abc(i));
    assert!(
        delta[0] > 0.0 && delta[2] < 0.0 && delta[1] < -0.9 * FRAC,
        "{delta:?}"
    );
    // Phase a: 1 + delta is clamped to 1; phase c: 0 - delta to 0; phase b compensated.
    assert_eq!(o1.duties[0], 1.0);
    assert_eq!(o1.duties[2], 0.0);
    assert!(close(o1.duties[1], o0.duties[1] + delta[1], 1e-6));
    // The observer is told what the bridge realizes: 1 - delta_a and -delta_c, i.e. a
    // shorter vector than the one intended.
    let expect = duties_to_alpha_beta(
        [0, 1, 2].map(|x| (o1.duties[x] - delta[x]).clamp(0.0, 1.0)),
        U_DC,
    );
    let u1 = o1.telemetry.u_ab;
    assert!(
        close(u1.alpha, expect.alpha, 1e-3) && close(u1.beta, expect.beta, 1e-3),
        "{u1:?} vs {expect:?}"
    );
    let (n0, n1) = (o0.telemetry.u_ab.norm_squared(), u1.norm_squared());
    assert!(
        n1.sqrt() < n0.sqrt() - 2.0,
        "{} vs {}",
        n1.sqrt(),
        n0.sqrt()
    );
    assert!(o1.duties.iter().all(|d| (0.0..=1.0).contains(d)));
}

#[test]
fn bad_settings_are_refused() {
    let base = cfg();
    let bad = |f: fn(&mut FocConfig)| {
        let mut c = base;
        f(&mut c);
        (c.validate(), Foc::new(&c).err())
    };
    for (f, e) in [
        (
            (|c: &mut FocConfig| c.dead_time_s = -1e-9) as fn(&mut FocConfig),
            ConfigError::OutOfRange(Field::DeadTime),
        ),
        (
            |c| c.dead_time_s = f32::NAN,
            ConfigError::NonFinite(Field::DeadTime),
        ),
        (
            |c| c.dead_time_s = f32::INFINITY,
            ConfigError::NonFinite(Field::DeadTime),
        ),
        (
            |c| c.dead_time_s = 0.5 * c.ts_s,
            ConfigError::OutOfRange(Field::DeadTime),
        ),
        (
            |c| {
                c.dead_time_s = 1e-6;
                c.dead_time_band_a = Some(0.0);
            },
            ConfigError::NotPositive(Field::DeadTimeBand),
        ),
        (
            |c| c.dead_time_band_a = Some(f32::NAN),
            ConfigError::NonFinite(Field::DeadTimeBand),
        ),
        (
            |c| c.dead_time_band_a = Some(-0.1),
            ConfigError::NotPositive(Field::DeadTimeBand),
        ),
    ] {
        assert_eq!(bad(f), (Err(e), Some(e)));
    }
    let mut c = base;
    c.dead_time_s = 0.49 * c.ts_s;
    assert_eq!(c.validate(), Ok(()));
}

/// What [`run_rig`] measured over 1.0-1.5 s.
#[derive(Debug)]
struct RigRun {
    /// Observer angle error RMS and mean, deg el.
    angle_rms: f64,
    angle_mean: f64,
    /// Observer speed error (estimate - true), mean, rad/s el.
    speed_est_mean: f64,
    /// Plant speed - reference, mean, rad/s mech.
    speed_mean: f64,
}

/// Closed loop on the test rig with a 1 us dead-time bridge at 20 kHz (2 % of the period,
/// 6 V per leg on 300 V): sensorless start, 1000 rpm, 40 mA noise, as the smoke test;
/// `load_nm` from 0.9 s on; measured over 1.1-1.5 s.
fn run_rig(compensate: bool, load_nm: f64) -> RigRun {
    run_rig_tracking(compensate, load_nm, false)
}

/// As [`run_rig`], with the observer's parameter tracking on or off (off isolates the
/// compensation's effect: a tracked flux absorbs much of the dead-time bias by itself).
fn run_rig_tracking(compensate: bool, load_nm: f64, tracking: bool) -> RigRun {
    run_rig_seeded(compensate, load_nm, tracking, None)
}

/// As [`run_rig_tracking`], with the rig's noise seeded by `seed` (`None`: the rig's own).
fn run_rig_seeded(compensate: bool, load_nm: f64, tracking: bool, seed: Option<u64>) -> RigRun {
    let mut c = FocConfig::new(MotorParams::servo(), 50e-6, 300.0).with_inertia(8e-4);
    if !tracking {
        c.observer.parameter_tracking = None;
    }
    if compensate {
        c.dead_time_s = 1e-6;
    }
    let mut rig = Rig::new(&c, Plant::servo(), 300.0);
    rig.dead_time_s = 1e-6;
    rig.noise_a = 0.04;
    if let Some(seed) = seed {
        rig.reseed(seed);
    }
    rig.plant.x[3] = 1.0;
    let target = 104.72_f64;
    rig.foc.set_speed_ref_mech_rad_s(target as f32).unwrap();
    rig.foc.start().unwrap();
    let (mut e2, mut e1, mut we, mut w, mut n) = (0.0, 0.0, 0.0, 0.0, 0usize);
    for _ in 0..(1.5 / rig.ts).round() as usize {
        let out = rig.step();
        assert!(out.fault.is_none(), "{:?}", rig.foc.fault_info());
        if rig.t >= 0.9 {
            rig.plant.load_nm = load_nm;
        }
        if rig.t >= 1.1 {
            assert_eq!(out.state, State::ClosedLoop);
            let e = rig.angle_error_deg(&out);
            e2 += e * e;
            e1 += e;
            we += f64::from(out.telemetry.estimate.omega_e_rad_s) - rig.sample_omega_e;
            w += rig.plant.omega_mech() - target;
            n += 1;
        }
    }
    let n = n as f64;
    let r = RigRun {
        angle_rms: (e2 / n).sqrt(),
        angle_mean: e1 / n,
        speed_est_mean: we / n,
        speed_mean: w / n,
    };
    println!("compensation {compensate}, load {load_nm} N m, tracking {tracking}: {r:?}");
    r
}

/// Measured (`-- --nocapture`), default band (2 % of the 5.1 A limit, 0.10 A), one noise
/// realization (the rig's seed):
///
/// | load | compensation | angle error RMS / mean (deg el.) | speed estimate bias (rad/s el.) | speed error (rad/s mech.) |
/// |---|---|---|---|---|
/// | 1.5 N m | off | 6.31 / +6.30 | +37.1 | -9.29 |
/// | 1.5 N m | on | 0.097 / +0.018 | +0.005 | -0.022 |
/// | none | off | 0.54 / +0.35 | +1.79 | -0.31 |
/// | none | on | 0.46 / +0.26 | +1.11 | -0.29 |
///
/// Unloaded, the 0.6 A of friction current spends a fifth of each period within the band
/// of a zero crossing, where the smooth sign under-compensates this rig's hard-sign bridge;
/// a 0.02 A band gives 0.32 / +0.02 deg and +0.26 rad/s there (no real bridge has a hard
/// sign: the current ripple softens it, module `deadtime`).
///
/// Unloaded, the bias the compensation removes is small against the noise of a 0.4 s mean:
/// over noise seeds 1-16 the compensated/uncompensated ratio of the mean angle error ranges
/// 0.18-0.84 (mean 0.69, standard deviation 0.16), of the speed bias 0.39-0.80 (mean 0.60,
/// 0.10). One run compared against 0.7 passed or failed with the seed (seeds 6, 8, 9 of the
/// former generator failed). The unloaded part therefore compares means over [`SEEDS`]
/// seeds (ratio of the means: 0.68 for the angle, 0.60 for the speed; standard errors
/// about 0.04 and 0.025): the bounds, 0.8 and 0.75, lie about 3 and 6 standard errors
/// above, and still fail a compensation that removes less than a fifth of the angle bias.
#[test]
fn compensation_removes_the_observer_bias_on_a_dead_time_bridge() {
    let off = run_rig(false, 1.5);
    let on = run_rig(true, 1.5);
    assert!(
        off.angle_mean > 4.0 && off.speed_est_mean > 25.0 && off.speed_mean < -6.0,
        "{off:?}"
    );
    assert!(on.angle_rms < 0.2 && on.angle_mean.abs() < 0.1, "{on:?}");
    assert!(
        on.speed_est_mean.abs() < 0.3 && on.speed_mean.abs() < 0.1,
        "{on:?}"
    );
    // Unloaded: means over SEEDS noise realizations.
    let mean = |compensate: bool| {
        let runs: Vec<RigRun> = (1..=SEEDS)
            .map(|s| run_rig_seeded(compensate, 0.0, false, Some(s)))
            .collect();
        let n = runs.len() as f64;
        (
            runs.iter().map(|r| r.angle_mean).sum::<f64>() / n,
            runs.iter().map(|r| r.speed_est_mean).sum::<f64>() / n,
        )
    };
    let (off_angle, off_speed) = mean(false);
    let (on_angle, on_speed) = mean(true);
    println!(
        "unloaded, {SEEDS} seeds: angle mean {off_angle:.3} -> {on_angle:.3} deg (x{:.2}), \
         speed bias {off_speed:.3} -> {on_speed:.3} rad/s (x{:.2})",
        on_angle / off_angle,
        on_speed / off_speed
    );
    assert!(
        off_angle > 0.25 && off_speed > 1.2,
        "{off_angle} {off_speed}"
    );
    assert!(
        on_angle < 0.8 * off_angle && on_speed < 0.75 * off_speed,
        "{on_angle} {on_speed}"
    );
}

/// Noise realizations the unloaded comparison averages over.
const SEEDS: u64 = 16;

/// With the observer's online flux tracking on (the default), an uncompensated dead time
/// under rated load no longer biases the angle by 6 deg: the tracked flux lumps the
/// voltage error, which lies along the current (the q axis) at `i_d = 0`, with the EMF.
/// Measured: 0.29 deg RMS, mean +0.12 deg (6.3 / +6.3 with tracking off, table above).
#[test]
fn tracking_absorbs_the_dead_time_bias_under_load() {
    let r = run_rig_tracking(false, 1.5, true);
    assert!(r.angle_mean.abs() < 0.5 && r.angle_rms < 0.6, "{r:?}");
}
