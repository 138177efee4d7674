//! Replay of a recorded drive: a user's own log (CSV, documented below) or a `pmsm-sim` MCAP
//! log, run through the default EKF ([`ekf_core::PmsmObserver`] with
//! [`ekf_core::ObserverConfig::new`]), the drive observer ([`ekf_core::DriveObserver`] with
//! [`ekf_core::DriveConfig::new`]: acceleration, voltage lead, resistance error and dead-time
//! voltage as states) and the flux + PLL baseline ([`ekf_core::FluxObserver`]), scored against
//! the log's reference angle when it has one.
//!
//! # The CSV format
//!
//! A header row, then one row per current sample, comma separated. Columns by name (any
//! order; other columns are ignored, but every row must have as many cells as the header):
//!
//! | column | unit | meaning |
//! |---|---|---|
//! | `t_s` | s | time stamp of the current sample |
//! | `dt_s` | s | the control period that **ended** at this sample (> 0) |
//! | `u_alpha_v`, `u_beta_v` | V | the commanded alpha-beta voltage of the period that **ended** at this sample |
//! | `i_alpha_a`, `i_beta_a` | A | stator currents sampled at this sample |
//! | `theta_ref_rad` | rad | optional: reference electrical angle (encoder); never an input |
//! | `omega_ref_rad_s` | rad/s | optional: reference electrical speed; never an input |
//!
//! Every used cell must be a finite number. A malformed file (missing column, a cell that is
//! not a number or not finite, a row with the wrong number of cells, `dt_s <= 0`, no data
//! row) is a [`ReplayError::Csv`] naming the line and the column (both 1-based).
//!
//! # Alignment
//!
//! The project's convention (crate README): row `k` of `u_ab` is the voltage held over
//! `[t_k, t_k+1)`, and the estimate at `k` predicts with `u_ab[k-1]` over the period that
//! ended at `t_k`. A CSV row carries the voltage of the period that ended at it, so
//! [`DriveLog`] holds `u_ab[k] = u_csv[k+1]` (the last row repeated), `u_prev = u_csv[0]` (the
//! voltage before row 0) and `dt_s[k] = dt_csv[k]`, the period that ended at row `k`.
//!
//! A row the EKF refuses (a non-finite sample, or a corrupted one: module docs of
//! `ekf_core::observer`, "Implausible input") is a skipped cycle: its period joins the next
//! row's, and it reports the estimate with the angle advanced to its time (status REJECTED).
//!
//! # Scaling
//!
//! [`Scaling::Amplitude`] (default): the amplitude-invariant Clarke transform of the project.
//! [`Scaling::Power`]: the log used the power-invariant transform, whose values are
//! `sqrt(3/2)` times larger; voltages and currents are divided by `sqrt(3/2)` on reading.
//!
//! # MCAP logs of `pmsm-sim run`
//!
//! [`read_log`] also reads the simulator's own logs: `u_ab` is the voltage the simulator's
//! observer was given, `i_ab` the measured currents, `dt_s = Ts`, `u_prev = 0`, and the
//! reference is the true angle and speed. A corrupt file is an error, never a panic.
//!
//! # Scoring ([`score`])
//!
//! Over the samples with `|omega_ref| >= 10 %` of the run's largest `|omega_ref|`, leaving
//! out the 20 ms after each period longer than `1.35 Ts` (`round(0.02 / Ts)` rows from that
//! row on): the angle error `wrap(theta_hat - theta_ref)` (a non-finite estimate counts as
//! 180 deg), minus its circular mean over those samples (the reference's constant mounting
//! offset; reported), in electrical degrees. Reported: RMS, max, the share of samples more
//! than 45 deg off, the share of samples in each status, and the samples with status
//! TRACKING while more than 45 deg off. The three observers are scored alike. The drive
//! observer's status is TRACKING when its estimate says `tracking`, else UNCERTAIN. The flux
//! baseline has no confidence measure: its status is UNCERTAIN on every accepted sample (it
//! never claims TRACKING).
//!
//! Two diagnostics of the default EKF's error say where it comes from: the part that repeats
//! with the reference's mechanical angle (module `reference`: the encoder's own error), and
//! its split by speed band and direction with a fit to a d-axis voltage the model lacks and a
//! timing (module `speed_bands`).
//!
//! # Two passes: the record's calibration
//!
//! The drive observer's estimates of the voltage lead, the resistance and the dead-time
//! voltage, averaged over the record ([`ekf_core::RecordCalibration`]: its tracked samples,
//! weighted by the speed squared), are told to the default EKF with the acceleration
//! feedforward, which runs over the record again ([`run_ekf_calibrated`]): the row "EKF +
//! feedforward told the record's calibration". It is what a
//! user does with a log of a drive whose timing and inverter are unknown: replay it once to
//! find them, then set them (`voltage_delay_s`, `rs_ohm`, `inverter_voltage_v`). The row
//! "calibration online" does it while it runs ([`run_ekf_online`]): the drive observer runs
//! alongside and its running calibration is handed to the EKF with the feedforward while it
//! runs (module `ekf_core::calibration`, "Online"); the rows before the first hand-over run on
//! the voltage delay a first pass over the record handed over last (the same module, "Primed
//! by the record") and the motor file's other values.
//!
//! # Outputs of a replay ([`write_outputs`])
//!
//! The MCAP log and the plot reuse the simulator's record ([`Sample`]); the fields a replay
//! cannot fill are: `truth` = the reference (angle, speed, the currents rotated by the
//! reference angle; `NaN` without a reference), `truth.torque_nm` and `load_torque_nm` `NaN`,
//! `truth.psi_f_wb` / `rs_ohm` the configured motor's; `measured.u_dc_v` `NaN`;
//! `observer` the default EKF; `controller_observer` the **flux + PLL baseline** (the plot
//! labels it as the controller's observer); `seed_filter` absent (the drive observer is
//! scored in `metrics.json` and the table, not logged); `control` zero except
//! `telemetry.state` (`replay`) and `speed_ref_rpm` (the reference speed, 0 without);
//! `inverter.u_ab_commanded_v` = `u_ab[k]`, the other inverter fields 0. The observers'
//! `angle_error_deg` is the error with that observer's offset removed. Log times are
//! `k Ts` (the row's own time is `t_s`); the scenario message is a placeholder with the
//! motor and `Ts` (the default scenario otherwise).

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use ekf_core::{
    AccelerationFeedforward, Calibration, DriveConfig, DriveObserver, FluxObserver,
    FluxObserverConfig, MotorParams, ObserverConfig, PmsmObserver, RecordCalibration, Status,
    wrap_angle,
};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::output::metrics::rpm;
use crate::output::record::{ControllerTelemetry, ObserverSample, Sample};
use crate::sim::SampleSink;

