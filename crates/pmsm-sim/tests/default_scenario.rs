//! Closed-loop runs of the built-in scenarios: determinism, observer accuracy next to a drive
//! given the true angle (`servo-sensored`: foc in sensored mode), and the `foc` default running
//! through. The detailed closed-loop tests of `foc` on this simulator are in the workspace's
//! `tests/foc_closed_loop.rs`.

use pmsm_sim::output::metrics::ObserverMetrics;
use pmsm_sim::scenario::{PRESETS, Scenario};
use pmsm_sim::sim::{self, RunOutput};

fn run(scenario: &Scenario) -> RunOutput {
    match sim::run(scenario) {
        Ok(r) => r,
        Err(e) => panic!("run failed: {e}"),
    }
}

/// `Debug` prints every `f64` in its shortest round-trip form, so equal strings mean
/// bit-identical numbers (there is no NaN in a healthy trace).
fn fingerprint(out: &RunOutput) -> Vec<String> {
    out.trace.samples.iter().map(|s| format!("{s:?}")).collect()
}

#[test]
fn same_seed_and_file_give_a_bit_identical_run() {
    // The non-ideal preset exercises every random and non-linear path (noise, ADC, dead
    // time, ripple, friction).
    for name in ["default", "servo-harsh"] {
        let sc = Scenario::preset(name)
            .unwrap_or_else(|e| panic!("{e}"))
            .with_duration(0.3);
        let a = run(&sc);
        let b = run(&sc);
        assert_eq!(a.trace.samples.len(), 3000);
        assert_eq!(fingerprint(&a), fingerprint(&b), "{name}");
        for (x, y) in a.trace.samples.iter().zip(&b.trace.samples) {
            assert_eq!(x.truth.theta_e_rad.to_bits(), y.truth.theta_e_rad.to_bits());
            assert_eq!(
                x.observer.theta_e_rad.to_bits(),
                y.observer.theta_e_rad.to_bits()
            );
        }
        // Same metrics too (the wall-clock figures aside).
        let (mut ma, mut mb) = (a.metrics.clone(), b.metrics.clone());
        ma.wall_time_s = 0.0;
        mb.wall_time_s = 0.0;
        ma.real_time_factor = 0.0;
        mb.real_time_factor = 0.0;
        assert_eq!(format!("{ma:?}"), format!("{mb:?}"));

        let mut other = sc.clone();
        other.seed += 1;
        let c = run(&other);
        assert_ne!(fingerprint(&a), fingerprint(&c));
    }
}

fn observer(m: &Option<ObserverMetrics>) -> ObserverMetrics {
    m.unwrap_or_else(|| panic!("no observer metrics"))
}

/// The full 1.5 s `servo-sensored` scenario (foc in sensored mode, seed 1). Measured
/// (`pmsm-sim run servo-sensored`, release):
///
/// | metric                  | EKF (default) | reference filter |
/// |-------------------------|---------------|-------------|
/// | convergence time        | 0.0578 s      | 0.0590 s    |
/// | angle error RMS         | 0.063 deg     | 1.862 deg   |
/// | angle error max         | 0.522 deg     | 3.386 deg   |
/// | angle error mean        | +0.004 deg    | +1.122 deg  |
/// | speed error RMS         | 1.757 rad/s (0.21 %) | 4.173 rad/s (0.50 %) |
/// | speed error max         | 8.02 rad/s    | 10.39 rad/s |
/// | Tracking in window      | 100 %         | 87.4 %      |
///
/// The thresholds leave about 2x margin. The reference filter's bias is its half-sample lag
/// (`w_e Ts / 2` = 2.4 deg at 2000 rpm), which the default's lag-free step removes.
#[test]
fn sensored_scenario_observer_metrics() {
    let sc = Scenario::preset("servo-sensored").unwrap_or_else(|e| panic!("{e}"));
    let out = run(&sc);
    let m = &out.metrics;
    assert_eq!(m.end, "completed");
    assert_eq!(m.periods, 15_000);
    let o = observer(&m.observer);
    assert!(o.converged);
    let t_conv = o.convergence_time_s.unwrap_or(f64::INFINITY);
    // The ramp starts at 0.05 s; at standstill the angle is unobservable.
    assert!(t_conv > 0.05 && t_conv < 0.08, "convergence {t_conv} s");
    assert!(o.window_s > 1.3, "window {} s", o.window_s);
    assert!(o.angle_error_rms_deg < 0.15, "{o:?}");
    assert!(o.angle_error_max_deg < 1.2, "{o:?}");
    assert!(o.angle_error_mean_deg.abs() < 0.03, "{o:?}");
    assert!(o.speed_error_rms_rad_s < 3.5, "{o:?}");
    assert!(o.speed_error_rms_pct < 0.4, "{o:?}");
    assert!(o.speed_error_max_rad_s < 15.0, "{o:?}");
    assert!(o.tracking_pct > 99.0, "{o:?}");

    let s = observer(&m.seed_filter);
    assert!(s.converged);
    assert!(s.angle_error_rms_deg < 3.0, "{s:?}");
    assert!(
        s.angle_error_mean_deg > 0.5 && s.angle_error_mean_deg < 2.0,
        "{s:?}"
    );
    assert!(o.angle_error_rms_deg * 10.0 < s.angle_error_rms_deg);

    // The drive itself did its job.
    assert!(
        (m.drive.final_speed_rpm + 1000.0).abs() < 5.0,
        "{:?}",
        m.drive
    );
    assert!(m.drive.peak_current_a <= sc.controller.current_limit_a * 1.1);
    assert!(m.real_time_factor > 0.0);

    // The streaming metrics equal the ones recomputed from the trace.
    let rated = sc.rated_speed_e_rad_s();
    let again =
        ObserverMetrics::compute(&out.trace.samples, sc.ts_s(), rated, |s| Some(s.observer));
    assert_eq!(again, m.observer);
}

