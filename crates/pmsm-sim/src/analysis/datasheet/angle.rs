//! Section 1: the observer's angle error against load and speed.
//!
//! One run per cell of a grid of speeds (% of rated) and loads (% of rated torque): the
//! low-speed table's run ([`crate::analysis::low_speed::scenario`]: foc sensorless from
//! standstill, up to 20 % of rated speed, an active load stepped on at 0.8 s, the reference
//! ramped to the test speed over 1.0-1.5 s) with the load set to the cell's level, held
//! [`SETTLE_S`] plus the window. In the window: the RMS angle error of foc's own observer
//! (the EKF that closes the loop, `wrap(theta_hat - theta)`, electrical degrees) and of the
//! simulator's f64 default EKF riding along on the same samples, and whether the loop stayed
//! closed all the way. The noise seed is the preset's (one run a cell: the grid is
//! deterministic).

use serde::Serialize;

use crate::SimError;
use crate::analysis::low_speed;
use crate::analysis::suite::SuiteMotor;
use crate::plant::load::LoadTerm;
use crate::sim::{self, RunOptions, Sample, SampleSink};

use super::{Sizes, all_ok, par_map};

/// Settling after the ramp to the test speed, before the window, s.
pub const SETTLE_S: f64 = 0.3;
/// End of the ramp to the test speed in the low-speed run, s.
const RAMP_END_S: f64 = 1.5;

/// One cell of the grid.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AngleCell {
    /// Test speed, % of rated.
    pub speed_pct: f64,
    /// Load, % of rated torque.
    pub load_pct: f64,
    /// RMS angle error of foc's observer over the window, deg el.
    pub angle_error_rms_deg: f64,
    /// RMS angle error of the simulator's default EKF over the window, deg el.
    pub ekf_angle_error_rms_deg: f64,
    /// Share of the window in closed loop, %.
    pub closed_loop_pct: f64,
    /// The drive's fault, if any.
    pub fault: Option<String>,
    /// Closed loop over the whole window and no fault.
    pub held: bool,
}

/// The grid, speeds fastest-varying within each load.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AngleGrid {
    /// Speeds, % of rated.
    pub speeds_pct: Vec<f64>,
    /// Loads, % of rated torque.
    pub loads_pct: Vec<f64>,
    /// Window length, s.
    pub window_s: f64,
    /// Noise seed of every run (the preset's).
    pub seed: u64,
    /// One cell per (load, speed), load-major.
    pub cells: Vec<AngleCell>,
}

impl AngleGrid {
    /// The cells at `load_pct`, by speed.
    pub fn at_load(&self, load_pct: f64) -> impl Iterator<Item = &AngleCell> {
        self.cells.iter().filter(move |c| c.load_pct == load_pct)
    }

    /// The largest RMS error over the cells that held (`None`: none held).
    pub fn worst_held(&self) -> Option<&AngleCell> {
        self.cells
            .iter()
            .filter(|c| c.held)
            .max_by(|a, b| a.angle_error_rms_deg.total_cmp(&b.angle_error_rms_deg))
    }
}

/// Window accumulator of one cell.
struct Window {
    t0: f64,
    n: usize,
    closed: usize,
    sum_e2: f64,
    sum_ekf2: f64,
}

impl SampleSink for Window {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        if s.t_s < self.t0 - 1e-9 {
            return Ok(());
        }
        self.n += 1;
        self.closed += usize::from(s.control.telemetry.closed_loop);
        if let Some(o) = &s.controller_observer {
            self.sum_e2 += o.angle_error_deg * o.angle_error_deg;
        }
        self.sum_ekf2 += s.observer.angle_error_deg * s.observer.angle_error_deg;
        Ok(())
    }
}

/// Runs one cell.
pub fn run_cell(
    motor: SuiteMotor,
    speed_pct: f64,
    load_pct: f64,
    window_s: f64,
) -> Result<AngleCell, SimError> {
    let mut sc = low_speed::scenario(motor, speed_pct, SETTLE_S + window_s)?;
    sc.name = format!(
        "{} at {speed_pct} % rated speed, {load_pct} % rated torque",
        motor.name()
    );
    sc.observer.reference_filter = false;
    let load = load_pct / 100.0 * sc.rated_torque_nm;
    for term in &mut sc.load {
        if let LoadTerm::Step { after_nm, .. } = term {
            *after_nm = load;
        }
    }
    let mut win = Window {
        t0: RAMP_END_S + SETTLE_S,
        n: 0,
        closed: 0,
        sum_e2: 0.0,
        sum_ekf2: 0.0,
    };
    let out = sim::run_with(
        &sc,
        RunOptions {
            sinks: vec![&mut win],
            inline_observers: true,
            ..RunOptions::default()
        },
    )?;
    let n = win.n.max(1) as f64;
    let fault = out.metrics.drive.fault.clone();
    let held = fault.is_none() && win.n > 0 && win.closed == win.n;
    Ok(AngleCell {
        speed_pct,
        load_pct,
        angle_error_rms_deg: (win.sum_e2 / n).sqrt(),
        ekf_angle_error_rms_deg: (win.sum_ekf2 / n).sqrt(),
        closed_loop_pct: 100.0 * win.closed as f64 / n,
        fault,
        held,
    })
}

/// The grid of `sizes` on `threads` threads.
pub fn run(motor: SuiteMotor, sizes: &Sizes, threads: usize) -> Result<AngleGrid, SimError> {
    let cells: Vec<(f64, f64)> = sizes
        .angle_loads_pct
        .iter()
        .flat_map(|&l| sizes.angle_speeds_pct.iter().map(move |&s| (l, s)))
        .collect();
    let window = sizes.angle_window_s;
    let cells = all_ok(par_map(&cells, threads, |&(load, speed)| {
        run_cell(motor, speed, load, window)
    }))?;
    let seed = crate::scenario::Scenario::preset(low_speed::preset_name(motor))?.seed;
    Ok(AngleGrid {
        speeds_pct: sizes.angle_speeds_pct.clone(),
        loads_pct: sizes.angle_loads_pct.clone(),
        window_s: window,
        seed,
        cells,
    })
}