/// Share of the run's largest `|omega_ref|` below which a sample is not scored.
pub const MIN_SPEED_SHARE: f64 = 0.1;
/// A period longer than this many `Ts` is a skipped cycle: the window after it is not scored.
pub const LONG_PERIOD_TS: f64 = 1.35;
/// Time not scored after a long period, s.
pub const SKIP_AFTER_LONG_S: f64 = 0.02;
/// Angle error above which a sample counts as lost, electrical degrees (the simulator's).
pub use crate::output::metrics::LOST_DEG;

mod input;
pub use input::*;
mod reference;
pub use reference::{MechanicalComponent, mechanical_component};
mod flux_check;
pub use flux_check::{FLUX_WARN_SHARE, FluxCheck, flux_check};
mod speed_bands;
pub use speed_bands::{BAND_EDGES, SpeedBand, SpeedBands, speed_bands};

/// Why a log or motor file could not be read, or a replay not run.
#[derive(Debug, Error)]
pub enum ReplayError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A malformed CSV log.
    #[error("{file}: line {line}, column {column}: {problem}")]
    Csv {
        /// The file.
        file: String,
        /// Line, 1-based.
        line: usize,
        /// Column (cell), 1-based.
        column: usize,
        /// What is wrong.
        problem: String,
    },
    /// An MCAP log that is not a readable `pmsm-sim` log.
    #[error("{file}: {message}")]
    Mcap {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A malformed or invalid motor file.
    #[error("{file}: {problem}")]
    Motor {
        /// The file.
        file: String,
        /// What is wrong (with line and column for a TOML syntax error).
        problem: String,
    },
    /// A [`DriveLog`] whose arrays differ in length or hold a bad period.
    #[error("inconsistent log: {0}")]
    Inconsistent(String),
    /// The observer refused its configuration.
    #[error("observer configuration refused: {0}")]
    Config(#[from] ekf_core::ConfigError),
    /// Writing an output failed.
    #[error("{path}: {message}")]
    Output {
        /// The file.
        path: String,
        /// What failed.
        message: String,
    },
}

/// Status of a replayed sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReplayStatus {
    /// The observer trusts its angle.
    Tracking,
    /// The observer ran but does not trust its angle.
    Uncertain,
    /// The sample was refused (the estimate is the previous one).
    Rejected,
}

/// One observer's outputs over a log.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObserverTrace {
    /// Electrical angle, rad.
    pub theta: Vec<f64>,
    /// Electrical speed, rad/s.
    pub omega: Vec<f64>,
    /// Status per row.
    pub status: Vec<ReplayStatus>,
    /// The record's sample per row (covariance, NIS, tracked parameters; the angle error is
    /// filled by [`replay`]).
    pub samples: Vec<ObserverSample>,
}

/// The rows of `log` as an observer steps on them: `(u_prev, i, dt)`, row `k` predicted with
/// the voltage of row `k - 1` (`log.u_prev` for row 0) over its own period.
fn rows(log: &DriveLog) -> impl Iterator<Item = ([f64; 2], [f64; 2], f64)> + Clone + '_ {
    (0..log.len()).map(|k| {
        let u_prev = if k == 0 { log.u_prev } else { log.u_ab[k - 1] };
        (u_prev, log.i_ab[k], log.dt_s[k])
    })
}

