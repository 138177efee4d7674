//! The scenario suite (`pmsm-sim suite`): a fixed set of runs on the three reference motors
//! of docs/design.md, "Reference motors" and the two interior ones of the README's reference-motor table,
//! that scores every observer on identical data, and the tables that compare them over time.
//!
//! # What runs
//!
//! For each motor ([`SuiteMotor`]: servo, industrial 2.2 kW, small fast, industrial IPM,
//! traction IPM; the rated speeds, PWM and sensing of the simulator's presets for them) one
//! main scenario and 8 (4 with `short`) convergence runs (one more, from 180 deg, on an
//! interior motor), built here from the scenario structs (no TOML), with realistic sensing:
//! sensor noise, a 12-bit ADC, residual offsets (0.1 % and -0.06 % of full scale) and gain
//! errors (+0.2 %, -0.1 %), the inverter's dead time, one period of computation delay
//! ([`SuiteOptions::ideal`] turns the sensing and dead time off). Load: friction, a fan load
//! of [`FAN_LOAD_FRACTION`] of the rated torque at rated speed, and a rated load step.
//!
//! The drive is `foc` in **sensored** mode (`ControllerKind::FocSensored`): it sees the true
//! angle, so the trajectory does not depend on any observer under test, and it compensates
//! the dead time as a real drive does. Its speed-reference slew is raised a hundredfold so
//! that the scenario's ramps, not the slew, set the acceleration. Every observer is stepped
//! alongside ([`crate::sim::SideObserver`]) on exactly the same inputs: the measured currents
//! and the voltage the controller expects of its duties (net of its dead-time compensation),
//! delayed like the duties.
//!
//! **Interior motors** ([`SuiteMotor::INTERIOR`]): the same foc drive with its MTPA (on by
//! default: `i_d` from the MTPA law, the reluctance torque in the torque-to-current
//! conversion; with `i_d = 0` the traction motor's rated torque would need 208 A and a base
//! speed of 1931 rpm, below its rated 3000 rpm). Their load step is the rated torque less the fan's share (rated torque in all at rated speed,
//! the traction motor's rated point being 4 % below its base speed); their convergence runs
//! add the start at 180 deg (`theta + pi`, [`motor_start_angles_deg`]), with the goal
//! [`GOAL_IPM_CONVERGENCE_S`]; the mismatch rows stay on the surface motors.
//!
//! The observers ([`ObserverKind`]; on an interior motor each takes `Ld` and `Lq`: the
//! active-flux EKF and the salient flux baseline):
//!
//! - the reference filter (`ObserverConfig::seed`: forward Euler, the seed's Q and R);
//! - the baseline: the flux observer with PLL of open firmware
//!   (`FluxObserverConfig::new`, firmware timing, flux angle): the row to beat;
//! - the project's default EKF (`ObserverConfig::new`: lag-free, scaled Q and R).
//!
//! Every observer starts knowing nothing (zero speed, zero angle, zero flux) while the rotor
//! already spins at half its rated speed: at [`INITIAL_ANGLE_RAD`] in the main run, at each of
//! [`start_angles_deg`] in the convergence runs (which are the convergence phase alone).
//!
//! # Timeline of one motor's main run (full; `short` in brackets)
//!
//! ```text
//! convergence 0.5 s [0.3] at 50 % rated speed, from the unknown start
//! ramp 0.2 s [0.15] to 10 %, settle 0.3 s [0.25], window 0.5 s [0.2]   -> row "10 %"
//! ramp to 50 %, settle, window                                         -> row "50 %"
//! ramp to 100 %, settle, window                                        -> row "100 %"
//! rated load step, transient window 0.3 s [0.25]                       -> "load step"
//! settle, window                                                       -> row "100 %, rated load"
//! ```
//!
//! # Metrics (docs/design.md, "Metrics")
//!
//! Over each steady-state window: angle error `wrap(th_hat - th)` RMS, max `|.|` and mean
//! (electrical degrees), speed error RMS (electrical rad/s and % of rated). Load step: the
//! largest `|e_th|` and speed error in the transient window. Convergence time: the first time
//! after which `|e_th| < 5 deg` holds to the end of the convergence phase (`None`: not
//! converged by then). `w_e Ts` of every row is in the tables.
//!
//! # Mismatch through a reversal
//!
//! On each surface motor a run of its own (module [`reversal`]) scores the default EKF and
//! the baseline told each wrong motor of [`MISMATCHES`] through a speed reversal from +10 % to
//! -10 % of rated speed under the rated load torque (a constant torque: the drive generates
//! on the way back), over a window from 0.25 s after the load step to the end of the run.
//! Goal: RMS <= [`GOAL_MISMATCH_LOW_SPEED_RMS_DEG`], as in the steady 10 % window.
//!
//! Every mismatch row (these and the main run's) also counts the default EKF's estimates with
//! status `Tracking` while more than 45 deg off, in its window (a goal: none) and over the
//! observer's whole run (in the table): the status must stay honest when the observer is told
//! a wrong motor.
//!
//! # Real-drive effects ([`SuiteReport::real_drive`])
//!
//! What real drives do and the observers' model leaves out, on the servo and the small fast
//! motor ([`REAL_DRIVE_MOTORS`], when selected), each in a run of its own
//! ([`RealDriveEffect`]): the voltage applied 1.5 periods after the sample instead of the one
//! period foc and the observers assume (`inverter.delay_periods`), 5th and 7th back-EMF
//! harmonics of 3 % and 2 % of the fundamental (`motor.emf_harmonics`: flux harmonics of
//! 0.6 % and 0.29 % of `psi_f`), 1 % of the control periods skipped (`[skipped_cycles]`),
//! and the same run without any (the reference). Each run: the observers converge at 50 %
//! rated speed, the speed rises to rated, the rated load steps on, and the angle error is
//! scored over a window at rated speed and load (`Plan::real_drive`). The default EKF and
//! the baseline step on every sample with the voltage the drive believes it applied (not
//! told of the effect); foc's own `f32` observer (foc runs sensored, its observer alongside)
//! misses the skipped periods with its controller. No goals: the table shows what each
//! effect costs, so that a regression shows.
//!
//! # Goals and limits ([`SuiteReport::checks`])
//!
//! The goals: the default EKF's RMS angle error at most half the baseline's in every
//! steady-state row, and its mean error within 0.1 deg el. where `w_e Ts <= 0.3 rad`. Sane
//! absolute limits besides: the default EKF converges from every start angle within the
//! convergence phase, its
//! steady-state RMS is below 1 deg, its steady-state max below 5 deg, its worst error through
//! the load step below 5 deg and its speed RMS below 1 % of rated. On the interior motors also
//! the goal that it converges from every start (`theta + pi` included) within 50 ms. The
//! report states which hold; nothing is loosened to pass.
//!
//! # Known limits
//!
//! A failing check is a regression, except where it fails for a documented property of the
//! method; the tables name it there ([`Check::known_limit`]) and `pmsm-sim suite` exits 0
//! when every failure is one of these, 1 otherwise:
//!
//! - [`KNOWN_LIMIT_LS`]: the EKF does not track `Ls` online. Told an inductance off by
//!   `dL`, its model's voltage drop `w_e dL i_q` is attributed to the back-EMF, whose angle
//!   then lags or leads by about `atan(dL i_q / psi_f)`: under rated load (rated `i_q`) and
//!   `Ls` +-20 % that is 1.0-3.8 deg el. on the three surface motors, above the 1 deg goal
//!   (the README's "Known limitations"). Without load (`i_q` small) the goal holds. The remedy
//!   is foc's d-axis excitation with `ekf_core::excitation` feeding the EKF (module
//!   [`excitation`], its own section); the rows without it stay this known limit.
//!
//! The small fast motor's "EKF RMS / baseline RMS" at 50 % speed (0.551 against 0.5 with
//! seed 1) is not one, so it fails the exit code. Its cause is in the simulated drive, not in
//! the motor or the observer: a mean angle error of -0.06 deg (at 10-100 % speed) that the
//! dead time leaves. The plant takes the dead-time voltage's sign from the current at the
//! start of the period (motulator's averaged model, module `plant::inverter`); foc's
//! compensation takes it from the current predicted for the middle of the interval the
//! duties act over (where centre-aligned PWM's switching edges are centred, module
//! `foc::deadtime`). Near each zero crossing the two differ for half a period, which leaves a
//! voltage across the current of about `(4 / pi) (t_dead / Ts) u_dc (w Ts / 2)`, an angle
//! error of about `2 t_dead u_dc / (pi psi_f)` whatever the speed. Measured with foc's sign
//! moved to the period's start (a local build), the mean angle error at 50 % speed moves by
//! +0.059 deg on this motor (predicted 0.058: 0.2 us, 48 V, 6 mWb), +0.027 on the servo
//! (0.031) and +0.032 on the 2.2 kW motor (0.036); the small fast motor's mean goes to -0.001
//! deg and its ratio to 0.49 (seed 1). Without dead time the ratio is 0.47 (seed 1), with
//! ideal sensing and inverter the mean -0.016 deg. Bringing the plant's model to the switching
//! edges would move every realistic row of the suite; not done.

