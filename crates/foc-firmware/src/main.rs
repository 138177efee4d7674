//! Cortex-M4F firmware example: the `ekf-core` PMSM observer in `f32` on QEMU's `mps2-an386`.
//!
//! It runs the observer over a deterministic synthetic run of the servo motor at 1000 rpm
//! ([`synth`]), checks that the estimate converged to the true speed and angle, prints the
//! final estimate and a checksum over semihosting, and counts the instructions retired per call
//! of the measured functions ([`meter`]), printing one line per function of the form
//!
//! ```text
//! cortex-m4 <name>: <N> instructions/call
//! ```
//!
//! (`N` is the median over the calls, except for `identify_tick`, the worst; a detail line
//! gives mean, min and max). It exits through semihosting with status 0 when every check
//! passed and 1 otherwise (also on a panic or a hard fault).
//!
//! Build and run (`scripts/qemu-firmware.sh` does both and checks the output):
//!
//! ```text
//! cargo build -p foc-firmware --release --target thumbv7em-none-eabihf
//! qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -nographic -icount shift=10 \
//!     -semihosting-config enable=on,target=native \
//!     -kernel target/thumbv7em-none-eabihf/release/foc-firmware
//! ```
//!
//! Measured functions: `ekf_step` (`PmsmObserver::step`, default config: lag-free, Joseph,
//! online parameter tracking), `ekf_step_untracked` (the same without the tracking),
//! `ekf_step_salient` (the default on an interior motor, `Lq / Ld = 1.43`: the active-flux path),
//! `ekf_step_standard` (standard symmetrized covariance update), `ekf_step_euler` (forward
//! Euler), `ekf_step_seed` (`ObserverConfig::seed`), `ekf_predict` and `ekf_correct` (the two
//! halves of the default step), `ekf_step_bare` (untracked, no safeguards) and
//! `ekf_step_bare_gate` / `_branch` / `_health` (one safeguard on), the pieces of the untracked
//! step `ekf_part_trig`, `ekf_part_terms`, `ekf_part_predict`, `ekf_part_innovation`,
//! `ekf_part_correct` (the cost map in the ekf-core README), the peers `flux_step` (the flux observer + PLL baseline) and
//! `ekf_step_generic` (the generic `Ekf` on the same model, no safeguards or tracking), and
//! `sin_cos_f32` (the observer's pure-`f32` sine/cosine,
//! `ekf_core::trig`), and `foc_tick` (the full controller tick in sensorless closed loop, with
//! `foc_tick_align`, `foc_tick_openloop`, `foc_tick_handover` for the start-up states, and the closed-loop tick split into
//! `foc_tick_observer`, its observer step, and `foc_tick_rest`, the rest; see [`drive`]), `foc_tick_ipm` (the tick on an interior PMSM in closed loop with MTPA and
//! field weakening engaged, at 1.5-2x base speed) and `foc_tick_ipm_mtpa` (the same motor
//! below base speed), `foc_tick_hfi` and `foc_tick_hfi_blend` (the same motor at standstill
//! on high-frequency injection, and in its hand-over band to the observer), and `identify_tick` (`foc::Identifier::tick` over the whole self-commissioning
//! sequence; its line gives the **worst** tick, `identify_tick_median` the median; see
//! [`identify`]). To add one, count calls with [`meter::Clock::count`] into a [`meter::Tally`] and report it under its name (or call [`meter::Clock::measure`]).
#![no_std]
#![no_main]

mod drive;
mod identify;
mod meter;
mod saturated;
mod synth;

use core::hint::black_box;
use core::panic::PanicInfo;

use cortex_m_rt::{ExceptionFrame, entry, exception};
use cortex_m_semihosting::{debug, heprintln, hprintln};
use ekf_core::catalog::SERVO;
use ekf_core::nalgebra::Vector2;
use ekf_core::observer::parts::Parts;
use ekf_core::{
    CovarianceUpdate, Discretization, Ekf, EkfError, Estimate, FluxObserver, FluxObserverConfig,
    MotorParams, ObserverConfig, PmsmModel, PmsmObserver, wrap_angle,
};