/// Steps an observer over `log` (row `k` predicts with the voltage of the period before it,
/// over the period that ended at it, and corrects with its currents): `step(u_prev, i, dt)`
/// gives the row's sample (angle error not filled) and status.
fn trace(
    log: &DriveLog,
    mut step: impl FnMut([f64; 2], [f64; 2], f64) -> (ObserverSample, ReplayStatus),
) -> ObserverTrace {
    let n = log.len();
    let mut tr = ObserverTrace {
        theta: Vec::with_capacity(n),
        omega: Vec::with_capacity(n),
        status: Vec::with_capacity(n),
        samples: Vec::with_capacity(n),
    };
    for (u_prev, i, dt) in rows(log) {
        let (sample, status) = step(u_prev, i, dt);
        tr.theta.push(sample.theta_e_rad);
        tr.omega.push(sample.omega_e_rad_s);
        tr.status.push(status);
        tr.samples.push(sample);
    }
    tr
}

/// Runs the default EKF (`ObserverConfig::new(motor, ts)` with the motor file's
/// `voltage_delay_s` and `inverter_voltage_v`) over `log`.
pub fn run_ekf(log: &DriveLog, motor: &ReplayMotor) -> Result<ObserverTrace, ReplayError> {
    run_ekf_with(log, motor, false)
}

/// [`run_ekf`], with the acceleration feedforward
/// ([`ekf_core::AccelerationFeedforward::default_for`]) when `feedforward`.
pub fn run_ekf_with(
    log: &DriveLog,
    motor: &ReplayMotor,
    feedforward: bool,
) -> Result<ObserverTrace, ReplayError> {
    let cfg = if feedforward {
        feedforward_config(motor)
    } else {
        default_config(motor)
    };
    run_ekf_config(log, &cfg)
}

/// The default EKF's configuration for a replay: `ObserverConfig::new(motor, ts)` with the
/// motor file's `voltage_delay_s` and `inverter_voltage_v`.
fn default_config(motor: &ReplayMotor) -> ObserverConfig<f64> {
    ObserverConfig {
        voltage_delay_s: motor.voltage_delay_s,
        inverter_voltage_v: motor.inverter_voltage_v,
        ..ObserverConfig::new(motor.params, motor.ts_s)
    }
}

/// [`default_config`] with the acceleration feedforward
/// ([`ekf_core::AccelerationFeedforward::default_for`]).
fn feedforward_config(motor: &ReplayMotor) -> ObserverConfig<f64> {
    ObserverConfig {
        acceleration_feedforward: Some(AccelerationFeedforward::default_for(
            &motor.params,
            motor.ts_s,
        )),
        ..default_config(motor)
    }
}

/// The default EKF with the acceleration feedforward, told the record's calibration (module
/// `ekf_core::calibration`: the drive observer's input errors; the second of two passes):
/// its trace.
pub fn run_ekf_calibrated(
    log: &DriveLog,
    motor: &ReplayMotor,
    cal: &Calibration<f64>,
) -> Result<ObserverTrace, ReplayError> {
    run_ekf_config(log, &cal.apply(&feedforward_config(motor)))
}

/// The default EKF with the acceleration feedforward and the online input calibration
/// (`ObserverConfig::input_calibration`: the drive observer's lead, dead-time voltage and `Rs`
/// handed over while it runs), primed by the record (the voltage delay a first pass handed over
/// last, `PmsmObserver::prime_input_calibration`), as `pyfoc.Ekf`'s defaults run: its trace.
pub fn run_ekf_online(log: &DriveLog, motor: &ReplayMotor) -> Result<ObserverTrace, ReplayError> {
    let cfg = ObserverConfig {
        input_calibration: true,
        ..feedforward_config(motor)
    };
    log.check()?;
    let mut obs = PmsmObserver::new(&cfg)?;
    obs.prime_input_calibration(rows(log));
    Ok(run_ekf_observer(log, obs))
}

/// Steps a [`PmsmObserver`] built from `cfg` over `log`.
fn run_ekf_config(log: &DriveLog, cfg: &ObserverConfig<f64>) -> Result<ObserverTrace, ReplayError> {
    log.check()?;
    Ok(run_ekf_observer(log, PmsmObserver::new(cfg)?))
}

