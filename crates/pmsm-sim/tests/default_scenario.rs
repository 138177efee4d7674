//! Closed-loop runs of the built-in default scenario: determinism and observer accuracy.

use pmsm_sim::metrics::{ObserverMetrics, RunMetrics};
use pmsm_sim::scenario::Scenario;
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
fn same_seed_gives_a_bit_identical_trace() {
    let sc = Scenario::default_servo().with_duration(0.3);
    let a = run(&sc);
    let b = run(&sc);
    assert_eq!(a.trace.samples.len(), 3000);
    assert_eq!(fingerprint(&a), fingerprint(&b));
    for (x, y) in a.trace.samples.iter().zip(&b.trace.samples) {
        assert_eq!(x.plant.theta_e_rad.to_bits(), y.plant.theta_e_rad.to_bits());
        assert_eq!(
            x.observer.theta_e_rad.to_bits(),
            y.observer.theta_e_rad.to_bits()
        );
    }

    let mut other = sc.clone();
    other.sensor.seed += 1;
    let c = run(&other);
    assert_ne!(fingerprint(&a), fingerprint(&c));
}

fn observer(m: &RunMetrics) -> ObserverMetrics {
    m.observer.unwrap_or_else(|| panic!("no observer metrics"))
}

/// The full 1.5 s default scenario (seed 1). Measured (release and debug give the same
/// numbers):
///
/// | metric                  | EKF (default) | seed filter |
/// |-------------------------|---------------|-------------|
/// | convergence time        | 0.0590 s      | 0.0590 s    |
/// | angle error RMS         | 0.056 deg     | 1.856 deg   |
/// | angle error max         | 0.308 deg     | 3.217 deg   |
/// | angle error mean        | +0.004 deg    | +1.122 deg  |
/// | speed error RMS         | 1.680 rad/s (0.20 %) | 4.167 rad/s (0.50 %) |
/// | speed error max         | 6.68 rad/s    | 9.88 rad/s  |
/// | Tracking in window      | 100 %         | 87.4 %      |
///
/// The thresholds leave 2-5x margin. The seed filter's bias is its half-sample lag
/// (`w_e Ts / 2` = 2.4 deg at 2000 rpm), which the default's lag-free step removes.
#[test]
fn default_scenario_observer_metrics() {
    let sc = Scenario::default_servo();
    let out = run(&sc);
    let m = RunMetrics::compute(&sc, &out);
    let o = observer(&m);
    assert!(o.converged);
    let t_conv = o.convergence_time_s.unwrap_or(f64::INFINITY);
    // The ramp starts at 0.05 s; at standstill the angle is unobservable.
    assert!(t_conv > 0.05 && t_conv < 0.08, "convergence {t_conv} s");
    assert!(o.window_s > 1.3, "window {} s", o.window_s);
    assert!(o.angle_error_rms_deg < 0.15, "{o:?}");
    assert!(o.angle_error_max_deg < 1.0, "{o:?}");
    assert!(o.angle_error_mean_deg.abs() < 0.03, "{o:?}");
    assert!(o.speed_error_rms_rad_s < 3.5, "{o:?}");
    assert!(o.speed_error_rms_pct < 0.4, "{o:?}");
    assert!(o.speed_error_max_rad_s < 15.0, "{o:?}");
    assert!(o.tracking_pct > 99.0, "{o:?}");

    let s = m
        .seed_filter
        .unwrap_or_else(|| panic!("no seed filter metrics"));
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
    assert!(m.drive.peak_current_a <= sc.drive.current_limit_a * 1.1);
    assert!(m.real_time_factor > 0.0);
}

/// Started 57 deg off at standstill, the default observer falls into the theta + pi lock of
/// `design.md` section 3 for about a third of the noise seeds (13 of seeds 1-40; here seeds 2
/// and 3): it settles near 180 deg off with the speed of the wrong sign at about 10 rpm and
/// reports `Tracking`, then slides out as the speed rises and is within 5 deg from 0.1096 s
/// (385 rpm) on. This pins the worst case measured: converged by 0.11 s, then accurate.
#[test]
fn default_observer_converges_for_several_noise_seeds() {
    for seed in 1..=4 {
        let mut sc = Scenario::default_servo().with_duration(0.4);
        sc.sensor.seed = seed;
        sc.run_seed_filter = false;
        let out = run(&sc);
        let o = observer(&RunMetrics::compute(&sc, &out));
        let t_conv = o.convergence_time_s.unwrap_or(f64::INFINITY);
        assert!(t_conv < 0.13, "seed {seed}: convergence {t_conv} s");
        assert!(o.angle_error_rms_deg < 0.6, "seed {seed}: {o:?}");
    }
}
