//! High-frequency injection (`foc::hfi`) in the simulator's closed loop, on the two interior
//! reference motors (`industrial-ipm`: Lq/Ld 1.4, 540 V, 10 kHz, 50 mA sensor noise;
//! `traction-ipm`: Lq/Ld 3, 48 V, 20 kHz, 0.3 A noise), with the scenarios' inverters (delay,
//! dead time compensated by foc) and sensors, the `foc` controller sensorless with HFI on
//! (`Foc::enable_hfi` with the defaults `HfiConfig::with_current_noise` derives from the
//! motor and the scenario's current noise: `HfiConfig::new`'s unless too noisy).
//!
//! Diagnostics (environment): `HFI_PLL`, `HFI_N`, `HFI_V` override the settings, `HFI_SEED`
//! the noise seed, `HFI_NOISE` the current noise (A), `HFI_DT` the dead time (s), `HFI_CBW`
//! the current-loop bandwidth (Hz), `HFI_TH0` the hold's start angle (rad), `HFI_NOTRACK`
//! turns the observer's online `psi_f`/`Rs` tracking off, `HFI_DUMP=prefix` writes a CSV per
//! run, `HFI_FUSE` sets the standard deviation of HFI's angle fused into the observer (rad,
//! where the defaults fuse), `HFI_SEEDS=a-b` the seeds of the sweeps.
//!
//! The plant gets the simulator's optional d-axis saturation (`RunOptions::d_saturation`:
//! `Ld` falls by 20 % at `+current_limit`, nothing for negative `i_d`), which the polarity
//! test needs; without saturation no test can tell north from south.
//!
//! Each job: `start()` at t = 0 from standstill, the HFI start (60 ms settling, two 20 ms
//! d-axis pulses), then closed loop on the HFI angle blended with the EKF's by speed.
//!
//! Ripple (what the carrier costs): the samples sit at the carrier's extremes, so the
//! deviation of each sample from the centred mean `(x[k-1] + 2 x[k] + x[k+1]) / 4` is half the
//! peak-to-peak ripple; the RMS of the (triangular) current ripple is that over `sqrt(3)`, as
//! is the torque's (linear in the ripple current). Both are reported against the rated
//! current (MTPA) and torque.
//!
//! `cargo test --release -p pmsm-sim --test hfi -- --nocapture` prints every number.

use std::f64::consts::PI;

use foc::{HfiConfig, HfiPhase, HfiStatus};
use pmsm_sim::drive::foc_adapter::FocDrive;
use pmsm_sim::drive::interface::{ControllerInput, ControllerOutput, DriveController};
use pmsm_sim::plant::DSaturation;
use pmsm_sim::plant::load::{LoadTerm, Profile};
use pmsm_sim::scenario::{ControllerKind, RPM_PER_RAD_S, Scenario};
use pmsm_sim::sim::{self, RunOptions, Sample};

/// foc with HFI, recording HFI's status every period.
struct HfiDrive {
    drive: FocDrive,
    status: Vec<HfiStatus>,
}

impl DriveController for HfiDrive {
    fn sensored(&self) -> bool {
        false
    }
    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
        let out = self.drive.tick(input);
        if let Some(s) = self.drive.foc().hfi_status() {
            self.status.push(s);
        }
        out
    }
}

fn wrap(x: f64) -> f64 {
    (x + PI).rem_euclid(2.0 * PI) - PI
}

/// The preset `name` as a sensorless foc job: speed profile, load terms, initial angle.
fn job(
    name: &str,
    speed_rpm: Vec<(f64, f64)>,
    load: Vec<LoadTerm>,
    theta0: f64,
    t_end: f64,
) -> Scenario {
    let mut sc = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
    sc.controller.kind = ControllerKind::Foc;
    sc.speed_ref_rpm = Profile::linear(speed_rpm);
    sc.load = load;
    sc.initial.theta_e_rad = theta0;
    sc.duration_s = t_end;
    sc.observer.reference_filter = false;
    // Diagnostics: another noise realization, another dead time.
    if let Ok(x) = std::env::var("HFI_SEED") {
        sc.seed = x.parse().unwrap_or(sc.seed);
    }
    if let Ok(x) = std::env::var("HFI_NOISE") {
        sc.sensors.current_noise_std_a = x.parse().unwrap_or(sc.sensors.current_noise_std_a);
    }
    if let Ok(x) = std::env::var("HFI_CBW") {
        sc.controller.current_bandwidth_hz =
            x.parse().unwrap_or(sc.controller.current_bandwidth_hz);
    }
    if let Ok(x) = std::env::var("HFI_DT") {
        sc.inverter.dead_time_s = x.parse().unwrap_or(sc.inverter.dead_time_s);
    }
    sc
}