/// Steps `obs` over `log` (checked).
fn run_ekf_observer(log: &DriveLog, mut obs: PmsmObserver<f64>) -> ObserverTrace {
    let mut skipped = ekf_core::observer::SkippedCycles::default();
    trace(log, |u_prev, i, dt| {
        // The period that ended at this row (refused beyond 64 Ts: a rejected row); a refused
        // row is a skipped cycle (`ekf_core::observer::SkippedCycles`).
        let r = skipped.step(dt, |d| obs.step_dt(u_prev, i, d));
        let (e, status) = match r {
            Ok(e) => (
                e,
                match e.status {
                    Status::Tracking => ReplayStatus::Tracking,
                    Status::Uncertain => ReplayStatus::Uncertain,
                },
            ),
            Err(_) => {
                let mut e = obs.estimate();
                e.theta_rad = skipped.advance(e.theta_rad, e.omega_e_rad_s);
                (e, ReplayStatus::Rejected)
            }
        };
        let p = obs.covariance();
        let sample = ObserverSample {
            theta_e_rad: e.theta_rad,
            omega_e_rad_s: e.omega_e_rad_s,
            angle_error_deg: f64::NAN,
            speed_error_rad_s: f64::NAN,
            p_diag: [p[(0, 0)], p[(1, 1)], p[(2, 2)], p[(3, 3)]],
            nis: e.nis,
            tracking: status == ReplayStatus::Tracking,
            psi_f_wb: e.psi_f_wb,
            psi_f_sigma_wb: e.psi_f_sigma_wb,
            rs_ohm: e.rs_ohm,
            rs_sigma_ohm: e.rs_sigma_ohm,
            winding_temperature_c: e.winding_temperature_c,
        };
        (sample, status)
    })
}

/// Runs the flux + PLL baseline (`FluxObserverConfig::new(motor, ts)`) over `log`. It has a
/// fixed step: every period is taken as the nominal `Ts`. Status: UNCERTAIN on every accepted
/// sample (it has no confidence measure, so it never claims TRACKING), REJECTED on a refused
/// one.
pub fn run_flux(log: &DriveLog, motor: &ReplayMotor) -> Result<ObserverTrace, ReplayError> {
    log.check()?;
    let cfg = FluxObserverConfig::new(motor.params, motor.ts_s);
    let mut obs = FluxObserver::new(&cfg)?;
    let (psi, rs) = obs.parameters();
    Ok(trace(log, |u_prev, i, _dt| {
        let (e, status) = match obs.step(u_prev, i) {
            Ok(e) => (e, ReplayStatus::Uncertain),
            Err(_) => (obs.estimate(), ReplayStatus::Rejected),
        };
        let sample = ObserverSample {
            theta_e_rad: e.theta_rad,
            omega_e_rad_s: e.omega_e_rad_s,
            angle_error_deg: f64::NAN,
            speed_error_rad_s: f64::NAN,
            p_diag: [f64::NAN; 4],
            nis: f64::NAN,
            tracking: status == ReplayStatus::Tracking,
            psi_f_wb: psi,
            psi_f_sigma_wb: 0.0,
            rs_ohm: rs,
            rs_sigma_ohm: 0.0,
            winding_temperature_c: f64::NAN,
        };
        (sample, status)
    }))
}

/// Runs the drive observer (`DriveConfig::new(motor, ts)`) over `log`, each row over its own
/// period (refused beyond 64 Ts: a rejected row). Status: TRACKING when the estimate says
/// `tracking`, else UNCERTAIN; REJECTED on a refused sample.
pub fn run_drive(log: &DriveLog, motor: &ReplayMotor) -> Result<ObserverTrace, ReplayError> {
    run_drive_calibrated(log, motor).map(|(tr, _)| tr)
}

/// [`run_drive`], and the record's calibration from its estimates
/// ([`RecordCalibration`]; `None` when it never tracked).
pub fn run_drive_calibrated(
    log: &DriveLog,
    motor: &ReplayMotor,
) -> Result<(ObserverTrace, Option<Calibration<f64>>), ReplayError> {
    log.check()?;
    let cfg = DriveConfig::new(motor.params, motor.ts_s);
    let mut obs = DriveObserver::new(&cfg)?;
    let mut cal = RecordCalibration::new();
    let tr = trace(log, |u_prev, i, dt| {
        let (e, status) = match obs.step_dt(u_prev, i, dt) {
            Ok(e) if e.tracking => (e, ReplayStatus::Tracking),
            Ok(e) => (e, ReplayStatus::Uncertain),
            Err(_) => (obs.estimate(), ReplayStatus::Rejected),
        };
        if status != ReplayStatus::Rejected {
            cal.push(&e);
        }
        let p = obs.covariance();
        let sample = ObserverSample {
            theta_e_rad: e.theta_rad,
            omega_e_rad_s: e.omega_e_rad_s,
            angle_error_deg: f64::NAN,
            speed_error_rad_s: f64::NAN,
            p_diag: [p[(0, 0)], p[(1, 1)], p[(2, 2)], p[(3, 3)]],
            nis: e.nis,
            tracking: status == ReplayStatus::Tracking,
            psi_f_wb: motor.params.psi_f_wb,
            psi_f_sigma_wb: 0.0,
            rs_ohm: e.rs_ohm,
            rs_sigma_ohm: p[(6, 6)].max(0.0).sqrt(),
            winding_temperature_c: f64::NAN,
        };
        (sample, status)
    });
    Ok((tr, cal.result()))
}

