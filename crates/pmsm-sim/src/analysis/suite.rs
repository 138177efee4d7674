//! The scenario suite (`pmsm-sim suite`): a fixed set of runs on the three reference motors
//! of `design.md` section 6 and the two interior ones of the README's reference-motor table,
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
//! # Metrics (`design.md` section 5)
//!
//! Over each steady-state window: angle error `wrap(th_hat - th)` RMS, max `|.|` and mean
//! (electrical degrees), speed error RMS (electrical rad/s and % of rated). Load step: the
//! largest `|e_th|` and speed error in the transient window. Convergence time: the first time
//! after which `|e_th| < 5 deg` holds to the end of the convergence phase (`None`: not
//! converged by then). `w_e Ts` of every row is in the tables.
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
//! The issue's goals: the default EKF's RMS angle error at most half the baseline's in every
//! steady-state row, and its mean error within 0.1 deg el. where `w_e Ts <= 0.3 rad`. Sane
//! absolute limits besides: the default EKF converges from every start angle within the
//! convergence phase, its
//! steady-state RMS is below 1 deg, its steady-state max below 5 deg, its worst error through
//! the load step below 5 deg and its speed RMS below 1 % of rated. On the interior motors also
//! the goal that it converges from every start (`theta + pi` included) within 50 ms. The
//! report states which hold; nothing is loosened to pass.

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
/// Goal: EKF angle RMS (deg el.) told a wrong `Ls`, at >= 50 % speed.
pub const GOAL_MISMATCH_LS_RMS_DEG: f64 = 1.0;
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

/// The reference motors: the three surface motors of `design.md` section 6 and the two
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

    /// Name in the tables (the `ekf_core::MotorParams` preset's).
    pub fn name(self) -> &'static str {
        match self {
            SuiteMotor::Servo => "servo",
            SuiteMotor::Industrial2k2 => "industrial_2k2",
            SuiteMotor::SmallFast => "small_fast",
            SuiteMotor::IndustrialIpm => "industrial_ipm",
            SuiteMotor::TractionIpm => "traction_ipm",
        }
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
    /// Goals and limits.
    pub checks: Vec<Check>,
}

/// Times of one motor's run (module docs).
#[derive(Clone, Debug, PartialEq)]
struct Plan {
    conv_end_s: f64,
    /// `(condition, speed fraction, loaded, window start, window end)`.
    windows: Vec<(&'static str, f64, bool, f64, f64)>,
    step_s: f64,
    step_end_s: f64,
    duration_s: f64,
    /// Speed reference points `(t, fraction of rated)`.
    speed_points: Vec<(f64, f64)>,
}

impl Plan {
    /// The main run (module docs).
    fn main(short: bool) -> Self {
        let (conv, ramp, settle, window, step_window) = if short {
            (0.3, 0.15, 0.25, 0.2, 0.25)
        } else {
            (0.5, 0.2, 0.3, 0.5, 0.3)
        };
        let mut t = conv;
        let mut points = vec![(0.0, 0.5), (conv, 0.5)];
        let mut windows = Vec::new();
        for (name, frac) in [("10 %", 0.1), ("50 %", 0.5), ("100 %", 1.0)] {
            t += ramp;
            points.push((t, frac));
            windows.push((name, frac, false, t + settle, t + settle + window));
            t += settle + window;
        }
        let step_s = t;
        let step_end_s = t + step_window;
        let w0 = step_end_s + settle;
        windows.push(("100 %, rated load", 1.0, true, w0, w0 + window));
        Self {
            conv_end_s: conv,
            windows,
            step_s,
            step_end_s,
            duration_s: w0 + window,
            speed_points: points,
        }
    }

    /// A real-drive run (module docs): convergence at 50 % rated speed, up to rated, the
    /// rated load step, one window at rated speed and load.
    fn real_drive(short: bool) -> Self {
        let (conv, window) = if short { (0.2, 0.2) } else { (0.2, 0.3) };
        let up = conv + 0.2;
        let step_s = up + 0.1;
        let w0 = step_s + 0.2;
        Self {
            conv_end_s: conv,
            windows: vec![("100 %, rated load", 1.0, true, w0, w0 + window)],
            step_s,
            step_end_s: w0,
            duration_s: w0 + window,
            speed_points: vec![(0.0, 0.5), (conv, 0.5), (up, 1.0)],
        }
    }