use meter::{CalibrationError, Clock, Tally};
use synth::{OMEGA_E_RAD_S, SAMPLES, Sample, TS_S};

/// Samples at the end of the run over which the angle error is checked.
const CHECK_WINDOW: usize = 500;

#[entry]
fn main() -> ! {
    let status = match run() {
        Ok(()) => {
            hprintln!("foc-firmware: all checks passed");
            debug::EXIT_SUCCESS
        }
        Err(why) => {
            hprintln!("foc-firmware: FAILED: {}", why);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(status);
    loop {
        cortex_m::asm::wfi();
    }
}

/// One observer configuration to run and its acceptance limits.
struct Variant {
    name: &'static str,
    cfg: ObserverConfig<f32>,
    /// Largest `|angle error|` over the last [`CHECK_WINDOW`] samples, degrees electrical.
    max_angle_err_deg: f32,
    /// Largest final `|speed error|`, fraction of the true speed.
    max_speed_err: f32,
    /// Whether a miss of the limits fails the run (else it is only reported).
    checked: bool,
}

fn run() -> Result<(), &'static str> {
    // Built with `EKF_PROFILE=default` (or `untracked`, `seed`) in the environment, the
    // firmware only runs 1500 steps of that observer and exits: the run `profile_step.py`
    // traces.
    if let Some(which) = option_env!("EKF_PROFILE") {
        return profile_run(which);
    }
    let cp = cortex_m::Peripherals::take().ok_or("core peripherals already taken")?;
    let clock =
        Clock::start(cp.SYST).map_err(|CalibrationError::NotLinear { first, second }| {
            hprintln!(
                "calibration: 2000 instructions took {} ticks, the next 2000 took {}",
                first,
                second
            );
            "instruction counter not linear: run QEMU with -icount shift=10"
        })?;

    // The trace build (feature `trace`, `trace_tick.py`) runs the surface drive only.
    #[cfg(feature = "trace")]
    return drive::run(&clock);

    #[cfg_attr(feature = "trace", allow(unreachable_code))]
    let mut data = [Sample::default(); SAMPLES];
    synth::generate(&mut data);
    hprintln!(
        "run: servo motor, {} samples at Ts = 1e-4 s, w_e = {} rad/s (1000 rpm), x0 = 0",
        SAMPLES,
        OMEGA_E_RAD_S
    );
    hprintln!(
        "observer state: {} bytes (PmsmObserver<f32>, on the stack here)",
        core::mem::size_of::<PmsmObserver<f32>>()
    );

    let default = ObserverConfig::new(MotorParams::servo(), TS_S);
    let variants = [
        Variant {
            name: "ekf_step",
            cfg: default,
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            // The default without online parameter tracking: the tracking's cost is the
            // difference to `ekf_step`.
            name: "ekf_step_untracked",
            cfg: ObserverConfig {
                parameter_tracking: None,
                ..default
            },
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            // An interior motor (Lq / Ld = 1.43) on the same data: with i_d = 0 in steady
            // state its active-flux model is the surface one, so the run converges while the
            // salient path (active flux, d-axis correction, full current block) is counted.
            name: "ekf_step_salient",
            cfg: ObserverConfig::new(
                MotorParams::salient_from_f64(
                    SERVO.rs_ohm,
                    0.7 * SERVO.ld_h,
                    SERVO.ld_h,
                    SERVO.psi_f_wb,
                    SERVO.pole_pairs,
                ),
                TS_S,
            ),
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            // The untracked step without the three safeguards (gate, branch check, health):
            // the filter alone; the safeguards' cost is the difference to
            // `ekf_step_untracked` (cost map: ekf-core README).
            name: "ekf_step_bare",
            cfg: ObserverConfig {
                parameter_tracking: None,
                innovation_gate: None,
                branch_check: None,
                covariance_health: None,
                ..default
            },
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            name: "ekf_step_bare_gate",
            cfg: ObserverConfig {
                parameter_tracking: None,
                branch_check: None,
                covariance_health: None,
                ..default
            },
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            name: "ekf_step_bare_branch",
            cfg: ObserverConfig {
                parameter_tracking: None,
                innovation_gate: None,
                covariance_health: None,
                ..default
            },
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            name: "ekf_step_bare_health",
            cfg: ObserverConfig {
                parameter_tracking: None,
                innovation_gate: None,
                branch_check: None,
                ..default
            },
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            name: "ekf_step_standard",
            cfg: ObserverConfig {
                covariance_update: CovarianceUpdate::StandardSymmetrized,
                ..default
            },
            max_angle_err_deg: 1.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            // Forward Euler lags by about w Ts / 2 = 1.2 deg here (docs/design.md, "The reference filter").
            name: "ekf_step_euler",
            cfg: ObserverConfig {
                discretization: Discretization::ForwardEuler,
                ..default
            },
            max_angle_err_deg: 3.0,
            max_speed_err: 0.005,
            checked: true,
        },
        Variant {
            // The seed's tuning, counted only: started from x0 = 0 it can settle in the
            // theta + pi state with the speed's sign flipped (docs/design.md, "The reference filter").
            name: "ekf_step_seed",
            cfg: ObserverConfig::seed(MotorParams::servo(), TS_S),
            max_angle_err_deg: 5.0,
            max_speed_err: 0.02,
            checked: false,
        },
    ];
    let mut ok = true;
    for v in &variants {
        ok &= run_variant(&clock, v, &data)?;
    }

    // The two halves of the default step, on their own.
    let mut obs = PmsmObserver::new(&default).map_err(|_| "invalid default config")?;
    let (mut predict, mut correct) = (Tally::new(), Tally::new());
    let mut u_prev = [0.0; 2];
    let mut failures = 0u32;
    for s in &data {
        let mut p: Result<(), EkfError> = Ok(());
        predict.push(clock.count(&mut || p = obs.predict(u_prev)));
        let mut c: Result<Estimate<f32>, EkfError> = Err(EkfError::NonFiniteResult);
        correct.push(clock.count(&mut || c = obs.correct(s.i)));
        failures += u32::from(p.is_err()) + u32::from(c.is_err());
        u_prev = s.u;
    }
    predict.report("ekf_predict");
    correct.report("ekf_correct");
    if failures > 0 {
        hprintln!("ekf_predict/ekf_correct: {} calls failed", failures);
        ok = false;
    }

    // The pieces of the untracked step, one at a time (cost map: ekf-core README).
    parts(&clock, &data, &default)?;

    // The peers, on the same data: the flux observer + PLL baseline (the estimator of open
    // firmware) and the generic nalgebra `Ekf` driven by the same model as `ekf_step_untracked`
    // (no safeguards, no tracking: the cost of the plain textbook filter).
    peers(&clock, &data, &default)?;

    // The observer's f32 sine/cosine (ekf_core::trig; libm's sincosf would compute in f64).
    // The closure reads the angle and writes the result through its captures (as the step
    // lines do): no indexing or `black_box` stack round trip is counted with the function.
    let mut trig = Tally::new();
    let mut sc = (0.0f32, 0.0f32);
    for s in &data {
        let th = s.theta_rad;
        trig.push(clock.count(&mut || sc = ekf_core::trig::sin_cos_f32(th)));
        black_box(sc);
    }
    trig.report("sin_cos_f32");

    // A flux map (saturating machines): its evaluation and the map observer's step.
    saturated::run(&clock, &data)?;

    // The full controller tick (foc), sensorless closed loop on an on-target plant.
    drive::run(&clock)?;
    // The same for an interior PMSM with MTPA and field weakening.
    drive::run_ipm(&clock)?;
    // The same motor at standstill and low speed on high-frequency injection.
    drive::run_ipm_hfi(&clock)?;
    // The damped start (align by kick, coast, damped I/f).
    drive::run_damped(&clock)?;

    // The self-commissioning sequence (foc::identify): its worst tick.
    identify::run(&clock)?;

    if ok {
        Ok(())
    } else {
        Err("an observer did not converge (see above)")
    }
}

/// 1500 steps of the default observer (`which == "untracked"`: without the tracking;
/// `"seed"`: `ObserverConfig::seed`) on the synthetic run, for an execution trace
/// (`crates/foc-firmware/profile_step.py`).
fn profile_run(which: &str) -> Result<(), &'static str> {
    let mut data = [Sample::default(); SAMPLES];
    synth::generate(&mut data);
    let mut cfg = ObserverConfig::new(MotorParams::servo(), TS_S);
    if which == "untracked" {
        cfg.parameter_tracking = None;
    } else if which == "seed" {
        cfg = ObserverConfig::seed(MotorParams::servo(), TS_S);
    }
    let mut obs = PmsmObserver::new(&cfg).map_err(|_| "invalid observer config")?;
    let mut u_prev = [0.0; 2];
    for s in data.iter().take(1500) {
        let _ = black_box(obs.step(black_box(u_prev), black_box(s.i)));
        u_prev = s.u;
    }
    Ok(())
}