/// One observer's score against the reference (module docs, "Scoring").
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Score {
    /// Samples scored.
    pub samples: usize,
    /// The constant (circular-mean) offset removed, electrical degrees.
    pub offset_deg: f64,
    /// RMS angle error, electrical degrees.
    pub rms_deg: f64,
    /// Largest angle error, electrical degrees.
    pub max_deg: f64,
    /// Share of scored samples more than 45 deg off.
    pub lost_share: f64,
    /// Share of scored samples with status TRACKING.
    pub tracking_share: f64,
    /// Share with status UNCERTAIN.
    pub uncertain_share: f64,
    /// Share with status REJECTED.
    pub rejected_share: f64,
    /// Scored samples with status TRACKING while more than 45 deg off.
    pub tracking_while_lost: usize,
}

/// Which rows are scored (module docs): `None` without a reference.
pub fn score_mask(log: &DriveLog, ts_s: f64) -> Option<Vec<bool>> {
    let w = log.omega_ref.as_ref()?;
    let w_max = w.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut mask: Vec<bool> = w
        .iter()
        .map(|v| w_max > 0.0 && v.abs() >= MIN_SPEED_SHARE * w_max)
        .collect();
    let window = (SKIP_AFTER_LONG_S / ts_s).round().max(0.0) as usize;
    for (k, &dt) in log.dt_s.iter().enumerate().skip(1) {
        if dt > LONG_PERIOD_TS * ts_s {
            let end = k.saturating_add(window).min(mask.len());
            mask[k..end].iter_mut().for_each(|m| *m = false);
        }
    }
    Some(mask)
}

/// The angle errors `wrap(theta - theta_ref)`, rad (`pi` where not finite).
fn raw_errors(theta: &[f64], theta_ref: &[f64]) -> Vec<f64> {
    theta
        .iter()
        .zip(theta_ref)
        .map(|(a, b)| {
            let e = wrap_angle(a - b);
            if e.is_finite() { e } else { PI }
        })
        .collect()
}

/// Scores an observer's angle and status against the log's reference; `None` without a
/// reference or without a scored sample. Also returns the offset in rad (0 when `None`).
pub fn score(log: &DriveLog, ts_s: f64, theta: &[f64], status: &[ReplayStatus]) -> Option<Score> {
    let th_ref = log.theta_ref.as_ref()?;
    let mask = score_mask(log, ts_s)?;
    let err = raw_errors(theta, th_ref);
    let (mut s, mut c, mut n) = (0.0, 0.0, 0usize);
    for (e, _) in err.iter().zip(&mask).filter(|(_, m)| **m) {
        s += e.sin();
        c += e.cos();
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let off = s.atan2(c);
    let (mut sq, mut max, mut lost, mut dishonest) = (0.0, 0.0f64, 0usize, 0usize);
    let mut counts = [0usize; 3];
    for ((e, st), _) in err.iter().zip(status).zip(&mask).filter(|(_, m)| **m) {
        let d = wrap_angle(e - off).abs().to_degrees();
        sq += d * d;
        max = max.max(d);
        counts[*st as usize] += 1;
        if d > LOST_DEG {
            lost += 1;
            if *st == ReplayStatus::Tracking {
                dishonest += 1;
            }
        }
    }
    let nf = n as f64;
    Some(Score {
        samples: n,
        offset_deg: off.to_degrees(),
        rms_deg: (sq / nf).sqrt(),
        max_deg: max,
        lost_share: lost as f64 / nf,
        tracking_share: counts[0] as f64 / nf,
        uncertain_share: counts[1] as f64 / nf,
        rejected_share: counts[2] as f64 / nf,
        tracking_while_lost: dishonest,
    })
}

/// The result of a replay: what `metrics.json` holds.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReplayReport {
    /// The log replayed.
    pub log: String,
    /// Rows.
    pub rows: usize,
    /// Nominal period, s.
    pub ts_s: f64,
    /// Periods longer than `1.35 Ts` (skipped cycles).
    pub long_periods: usize,
    /// Whether the log has a reference angle.
    pub has_reference: bool,
    /// The default EKF's score (`null` without a reference).
    pub ekf: Option<Score>,
    /// The default EKF with the acceleration feedforward (`ekf_core::AccelerationFeedforward`,
    /// opt-in): its score.
    pub ekf_feedforward: Option<Score>,
    /// The drive observer's score.
    pub drive: Option<Score>,
    /// The record's input errors from the drive observer (module `ekf_core::calibration`;
    /// `null` when it never tracked).
    pub calibration: Option<CalibrationReport>,
    /// The default EKF with the acceleration feedforward told that calibration (the second
    /// pass): its score.
    pub ekf_calibrated: Option<Score>,
    /// The default EKF with the acceleration feedforward and the online input calibration,
    /// primed by the record ([`run_ekf_online`]): its score.
    pub ekf_online: Option<Score>,
    /// The flux + PLL baseline's score.
    pub flux: Option<Score>,
    /// The part of the default EKF's error periodic in the reference's mechanical angle
    /// (module `reference`: the reference's own error; `null` without a reference).
    pub ekf_reference_periodic: Option<MechanicalComponent>,
    /// The default EKF's error by speed band and direction, and its fit to a d-axis voltage
    /// and a timing (module `speed_bands`; `null` without a reference).
    pub ekf_speed_bands: Option<SpeedBands>,
    /// Samples refused by the EKF (non-finite result).
    pub ekf_rejected: usize,
    /// The record's back-EMF per unit speed against the told flux (module `flux_check`);
    /// `None` when no block of the record qualifies.
    pub flux_check: Option<FluxCheck>,
    /// Samples refused by the drive observer.
    pub drive_rejected: usize,
}