    /// A convergence run: the convergence phase only.
    fn convergence(short: bool) -> Self {
        let conv = Self::main(short).conv_end_s;
        Self {
            conv_end_s: conv,
            windows: Vec::new(),
            step_s: f64::INFINITY,
            step_end_s: f64::INFINITY,
            duration_s: conv,
            speed_points: vec![(0.0, 0.5)],
        }
    }
}

/// `(motor, rated rpm, rated torque, bus V, dead time s, noise A, ADC full scale A, current
/// limit A, current bandwidth Hz, speed bandwidth Hz, PWM period s)`: the simulator's presets
/// for these motors (`servo-sensored`/`default`, `industrial-2k2`, `drone`, `industrial-ipm`,
/// `traction-ipm`).
fn setting(m: SuiteMotor) -> (MotorModel, f64, f64, f64, f64, f64, f64, f64, f64, f64, f64) {
    match m {
        SuiteMotor::Servo => (
            MotorModel::servo(),
            2000.0,
            1.5,
            300.0,
            0.5e-6,
            0.02,
            10.0,
            4.5,
            500.0,
            20.0,
            TS_S,
        ),
        SuiteMotor::Industrial2k2 => (
            MotorModel::industrial_2k2(),
            1500.0,
            10.0,
            540.0,
            1e-6,
            0.05,
            25.0,
            8.0,
            300.0,
            10.0,
            TS_S,
        ),
        SuiteMotor::SmallFast => (
            MotorModel::small_fast(),
            3429.0,
            0.4,
            48.0,
            0.2e-6,
            0.1,
            40.0,
            15.0,
            800.0,
            40.0,
            TS_S,
        ),
        SuiteMotor::IndustrialIpm => (
            MotorModel::industrial_ipm(),
            1500.0,
            14.0,
            540.0,
            1e-6,
            0.05,
            25.0,
            9.0,
            300.0,
            10.0,
            TS_S,
        ),
        SuiteMotor::TractionIpm => (
            MotorModel::traction_ipm(),
            3000.0,
            15.0,
            48.0,
            0.2e-6,
            0.3,
            300.0,
            180.0,
            1000.0,
            30.0,
            TS_S_TRACTION,
        ),
    }
}

/// The main scenario of one motor (module docs).
pub fn suite_scenario(motor: SuiteMotor, opts: &SuiteOptions) -> Scenario {
    scenario_with(motor, opts, &Plan::main(opts.short), INITIAL_ANGLE_RAD)
}

/// Start angles of the convergence runs, deg el.: 8 (4 with `short`) around the circle,
/// none at 0 or 180 deg.
pub fn start_angles_deg(short: bool) -> Vec<f64> {
    if short {
        vec![-135.0, -45.0, 45.0, 135.0]
    } else {
        (0..8).map(|i| -157.5 + 45.0 * f64::from(i)).collect()
    }
}

/// Start angles of one motor's convergence runs, deg el.: [`start_angles_deg`], and for an
/// interior motor also 180 deg (the observers start at 0: the `theta + pi` cell).
pub fn motor_start_angles_deg(motor: SuiteMotor, short: bool) -> Vec<f64> {
    let mut a = start_angles_deg(short);
    if motor.is_interior() {
        a.push(180.0);
    }
    a
}

/// The scenario of one motor for a plan and a start angle.
fn scenario_with(motor: SuiteMotor, opts: &SuiteOptions, plan: &Plan, theta0_rad: f64) -> Scenario {
    let (model, rpm, torque, u_dc, dead, noise, fs, i_lim, bw_i, bw_w, ts) = setting(motor);
    let index = SuiteMotor::ALL
        .iter()
        .position(|&x| x == motor)
        .unwrap_or(0) as u64;
    Scenario {
        name: format!("suite-{}", motor.name()),
        description: format!(
            "suite: {} spinning at 50 % rated, observers from zero; 10/50/100 % rated, rated load step",
            motor.name()
        ),
        duration_s: plan.duration_s,
        seed: opts.seed.wrapping_add(index),
        rated_speed_rpm: rpm,
        rated_torque_nm: torque,
        motor: model,
        initial: InitialState {
            theta_e_rad: theta0_rad,
            speed_rpm: 0.5 * rpm,
        },
        inverter: InverterConfig {
            ts_s: ts,
            u_dc_v: u_dc,
            dead_time_s: if opts.ideal { 0.0 } else { dead },
            delay: true,
            delay_periods: None,
            ripple_fraction: 0.0,
            ripple_hz: 0.0,
        },
        sensors: if opts.ideal {
            SensorConfig::default()
        } else {
            SensorConfig {
                current_noise_std_a: noise,
                gain_error: [0.002, -0.001],
                offset_a: [0.001 * fs, -0.0006 * fs],
                adc_bits: 12,
                adc_full_scale_a: fs,
            }
        },
        controller: ControllerSettings {
            // foc sensored, on the interior motors with its MTPA (on by default).
            kind: ControllerKind::FocSensored,
            current_limit_a: i_lim,
            current_bandwidth_hz: bw_i,
            speed_bandwidth_hz: bw_w,
            delay_compensation: None,
            foc: Some(FocSettings::default()),
        },
        observer: ObserverSettings {
            reference_filter: false,
            ..ObserverSettings::default()
        },
        speed_ref_rpm: Profile::linear(
            plan.speed_points
                .iter()
                .map(|&(t, f)| (t, f * rpm))
                .collect(),
        ),
        load: {
            let w_rated = rpm / RPM_PER_RAD_S;
            let mut load = vec![LoadTerm::Fan {
                coefficient_nm_s2_rad2: FAN_LOAD_FRACTION * torque / (w_rated * w_rated),
            }];
            if plan.step_s.is_finite() {
                // Interior motors: rated torque in all at rated speed (the fan's share less), since
                // the traction motor's rated point is just below its base speed.
                let step = if motor.is_interior() {
                    (1.0 - FAN_LOAD_FRACTION) * torque
                } else {
                    torque
                };
                load.push(LoadTerm::Step {
                    time_s: plan.step_s,
                    before_nm: 0.0,
                    after_nm: step,
                });
            }
            load
        },
        faults: Vec::new(),
        skipped_cycles: Default::default(),
    }
}

/// An observer stepped alongside the run, scoring itself per window.
struct Scored {
    kind: ObserverKind,
    /// The mismatch case told, if any (index in [`MISMATCHES`]).
    told: Option<usize>,
    est: Box<dyn Observer>,
    /// Tracked `(psi_f, Rs)` of the last step (the told ones for the baseline).
    params: (f64, f64),
    /// Per window: sums of the tracked `psi_f` and `Rs` over its samples.
    param_sums: Vec<[f64; 2]>,
    plan: Plan,
    windows: Vec<Sums>,
    step: Sums,
    /// Time of the last sample of the convergence phase with `|e_th| >= 5 deg` (or failed).
    last_bad_s: Option<f64>,
    /// Time of the last sample of the convergence phase.
    last_conv_s: f64,
    failures: usize,
    /// Every estimate of the whole run: the status shares.
    run: Sums,
}

impl Scored {
    fn new(
        kind: ObserverKind,
        told: Option<usize>,
        scenario: &Scenario,
        plan: Plan,
    ) -> Result<Self, SimError> {
        let mut params = scenario.observer_params();
        if let Some(m) = told.map(|i| MISMATCHES[i]) {
            params.psi_f_wb *= m.psi_f;
            params.rs_ohm *= m.rs;
            params.ld_h *= m.ls;
            params.lq_h *= m.ls;
        }
        let ts = scenario.ts_s();
        let est: Box<dyn Observer> = match kind {
            ObserverKind::SeedEkf => {
                Box::new(PmsmObserver::new(&ObserverConfig::seed(params, ts))?)
            }
            ObserverKind::DefaultEkf => {
                Box::new(PmsmObserver::new(&ObserverConfig::new(params, ts))?)
            }
            ObserverKind::FluxBaseline => {
                Box::new(FluxObserver::new(&FluxObserverConfig::new(params, ts))?)
            }
        };
        Ok(Self {
            kind,
            told,
            est,
            params: (params.psi_f_wb, params.rs_ohm),
            param_sums: vec![[0.0; 2]; plan.windows.len()],
            windows: vec![Sums::default(); plan.windows.len()],
            plan,
            step: Sums::default(),
            last_bad_s: None,
            last_conv_s: 0.0,
            failures: 0,
            run: Sums::default(),
        })
    }
}

impl Observer for Scored {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let e = self.est.step(u_prev, i_ab_a)?;
        self.params = (e.psi_f_wb, e.rs_ohm);
        Ok(e)
    }
}