use std::time::Instant;

use ekf_core::{EkfError, FluxObserver, FluxObserverConfig, ObserverConfig, PmsmObserver};
use serde::Serialize;

use crate::SimError;
use crate::drive::foc_adapter::FocDrive;
use crate::drive::rotor_observers::{Observer, ObserverEstimate};
use crate::output::metrics::{Sums, is_converged};
use crate::output::record::{ObserverSample, Sample};
use crate::plant::MotorModel;
use crate::plant::inverter::InverterConfig;
use crate::plant::load::{LoadTerm, Profile};
use crate::plant::sensors::SensorConfig;
use crate::scenario::{
    ControllerKind, ControllerSettings, FocSettings, InitialState, ObserverSettings, RPM_PER_RAD_S,
    Scenario,
};
use crate::sim::{SideObserver, run_with_side_observers};

pub use crate::output::metrics::CONVERGED_DEG;

pub mod excitation;
pub mod identified;
pub mod reversal;
mod runs;
mod saturated;
mod tables;
pub use runs::*;
pub use saturated::*;

/// The rotor's electrical angle at `t = 0`, rad (the observers start at 0: 115 deg off).
pub const INITIAL_ANGLE_RAD: f64 = 2.0;
/// Fan load at rated speed, fraction of the rated torque (quadratic in speed: 4 % at 50 %,
/// 0.2 % at 10 % of rated speed).
pub const FAN_LOAD_FRACTION: f64 = 0.2;
/// PWM period of every run but the traction motor's, s (10 kHz).
pub const TS_S: f64 = 1e-4;
/// PWM period of the traction motor's runs, s (20 kHz, as its `traction-ipm` preset).
pub const TS_S_TRACTION: f64 = 5e-5;
/// Goal on the interior motors: the default EKF converges from every start angle (the
/// `theta + pi` cell included) within this, s.
pub const GOAL_IPM_CONVERGENCE_S: f64 = 0.05;