/// The record's calibration as the report gives it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CalibrationReport {
    /// Lead of the applied voltage over the logged one, s.
    pub voltage_lead_s: f64,
    /// The lead in nominal periods.
    pub voltage_lead_periods: f64,
    /// Stator resistance, ohm.
    pub rs_ohm: f64,
    /// Inverter dead-time voltage, V.
    pub dead_time_v: f64,
    /// Samples averaged.
    pub samples: u64,
}

/// A replay's traces and report.
#[derive(Clone, Debug)]
pub struct Replay {
    /// The report.
    pub report: ReplayReport,
    /// The default EKF's outputs.
    pub ekf: ObserverTrace,
    /// The drive observer's outputs.
    pub drive: ObserverTrace,
    /// The flux baseline's outputs.
    pub flux: ObserverTrace,
}

/// Runs the three observers over `log` and scores them; `name` names the log in the report.
pub fn replay(log: &DriveLog, motor: &ReplayMotor, name: &str) -> Result<Replay, ReplayError> {
    let mut ekf = run_ekf(log, motor)?;
    let (mut drive, cal) = run_drive_calibrated(log, motor)?;
    let mut flux = run_flux(log, motor)?;
    let ts = motor.ts_s;
    let calibrated_score = match &cal {
        Some(c) => {
            let t = run_ekf_calibrated(log, motor, c)?;
            score(log, ts, &t.theta, &t.status)
        }
        None => None,
    };
    let ekf_score = score(log, ts, &ekf.theta, &ekf.status);
    let ff = run_ekf_with(log, motor, true)?;
    let ff_score = score(log, ts, &ff.theta, &ff.status);
    let online = run_ekf_online(log, motor)?;
    let online_score = score(log, ts, &online.theta, &online.status);
    let drive_score = score(log, ts, &drive.theta, &drive.status);
    let flux_score = score(log, ts, &flux.theta, &flux.status);
    if let Some(th_ref) = &log.theta_ref {
        for (tr, sc) in [
            (&mut ekf, &ekf_score),
            (&mut drive, &drive_score),
            (&mut flux, &flux_score),
        ] {
            let off = sc.map_or(0.0, |s| s.offset_deg.to_radians());
            for (k, smp) in tr.samples.iter_mut().enumerate() {
                smp.angle_error_deg = wrap_angle(smp.theta_e_rad - th_ref[k] - off).to_degrees();
                if let Some(w) = &log.omega_ref {
                    smp.speed_error_rad_s = smp.omega_e_rad_s - w[k];
                }
            }
        }
    }
    let report = ReplayReport {
        log: name.to_string(),
        rows: log.len(),
        ts_s: ts,
        long_periods: log
            .dt_s
            .iter()
            .filter(|&&d| d > LONG_PERIOD_TS * ts)
            .count(),
        has_reference: log.theta_ref.is_some(),
        ekf: ekf_score,
        ekf_feedforward: ff_score,
        drive: drive_score,
        calibration: cal.map(|c| CalibrationReport {
            voltage_lead_s: c.voltage_lead_s,
            voltage_lead_periods: c.voltage_lead_s / ts,
            rs_ohm: c.rs_ohm,
            dead_time_v: c.dead_time_v,
            samples: c.samples,
        }),
        ekf_calibrated: calibrated_score,
        ekf_online: online_score,
        flux: flux_score,
        ekf_reference_periodic: mechanical_component(
            log,
            ts,
            &ekf.theta,
            ekf_score.map_or(0.0, |s| s.offset_deg.to_radians()),
            motor.params.pole_pairs,
        ),
        ekf_speed_bands: speed_bands(
            log,
            ts,
            &ekf.theta,
            ekf_score.map_or(0.0, |s| s.offset_deg.to_radians()),
            motor.params.psi_f_wb,
        ),
        ekf_rejected: rejected(&ekf),
        drive_rejected: rejected(&drive),
        flux_check: flux_check(log, motor, &ekf),
    };
    Ok(Replay {
        report,
        ekf,
        drive,
        flux,
    })
}

/// Rows of a trace with status REJECTED.
fn rejected(tr: &ObserverTrace) -> usize {
    tr.status
        .iter()
        .filter(|s| **s == ReplayStatus::Rejected)
        .count()
}