struct Run {
    samples: Vec<Sample>,
    status: Vec<HfiStatus>,
    hfi: HfiConfig,
}

fn run(sc: &Scenario) -> Run {
    let mut fc = sc.foc_config().unwrap_or_else(|e| panic!("{}", e.problem));
    if std::env::var("HFI_NOTRACK").is_ok() {
        fc.observer.parameter_tracking = None;
    }
    let s = sc.controller.foc.unwrap_or_default();
    let mut drive =
        FocDrive::new(&fc, s.start_time_s, s.stop_time_s).unwrap_or_else(|e| panic!("{e}"));
    let cfg = *drive.foc().config();
    let u_dc = sc.inverter.u_dc_v as f32;
    let noise = sc.sensors.current_noise_std_a as f32;
    let mut hfi =
        HfiConfig::with_current_noise(&cfg, u_dc, noise).unwrap_or_else(|e| panic!("{e}"));
    if let Ok(x) = std::env::var("HFI_PLL") {
        hfi.pll_bandwidth_rad_s = x.parse().unwrap_or(0.0);
    }
    if let Ok(x) = std::env::var("HFI_N") {
        hfi.half_period_ticks = x.parse().unwrap_or(0);
    }
    if let Ok(x) = std::env::var("HFI_V") {
        hfi.injection_v = x.parse().unwrap_or(0.0);
    }
    if let Ok(x) = std::env::var("HFI_FUSE")
        && hfi.fusion_sigma_rad > 0.0
    {
        hfi.fusion_sigma_rad = x.parse().unwrap_or(0.0);
    }
    drive
        .foc_mut()
        .enable_hfi(&hfi, u_dc)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut d = HfiDrive {
        drive,
        status: Vec::new(),
    };
    let sat = DSaturation {
        drop: 0.2,
        current_a: sc.controller.current_limit_a,
    };
    let out = sim::run_with_controller(
        sc,
        &mut d,
        RunOptions {
            record_trace: true,
            d_saturation: Some(sat),
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{}: {e}", sc.name));
    assert!(out.end.stop_time_s().is_none(), "{}", out.end.describe());
    Run {
        samples: out.trace.samples,
        status: d.status,
        hfi,
    }
}

/// With `HFI_DUMP=prefix`, writes `prefix-tag.csv` (t, control angle error, HFI angle error,
/// speed rpm, i_q, eps, EKF angle error, observer weight, rotor angle; electrical speeds: true,
/// control, EKF, HFI tracker; carrier on; the EKF's psi_f and Rs) for a look at a run.
fn dump(tag: &str, r: &Run) {
    let Ok(path) = std::env::var("HFI_DUMP") else {
        return;
    };
    let mut out = String::new();
    for (x, st) in r.samples.iter().zip(&r.status) {
        out += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            x.t_s,
            angle_error_deg(x),
            wrap(f64::from(st.theta_rad) - x.truth.theta_e_rad).to_degrees(),
            x.truth.speed_rpm,
            x.truth.i_dq_a[1],
            st.response.eps,
            x.controller_observer
                .as_ref()
                .map_or(0.0, |o| o.angle_error_deg),
            st.observer_weight,
            x.truth.theta_e_rad,
            x.truth.omega_e_rad_s,
            x.control.telemetry.omega_e_rad_s,
            x.control
                .telemetry
                .estimate
                .as_ref()
                .map_or(f64::NAN, |e| e.omega_e_rad_s),
            st.omega_rad_s,
            u8::from(st.injecting),
            x.control
                .telemetry
                .estimate
                .as_ref()
                .map_or(f64::NAN, |e| e.psi_f_wb),
            x.control
                .telemetry
                .estimate
                .as_ref()
                .map_or(f64::NAN, |e| e.rs_ohm),
        );
    }
    std::fs::write(format!("{path}-{tag}.csv"), out).unwrap_or_else(|e| panic!("{e}"));
}

/// Angle error of the control frame (wrapped), deg el.
fn angle_error_deg(x: &Sample) -> f64 {
    wrap(x.control.telemetry.theta_e_rad - x.truth.theta_e_rad).to_degrees()
}

/// Mean, RMS and largest |e| of the control frame's angle error over `[t0, t1)`, deg el.
fn angle_stats(s: &[Sample], t0: f64, t1: f64) -> (f64, f64, f64) {
    let e: Vec<f64> = s
        .iter()
        .filter(|x| x.t_s >= t0 && x.t_s < t1)
        .map(angle_error_deg)
        .collect();
    assert!(!e.is_empty());
    let n = e.len() as f64;
    let mean = e.iter().sum::<f64>() / n;
    let rms = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    (mean, rms, e.iter().fold(0.0_f64, |m, x| m.max(x.abs())))
}

/// Ripple over `[t0, t1)` for a carrier of half period `n` ticks (module docs): RMS current
/// ripple (A, |dq| vector) and RMS torque ripple (N m) of the triangle.
fn ripple(s: &[Sample], t0: f64, t1: f64, n: usize) -> (f64, f64) {
    // Centred mean over one carrier period (2n samples: weights 1/(4n) at both ends).
    let w: Vec<f64> = (0..=2 * n)
        .map(|j| {
            if j == 0 || j == 2 * n {
                0.25 / n as f64
            } else {
                0.5 / n as f64
            }
        })
        .collect();
    // Samples of a triangle taken at 2n points per period starting at an extreme: mean square
    // deviation A^2 (1/n) sum (1 - 2j/n)^2; the continuous RMS is A / sqrt(3).
    let ms = (0..n)
        .map(|j| (1.0 - 2.0 * j as f64 / n as f64).powi(2))
        .sum::<f64>()
        / n as f64;
    let to_rms = (1.0 / 3.0 / ms).sqrt();
    let (mut si, mut st, mut cnt) = (0.0, 0.0, 0.0);
    for win in s.windows(2 * n + 1) {
        let x = &win[n];
        if !(x.t_s >= t0 && x.t_s < t1) {
            continue;
        }
        let mean =
            |f: &dyn Fn(&Sample) -> f64| win.iter().zip(&w).map(|(y, k)| k * f(y)).sum::<f64>();
        let dd = x.truth.i_dq_a[0] - mean(&|y| y.truth.i_dq_a[0]);
        let dq = x.truth.i_dq_a[1] - mean(&|y| y.truth.i_dq_a[1]);
        let dt = x.truth.torque_nm - mean(&|y| y.truth.torque_nm);
        si += dd * dd + dq * dq;
        st += dt * dt;
        cnt += 1.0;
    }
    ((si / cnt).sqrt() * to_rms, (st / cnt).sqrt() * to_rms)
}

fn rated(sc: &Scenario) -> (f64, f64) {
    let (_, _, i) = sc.motor.mtpa_currents_for_torque(sc.rated_torque_nm);
    (i, sc.rated_torque_nm)
}

fn tracking_start(r: &Run, ts: f64) -> f64 {
    let k = r
        .status
        .iter()
        .position(|s| s.phase == HfiPhase::Tracking)
        .unwrap_or_else(|| panic!("HFI never tracked"));
    k as f64 * ts
}

/// 0 rpm under the rated load (an active, constant torque from 0.3 s) for 5 s: the angle
/// error of the control frame and the speed over 0.5-5.5 s.
fn hold_zero(name: &str) -> (f64, f64, f64) {
    let sc0 = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
    let load = vec![LoadTerm::Ramp {
        start_s: 0.3,
        end_s: 0.8,
        from_nm: 0.0,
        to_nm: sc0.rated_torque_nm,
    }];
    let theta0 = std::env::var("HFI_TH0").map_or(1.0, |x| x.parse().unwrap_or(1.0));
    let sc = job(name, vec![(0.0, 0.0), (6.0, 0.0)], load, theta0, 6.0);
    let r = run(&sc);
    let s = &r.samples;
    dump(&format!("hold-{name}"), &r);
    let t_track = tracking_start(&r, sc.ts_s());
    let (mean, rms, max) = angle_stats(s, 1.0, 6.0);
    let (_, _, max_ramp) = angle_stats(s, 0.3, 1.0);
    let w = s
        .iter()
        .filter(|x| x.t_s >= 1.0)
        .fold(0.0_f64, |m, x| m.max(x.truth.speed_rpm.abs()));
    let (i_r, t_r) = rated(&sc);
    let (ri, rt) = ripple(s, 1.0, 6.0, usize::from(r.hfi.half_period_ticks));
    let states: std::collections::BTreeSet<_> =
        s.iter().map(|x| x.control.telemetry.state).collect();
    let i_end = s.last().map_or([0.0; 2], |x| x.truth.i_dq_a);
    let flips = r
        .status
        .last()
        .map(|x| (x.polarity_flipped, x.polarity_contrast));
    println!(
        "{name}: hold 0 rpm at {t_r} N m: tracking from {t_track:.3} s (polarity flipped, contrast {flips:?}); \
         angle error (1-6 s) mean {mean:+.2} / RMS {rms:.2} / max {max:.2} deg el. (max {max_ramp:.2} while the load ramps up); max |speed| {w:.2} rpm; \
         i_dq at the end {i_end:.2?} A; injection {:.1} V at {:.0} Hz, PLL {:.0} rad/s; \
         ripple: current {ri:.3} A RMS ({:.2} % of {i_r:.2} A), torque {rt:.3} N m RMS ({:.2} % of rated); states {states:?}",
        r.hfi.injection_v,
        0.5 / sc.ts_s() / f64::from(r.hfi.half_period_ticks),
        r.hfi.pll_bandwidth_rad_s,
        100.0 * ri / i_r,
        100.0 * rt / t_r,
    );
    assert!(s.iter().all(|x| x.control.telemetry.fault.is_none()));
    (rms, max, w)
}

/// The goal on the industrial motor (Lq/Ld 1.4, 50 mA sensor noise), with the
/// defaults `HfiConfig::with_current_noise` derives for that noise (`N = 7`, 714 Hz, 249 V,
/// PLL 60 rad/s): held at zero speed under rated load, the angle error stays within 5 deg.
/// Measured over 1-6 s, seeds 7 / 1 / 2 / 3: RMS 0.61 / 0.57 / 0.59 / 0.59, max 2.09 / 2.17 /
/// 2.16 / 2.08 deg el.; over 7 start angles (0 to 3 rad) x 3 seeds the worst max is 4.13 deg
/// (the angle noise depends on the rotor's orientation to the two current sensors by up to
/// sqrt 3, `foc::hfi` "Angle noise"). Ripple: 1.69 A RMS (27.4 % of the rated current),
/// torque 0.56 N m RMS (4.0 % of rated).
#[test]
fn industrial_ipm_holds_zero_speed_under_rated_load_within_5_deg() {
    let (rms, max, w) = hold_zero("industrial-ipm");
    assert!(max <= 5.0, "max angle error {max} deg (RMS {rms})");
    assert!(w < 30.0, "speed {w} rpm");
}

/// A looser regression guard at zero speed under 14 N m; measured RMS 0.61, max 2.27 deg el.,
/// max |speed| 3.6 rpm.
#[test]
fn industrial_ipm_holds_zero_speed_under_rated_load() {
    let (rms, max, w) = hold_zero("industrial-ipm");
    assert!(
        rms <= 2.5 && max <= 10.0,
        "angle error RMS {rms}, max {max} deg"
    );
    assert!(w < 30.0, "speed {w} rpm");
}

#[test]
fn traction_ipm_holds_zero_speed_under_rated_load() {
    let (rms, max, w) = hold_zero("traction-ipm");
    assert!(max <= 5.0, "max angle error {max} deg (RMS {rms})");
    assert!(w < 30.0, "speed {w} rpm");
}

/// Polarity from 12 initial rotor angles: after the start, the control angle is within
/// 20 deg of the rotor (not pi off).
fn polarity_grid(name: &str) -> usize {
    let mut ok = 0;
    for k in 0..12 {
        let th0 = -PI + (f64::from(k) + 0.5) * PI / 6.0;
        let sc = job(name, vec![(0.0, 0.0), (0.3, 0.0)], vec![], th0, 0.3);
        let r = run(&sc);
        let t_track = tracking_start(&r, sc.ts_s());
        let (mean, _, max) = angle_stats(&r.samples, t_track + 0.02, 0.3);
        let st = r.status.last().copied().unwrap_or_default();
        let good = max < 20.0;
        ok += usize::from(good);
        println!(
            "{name}: rotor at {:+7.1} deg: flipped {}, contrast {:.4}, error after: mean {mean:+.2} max {max:.2} deg -> {}",
            th0.to_degrees(),
            st.polarity_flipped,
            st.polarity_contrast,
            if good { "ok" } else { "WRONG" }
        );
    }
    println!("{name}: polarity right {ok} / 12");
    ok
}

#[test]
fn polarity_is_found_from_any_rotor_angle() {
    assert_eq!(polarity_grid("industrial-ipm"), 12);
    assert_eq!(polarity_grid("traction-ipm"), 12);
}

/// A reversal through zero under the rated active load, closed loop all the way: +n to -n
/// rpm over 1 s (n = 2x the speed where the carrier stops), the rated torque ramped in over
/// 0.2-0.7 s while the speed rises to +n. The angle error is asserted where HFI has a say
/// (observer weight below 1); where the observer is alone (above the band) it is the EKF's:
/// on the traction motor it settles about 7 deg off at +430 rpm under rated load after the
/// hand-over (its speed estimate too: the drive holds ~430 rpm for a 573 rpm reference), and
/// recovers when HFI re-seeds it on the way down; the negative direction is clean.
fn reversal(name: &str) -> (f64, f64) {
    reversal_with(name, None)
}

/// [`reversal`] with the preset's current limit and ADC full scale replaced (A).
fn reversal_with(name: &str, limits: Option<(f64, f64)>) -> (f64, f64) {
    reversal_seeded(name, limits, None)
}

/// [`reversal_with`] on the noise seed `seed` (`None`: the preset's, or `HFI_SEED`).
fn reversal_seeded(name: &str, limits: Option<(f64, f64)>, seed: Option<u64>) -> (f64, f64) {
    let mut sc0 = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
    if let Some((limit, adc)) = limits {
        sc0.controller.current_limit_a = limit;
        sc0.sensors.adc_full_scale_a = adc;
    }
    let cfg = sc0.foc_config().unwrap_or_else(|e| panic!("{e}"));
    let hi = HfiConfig::new(&cfg, sc0.inverter.u_dc_v as f32).unwrap_or_else(|e| panic!("{e}"));
    let n_rpm =
        2.0 * f64::from(hi.blend_high_rad_s) / f64::from(cfg.motor.pole_pairs) * RPM_PER_RAD_S;
    let load = vec![LoadTerm::Ramp {
        start_s: 0.2,
        end_s: 0.7,
        from_nm: 0.0,
        to_nm: sc0.rated_torque_nm,
    }];
    let profile = vec![
        (0.2, 0.0),
        (0.7, n_rpm),
        (1.2, n_rpm),
        (2.2, -n_rpm),
        (2.7, -n_rpm),
    ];
    let mut sc = job(name, profile, load, -2.0, 2.7);
    if let Some(seed) = seed {
        sc.seed = seed;
    }
    if let Some((limit, adc)) = limits {
        sc.controller.current_limit_a = limit;
        sc.sensors.adc_full_scale_a = adc;
    }
    let r = run(&sc);
    dump(&format!("rev-{name}"), &r);
    let s = &r.samples;
    let t_track = tracking_start(&r, sc.ts_s());
    let after: Vec<&Sample> = s.iter().filter(|x| x.t_s > t_track).collect();
    let left = after
        .iter()
        .filter(|x| x.control.telemetry.state != "closed_loop")
        .count();
    let (mean, rms, max) = angle_stats(s, 1.2, 2.2);
    // Where HFI has a say (observer weight below 1) and where the observer is alone.
    let band: Vec<f64> = s
        .iter()
        .zip(&r.status)
        .filter(|(x, st)| x.t_s >= 1.2 && x.t_s < 2.2 && st.observer_weight < 1.0)
        .map(|(x, _)| angle_error_deg(x).abs())
        .collect();
    let max_hfi = band.iter().fold(0.0_f64, |m, x| m.max(*x));
    let hfi_s = band.len() as f64 * sc.ts_s();
    let track = s.iter().filter(|x| x.t_s >= 0.5).fold(0.0_f64, |m, x| {
        m.max((x.truth.speed_rpm - x.control.speed_ref_rpm).abs())
    });
    let speeds = s
        .iter()
        .filter(|x| (2.5..2.7).contains(&x.t_s))
        .map(|x| x.truth.speed_rpm)
        .sum::<f64>()
        / s.iter().filter(|x| (2.5..2.7).contains(&x.t_s)).count() as f64;
    println!(
        "{name}: reversal {n_rpm:.0} -> {:.0} rpm under {} N m: periods out of closed loop {left}; \
         angle error 1.2-2.2 s mean {mean:+.2} / RMS {rms:.2} / max {max:.2} deg el., \
         max {max_hfi:.2} deg over the {hfi_s:.3} s with HFI in the angle (observer weight < 1); \
         worst |speed - ref| {track:.1} rpm ({:.2} % of rated {} rpm); mean speed at the end {speeds:.1} rpm",
        -n_rpm,
        sc.rated_torque_nm,
        100.0 * track / sc.rated_speed_rpm,
        sc.rated_speed_rpm
    );
    assert!(s.iter().all(|x| x.control.telemetry.fault.is_none()));
    assert_eq!(left, 0, "left closed loop");
    assert!((speeds + n_rpm).abs() < 0.05 * n_rpm, "end speed {speeds}");
    (max_hfi, track)
}

/// The industrial IPM reverses through zero speed under rated load with the noise-derived
/// defaults (`N = 7`): the largest errors sit in the blend band (observer weight ~0.6) and at
/// 100-250 rpm, where HFI's own error grows with the half period. The observer's weight
/// follows the faster of HFI's speed and the observer's low-passed speed on this long
/// carrier period (`foc::hfi`, "Hand-over band"). Over the noise seeds 1-8 (`HFI_SEED=n`):
/// max angle error / worst speed error 9.2 / 42, 12.8 / 35, 7.4 / 44, 13.6 / 44, 9.0 / 35,
/// 11.6 / 30, 11.7 / 43, 12.9 / 45 deg el. / rpm. The preset's seed is 7.
#[test]
fn industrial_ipm_reverses_through_zero_under_rated_load() {
    let (max, track) = reversal("industrial-ipm");
    assert!(max < 15.0, "angle error {max} deg");
    assert!(track < 0.05 * 1500.0, "speed error {track} rpm");
}

/// The traction motor with the sizing the HFI defaults were tuned on (current limit 180 A,
/// ADC full scale 300 A), HFI's angle fused into the observer while HFI has a say. Seeds
/// 1-8: max angle error 1.3-2.7 deg el., worst speed error 22-29 rpm; the preset's seed 9:
/// 2.3 deg, 25 rpm.
#[test]
fn traction_ipm_reverses_through_zero_under_rated_load() {
    let (max, track) = reversal_with("traction-ipm", Some((180.0, 300.0)));
    assert!(max < 15.0, "angle error {max} deg");
    assert!(track < 0.08 * 3000.0, "speed error {track} rpm");
}

/// The same with the preset's current limit (250 A) and ADC full scale (400 A): the HFI
/// defaults derived from them (carrier amplitude from the limit) and the coarser ADC, HFI's
/// angle fused into the observer while HFI has a say (`foc::hfi` "Hand-over band", `sigma_f`
/// 0.03 rad): seeds 1-8 max angle error 1.3-7.0 deg el., worst speed error 23-32 rpm (seeds
/// 9-24: 1.8-9.0 deg, 23-35 rpm); the preset's seed 9: 3.3 deg, 23 rpm.
///
/// Why the fusion is needed at this sizing: at 40-80 rad/s el. this motor's back-EMF
/// (`psi_f w` = 0.7 V at 60 rad/s el.) is no larger than the resistive drop at the band's
/// ~70 A (0.56 V), and the sensors carry 0.3 A of noise: the EKF's speed estimate alone swings
/// by +-30 rad/s el. from one millisecond to the next, and the larger current limit turns that
/// noise, through the speed loop, into larger torque steps. The fusion's own sensitivity
/// (`HFI_FUSE`): `foc::hfi`, "Hand-over band".
#[test]
fn traction_ipm_reverses_with_the_presets_sizing() {
    let (max, track) = reversal("traction-ipm");
    assert!(max < 15.0, "angle error {max} deg");
    assert!(track < 0.08 * 3000.0, "speed error {track} rpm");
}

/// The reversal over the noise seeds 1-8; returns the seeds outside the bounds (angle where
/// HFI has a say < 15 deg el., worst speed error < `track_max` rpm), with their numbers.
fn seed_sweep(name: &str, limits: Option<(f64, f64)>, track_max: f64) -> Vec<(u64, f64, f64)> {
    let mut bad = Vec::new();
    // Diagnostics: `HFI_SEEDS=a-b` sweeps other seeds.
    let (first, last) = std::env::var("HFI_SEEDS")
        .ok()
        .and_then(|x| {
            let (a, b) = x.split_once('-')?;
            Some((a.parse().ok()?, b.parse().ok()?))
        })
        .unwrap_or((1, 8));
    for seed in first..=last {
        let (max, track) = reversal_seeded(name, limits, Some(seed));
        let sizing = limits.map_or("preset's sizing".to_string(), |(l, a)| {
            format!("{l} A / {a} A")
        });
        println!(
            "{name} ({sizing}): seed {seed}: max {max:.2} deg el., worst speed error {track:.1} rpm"
        );
        if !(max < 15.0 && track < track_max) {
            bad.push((seed, max, track));
        }
    }
    bad
}

/// Robustness over the noise: the reversal of the industrial IPM and the traction IPM at
/// 180 A / 300 A, each on the noise seeds 1-8 (16 runs, about 12 s in release). Max angle
/// error where HFI has a say / worst speed error (deg el. / rpm), seeds 1-8: industrial 9.2 /
/// 42, 12.8 / 35, 7.4 / 44, 13.6 / 44, 9.0 / 35, 11.6 / 30, 11.7 / 43, 12.9 / 45; traction at
/// 180 A 1.3-2.7 deg, 22-29 rpm (seeds 9-24: 1.5-3.5 deg, 20-30 rpm).
#[test]
fn reversal_passes_on_noise_seeds_1_to_8() {
    let bad = seed_sweep("industrial-ipm", None, 0.05 * 1500.0);
    assert!(
        bad.is_empty(),
        "industrial-ipm: seeds out of bounds {bad:?}"
    );
    let bad = seed_sweep("traction-ipm", Some((180.0, 300.0)), 0.08 * 3000.0);
    assert!(
        bad.is_empty(),
        "traction-ipm 180 A: seeds out of bounds {bad:?}"
    );
}

/// The traction IPM at the preset's sizing over the noise seeds 1-8: 8 of 8 (numbers:
/// [`traction_ipm_reverses_with_the_presets_sizing`]).
#[test]
fn traction_ipm_presets_sizing_passes_on_noise_seeds_1_to_8() {
    let bad = seed_sweep("traction-ipm", None, 0.08 * 3000.0);
    assert!(bad.is_empty(), "traction-ipm: seeds out of bounds {bad:?}");
}