/// Goal: default EKF RMS / baseline RMS at most this, every steady-state row.
pub const GOAL_RMS_RATIO: f64 = 0.5;
/// Goal: `|mean|` of the default EKF at most this (deg el.) where `w_e Ts <= 0.3 rad`.
pub const GOAL_MEAN_DEG: f64 = 0.1;
/// Largest `w_e Ts` the mean goal applies to, rad.
pub const GOAL_MEAN_MAX_WTS: f64 = 0.3;
/// Limit: default EKF steady-state RMS, deg el.
pub const LIMIT_RMS_DEG: f64 = 1.0;
/// Limit: default EKF steady-state max `|e_th|`, deg el.
pub const LIMIT_MAX_DEG: f64 = 5.0;
/// Limit: default EKF worst `|e_th|` through the rated load step, deg el.
pub const LIMIT_LOAD_STEP_DEG: f64 = 5.0;
/// Limit: default EKF steady-state speed RMS, % of rated electrical speed.
pub const LIMIT_SPEED_PCT: f64 = 1.0;

/// Goal: EKF angle RMS (deg el.) told a wrong `psi_f`, `Rs` or temperature, at >= 50 % speed.
pub const GOAL_MISMATCH_RMS_DEG: f64 = 0.5;
/// The known limit of a failing "told a wrong Ls" check (module docs, "Known limits").
pub const KNOWN_LIMIT_LS: &str = "known limit: Ls is not tracked online, bias about atan(dL i_q / psi_f) under load (remedy: the d excitation, section excitation)";
/// Goal: EKF angle RMS (deg el.) told a wrong `Ls`, at >= 50 % speed.
pub const GOAL_MISMATCH_LS_RMS_DEG: f64 = 1.0;
/// Goal: EKF angle RMS (deg el.) told any wrong motor at 10 % speed, in the steady window
/// and through the reversal under rated load ([`reversal`]).
pub const GOAL_MISMATCH_LOW_SPEED_RMS_DEG: f64 = 1.0;
/// Goal: the tracked `psi_f` within this of the truth (%) when told a wrong `psi_f`, at
/// >= 50 % speed.
pub const GOAL_MISMATCH_PSI_PCT: f64 = 1.0;