/// Runs one configuration over the data, counting instructions per `step`; prints the final
/// estimate, the errors and a checksum. `Ok(false)` when a check failed.
fn run_variant(clock: &Clock, v: &Variant, data: &[Sample; SAMPLES]) -> Result<bool, &'static str> {
    let mut obs = PmsmObserver::new(&v.cfg).map_err(|_| "invalid observer config")?;
    let mut tally = Tally::new();
    let mut checksum = Fnv1a::new();
    let mut failures = 0u32;
    let mut max_err_deg = 0.0f32;
    let mut last: Option<Estimate<f32>> = None;
    let mut u_prev = [0.0; 2];
    for (k, s) in data.iter().enumerate() {
        let mut out: Result<Estimate<f32>, EkfError> = Err(EkfError::NonFiniteResult);
        tally.push(clock.count(&mut || out = obs.step(u_prev, s.i)));
        u_prev = s.u;
        match out {
            Ok(e) => {
                checksum.add(e.theta_rad.to_bits());
                checksum.add(e.omega_e_rad_s.to_bits());
                if k + CHECK_WINDOW >= SAMPLES {
                    let err = angle_err_deg(e.theta_rad, s.theta_rad).abs();
                    max_err_deg = max_err_deg.max(err);
                }
                last = Some(e);
            }
            Err(_) => failures += 1,
        }
    }
    tally.report(v.name);

    let (Some(e), Some(s)) = (last, data.last()) else {
        hprintln!("{}: no successful step", v.name);
        return Ok(false);
    };
    let speed_err = e.omega_e_rad_s - OMEGA_E_RAD_S;
    let final_err_deg = angle_err_deg(e.theta_rad, s.theta_rad);
    hprintln!(
        "    {}: final theta {} rad (true {}), omega_e {} rad/s (true {}); \
         angle error final {} deg, max |.| {} deg over the last {} samples; \
         {} failed steps; checksum {:#010x}",
        v.name,
        e.theta_rad,
        s.theta_rad,
        e.omega_e_rad_s,
        OMEGA_E_RAD_S,
        final_err_deg,
        max_err_deg,
        CHECK_WINDOW,
        failures,
        checksum.0
    );
    let converged = failures == 0
        && max_err_deg <= v.max_angle_err_deg
        && speed_err.abs() <= v.max_speed_err * OMEGA_E_RAD_S;
    if !converged {
        hprintln!(
            "    {}: {} (limits: {} deg, {} of the speed)",
            v.name,
            if v.checked {
                "NOT CONVERGED"
            } else {
                "not converged (not checked: the seed's tuning is counted only)"
            },
            v.max_angle_err_deg,
            v.max_speed_err
        );
    }
    Ok(converged || !v.checked)
}

