//! Sections 3 and 4: the sensorless start and HFI's magnet polarity from random rotor angles.
//!
//! **Start-up** ([`startups`]): the motor's preset with foc sensorless (its start-up
//! defaults), no load but the preset's friction, the rotor at rest at an angle drawn uniformly
//! in `[-180, 180)` deg el. and a noise seed drawn per run; the reference ramps from 0 to
//! [`STARTUP_SPEED_FRAC`] of rated speed over 0.5 s and holds to [`STARTUP_END_S`]. **Success**:
//! no fault, the run completed, the loop closed and never left, and the final speed within
//! 25 % of the reference. The backward speed is the run's `startup.backward_speed_max_pct`
//! (the largest negative true speed before the hand-over, % of rated).
//!
//! **HFI polarity** ([`hfi_polarity`], salient motors only): foc sensorless with HFI on (the
//! defaults `HfiConfig::with_current_noise` derives from the motor and the preset's sensor
//! noise), the rotor at rest at a uniform random angle, speed reference 0, no load, for
//! [`HFI_END_S`]; the plant with d-axis saturation (`Ld` 20 % lower at `+current_limit`, what
//! lets HFI tell north from south). **Right**: HFI reached tracking and the control angle
//! stays within [`POLARITY_TOLERANCE_DEG`] of the rotor from 20 ms after that to the end (a
//! wrong polarity is 180 deg off).

use std::f64::consts::PI;

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use serde::Serialize;

use crate::SimError;
use crate::analysis::low_speed;
use crate::analysis::suite::SuiteMotor;
use crate::drive::foc_adapter::FocDrive;
use crate::drive::interface::{ControllerInput, ControllerOutput, DriveController};
use crate::plant::DSaturation;
use crate::plant::load::Profile;
use crate::scenario::{ControllerKind, Scenario};
use crate::sim::{self, RunEnd, RunOptions, Sample, SampleSink};

use super::{all_ok, par_map, unit};

/// Start-up reference: this fraction of rated speed.
pub const STARTUP_SPEED_FRAC: f64 = 0.2;
/// End of a start-up run, s.
pub const STARTUP_END_S: f64 = 1.2;
/// End of an HFI run, s.
pub const HFI_END_S: f64 = 0.3;
/// Largest control-angle error after HFI's polarity decision that counts as right, deg el.
pub const POLARITY_TOLERANCE_DEG: f64 = 20.0;

/// Added to the datasheet's seed for the start-up draws (a stream of its own).
const STARTUP_STREAM: u64 = 0x5747_0003;
/// Added to the datasheet's seed for the HFI draws.
const HFI_STREAM: u64 = 0x5747_0004;

/// One start-up.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StartupRun {
    /// Initial rotor angle, deg el.
    pub theta0_deg: f64,
    /// Noise seed.
    pub seed: u64,
    /// Success (module docs).
    pub success: bool,
    /// Largest backward speed, % of rated.
    pub backward_pct: f64,
    /// Time the loop closed, s (`None`: never).
    pub closed_loop_s: Option<f64>,
    /// The fault or early end, if any.
    pub failure: Option<String>,
}

/// Section 3's sweep.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StartupSweep {
    /// Every run, in draw order.
    pub runs: Vec<StartupRun>,
}

impl StartupSweep {
    /// Successes, %.
    pub fn success_pct(&self) -> f64 {
        pct(
            self.runs.iter().filter(|r| r.success).count(),
            self.runs.len(),
        )
    }

    /// The run with the largest backward speed.
    pub fn worst_backward(&self) -> Option<&StartupRun> {
        self.runs
            .iter()
            .max_by(|a, b| a.backward_pct.total_cmp(&b.backward_pct))
    }

    /// The latest closing of the loop over the successful runs, s.
    pub fn latest_closed_loop_s(&self) -> Option<f64> {
        self.runs
            .iter()
            .filter(|r| r.success)
            .filter_map(|r| r.closed_loop_s)
            .max_by(f64::total_cmp)
    }
}

/// `100 k / n` (0 for no runs).
pub(crate) fn pct(k: usize, n: usize) -> f64 {
    if n == 0 {
        0.0
    } else {
        100.0 * k as f64 / n as f64
    }
}

/// Wilson's 95 % score interval of a rate of `k` in `n`, % (`(0, 100)` for no runs).
pub fn wilson95_pct(k: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 100.0);
    }
    let (z, n) = (1.959_964, n as f64);
    let p = k as f64 / n;
    let centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let half = z / (1.0 + z * z / n) * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    (
        100.0 * (centre - half).max(0.0),
        100.0 * (centre + half).min(1.0),
    )
}