/// A wrong motor the observers are told (module docs, "Mismatch rows"): the scenario's
/// observer parameters scaled. The thermal cases are the motor 100 K warmer (or colder) than
/// its parameters: told `psi_f / (1 - 0.12)` and `Rs / (1 + 0.393)` (or the reverse).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Mismatch {
    /// Name in the tables.
    pub name: &'static str,
    /// Told `psi_f` / true `psi_f`.
    pub psi_f: f64,
    /// Told `Rs` / true `Rs`.
    pub rs: f64,
    /// Told `Ls` / true `Ls`.
    pub ls: f64,
}

/// The mismatch cases of the suite.
pub const MISMATCHES: [Mismatch; 8] = [
    Mismatch {
        name: "psi_f +10 %",
        psi_f: 1.1,
        rs: 1.0,
        ls: 1.0,
    },
    Mismatch {
        name: "psi_f -10 %",
        psi_f: 0.9,
        rs: 1.0,
        ls: 1.0,
    },
    Mismatch {
        name: "Rs +30 %",
        psi_f: 1.0,
        rs: 1.3,
        ls: 1.0,
    },
    Mismatch {
        name: "Rs -30 %",
        psi_f: 1.0,
        rs: 0.7,
        ls: 1.0,
    },
    Mismatch {
        name: "Ls +20 %",
        psi_f: 1.0,
        rs: 1.0,
        ls: 1.2,
    },
    Mismatch {
        name: "Ls -20 %",
        psi_f: 1.0,
        rs: 1.0,
        ls: 0.8,
    },
    Mismatch {
        name: "100 K hot",
        psi_f: 1.0 / 0.88,
        rs: 1.0 / 1.393,
        ls: 1.0,
    },
    Mismatch {
        name: "100 K cold",
        psi_f: 1.0 / 1.12,
        rs: 1.0 / 0.607,
        ls: 1.0,
    },
];

impl Mismatch {
    /// `true` for the `Ls` cases (not tracked: their own goal).
    pub fn is_ls(&self) -> bool {
        self.ls != 1.0
    }

    /// `true` for the cases with the right `Rs` and `Ls` and a wrong `psi_f`.
    pub fn is_psi_only(&self) -> bool {
        self.psi_f != 1.0 && self.rs == 1.0 && self.ls == 1.0
    }
}

/// One observer told a wrong motor ([`Mismatch`]), on one motor, in one steady window.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MismatchRow {
    /// Observer (the default EKF or the baseline).
    pub observer: ObserverKind,
    /// Motor.
    pub motor: SuiteMotor,
    /// Mismatch case.
    pub case: &'static str,
    /// Condition (as [`SteadyRow::condition`]).
    pub condition: String,
    /// Speed, fraction of rated.
    pub speed_fraction: f64,
    /// Samples in the window (failed steps excluded).
    pub samples: usize,
    /// RMS angle error, deg el.
    pub angle_rms_deg: f64,
    /// Largest `|e_th|`, deg el.
    pub angle_max_deg: f64,
    /// Mean angle error, deg el.
    pub angle_mean_deg: f64,
    /// Mean tracked `psi_f` over the window against the truth, % (EKF; `None` for the
    /// baseline, which does not track it).
    pub psi_f_error_pct: Option<f64>,
    /// Mean `Rs` in use over the window against the truth, %.
    pub rs_error_pct: f64,
    /// Share of the window's estimates with status `Tracking`, %.
    pub tracking_pct: f64,
    /// The window's estimates with status `Tracking` while more than
    /// [`LOST_DEG`](crate::output::metrics::LOST_DEG) off: an honest status has none.
    pub tracking_while_lost: usize,
    /// The same over the observer's whole run (convergence, load step and every window).
    pub run_tracking_while_lost: usize,
}

/// The motors with real-drive rows (module docs).
pub const REAL_DRIVE_MOTORS: [SuiteMotor; 2] = [SuiteMotor::Servo, SuiteMotor::SmallFast];

/// A real-drive effect (module docs, "Real-drive effects").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RealDriveEffect {
    /// None: the reference run.
    None,
    /// The voltage applied 1.5 periods after the sample (`inverter.delay_periods = 1.5`).
    VoltageDelay,
    /// 5th and 7th back-EMF harmonics of 3 % and 2 % of the fundamental.
    EmfHarmonics,
    /// 1 % of the control periods skipped.
    SkippedCycles,
}