/// Started 57 deg off at standstill (foc sensored), the default observer converges for every noise seed
/// tried (1-6 measured: 0.056-0.060 s, 0.068-0.071 deg RMS over the first 0.4 s).
#[test]
fn default_observer_converges_for_several_noise_seeds() {
    for seed in 1..=4 {
        let mut sc = Scenario::preset("servo-sensored")
            .unwrap_or_else(|e| panic!("{e}"))
            .with_duration(0.4);
        sc.seed = seed;
        sc.observer.reference_filter = false;
        let out = run(&sc);
        let o = observer(&out.metrics.observer);
        let t_conv = o.convergence_time_s.unwrap_or(f64::INFINITY);
        assert!(t_conv < 0.13, "seed {seed}: convergence {t_conv} s");
        assert!(o.angle_error_rms_deg < 0.6, "seed {seed}: {o:?}");
    }
}

/// Every preset runs (a short part of it) without stopping, and its drive follows the
/// reference.
#[test]
fn every_preset_runs() {
    for (name, _) in PRESETS {
        let sc = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
        let short = sc.clone().with_duration(0.25_f64.min(sc.duration_s));
        let out = run(&short);
        assert!(out.end.is_completed(), "{name}: {}", out.end.describe());
        assert!(out.metrics.drive.peak_current_a <= sc.controller.current_limit_a * 1.3);
    }
}