/// `flux_step` (`FluxObserver::step`, `FluxObserverConfig::new`) and `ekf_step_generic`
/// (`Ekf::<f32, 4, 2>` predict + correct with `PmsmModel`, the default's model and noise).
fn peers(
    clock: &Clock,
    data: &[Sample; SAMPLES],
    default: &ObserverConfig<f32>,
) -> Result<(), &'static str> {
    let mut flux = FluxObserver::new(&FluxObserverConfig::new(MotorParams::servo(), TS_S))
        .map_err(|_| "invalid flux observer config")?;
    let mut tally = Tally::new();
    let mut u_prev = [0.0; 2];
    let mut failures = 0u32;
    for s in data {
        let mut ok = false;
        tally.push(clock.count(&mut || ok = flux.step(u_prev, s.i).is_ok()));
        failures += u32::from(!ok);
        u_prev = s.u;
    }
    tally.report("flux_step");

    let model = PmsmModel::new(default);
    let mut ekf = Ekf::<f32, 4, 2>::new(default.x0, default.p0, default.covariance_update);
    let mut tally = Tally::new();
    let mut u_prev = [0.0; 2];
    for s in data {
        let mut ok = false;
        tally.push(clock.count(&mut || {
            ok = ekf.predict(&model, &Vector2::from(u_prev)).is_ok()
                && ekf.correct(&model, &Vector2::from(s.i)).is_ok();
        }));
        failures += u32::from(!ok);
        u_prev = s.u;
    }
    tally.report("ekf_step_generic");
    if failures > 0 {
        hprintln!("flux_step/ekf_step_generic: {} calls failed", failures);
        return Err("a peer's step failed");
    }
    Ok(())
}