impl RealDriveEffect {
    /// All four, in table order.
    pub const ALL: [RealDriveEffect; 4] = [
        RealDriveEffect::None,
        RealDriveEffect::VoltageDelay,
        RealDriveEffect::EmfHarmonics,
        RealDriveEffect::SkippedCycles,
    ];

    /// Name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            RealDriveEffect::None => "none (reference)",
            RealDriveEffect::VoltageDelay => "voltage delay 1.5 periods",
            RealDriveEffect::EmfHarmonics => "EMF 5th 3 %, 7th 2 %",
            RealDriveEffect::SkippedCycles => "1 % skipped cycles",
        }
    }

    /// The scenario with the effect.
    pub fn apply(self, sc: &mut Scenario) {
        match self {
            RealDriveEffect::None => {}
            RealDriveEffect::VoltageDelay => sc.inverter.delay_periods = Some(1.5),
            RealDriveEffect::EmfHarmonics => {
                sc.motor.emf_harmonics = crate::plant::EmfHarmonics {
                    h5: 0.03 / 5.0,
                    h5_phase_rad: 0.0,
                    h7: 0.02 / 7.0,
                    h7_phase_rad: 0.0,
                };
            }
            RealDriveEffect::SkippedCycles => sc.skipped_cycles.probability = 0.01,
        }
    }
}

/// Angle error over a window: RMS, max `|.|`, mean, deg el., and the samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AngleStats {
    /// Samples scored.
    pub samples: usize,
    /// RMS, deg el.
    pub rms_deg: f64,
    /// Largest `|e_th|`, deg el.
    pub max_deg: f64,
    /// Mean, deg el.
    pub mean_deg: f64,
}

impl AngleStats {
    fn of(s: &Sums) -> Self {
        Self {
            samples: s.n,
            rms_deg: s.angle_rms_deg(),
            max_deg: s.max_e,
            mean_deg: s.angle_mean_deg(),
        }
    }
}

/// One real-drive run's window (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RealDriveRow {
    /// Motor.
    pub motor: SuiteMotor,
    /// The effect.
    pub effect: RealDriveEffect,
    /// Condition of the window.
    pub condition: String,
    /// `w_e Ts` of the window's speed, rad.
    pub w_ts_rad: f64,
    /// The default EKF.
    pub ekf: AngleStats,
    /// The baseline (flux observer + PLL).
    pub baseline: AngleStats,
    /// foc's own `f32` observer (no estimate in skipped periods).
    pub foc_observer: AngleStats,
    /// Control periods skipped over the run.
    pub skipped_periods: u64,
    /// Periods of the run.
    pub periods: usize,
}

/// Options of [`run_suite`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SuiteOptions {
    /// Shortened windows (module docs): about half the simulated time.
    pub short: bool,
    /// Seed of the sensor noise (each motor adds its index).
    pub seed: u64,
    /// Ideal sensing and inverter instead of the realistic ones: no noise, no ADC, no offset
    /// or gain error, no dead time (what is left is the observers' own error).
    pub ideal: bool,
}

impl Default for SuiteOptions {
    /// The full run, seed 1, realistic sensing.
    fn default() -> Self {
        Self {
            short: false,
            seed: 1,
            ideal: false,
        }
    }
}

/// The reference motors: the three surface motors of docs/design.md, "Reference motors" and the two
/// interior ones of the README's reference-motor table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SuiteMotor {
    /// Servo (textbook default), 300 V bus, rated 2000 rpm, 1.5 N m.
    Servo,
    /// Industrial 2.2 kW (surface variant), 540 V bus, rated 1500 rpm, 10 N m.
    Industrial2k2,
    /// Small fast (drone class), 48 V bus, rated 3429 rpm (400 Hz el.), 0.4 N m.
    SmallFast,
    /// Industrial interior PMSM (Lq/Ld 1.4), 540 V bus, 10 kHz, rated 1500 rpm, 14 N m.
    IndustrialIpm,
    /// Traction-class interior PMSM (Lq/Ld 3), 48 V bus, 20 kHz, rated 3000 rpm, 15 N m.
    TractionIpm,
}