/// A controller of one's own plugs into the loop through `DriveController` (as the `foc`
/// adapter does): here the sensored one, wrapped to open the bridge for 10 ms at full speed.
#[test]
fn a_custom_controller_can_open_the_bridge() {
    use pmsm_sim::drive::interface::{ControllerInput, ControllerOutput, DriveController};
    use pmsm_sim::sim::{RunOptions, run_with_controller};

    struct Gated(Box<dyn DriveController>);
    impl DriveController for Gated {
        fn sensored(&self) -> bool {
            self.0.sensored()
        }
        fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
            let mut out = self.0.tick(input);
            if (0.50..0.51).contains(&input.t_s) {
                out.pwm_enabled = false;
            }
            out
        }
    }

    let sc = Scenario::preset("servo-sensored")
        .unwrap_or_else(|e| panic!("{e}"))
        .with_duration(0.6);
    let mut ctl = Gated(sim::build_controller(&sc).unwrap_or_else(|e| panic!("{e}")));
    let out = run_with_controller(
        &sc,
        &mut ctl,
        RunOptions {
            record_trace: true,
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(out.end.is_completed());
    let s = &out.trace.samples;
    // Open from k = 5000 to 5099: no current from the period after the first one.
    for x in &s[5001..5100] {
        assert!(!x.inverter.pwm_enabled);
        assert_eq!(x.truth.i_dq_a, [0.0, 0.0]);
        assert_eq!(x.inverter.u_ab_commanded_v, [0.0, 0.0]);
    }
    assert!(s[5100].inverter.pwm_enabled);
    // The shaft coasts down (viscous friction: 0.21 N m on 8e-4 kg m^2, -25 rpm in 10 ms),
    // then the drive takes it back.
    let lost = s[5000].truth.speed_rpm - s[5099].truth.speed_rpm;
    assert!((lost - 25.0).abs() < 2.0, "{lost} rpm");
    assert!((s[5999].truth.speed_rpm - 2000.0).abs() < 20.0);
}

/// The built-in default runs the `foc` crate's sensorless controller through the whole job
/// without a fault, and reports foc's own observer next to the simulator's. Measured (seed 1,
/// 0.5 us dead time compensated by foc): no closed-loop exit (the reversal stays in closed
/// loop), final speed -999.7 rpm, settled speed error 0.40 rpm RMS, foc observer after the
/// hand-over (at 3 % of rated speed) 0.073 deg RMS, 0.426 deg max, -0.010 deg mean over
/// 1.79 s. The bounds below are
/// those values with a margin of about 1.5x (the run is deterministic; the margin absorbs a
/// last-digit change of the float math, not a regression). A last-digit change moves the run
/// onto another noise path, so the mean's bound covers its spread over noise seeds: seeds 1-8
/// give -0.012 to +0.001 deg (RMS 0.071-0.075, max 0.32-0.51 deg), hence 0.025 deg (the
/// suite's bias goal is 0.1).
#[test]
fn default_scenario_runs_foc_sensorless_through_the_job() {
    let sc = Scenario::default_servo();
    assert_eq!(sc.controller.kind, pmsm_sim::scenario::ControllerKind::Foc);
    let out = run(&sc);
    let m = &out.metrics;
    assert_eq!(m.end, "completed");
    assert!(
        m.controller.starts_with("foc, sensorless"),
        "{}",
        m.controller
    );
    let d = &m.drive;
    assert_eq!(d.fault, None);
    let t_cl = d.closed_loop_time_s.unwrap_or(f64::INFINITY);
    assert!(t_cl > 0.1 && t_cl < 0.5, "closed loop at {t_cl} s");
    // The reversal to -1000 rpm under the active load stays in closed loop (foc's default
    // `Reversal::ClosedLoop`; with `reversal = "open_loop"` it took 150 ms of I/f and lagged
    // the reference by 926 rpm): no exit, and the reference followed within 5 % of rated.
    assert_eq!(d.closed_loop_exits, 0, "{d:?}");
    let r = m.reversal.unwrap_or_else(|| panic!("no reversal scored"));
    assert_eq!((r.count, r.closed_loop_exits), (1, 0), "{r:?}");
    assert!(r.outside_closed_loop_max_s <= 0.03, "{r:?}");
    assert!(r.tracking_error_max_pct <= 5.0, "{r:?}");
    assert!((d.final_speed_rpm + 1000.0).abs() < 1.0, "{d:?}");
    assert!(d.speed_error_settled_rms_rpm < 0.8, "{d:?}");
    assert!(d.peak_current_a < sc.controller.current_limit_a, "{d:?}");
    let cl = m
        .controller_observer_closed_loop
        .unwrap_or_else(|| panic!("no closed-loop window"));
    assert!(cl.window_s > 1.45, "{cl:?}");
    assert!(cl.angle_error_rms_deg < 0.12, "{cl:?}");
    assert!(cl.angle_error_max_deg < 0.6, "{cl:?}");
    assert!(cl.angle_error_mean_deg.abs() < 0.025, "{cl:?}");
    assert!(m.controller_observer.is_some());
    // The first samples: foc aligns with the PWM on; its state is in the telemetry.
    let s = &out.trace.samples;
    assert_eq!(s[10].control.telemetry.state, "align");
    assert!(s[10].inverter.pwm_enabled);
    assert!(s[10].controller_observer.is_some());
    // The streaming metrics equal the ones recomputed from the trace.
    let again = ObserverMetrics::compute(s, sc.ts_s(), sc.rated_speed_e_rad_s(), |x| {
        x.controller_observer
    });
    assert_eq!(again, m.controller_observer);
}

/// The main job (foc sensorless, 0.5 us dead time compensated by foc): the simulator's own f64
/// EKF is fed the voltage foc expects its duties to realize (`expected_u_ab_v`), so the
/// compensated dead time does not bias it. Measured: rms 0.085 deg, mean +0.004 deg, max
/// 0.46 deg, converged at 10 ms; seed filter 1.77 deg rms (its half-sample lag). Fed the raw
/// duties instead, it read the compensation as back-EMF: 1.6 deg rms, +1.5 deg bias.
#[test]
fn default_main_job_simulator_observer_is_not_biased_by_compensated_dead_time() {
    let sc = Scenario::preset("default").unwrap_or_else(|e| panic!("{e}"));
    assert!(sc.inverter.dead_time_s > 0.0, "the default has dead time");
    let out = run(&sc);
    let o = observer(&out.metrics.observer);
    assert!(o.angle_error_rms_deg < 0.25, "{o:?}");
    assert!(o.angle_error_mean_deg.abs() < 0.1, "{o:?}");
    assert!(o.angle_error_max_deg < 1.5, "{o:?}");
    let foc = observer(&out.metrics.controller_observer);
    assert!(foc.angle_error_rms_deg < 0.25, "{foc:?}");
}
