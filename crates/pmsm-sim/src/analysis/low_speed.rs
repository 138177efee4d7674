//! The low-speed table (`pmsm-sim low-speed`): for each reference motor, the
//! lowest speed at which `foc` sensorless runs closed loop under rated load for
//! [`HOLD_S`] without a fall-back, with the current it draws per rated-torque current.
//!
//! # One run
//!
//! The motor's simulator preset (`default` for the servo, `industrial-2k2`, `drone`,
//! `industrial-ipm`, `traction-ipm`: plant, inverter with delay and dead time, sensing) with
//! `foc` sensorless (its defaults of [`Scenario::foc_config`], closed-loop reversal) and:
//!
//! ```text
//! 0      start; reference 0 -> 20 % rated over 0.5 s (align, I/f, hand-over on the way)
//! 0.8 s  rated active (constant) load, braking the forward rotation
//! 1.0 s  reference ramp down to the test speed over 0.5 s
//! 1.5 s  held for HOLD_S (the window), end
//! ```
//!
//! The exit speed of `foc` (below which closed loop returns to I/f for a slow command) is
//! set to half the test speed (`exit_speed_ratio`, at least foc's floor of 0.01 of the
//! hand-over speed): the run asks whether the observer carries the loop there, not where the
//! default hysteresis sits.
//!
//! **The default drive** ([`default_drive_scenario`]): the same job with the drive's own exit
//! speed (`foc::StartupConfig::exit_speed_ratio_for`: 1.5 % of rated speed, 1.5 times the
//! table's worst lowest speed, 1 % on industrial_2k2; half the damped start's hand-over at 3 %
//! of rated, `StartupConfig::handover_speed_for`): at 3 % of rated it stays in closed loop
//! (the test
//! `tests/lowspeed_defaults.rs`).
//!
//! **Pass** at a speed: no fault, closed loop in every period of the window (no exit, no
//! fall-back), and the mean true speed over the window within [`SPEED_TOLERANCE`] of the
//! test speed. The **lowest speed** of a motor is the lowest of [`SPEEDS_PCT`] down to which
//! every listed speed passes (a pass below a failure is shown in the table but does not
//! count).
//!
//! **Current per torque**: the RMS of the current vector's magnitude over the window against
//! the current that makes the rated torque (`T / k_t` on a surface motor; the MTPA current's
//! magnitude on an interior one). Friction and the angle error raise it above 1.
//!
//! Goals (surface motors): lowest speed at most [`GOAL_SPEED_PCT`] of rated, current ratio at
//! most [`GOAL_CURRENT_RATIO`] there.

use serde::Serialize;

use crate::SimError;
use crate::analysis::suite::SuiteMotor;
use crate::plant::load::{LoadTerm, Profile};
use crate::scenario::{ControllerKind, Scenario};
use crate::sim::{self, RunOptions, Sample, SampleSink};

/// Test speeds, % of rated, from the top.
pub const SPEEDS_PCT: [f64; 9] = [10.0, 7.0, 5.0, 3.0, 2.0, 1.5, 1.0, 0.7, 0.5];
/// Time held at the test speed under rated load, s.
pub const HOLD_S: f64 = 10.0;
/// The mean speed over the window must lie within this fraction of the test speed.
pub const SPEED_TOLERANCE: f64 = 0.25;
/// Goal for the surface motors: lowest closed-loop speed, % of rated.
pub const GOAL_SPEED_PCT: f64 = 2.0;
/// Goal for the surface motors: RMS current / rated-torque current at that speed.
pub const GOAL_CURRENT_RATIO: f64 = 1.15;

/// Start of the window (end of the ramp to the test speed), s.
const WINDOW_START_S: f64 = 1.5;

/// The simulator preset of a reference motor.
pub fn preset_name(motor: SuiteMotor) -> &'static str {
    match motor {
        SuiteMotor::Servo => "default",
        SuiteMotor::Industrial2k2 => "industrial-2k2",
        SuiteMotor::SmallFast => "drone",
        SuiteMotor::IndustrialIpm => "industrial-ipm",
        SuiteMotor::TractionIpm => "traction-ipm",
    }
}