impl SuiteMotor {
    /// All five, in table order (the surface motors first).
    pub const ALL: [SuiteMotor; 5] = [
        SuiteMotor::Servo,
        SuiteMotor::Industrial2k2,
        SuiteMotor::SmallFast,
        SuiteMotor::IndustrialIpm,
        SuiteMotor::TractionIpm,
    ];

    /// The surface motors (`Ld == Lq`).
    pub const SURFACE: [SuiteMotor; 3] = [
        SuiteMotor::Servo,
        SuiteMotor::Industrial2k2,
        SuiteMotor::SmallFast,
    ];

    /// The interior motors (`Lq > Ld`).
    pub const INTERIOR: [SuiteMotor; 2] = [SuiteMotor::IndustrialIpm, SuiteMotor::TractionIpm];

    /// The motor's catalog entry (`ekf_core::catalog`).
    pub fn reference(self) -> &'static ekf_core::catalog::ReferenceMotor {
        use ekf_core::catalog;
        match self {
            SuiteMotor::Servo => &catalog::SERVO,
            SuiteMotor::Industrial2k2 => &catalog::INDUSTRIAL_2K2,
            SuiteMotor::SmallFast => &catalog::SMALL_FAST,
            SuiteMotor::IndustrialIpm => &catalog::INDUSTRIAL_IPM,
            SuiteMotor::TractionIpm => &catalog::TRACTION_IPM,
        }
    }

    /// Name in the tables (the catalog's).
    pub fn name(self) -> &'static str {
        self.reference().name
    }

    /// The motor of a name ([`SuiteMotor::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// `true` for the interior motors (their drive, load and goals differ: module docs).
    pub fn is_interior(self) -> bool {
        Self::INTERIOR.contains(&self)
    }
}

/// The observers the suite compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ObserverKind {
    /// The reference filter, `ObserverConfig::seed`.
    SeedEkf,
    /// The baseline: flux observer with PLL, `FluxObserverConfig::new` (firmware form).
    FluxBaseline,
    /// The project's default EKF, `ObserverConfig::new`.
    DefaultEkf,
}

impl ObserverKind {
    /// All three, in table order.
    pub const ALL: [ObserverKind; 3] = [
        ObserverKind::SeedEkf,
        ObserverKind::FluxBaseline,
        ObserverKind::DefaultEkf,
    ];

    /// Title in the tables.
    pub fn title(self) -> &'static str {
        match self {
            ObserverKind::SeedEkf => "seed's filter (ObserverConfig::seed)",
            ObserverKind::FluxBaseline => {
                "baseline: flux observer + PLL (FluxObserverConfig::new, firmware form)"
            }
            ObserverKind::DefaultEkf => "default EKF (ObserverConfig::new)",
        }
    }
}

/// One motor's setting in the report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MotorInfo {
    /// Which motor.
    pub motor: SuiteMotor,
    /// Rated mechanical speed, rpm.
    pub rated_speed_rpm: f64,
    /// Rated electrical speed, rad/s.
    pub rated_omega_e_rad_s: f64,
    /// `w_e Ts` at rated speed, rad.
    pub rated_w_ts_rad: f64,
    /// Rated (load step) torque, N m.
    pub rated_torque_nm: f64,
    /// PWM period, s.
    pub ts_s: f64,
    /// The drive: `"foc sensored"`, or `"foc sensored, MTPA"` for an interior motor.
    pub drive: String,
    /// DC bus, V.
    pub u_dc_v: f64,
    /// Dead time, s.
    pub dead_time_s: f64,
    /// Current-sensor noise per phase, A.
    pub noise_a: f64,
    /// ADC full scale, A (12 bits).
    pub adc_full_scale_a: f64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// How the run ended (`completed`).
    pub end: String,
}

/// One observer on one motor in one steady-state window.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SteadyRow {
    /// Observer.
    pub observer: ObserverKind,
    /// Motor.
    pub motor: SuiteMotor,
    /// Condition (`"10 %"`, `"50 %"`, `"100 %"`, `"100 %, rated load"`).
    pub condition: String,
    /// Speed, fraction of rated.
    pub speed_fraction: f64,
    /// Whether the rated load is applied.
    pub loaded: bool,
    /// `w_e Ts` of the speed, rad.
    pub w_ts_rad: f64,
    /// Samples in the window (failed steps excluded).
    pub samples: usize,
    /// Failed observer steps in the window.
    pub failures: usize,
    /// RMS angle error, deg el.
    pub angle_rms_deg: f64,
    /// Largest `|e_th|`, deg el.
    pub angle_max_deg: f64,
    /// Mean angle error, deg el.
    pub angle_mean_deg: f64,
    /// RMS speed error, rad/s el.
    pub speed_rms_rad_s: f64,
    /// RMS speed error, % of rated electrical speed.
    pub speed_rms_pct: f64,
}