/// The report's sentence on the record's flux (module `flux_check`), with a blank line after;
/// empty when no block qualified.
pub fn flux_check_line(r: &ReplayReport) -> String {
    let Some(f) = &r.flux_check else {
        return String::new();
    };
    let mut s = format!(
        "The record's back-EMF per unit speed (light-load blocks where the EKF tracks: {}): \
         {:.5} Wb, {:.3} times the told psi_f ({:.5} Wb).",
        f.blocks, f.flux_wb, f.ratio, f.told_wb
    );
    if f.off() {
        s.push_str(&format!(
            " **More than {:.0} % off**: the motor file does not fit this record, or the log's \
             scaling does not (a power-invariant log read as amplitude-invariant reads sqrt(3/2) \
             = 1.22 times the flux: `--scaling power`). The observers were told the file's \
             value.",
            100.0 * FLUX_WARN_SHARE
        ));
    }
    s.push_str("\n\n");
    s
}

/// The report as a Markdown table.
pub fn markdown(r: &ReplayReport) -> String {
    let mut s = format!(
        "## Replay of {}\n\n{} rows, Ts {:.1} us, {} periods longer than {LONG_PERIOD_TS} Ts\n\n",
        r.log,
        r.rows,
        r.ts_s * 1e6,
        r.long_periods
    );
    s.push_str(&flux_check_line(r));
    if !r.has_reference {
        s.push_str("no reference angle in the log: nothing scored\n");
        return s;
    }
    s.push_str(
        "| observer | scored | offset deg | RMS deg | max deg | > 45 deg | TRACKING | UNCERTAIN | REJECTED | TRACKING while > 45 deg |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for (name, sc) in [
        ("EKF (firmware's defaults)", &r.ekf),
        ("EKF + acceleration feedforward", &r.ekf_feedforward),
        ("drive observer", &r.drive),
        (
            "EKF + feedforward told the record's calibration (second pass)",
            &r.ekf_calibrated,
        ),
        (
            "EKF + feedforward, calibration online, primed by the record (pyfoc's defaults)",
            &r.ekf_online,
        ),
        ("flux + PLL", &r.flux),
    ] {
        match sc {
            Some(x) => s.push_str(&format!(
                "| {name} | {} | {:.1} | {:.2} | {:.1} | {:.2} % | {:.1} % | {:.1} % | {:.1} % | {} |\n",
                x.samples,
                x.offset_deg,
                x.rms_deg,
                x.max_deg,
                100.0 * x.lost_share,
                100.0 * x.tracking_share,
                100.0 * x.uncertain_share,
                100.0 * x.rejected_share,
                x.tracking_while_lost
            )),
            None => s.push_str(&format!("| {name} | 0 | | | | | | | | |\n")),
        }
    }
    if let Some(c) = &r.calibration {
        s.push_str(&format!(
            "\nThe record's calibration (the drive observer's estimates over its {} tracked \
             samples, weighted by the speed squared): the applied voltage leads the logged one \
             by {:.3} periods ({:.1} us), Rs {:.4} ohm, dead-time voltage {:.3} V.\n",
            c.samples,
            c.voltage_lead_periods,
            c.voltage_lead_s * 1e6,
            c.rs_ohm,
            c.dead_time_v
        ));
    }
    if let Some(m) = &r.ekf_reference_periodic {
        s.push_str(&format!(
            "\nThe EKF's error periodic in the reference's mechanical angle (the reference's own \
             error: an encoder's eccentricity, which no observer of the voltages and currents \
             sees): {:.2} deg at once and {:.2} deg at twice the mechanical frequency, {:.2} deg \
             RMS; the EKF's RMS without it {:.2} deg.\n",
            m.first_deg, m.second_deg, m.rms_deg, m.rms_without_deg
        ));
    }
    if let Some(b) = &r.ekf_speed_bands {
        s.push_str(&speed_bands_markdown(b));
    }
    s
}

/// The EKF's error by speed band and direction (module `speed_bands`) as a paragraph and a
/// table.
fn speed_bands_markdown(b: &SpeedBands) -> String {
    let mut s = String::from(
        "\nThe EKF's error by speed (a share of the run's largest |omega_ref|) and direction, over \
         the scored samples no more than 45 deg off (module docs of \
         `pmsm_sim::analysis::replay::speed_bands`).",
    );
    match &b.fit {
        Some(f) => s.push_str(&format!(
            " Fitted as c + a / w + b w: c {:.2} deg; a d-axis voltage the model lacks, dU_d = a \
             psi_f = {:.4} V (an error in 1 / w that flips with the direction); a timing b = {:.1} \
             us (an error in w: the reference's delay behind the rotor, or the applied voltage's \
             lead over the logged one); {:.2} deg RMS left.\n\n",
            f.constant_deg,
            f.d_voltage_v,
            f.delay_s * 1e6,
            f.residual_rms_deg
        )),
        None => {
            s.push_str(" Not fitted: the run turns one way only, or its speeds are too alike.\n\n")
        }
    }
    s.push_str(
        "| band | direction | samples | mean abs(w) rad/s | mean deg | RMS deg |\n\
         |---|---|---:|---:|---:|---:|\n",
    );
    for x in &b.bands {
        s.push_str(&format!(
            "| {:.0}-{:.0} % | {} | {} | {:.0} | {:+.2} | {:.2} |\n",
            100.0 * x.from_share,
            100.0 * x.to_share,
            if x.forward { "forward" } else { "backward" },
            x.samples,
            x.speed_rad_s,
            x.mean_deg,
            x.rms_deg
        ));
    }
    s
}