/// The pieces of the untracked default step on a surface motor, each counted on a copy of
/// the observer's state before the sample (`ekf_core::observer::parts`, not counted), then the
/// observer steps (not counted): `ekf_part_trig` (sine and cosine of the angle),
/// `ekf_part_terms` (trig, EMF gain `G(w)`, EMF term and Jacobian entries), `ekf_part_predict`
/// (the terms, the predicted state and covariance), `ekf_part_innovation` (`S`, its inverse,
/// innovation, NIS), `ekf_part_correct` (the whole correction: innovation, gain, state and
/// Joseph covariance update, finiteness check).
fn parts(
    clock: &Clock,
    data: &[Sample; SAMPLES],
    default: &ObserverConfig<f32>,
) -> Result<(), &'static str> {
    let cfg = ObserverConfig {
        parameter_tracking: None,
        ..*default
    };
    let mut obs = PmsmObserver::new(&cfg).map_err(|_| "invalid untracked config")?;
    let mut tallies = [(); 5].map(|_| Tally::new());
    let mut u_prev = [0.0; 2];
    let mut failures = 0u32;
    for s in data {
        let parts = Parts::new(&obs);
        let [trig, terms, predict, innovation, correct] = &mut tallies;
        trig.push(clock.count(&mut || {
            black_box(black_box(&parts).trig());
        }));
        terms.push(clock.count(&mut || {
            black_box(black_box(&parts).terms(black_box(u_prev)));
        }));
        predict.push(clock.count(&mut || {
            black_box(black_box(&parts).predict(black_box(u_prev)));
        }));
        let mut ok = true;
        innovation.push(clock.count(&mut || {
            ok &= black_box(black_box(&parts).innovation(black_box(s.i))).is_some();
        }));
        correct.push(clock.count(&mut || {
            ok &= black_box(black_box(&parts).correct(black_box(s.i))).is_some();
        }));
        failures += u32::from(!ok) + u32::from(obs.step(u_prev, s.i).is_err());
        u_prev = s.u;
    }
    let names = [
        "ekf_part_trig",
        "ekf_part_terms",
        "ekf_part_predict",
        "ekf_part_innovation",
        "ekf_part_correct",
    ];
    for (t, name) in tallies.iter().zip(names) {
        t.report(name);
    }
    if failures > 0 {
        hprintln!("ekf_part_*: {} calls failed", failures);
        return Err("a part of the step failed");
    }
    Ok(())
}

/// `wrap(estimate - truth)` in degrees electrical.
fn angle_err_deg(estimate: f32, truth: f32) -> f32 {
    wrap_angle(estimate - truth) * (180.0 / core::f32::consts::PI)
}

/// FNV-1a over 32-bit words: a checksum of the estimates (bit-exact for a given build).
struct Fnv1a(u32);

impl Fnv1a {
    fn new() -> Self {
        Self(0x811c_9dc5)
    }

    fn add(&mut self, word: u32) {
        for byte in word.to_le_bytes() {
            self.0 = (self.0 ^ u32::from(byte)).wrapping_mul(0x0100_0193);
        }
    }
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    heprintln!("foc-firmware: panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    heprintln!("foc-firmware: hard fault at pc {:#010x}", frame.pc());
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