/// `n` (angle, noise seed) draws of the stream `seed + stream`.
fn draws(seed: u64, stream: u64, n: usize) -> Vec<(f64, u64)> {
    use rand::Rng;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed.wrapping_add(stream));
    (0..n)
        .map(|_| {
            let theta = -PI + 2.0 * PI * unit(&mut rng);
            (theta, rng.next_u64() >> 32)
        })
        .collect()
}

/// The preset of `motor` as a sensorless foc job from rest at `theta0`: no faults, no load,
/// no reference filter, foc started at 0.
fn job(motor: SuiteMotor, theta0: f64, seed: u64) -> Result<Scenario, SimError> {
    let mut sc = Scenario::preset(low_speed::preset_name(motor))?;
    sc.controller.kind = ControllerKind::Foc;
    sc.faults.clear();
    sc.load.clear();
    sc.observer.reference_filter = false;
    sc.initial.theta_e_rad = theta0;
    sc.initial.speed_rpm = 0.0;
    sc.seed = seed;
    let mut foc = sc.controller.foc.unwrap_or_default();
    foc.start_time_s = 0.0;
    foc.stop_time_s = None;
    sc.controller.foc = Some(foc);
    Ok(sc)
}

/// One start-up from `theta0` (rad el.) on noise seed `seed`.
pub fn startup_run(motor: SuiteMotor, theta0: f64, seed: u64) -> Result<StartupRun, SimError> {
    let mut sc = job(motor, theta0, seed)?;
    let target = STARTUP_SPEED_FRAC * sc.rated_speed_rpm;
    sc.name = format!("{} start from {:.1} deg", motor.name(), theta0.to_degrees());
    sc.speed_ref_rpm = Profile::linear(vec![(0.0, 0.0), (0.5, target), (STARTUP_END_S, target)]);
    sc.duration_s = STARTUP_END_S;
    let out = sim::run_with(
        &sc,
        RunOptions {
            inline_observers: true,
            ..RunOptions::default()
        },
    )?;
    let d = &out.metrics.drive;
    let failure = if let Some(f) = &d.fault {
        Some(f.clone())
    } else if !matches!(out.end, RunEnd::Completed) {
        Some(out.end.describe())
    } else if d.closed_loop_time_s.is_none() {
        Some("never closed the loop".into())
    } else if d.closed_loop_exits > 0 {
        Some(format!("left closed loop {} times", d.closed_loop_exits))
    } else if (d.final_speed_rpm - target).abs() > 0.25 * target {
        Some(format!(
            "final speed {:.0} rpm for {target:.0} rpm",
            d.final_speed_rpm
        ))
    } else {
        None
    };
    Ok(StartupRun {
        theta0_deg: theta0.to_degrees(),
        seed,
        success: failure.is_none(),
        backward_pct: out
            .metrics
            .startup
            .map_or(0.0, |s| s.backward_speed_max_pct),
        closed_loop_s: d.closed_loop_time_s,
        failure,
    })
}

/// Section 3: `n` start-ups (module docs).
pub fn startups(
    motor: SuiteMotor,
    n: usize,
    seed: u64,
    threads: usize,
) -> Result<StartupSweep, SimError> {
    let d = draws(seed, STARTUP_STREAM, n);
    let runs = all_ok(par_map(&d, threads, |&(th, s)| startup_run(motor, th, s)))?;
    Ok(StartupSweep { runs })
}

/// One HFI start.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HfiRun {
    /// Initial rotor angle, deg el.
    pub theta0_deg: f64,
    /// Noise seed.
    pub seed: u64,
    /// Right polarity (module docs).
    pub right: bool,
    /// Whether HFI flipped its first guess.
    pub flipped: bool,
    /// The polarity test's contrast (`HfiStatus::polarity_contrast`).
    pub contrast: f64,
    /// Largest |control-angle error| after the decision, deg el. (`NaN`: never tracked).
    pub max_error_deg: f64,
}

/// Section 4's sweep.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HfiSweep {
    /// Every run, in draw order.
    pub runs: Vec<HfiRun>,
}

impl HfiSweep {
    /// Right polarity, %.
    pub fn right_pct(&self) -> f64 {
        pct(
            self.runs.iter().filter(|r| r.right).count(),
            self.runs.len(),
        )
    }
}

/// foc with HFI: the first period HFI tracked and its last status.
struct HfiDrive {
    drive: FocDrive,
    ticks: usize,
    tracking_from: Option<usize>,
    last: Option<foc::HfiStatus>,
}