/// One observer on one motor: the transients.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TransientRow {
    /// Observer.
    pub observer: ObserverKind,
    /// Motor.
    pub motor: SuiteMotor,
    /// Convergence time in the main run (start angle [`INITIAL_ANGLE_RAD`]), s (`None`: not
    /// converged by the end of the convergence phase).
    pub convergence_time_s: Option<f64>,
    /// Length of the convergence phase, s.
    pub convergence_phase_s: f64,
    /// Start angles of the convergence runs, deg el. (rotor at 50 % rated speed).
    pub start_angles_deg: Vec<f64>,
    /// Convergence time from each start angle, s (`None`: not converged within the phase).
    pub convergence_times_s: Vec<Option<f64>>,
    /// How many of the start angles converged.
    pub converged_starts: usize,
    /// Worst convergence time over the start angles, s (`None`: some did not converge).
    pub convergence_worst_s: Option<f64>,
    /// Largest `|e_th|` through the rated load step, deg el.
    pub load_step_max_deg: f64,
    /// Largest speed error through the rated load step, rad/s el.
    pub load_step_speed_max_rad_s: f64,
    /// Failed observer steps over the whole run.
    pub failures: usize,
    /// Share of the whole run's estimates with status `Tracking`, %.
    pub tracking_pct: f64,
    /// Estimates with status `Tracking` while more than [`LOST_DEG`](crate::output::metrics::LOST_DEG) off, over the whole run
    /// (convergence phase included): an honest status has none.
    pub tracking_while_lost: usize,
}

/// One goal or limit, checked.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Check {
    /// What is checked.
    pub name: String,
    /// Motor.
    pub motor: SuiteMotor,
    /// Row (condition) or transient.
    pub row: String,
    /// Measured value.
    pub value: f64,
    /// Limit (`value <= limit` passes).
    pub limit: f64,
    /// Whether it holds.
    pub pass: bool,
    /// When it fails as a documented known limit (module docs, "Known limits"): which one.
    /// A failure without one is a regression (`pmsm-sim suite` exits 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub known_limit: Option<&'static str>,
}

/// Everything the suite measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SuiteReport {
    /// The options of the run.
    pub options: SuiteOptions,
    /// PWM period, s, of the surface motors ([`TS_S`]; each motor's is in [`MotorInfo`]).
    pub ts_s: f64,
    /// Wall-clock time of the whole suite, s (not deterministic).
    pub wall_time_s: f64,
    /// The motors' settings.
    pub motors: Vec<MotorInfo>,
    /// Steady-state rows, by observer, motor, condition.
    pub steady: Vec<SteadyRow>,
    /// Transient rows, by observer, motor.
    pub transients: Vec<TransientRow>,
    /// Mismatch rows (module docs), by motor, case, observer, condition.
    pub mismatch: Vec<MismatchRow>,
    /// Real-drive rows (module docs), by motor and effect.
    pub real_drive: Vec<RealDriveRow>,
    /// Saturated-motor rows and their goals (module `saturated`; run by [`run_suite`], not
    /// for a selection of motors).
    pub saturated: SaturatedReport,
    /// Goals and limits.
    pub checks: Vec<Check>,
    /// Rows with the d-axis excitation and their goals (module [`excitation`]).
    pub excitation: excitation::ExcitationReport,
}

/// Runs the suite (module docs): every motor ([`SuiteMotor::ALL`]), three observers.
pub fn run_suite(opts: &SuiteOptions) -> Result<SuiteReport, SimError> {
    let mut report = run_suite_motors(opts, &SuiteMotor::ALL)?;
    report.saturated = saturated_rows(opts)?;
    Ok(report)
}