/// The run of `motor` at `speed_pct` % of rated speed (module docs), held `hold_s`.
pub fn scenario(motor: SuiteMotor, speed_pct: f64, hold_s: f64) -> Result<Scenario, SimError> {
    let mut sc = Scenario::preset(preset_name(motor))?;
    let rated = sc.rated_speed_rpm;
    let speed = speed_pct / 100.0 * rated;
    sc.name = format!("{} at {speed_pct} % rated", motor.name());
    sc.controller.kind = ControllerKind::Foc;
    sc.faults.clear();
    sc.speed_ref_rpm = Profile::linear(vec![
        (0.0, 0.0),
        (0.5, 0.2 * rated),
        (1.0, 0.2 * rated),
        (WINDOW_START_S, speed),
    ]);
    sc.load = vec![LoadTerm::Step {
        time_s: 0.8,
        before_nm: 0.0,
        after_nm: sc.rated_torque_nm,
    }];
    sc.duration_s = WINDOW_START_S + hold_s;
    let mut foc = sc.controller.foc.unwrap_or_default();
    foc.start_time_s = 0.0;
    foc.stop_time_s = None;
    sc.controller.foc = Some(foc);
    // The exit speed at half the test speed (foc's floor 0.01 of the hand-over speed).
    let cfg = foc_config(&sc)?;
    let handover_rpm = f64::from(cfg.startup.handover_speed_rad_s) / f64::from(sc.motor.pole_pairs)
        * crate::scenario::RPM_PER_RAD_S;
    foc.exit_speed_ratio = Some((0.5 * speed / handover_rpm).clamp(0.01, 0.7));
    sc.controller.foc = Some(foc);
    Ok(sc)
}

/// The same job with the drive's own defaults (module docs, "The default drive"): foc's
/// exit speed (1.5 % of rated speed) instead of the table's half test speed.
pub fn default_drive_scenario(
    motor: SuiteMotor,
    speed_pct: f64,
    hold_s: f64,
) -> Result<Scenario, SimError> {
    let mut sc = scenario(motor, speed_pct, hold_s)?;
    sc.name = format!("{} at {speed_pct} % rated, default drive", motor.name());
    let mut foc = sc.controller.foc.unwrap_or_default();
    foc.exit_speed_ratio = None;
    sc.controller.foc = Some(foc);
    Ok(sc)
}

/// foc's configuration of `sc`, its refusal as a scenario error.
fn foc_config(sc: &Scenario) -> Result<foc::FocConfig, SimError> {
    sc.foc_config().map_err(|e| SimError::Scenario {
        file: sc.name.clone(),
        field: e.field,
        problem: e.problem,
    })
}

/// The current vector magnitude that makes the rated torque of `sc`'s motor, A.
pub fn rated_torque_current_a(sc: &Scenario) -> Result<f64, SimError> {
    let cfg = foc_config(sc)?;
    let kt = cfg.torque_constant_nm_a();
    let i = foc::Mtpa::new(&cfg.motor).currents_for_torque(sc.rated_torque_nm as f32 / kt);
    Ok(f64::from(i.d.hypot(i.q)))
}

/// The figures of one run over its window.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LowSpeedRun {
    /// Test speed, % of rated.
    pub speed_pct: f64,
    /// Test speed, mechanical rpm.
    pub speed_rpm: f64,
    /// Whether it passed (module docs).
    pub pass: bool,
    /// Share of the window in closed loop, %.
    pub closed_loop_pct: f64,
    /// Exits from closed loop in the window.
    pub exits: usize,
    /// Mean true speed over the window, rpm.
    pub mean_speed_rpm: f64,
    /// RMS of `speed - test speed` over the window, rpm.
    pub speed_error_rms_rpm: f64,
    /// RMS current magnitude over the window / rated-torque current.
    pub current_ratio: f64,
    /// RMS angle error of foc's observer over the window, deg el.
    pub angle_error_rms_deg: f64,
    /// The first fault, if any.
    pub fault: Option<String>,
}

/// The row of one motor: every speed tried and the lowest passing one.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LowSpeedRow {
    /// The motor.
    pub motor: SuiteMotor,
    /// Rated speed, rpm.
    pub rated_speed_rpm: f64,
    /// Rated-torque current, A.
    pub rated_torque_current_a: f64,
    /// One run per speed of [`SPEEDS_PCT`].
    pub runs: Vec<LowSpeedRun>,
    /// The lowest speed down to which every listed speed passes (`None`: not even the first).
    pub lowest: Option<LowSpeedRun>,
}

impl LowSpeedRow {
    /// Whether the goals hold (surface motors; `None` for an interior one).
    pub fn meets_goal(&self) -> Option<bool> {
        if self.motor.is_interior() {
            return None;
        }
        Some(self.lowest.as_ref().is_some_and(|l| {
            l.speed_pct <= GOAL_SPEED_PCT + 1e-9 && l.current_ratio <= GOAL_CURRENT_RATIO
        }))
    }
}

/// Window accumulator.
#[derive(Default)]
struct Window {
    speed_rpm: f64,
    n: usize,
    closed: usize,
    exits: usize,
    was_closed: bool,
    sum_w: f64,
    sum_ew2: f64,
    sum_i2: f64,
    sum_e2: f64,
}

impl SampleSink for Window {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        if s.t_s < WINDOW_START_S - 1e-9 {
            self.was_closed = s.control.telemetry.closed_loop;
            return Ok(());
        }
        let closed = s.control.telemetry.closed_loop;
        self.n += 1;
        self.closed += usize::from(closed);
        self.exits += usize::from(self.was_closed && !closed);
        self.was_closed = closed;
        let w = s.truth.speed_rpm;
        self.sum_w += w;
        self.sum_ew2 += (w - self.speed_rpm).powi(2);
        let [a, b] = s.truth.i_ab_a;
        self.sum_i2 += a * a + b * b;
        if let Some(o) = &s.controller_observer {
            self.sum_e2 += o.angle_error_deg * o.angle_error_deg;
        }
        Ok(())
    }
}