impl SideObserver for Scored {
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>) {
        let t = sample.t_s;
        let own = own.ok();
        match &own {
            None => self.failures += 1,
            Some(s) => self.run.add_sample(s),
        }
        if t < self.plan.conv_end_s {
            self.last_conv_s = t;
            let bad = own
                .as_ref()
                .is_none_or(|s| !is_converged(s.angle_error_deg));
            if bad {
                self.last_bad_s = Some(t);
            }
        }
        let in_window = |t0: f64, t1: f64| t >= t0 && t < t1;
        for ((sums, w), ps) in self
            .windows
            .iter_mut()
            .zip(&self.plan.windows)
            .zip(self.param_sums.iter_mut())
        {
            if in_window(w.3, w.4) {
                match &own {
                    Some(s) => {
                        sums.add_sample(s);
                        ps[0] += self.params.0;
                        ps[1] += self.params.1;
                    }
                    None => sums.add_failure(),
                }
            }
        }
        if in_window(self.plan.step_s, self.plan.step_end_s) {
            match &own {
                Some(s) => self.step.add_sample(s),
                None => self.step.add_failure(),
            }
        }
    }
}

/// Runs one scenario with the three observers alongside (and, with `mismatch`, the default
/// EKF and the baseline told each wrong motor of [`MISMATCHES`]); an early end is an error.
fn run_scored(
    sc: &Scenario,
    plan: &Plan,
    mismatch: bool,
) -> Result<(Vec<Scored>, String), SimError> {
    run_scored_with(sc, plan, &ObserverKind::ALL, mismatch, Vec::new()).map(|(s, e, _)| (s, e))
}