/// The record's [`Sample`] of row `k` (module docs: what a replay fills).
pub fn sample(log: &DriveLog, motor: &ReplayMotor, rep: &Replay, k: usize) -> Sample {
    let th = log
        .theta_ref
        .as_ref()
        .map_or(f64::NAN, |v| wrap_angle(v[k]));
    let w = log.omega_ref.as_ref().map_or(f64::NAN, |v| v[k]);
    let pp = f64::from(motor.params.pole_pairs);
    let i = log.i_ab[k];
    let (s, c) = th.sin_cos();
    let mut out = Sample {
        k: k as u64,
        t_s: log.t_s[k],
        ..Sample::default()
    };
    out.truth.theta_e_rad = th;
    out.truth.omega_e_rad_s = w;
    out.truth.speed_rpm = rpm(w / pp);
    out.truth.i_ab_a = i;
    out.truth.i_dq_a = [i[0] * c + i[1] * s, i[1] * c - i[0] * s];
    out.truth.torque_nm = f64::NAN;
    out.truth.load_torque_nm = f64::NAN;
    out.truth.psi_f_wb = motor.params.psi_f_wb;
    out.truth.rs_ohm = motor.params.rs_ohm;
    let (a, b) = (i[0], -0.5 * i[0] + 0.5 * 3f64.sqrt() * i[1]);
    out.measured.i_abc_a = [a, b, -a - b];
    out.measured.i_ab_a = i;
    out.measured.u_dc_v = f64::NAN;
    out.observer = rep.ekf.samples[k];
    out.controller_observer = Some(rep.flux.samples[k]);
    out.control.speed_ref_rpm = if w.is_finite() { rpm(w / pp) } else { 0.0 };
    out.control.telemetry = ControllerTelemetry {
        state: "replay",
        ..ControllerTelemetry::default()
    };
    out.inverter.u_ab_commanded_v = log.u_ab[k];
    out
}

/// Paths of a replay's outputs in `dir`: `(replay.mcap, plot.svg, metrics.json)`.
pub fn output_paths(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    (
        dir.join("replay.mcap"),
        dir.join("plot.svg"),
        dir.join("metrics.json"),
    )
}

/// Writes the MCAP log, the plot and `metrics.json` of a replay into `dir` (created);
/// returns their paths.
pub fn write_outputs(
    dir: &Path,
    log: &DriveLog,
    motor: &ReplayMotor,
    rep: &Replay,
    log_options: crate::output::mcap::LogOptions,
) -> Result<Vec<PathBuf>, ReplayError> {
    let out_err = |p: &Path, m: String| ReplayError::Output {
        path: p.display().to_string(),
        message: m,
    };
    std::fs::create_dir_all(dir).map_err(|e| out_err(dir, e.to_string()))?;
    let (mcap, svg, json) = output_paths(dir);
    let mut sc = crate::scenario::Scenario::default_servo();
    sc.name = "replay".into();
    sc.description = format!(
        "replay of {} (placeholder scenario: motor and Ts)",
        rep.report.log
    );
    sc.motor.rs_ohm = motor.params.rs_ohm;
    sc.motor.ld_h = motor.params.ld_h;
    sc.motor.lq_h = motor.params.lq_h;
    sc.motor.psi_f_wb = motor.params.psi_f_wb;
    sc.motor.pole_pairs = motor.params.pole_pairs;
    sc.inverter.ts_s = motor.ts_s;
    sc.duration_s = log.len() as f64 * motor.ts_s;
    let sim_err = |e: crate::SimError| out_err(&mcap, e.to_string());
    let mut mlog =
        crate::output::mcap::McapLog::create(&mcap, &sc, log_options).map_err(sim_err)?;
    let mut plot = crate::output::plot::PlotSink::new(log.len(), motor.params.pole_pairs);
    for k in 0..log.len() {
        let s = sample(log, motor, rep, k);
        mlog.record(&s).map_err(|e| out_err(&mcap, e))?;
        plot.record(&s).map_err(|e| out_err(&svg, e))?;
    }
    let text =
        serde_json::to_string_pretty(&rep.report).map_err(|e| out_err(&json, e.to_string()))?;
    mlog.event(
        log.t_s.last().copied().unwrap_or(0.0),
        "info",
        &serde_json::to_string(&rep.report).unwrap_or_default(),
    )
    .map_err(sim_err)?;
    mlog.finish(None).map_err(sim_err)?;
    plot.write_svg(&svg, &format!("pmsm-sim replay: {}", rep.report.log))
        .map_err(|e| out_err(&svg, e.to_string()))?;
    // Complete or absent (output::file): never an empty or cut metrics.json.
    crate::output::file::write_bytes(&json, format!("{text}\n").as_bytes()).map_err(
        |e| match e {
            crate::SimError::Output { message, .. } => out_err(&json, message),
            other => out_err(&json, other.to_string()),
        },
    )?;
    Ok(vec![mcap, svg, json])
}