/// Runs `motor` at `speed_pct` % of rated for `hold_s` (module docs).
pub fn run_speed(motor: SuiteMotor, speed_pct: f64, hold_s: f64) -> Result<LowSpeedRun, SimError> {
    run_scenario(&scenario(motor, speed_pct, hold_s)?, speed_pct)
}

/// Runs `sc`, a run of [`scenario`] or [`default_drive_scenario`] at `speed_pct` % of rated,
/// and measures its window.
pub fn run_scenario(sc: &Scenario, speed_pct: f64) -> Result<LowSpeedRun, SimError> {
    let i_rated = rated_torque_current_a(sc)?;
    let speed_rpm = speed_pct / 100.0 * sc.rated_speed_rpm;
    let mut win = Window {
        speed_rpm,
        ..Window::default()
    };
    let out = sim::run_with(
        sc,
        RunOptions {
            sinks: vec![&mut win],
            ..RunOptions::default()
        },
    )?;
    let n = win.n.max(1) as f64;
    let mean = win.sum_w / n;
    let fault = out.metrics.drive.fault.clone();
    let closed_loop_pct = 100.0 * win.closed as f64 / n;
    let pass = fault.is_none()
        && win.n > 0
        && win.closed == win.n
        && (mean - speed_rpm).abs() <= SPEED_TOLERANCE * speed_rpm;
    Ok(LowSpeedRun {
        speed_pct,
        speed_rpm,
        pass,
        closed_loop_pct,
        exits: win.exits,
        mean_speed_rpm: mean,
        speed_error_rms_rpm: (win.sum_ew2 / n).sqrt(),
        current_ratio: (win.sum_i2 / n).sqrt() / i_rated,
        angle_error_rms_deg: (win.sum_e2 / n).sqrt(),
        fault,
    })
}

/// The row of `motor` over `speeds_pct` (from the top), each held `hold_s`.
pub fn run_motor(
    motor: SuiteMotor,
    speeds_pct: &[f64],
    hold_s: f64,
) -> Result<LowSpeedRow, SimError> {
    let sc = scenario(motor, speeds_pct.first().copied().unwrap_or(10.0), hold_s)?;
    let mut runs = vec![];
    let mut lowest = None;
    let mut unbroken = true;
    for &pct in speeds_pct {
        let r = run_speed(motor, pct, hold_s)?;
        if r.pass && unbroken {
            lowest = Some(r.clone());
        } else {
            unbroken = false;
        }
        runs.push(r);
    }
    Ok(LowSpeedRow {
        motor,
        rated_speed_rpm: sc.rated_speed_rpm,
        rated_torque_current_a: rated_torque_current_a(&sc)?,
        runs,
        lowest,
    })
}

/// The table of `rows` in markdown: the summary (lowest speed, current ratio, goal) and every
/// run.
pub fn to_markdown(rows: &[LowSpeedRow]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Low speed: lowest closed-loop speed under rated load ({HOLD_S} s held, no fall-back)\n"
    );
    let _ = writeln!(
        s,
        "| motor | rated (rpm) | lowest speed (% rated) | (rpm) | RMS current / rated-torque current | goal (<= {GOAL_SPEED_PCT} %, <= {GOAL_CURRENT_RATIO}) |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for r in rows {
        let (pct, rpm, ratio) = match &r.lowest {
            Some(l) => (
                format!("{}", l.speed_pct),
                format!("{:.1}", l.speed_rpm),
                format!("{:.3}", l.current_ratio),
            ),
            None => ("none".into(), "-".into(), "-".into()),
        };
        let goal = match r.meets_goal() {
            Some(true) => "met",
            Some(false) => "MISSED",
            None => "- (interior)",
        };
        let _ = writeln!(
            s,
            "| {} | {:.0} | {pct} | {rpm} | {ratio} | {goal} |",
            r.motor.name(),
            r.rated_speed_rpm
        );
    }
    let _ = writeln!(s, "\n### Every run\n");
    let _ = writeln!(
        s,
        "| motor | speed (% rated) | (rpm) | pass | closed loop (% window) | exits | mean speed (rpm) | speed error RMS (rpm) | current ratio | angle error RMS (deg) | fault |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        for x in &r.runs {
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} | {} | {:.1} | {} | {:.2} | {:.2} | {:.3} | {:.2} | {} |",
                r.motor.name(),
                x.speed_pct,
                x.speed_rpm,
                if x.pass { "yes" } else { "no" },
                x.closed_loop_pct,
                x.exits,
                x.mean_speed_rpm,
                x.speed_error_rms_rpm,
                x.current_ratio,
                x.angle_error_rms_deg,
                x.fault.as_deref().unwrap_or("none"),
            );
        }
    }
    s
}