/// [`run_scored`] with the given observers and sinks, also returning the run.
fn run_scored_with(
    sc: &Scenario,
    plan: &Plan,
    kinds: &[ObserverKind],
    mismatch: bool,
    sinks: Vec<&mut dyn crate::sim::SampleSink>,
) -> Result<(Vec<Scored>, String, crate::sim::RunOutput), SimError> {
    let mut scored = kinds
        .iter()
        .map(|&k| Scored::new(k, None, sc, plan.clone()))
        .collect::<Result<Vec<_>, _>>()?;
    if mismatch {
        for i in 0..MISMATCHES.len() {
            for k in [ObserverKind::DefaultEkf, ObserverKind::FluxBaseline] {
                scored.push(Scored::new(k, Some(i), sc, plan.clone())?);
            }
        }
    }
    // foc sensored. Its own speed slew (half the acceleration of its current limit, for the
    // motor's inertia) would turn the scenario's ramps into slower ones and leave the windows
    // on a ramp; the profile's ramps are the acceleration here.
    let mut cfg = sc.foc_config().map_err(|e| SimError::Scenario {
        file: sc.name.clone(),
        field: e.field,
        problem: e.problem,
    })?;
    cfg.speed_slew_rad_s2 *= 100.0;
    let mut drive = FocDrive::new(&cfg, 0.0, None).map_err(|e| SimError::Scenario {
        file: sc.name.clone(),
        field: "controller.foc".into(),
        problem: e.to_string(),
    })?;
    let out = {
        let mut side: Vec<&mut dyn SideObserver> = scored
            .iter_mut()
            .map(|s| s as &mut dyn SideObserver)
            .collect();
        let opts = crate::sim::RunOptions {
            sinks,
            ..Default::default()
        };
        run_with_side_observers(sc, &mut drive, opts, &mut side)?
    };
    if !out.end.is_completed() {
        return Err(SimError::Stopped {
            t_s: out.end.stop_time_s().unwrap_or(0.0),
            reason: format!("suite scenario {}: {}", sc.name, out.end.describe()),
        });
    }
    let end = out.end.describe();
    Ok((scored, end, out))
}

/// Scores the controller's own observer over a window (a sink of the run).
struct FocScore {
    window: (f64, f64),
    sums: Sums,
}

impl crate::sim::SampleSink for FocScore {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        if s.t_s >= self.window.0
            && s.t_s < self.window.1
            && let Some(o) = &s.controller_observer
        {
            self.sums.add_sample(o);
        }
        Ok(())
    }
}