/// Runs the suite on the given motors only (in the order given; each keeps its own seed
/// offset, so its rows are those of the full suite).
pub fn run_suite_motors(
    opts: &SuiteOptions,
    selected: &[SuiteMotor],
) -> Result<SuiteReport, SimError> {
    let started = Instant::now();
    let mut motors = Vec::new();
    let mut steady = Vec::new();
    let mut transients = Vec::new();
    let mut mismatch = Vec::new();
    let mut real_drive = Vec::new();
    for &motor in selected {
        if REAL_DRIVE_MOTORS.contains(&motor) {
            real_drive.extend(real_drive_rows(motor, opts)?);
        }
        let starts = motor_start_angles_deg(motor, opts.short);
        let plan = Plan::main(opts.short);
        let sc = scenario_with(motor, opts, &plan, INITIAL_ANGLE_RAD);
        let ts = sc.ts_s();
        // Mismatch rows on the surface motors only (module docs).
        let (scored, end) = run_scored(&sc, &plan, !motor.is_interior())?;
        let truth = (sc.motor.psi_f_wb, sc.motor.rs_ohm);
        // Convergence from each start angle: per observer, the times (None: not converged).
        let conv_plan = Plan::convergence(opts.short);
        let mut conv: Vec<Vec<Option<f64>>> = vec![Vec::new(); ObserverKind::ALL.len()];
        for &deg in &starts {
            let csc = scenario_with(motor, opts, &conv_plan, deg.to_radians());
            let (cs, _) = run_scored(&csc, &conv_plan, false)?;
            for (times, o) in conv.iter_mut().zip(&cs) {
                times.push(o.convergence_time_s(ts));
            }
        }
        let rated = sc.rated_speed_e_rad_s();
        motors.push(MotorInfo {
            motor,
            rated_speed_rpm: sc.rated_speed_rpm,
            rated_omega_e_rad_s: rated,
            rated_w_ts_rad: rated * ts,
            rated_torque_nm: sc.rated_torque_nm,
            ts_s: ts,
            drive: if motor.is_interior() {
                "foc sensored, MTPA".to_string()
            } else {
                "foc sensored".to_string()
            },
            u_dc_v: sc.inverter.u_dc_v,
            dead_time_s: sc.inverter.dead_time_s,
            noise_a: sc.sensors.current_noise_std_a,
            adc_full_scale_a: sc.sensors.adc_full_scale_a,
            duration_s: sc.duration_s,
            end,
        });
        mismatch.extend(reversal::mismatch_rows(motor, &plan, &scored, truth));
        if !motor.is_interior() {
            mismatch.extend(reversal::reversal_rows(motor, opts)?);
        }
        for (s, times) in scored.iter().filter(|s| s.told.is_none()).zip(&conv) {
            for (sums, w) in s.windows.iter().zip(&plan.windows) {
                let speed_rms = sums.speed_rms_rad_s();
                steady.push(SteadyRow {
                    observer: s.kind,
                    motor,
                    condition: w.0.to_string(),
                    speed_fraction: w.1,
                    loaded: w.2,
                    w_ts_rad: w.1 * rated * ts,
                    samples: sums.n,
                    failures: sums.failures,
                    angle_rms_deg: sums.angle_rms_deg(),
                    angle_max_deg: sums.max_e,
                    angle_mean_deg: sums.angle_mean_deg(),
                    speed_rms_rad_s: speed_rms,
                    speed_rms_pct: 100.0 * speed_rms / rated,
                });
            }
            let converged: Vec<f64> = times.iter().flatten().copied().collect();
            transients.push(TransientRow {
                observer: s.kind,
                motor,
                convergence_time_s: s.convergence_time_s(ts),
                convergence_phase_s: plan.conv_end_s,
                start_angles_deg: starts.clone(),
                convergence_times_s: times.clone(),
                converged_starts: converged.len(),
                convergence_worst_s: (converged.len() == times.len())
                    .then(|| converged.iter().copied().fold(0.0, f64::max)),
                load_step_max_deg: if s.step.failures > 0 {
                    f64::NAN
                } else {
                    s.step.max_e
                },
                load_step_speed_max_rad_s: s.step.max_w,
                failures: s.failures,
                tracking_pct: s.run.tracking_pct(),
                tracking_while_lost: s.run.tracking_lost,
            });
        }
    }
    let mut report = SuiteReport {
        options: *opts,
        ts_s: TS_S,
        wall_time_s: 0.0,
        motors,
        steady,
        transients,
        mismatch,
        real_drive,
        saturated: SaturatedReport::default(),
        checks: Vec::new(),
        excitation: excitation::excitation_rows(opts, selected)?,
    };
    report.checks = report.evaluate();
    report.wall_time_s = started.elapsed().as_secs_f64();
    Ok(report)
}