impl DriveController for HfiDrive {
    fn sensored(&self) -> bool {
        false
    }
    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
        let out = self.drive.tick(input);
        if let Some(s) = self.drive.foc().hfi_status() {
            if self.tracking_from.is_none() && s.phase == foc::HfiPhase::Tracking {
                self.tracking_from = Some(self.ticks);
            }
            self.last = Some(s);
        }
        self.ticks += 1;
        out
    }
}

/// `(t, |control angle error| deg)` of every period.
#[derive(Default)]
struct Errors(Vec<(f64, f64)>);

impl SampleSink for Errors {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        let e =
            (s.control.telemetry.theta_e_rad - s.truth.theta_e_rad + PI).rem_euclid(2.0 * PI) - PI;
        self.0.push((s.t_s, e.to_degrees().abs()));
        Ok(())
    }
}

/// One HFI start from `theta0` (rad el.) on noise seed `seed`.
pub fn hfi_run(motor: SuiteMotor, theta0: f64, seed: u64) -> Result<HfiRun, SimError> {
    let mut sc = job(motor, theta0, seed)?;
    sc.name = format!("{} HFI from {:.1} deg", motor.name(), theta0.to_degrees());
    sc.speed_ref_rpm = Profile::linear(vec![(0.0, 0.0), (HFI_END_S, 0.0)]);
    sc.duration_s = HFI_END_S;
    let refused = |field: &str, problem: String| SimError::Scenario {
        file: sc.name.clone(),
        field: field.into(),
        problem,
    };
    let fc = sc
        .foc_config()
        .map_err(|e| refused(&e.field, e.problem.clone()))?;
    let s = sc.controller.foc.unwrap_or_default();
    let mut drive = FocDrive::new(&fc, s.start_time_s, s.stop_time_s)
        .map_err(|e| refused("controller.foc", e.to_string()))?;
    let cfg = *drive.foc().config();
    let u_dc = sc.inverter.u_dc_v as f32;
    let hfi = foc::HfiConfig::with_current_noise(&cfg, u_dc, sc.sensors.current_noise_std_a as f32)
        .map_err(|e| refused("controller.foc (HFI)", e.to_string()))?;
    drive
        .foc_mut()
        .enable_hfi(&hfi, u_dc)
        .map_err(|e| refused("controller.foc (HFI)", e.to_string()))?;
    let mut d = HfiDrive {
        drive,
        ticks: 0,
        tracking_from: None,
        last: None,
    };
    let mut errors = Errors::default();
    sim::run_with_controller(
        &sc,
        &mut d,
        RunOptions {
            sinks: vec![&mut errors],
            d_saturation: Some(DSaturation {
                drop: 0.2,
                current_a: sc.controller.current_limit_a,
            }),
            inline_observers: true,
            ..RunOptions::default()
        },
    )?;
    let max_error_deg = d.tracking_from.map_or(f64::NAN, |k| {
        let t0 = k as f64 * sc.ts_s() + 0.02;
        errors
            .0
            .iter()
            .filter(|(t, _)| *t >= t0)
            .fold(0.0_f64, |m, (_, e)| m.max(*e))
    });
    let last = d.last.unwrap_or_default();
    Ok(HfiRun {
        theta0_deg: theta0.to_degrees(),
        seed,
        right: max_error_deg < POLARITY_TOLERANCE_DEG,
        flipped: last.polarity_flipped,
        contrast: f64::from(last.polarity_contrast),
        max_error_deg,
    })
}

/// Section 4: `n` HFI starts (module docs).
pub fn hfi_polarity(
    motor: SuiteMotor,
    n: usize,
    seed: u64,
    threads: usize,
) -> Result<HfiSweep, SimError> {
    let d = draws(seed, HFI_STREAM, n);
    let runs = all_ok(par_map(&d, threads, |&(th, s)| hfi_run(motor, th, s)))?;
    Ok(HfiSweep { runs })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_interval_known_answers() {
        // 61 of 1000: 4.8-7.8 % (Wilson score interval, z = 1.96).
        let (lo, hi) = wilson95_pct(61, 1000);
        assert!(
            (lo - 4.78).abs() < 0.01 && (hi - 7.76).abs() < 0.01,
            "{lo} {hi}"
        );
        let (lo, hi) = wilson95_pct(200, 200);
        assert!((lo - 98.12).abs() < 0.01 && hi > 99.999, "{lo} {hi}");
        assert_eq!(wilson95_pct(0, 0), (0.0, 100.0));
    }
}