/// The real-drive rows of one motor (module docs).
fn real_drive_rows(motor: SuiteMotor, opts: &SuiteOptions) -> Result<Vec<RealDriveRow>, SimError> {
    let plan = Plan::real_drive(opts.short);
    let mut rows = Vec::new();
    for effect in RealDriveEffect::ALL {
        let mut sc = scenario_with(motor, opts, &plan, INITIAL_ANGLE_RAD);
        sc.name = format!("suite-{}-real-drive", motor.name());
        effect.apply(&mut sc);
        let mut foc = FocScore {
            window: (plan.windows[0].3, plan.windows[0].4),
            sums: Sums::default(),
        };
        let kinds = [ObserverKind::FluxBaseline, ObserverKind::DefaultEkf];
        let (scored, _, out) = run_scored_with(&sc, &plan, &kinds, false, vec![&mut foc])?;
        let stats = |k: ObserverKind| {
            scored
                .iter()
                .find(|s| s.kind == k)
                .and_then(|s| s.windows.first())
                .map_or(
                    AngleStats {
                        samples: 0,
                        rms_deg: f64::NAN,
                        max_deg: f64::NAN,
                        mean_deg: f64::NAN,
                    },
                    AngleStats::of,
                )
        };
        if let Some(w) = plan.windows.first() {
            rows.push(RealDriveRow {
                motor,
                effect,
                condition: w.0.to_string(),
                w_ts_rad: w.1 * sc.rated_speed_e_rad_s() * sc.ts_s(),
                ekf: stats(ObserverKind::DefaultEkf),
                baseline: stats(ObserverKind::FluxBaseline),
                foc_observer: AngleStats::of(&foc.sums),
                skipped_periods: out.metrics.skipped_control_periods,
                periods: out.metrics.periods,
            });
        }
    }
    Ok(rows)
}

impl Scored {
    /// Convergence time (`None`: the last sample of the convergence phase is off).
    fn convergence_time_s(&self, ts_s: f64) -> Option<f64> {
        let converged = self.last_bad_s.is_none_or(|t| t < self.last_conv_s);
        converged.then(|| self.last_bad_s.map_or(0.0, |t| t + ts_s))
    }
}

/// Runs the suite (module docs): every motor ([`SuiteMotor::ALL`]), three observers.
pub fn run_suite(opts: &SuiteOptions) -> Result<SuiteReport, SimError> {
    run_suite_motors(opts, &SuiteMotor::ALL)
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
        for s in scored.iter().filter(|s| s.told.is_some()) {
            let case = MISMATCHES[s.told.unwrap_or(0)].name;
            for ((sums, w), ps) in s.windows.iter().zip(&plan.windows).zip(&s.param_sums) {
                let n = sums.n as f64;
                let ekf = s.kind == ObserverKind::DefaultEkf;
                mismatch.push(MismatchRow {
                    observer: s.kind,
                    motor,
                    case,
                    condition: w.0.to_string(),
                    speed_fraction: w.1,
                    samples: sums.n,
                    angle_rms_deg: sums.angle_rms_deg(),
                    angle_max_deg: sums.max_e,
                    angle_mean_deg: sums.angle_mean_deg(),
                    psi_f_error_pct: ekf.then(|| 100.0 * (ps[0] / n / truth.0 - 1.0)),
                    rs_error_pct: 100.0 * (ps[1] / n / truth.1 - 1.0),
                });
            }
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
        checks: Vec::new(),
    };
    report.checks = report.evaluate();
    report.wall_time_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// `value <= limit`, NaN failing.
fn check(name: &str, motor: SuiteMotor, row: &str, value: f64, limit: f64) -> Check {
    Check {
        name: name.to_string(),
        motor,
        row: row.to_string(),
        value,
        limit,
        pass: value <= limit,
    }
}

impl SuiteReport {
    /// The steady-state row of an observer, motor and condition.
    pub fn steady_row(
        &self,
        observer: ObserverKind,
        motor: SuiteMotor,
        condition: &str,
    ) -> Option<&SteadyRow> {
        self.steady
            .iter()
            .find(|r| r.observer == observer && r.motor == motor && r.condition == condition)
    }

    /// The transient row of an observer and motor.
    pub fn transient_row(
        &self,
        observer: ObserverKind,
        motor: SuiteMotor,
    ) -> Option<&TransientRow> {
        self.transients
            .iter()
            .find(|r| r.observer == observer && r.motor == motor)
    }

    /// Length of the steady-state windows, s.
    pub fn window_s(&self) -> f64 {
        let w = &Plan::main(self.options.short).windows;
        w.first().map_or(0.0, |w| w.4 - w.3)
    }

    /// Whether every goal and limit holds.
    pub fn all_pass(&self) -> bool {
        self.checks.iter().all(|c| c.pass)
    }

    /// The goals and limits (module docs) on the rows.
    fn evaluate(&self) -> Vec<Check> {
        let mut out = Vec::new();
        for r in self
            .steady
            .iter()
            .filter(|r| r.observer == ObserverKind::DefaultEkf)
        {
            let base = self.steady_row(ObserverKind::FluxBaseline, r.motor, &r.condition);
            let ratio = base.map_or(f64::NAN, |b| r.angle_rms_deg / b.angle_rms_deg);
            out.push(check(
                "goal: EKF RMS / baseline RMS",
                r.motor,
                &r.condition,
                ratio,
                GOAL_RMS_RATIO,
            ));
            if r.w_ts_rad <= GOAL_MEAN_MAX_WTS {
                out.push(check(
                    "goal: EKF |mean| (deg)",
                    r.motor,
                    &r.condition,
                    r.angle_mean_deg.abs(),
                    GOAL_MEAN_DEG,
                ));
            }
            out.push(check(
                "limit: EKF RMS (deg)",
                r.motor,
                &r.condition,
                r.angle_rms_deg,
                LIMIT_RMS_DEG,
            ));
            out.push(check(
                "limit: EKF max (deg)",
                r.motor,
                &r.condition,
                r.angle_max_deg,
                LIMIT_MAX_DEG,
            ));
            out.push(check(
                "limit: EKF speed RMS (% rated)",
                r.motor,
                &r.condition,
                r.speed_rms_pct,
                LIMIT_SPEED_PCT,
            ));
        }
        for r in self
            .mismatch
            .iter()
            .filter(|r| r.observer == ObserverKind::DefaultEkf && r.speed_fraction >= 0.5)
        {
            let m = MISMATCHES.iter().find(|m| m.name == r.case);
            let row = format!("{}, {}", r.condition, r.case);
            if m.is_some_and(|m| m.is_ls()) {
                out.push(check(
                    "goal: EKF RMS told a wrong Ls (deg)",
                    r.motor,
                    &row,
                    r.angle_rms_deg,
                    GOAL_MISMATCH_LS_RMS_DEG,
                ));
            } else {
                out.push(check(
                    "goal: EKF RMS told a wrong psi_f, Rs or temperature (deg)",
                    r.motor,
                    &row,
                    r.angle_rms_deg,
                    GOAL_MISMATCH_RMS_DEG,
                ));
            }
            if m.is_some_and(|m| m.is_psi_only()) {
                out.push(check(
                    "goal: tracked psi_f error told a wrong psi_f (%)",
                    r.motor,
                    &row,
                    r.psi_f_error_pct.map_or(f64::NAN, f64::abs),
                    GOAL_MISMATCH_PSI_PCT,
                ));
            }
        }
        for t in self
            .transients
            .iter()
            .filter(|r| r.observer == ObserverKind::DefaultEkf)
        {
            out.push(check(
                "limit: EKF worst convergence time over the starts (s)",
                t.motor,
                "unknown start",
                t.convergence_worst_s.unwrap_or(f64::INFINITY),
                t.convergence_phase_s,
            ));
            out.push(check(
                "limit: EKF worst error, load step (deg)",
                t.motor,
                "load step",
                t.load_step_max_deg,
                LIMIT_LOAD_STEP_DEG,
            ));
            if t.motor.is_interior() {
                out.push(check(
                    "goal: EKF worst convergence over the starts, theta+pi included (s)",
                    t.motor,
                    "unknown start",
                    t.convergence_worst_s.unwrap_or(f64::INFINITY),
                    GOAL_IPM_CONVERGENCE_S,
                ));
            }
        }
        out
    }

    /// The report as markdown: one steady-state table per observer, the transients, the
    /// goals and limits.
    pub fn to_markdown(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# pmsm-sim suite ({} run, seed {}, {} sensing)\n",
            if self.options.short { "short" } else { "full" },
            self.options.seed,
            if self.options.ideal {
                "ideal"
            } else {
                "realistic"
            }
        );
        let sensing = if self.options.ideal {
            "ideal current sensing, ideal switches (no dead time)".to_string()
        } else {
            "sensor noise per phase as listed, 12-bit ADC, offsets 0.1 % / -0.06 % of full scale, \
             gain errors +0.2 % / -0.1 %, dead time as listed (compensated by foc)"
                .to_string()
        };
        let _ = writeln!(
            s,
            "foc in sensored mode drives every motor (it sees the true angle: the \
             trajectory does not depend on the observers); every observer runs alongside on the \
             same measured currents and the voltages the drive expects of its duties, delayed \
             like the duties. The \
             observers start at zero speed and angle while the rotor spins at 50 % rated speed, \
             {:.0} deg el. away. PWM as listed, one period of computation delay; {sensing}. Load: \
             friction, a fan load of {:.0} % of rated torque at rated speed, and the rated load \
             step (interior motors: the step less the fan's share, rated torque in all at rated \
             speed). Interior motors: foc runs them on its MTPA curve (until it had one, the \
             simulator's sensored drive did); their convergence starts add 180 deg (the theta+pi cell), goal: all within {:.0} ms. Steady-state \
             windows: {:.2} s each, after the speed has settled.\n",
            INITIAL_ANGLE_RAD.to_degrees(),
            FAN_LOAD_FRACTION * 100.0,
            GOAL_IPM_CONVERGENCE_S * 1e3,
            self.window_s(),
        );
        let _ = writeln!(
            s,
            "| motor | drive | PWM (kHz) | rated speed (rpm) | w_e Ts at rated (rad) | rated torque (N m) | bus (V) | dead time (us) | noise (A) | ADC full scale (A) | simulated (s) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
        for m in &self.motors {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.0} | {:.3} | {} | {} | {:.2} | {} | {} | {:.2} |",
                m.motor.name(),
                m.drive,
                1e-3 / m.ts_s,
                m.rated_speed_rpm,
                m.rated_w_ts_rad,
                m.rated_torque_nm,
                m.u_dc_v,
                m.dead_time_s * 1e6,
                m.noise_a,
                m.adc_full_scale_a,
                m.duration_s
            );
        }
        for kind in ObserverKind::ALL {
            let _ = writeln!(s, "\n## Steady state: {}\n", kind.title());
            let _ = writeln!(
                s,
                "| motor | speed | w_e Ts (rad) | angle RMS (deg) | angle max (deg) | angle mean (deg) | speed RMS (rad/s) | speed RMS (% rated) |"
            );
            let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
            for r in self.steady.iter().filter(|r| r.observer == kind) {
                let fail = if r.failures > 0 {
                    format!(" ({} failed steps)", r.failures)
                } else {
                    String::new()
                };
                let _ = writeln!(
                    s,
                    "| {} | {}{} | {:.3} | {:.3} | {:.3} | {:+.3} | {:.2} | {:.3} |",
                    r.motor.name(),
                    r.condition,
                    fail,
                    r.w_ts_rad,
                    r.angle_rms_deg,
                    r.angle_max_deg,
                    r.angle_mean_deg,
                    r.speed_rms_rad_s,
                    r.speed_rms_pct
                );
            }
        }
        let _ = writeln!(s, "\n## Transients\n");
        let _ = writeln!(
            s,
            "| observer | motor | convergence, main run (ms) | converged starts | worst convergence over starts (ms) | worst angle error, rated load step (deg) | worst speed error, load step (rad/s) | status Tracking, whole run (%) | Tracking while > 45 deg off (samples) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        let ms = |c: Option<f64>| match c {
            Some(c) => format!("{:.1}", c * 1e3),
            None => "not converged".to_string(),
        };
        for t in &self.transients {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {}/{} | {} | {:.2} | {:.2} | {:.1} | {} |",
                short_name(t.observer),
                t.motor.name(),
                ms(t.convergence_time_s),
                t.converged_starts,
                t.start_angles_deg.len(),
                ms(t.convergence_worst_s),
                t.load_step_max_deg,
                t.load_step_speed_max_rad_s,
                t.tracking_pct,
                t.tracking_while_lost
            );
        }
        if let Some(t) = self.transients.first() {
            let _ = writeln!(
                s,
                "\nConvergence: first time after which |e_th| < {CONVERGED_DEG} deg holds to the end of the {:.0} ms convergence phase; the rotor spins at 50 % rated speed, the observers start at zero speed and angle. Main run: start angle {:.0} deg; starts: {:?} deg.",
                t.convergence_phase_s * 1e3,
                INITIAL_ANGLE_RAD.to_degrees(),
                t.start_angles_deg
            );
        }
        let _ = writeln!(
            s,
            "\n## Mismatch: the observers told a wrong motor\n\nThe main runs again, the default EKF (online psi_f tracking, Rs by the split filter) and the baseline told a wrong motor; psi_f and Rs: the mean over the window of the EKF's tracked values (the baseline's are the told ones) against the truth.\n"
        );
        let _ = writeln!(
            s,
            "| motor | told | speed | EKF angle RMS / max / mean (deg) | baseline angle RMS / max / mean (deg) | EKF psi_f error (%) | EKF Rs error (%) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for r in self
            .mismatch
            .iter()
            .filter(|r| r.observer == ObserverKind::DefaultEkf)
        {
            let base = self.mismatch.iter().find(|b| {
                b.observer == ObserverKind::FluxBaseline
                    && b.motor == r.motor
                    && b.case == r.case
                    && b.condition == r.condition
            });
            let (brms, bmax, bmean) = base.map_or((f64::NAN, f64::NAN, f64::NAN), |b| {
                (b.angle_rms_deg, b.angle_max_deg, b.angle_mean_deg)
            });
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3} / {:.3} / {:+.3} | {:.3} / {:.3} / {:+.3} | {:+.2} | {:+.1} |",
                r.motor.name(),
                r.case,
                r.condition,
                r.angle_rms_deg,
                r.angle_max_deg,
                r.angle_mean_deg,
                brms,
                bmax,
                bmean,
                r.psi_f_error_pct.unwrap_or(f64::NAN),
                r.rs_error_pct
            );
        }
        if !self.real_drive.is_empty() {
            let _ = writeln!(
                s,
                "\n## Real-drive effects, not told to the observers\n\nOne run per motor and effect: the observers converge at 50 % rated speed, the speed rises to rated, the rated load steps on; angle error over a window at rated speed and load. The default EKF and the baseline step on every sample with the voltage the drive believes it applied; foc's own f32 observer runs inside the (sensored) drive and misses the skipped periods with it. Effects: the voltage applied 1.5 periods after the sample (the observers assume 1); 5th and 7th back-EMF harmonics of 3 % and 2 % of the fundamental; 1 % of the control periods skipped.\n"
            );
            let _ = writeln!(
                s,
                "| motor | effect | w_e Ts (rad) | EKF angle RMS / max / mean (deg) | baseline angle RMS / max / mean (deg) | foc observer angle RMS / max / mean (deg) | skipped periods |"
            );
            let _ = writeln!(s, "|---|---|---|---|---|---|---|");
            let f = |a: &AngleStats| {
                format!("{:.3} / {:.3} / {:+.3}", a.rms_deg, a.max_deg, a.mean_deg)
            };
            for r in &self.real_drive {
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.3} | {} | {} | {} | {} of {} |",
                    r.motor.name(),
                    r.effect.name(),
                    r.w_ts_rad,
                    f(&r.ekf),
                    f(&r.baseline),
                    f(&r.foc_observer),
                    r.skipped_periods,
                    r.periods
                );
            }
        }
        let _ = writeln!(
            s,
            "\n## Goals and limits (default EKF)\n\nGoals of the issue: RMS at most {GOAL_RMS_RATIO} x the baseline's in every steady-state row; |mean| at most {GOAL_MEAN_DEG} deg where w_e Ts <= {GOAL_MEAN_MAX_WTS} rad. Limits: RMS <= {LIMIT_RMS_DEG} deg, max <= {LIMIT_MAX_DEG} deg, speed RMS <= {LIMIT_SPEED_PCT} % of rated, converged from every start angle within the convergence phase, worst error through the load step <= {LIMIT_LOAD_STEP_DEG} deg. Mismatch goals at >= 50 % speed: RMS <= {GOAL_MISMATCH_RMS_DEG} deg told a wrong psi_f, Rs or temperature, <= {GOAL_MISMATCH_LS_RMS_DEG} deg told a wrong Ls; the tracked psi_f within {GOAL_MISMATCH_PSI_PCT} % told a wrong psi_f.\n"
        );
        let _ = writeln!(s, "| check | motor | row | value | limit | result |");
        let _ = writeln!(s, "|---|---|---|---|---|---|");
        for c in &self.checks {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3} | {} | {} |",
                c.name,
                c.motor.name(),
                c.row,
                c.value,
                c.limit,
                if c.pass { "pass" } else { "**FAIL**" }
            );
        }
        let failed = self.checks.iter().filter(|c| !c.pass).count();
        let _ = writeln!(
            s,
            "\n{} of {} checks pass. Wall time {:.2} s.",
            self.checks.len() - failed,
            self.checks.len(),
            self.wall_time_s
        );
        s
    }
}

/// Short observer name for the transient table.
fn short_name(k: ObserverKind) -> &'static str {
    match k {
        ObserverKind::SeedEkf => "seed's filter",
        ObserverKind::FluxBaseline => "flux + PLL baseline",
        ObserverKind::DefaultEkf => "default EKF",
    }
}
