//! Self-commissioning: measures `Rs`, `Ld`, `Lq`, `psi_f`, the inverter's voltage error and
//! (optionally) the inertia of a motor the drive knows nothing about.
//!
//! [`Identifier::tick`] takes the same [`TickInput`] as [`Foc::tick`](crate::Foc::tick), once
//! per PWM period, and returns duties; [`identify_period`] is the interrupt body for the
//! [`hal`](crate::hal) traits. Nothing here reads a clock, allocates or panics. Every step has
//! a fixed length in ticks (derived from [`IdentifyConfig`]), so the whole sequence is
//! time-bounded; it ends with the PWM off and [`Identifier::result`] set, either to the
//! [`Identified`] parameters or to an [`IdentifyFailure`] naming the error, the step and the
//! tick.
//!
//! # The sequence
//!
//! | step | what | how |
//! |---|---|---|
//! | [`IdentifyStep::Offsets`] | current-sensor offsets | PWM off, mean of the phase currents |
//! | [`IdentifyStep::Probe`] | wiring and a rough inductance | bipolar voltage pulses along the three phase axes, doubling the voltage (then the pulse length) until one axis reaches 40 % of the test current; an axis that stays dead is an open phase, all three: no motor. `L ~ U t / di` sizes the current loop |
//! | [`IdentifyStep::Align`] | rotor to a known angle | test current at 90 deg, then at 0 deg (the phase-a axis), so that a rotor at any angle (also 180 deg away) is pulled in; the q voltage is left at zero, so the swinging rotor's EMF drives a braking current (electrical damping) |
//! | [`IdentifyStep::Resistance`] | `Rs`, inverter voltage error | DC current along the aligned d axis at 50 % and 100 % of the test current: `Rs = dU / dI`; the dead-time voltage (the same at both levels, the phase currents keep their signs) cancels and is reported as `U1 - Rs I1` |
//! | [`IdentifyStep::InductanceD`] | `Ld` | the DC voltage held, plus a sinusoidal voltage along d; the current's response at the injection frequency, demodulated over whole periods, fitted to the exact zero-order-hold model of the RL circuit with the computation delay, `i[k+1] = a i[k] + b u[k-d]`: `L = Ts (1 - a) / (b (-ln a))` |
//! | [`IdentifyStep::InductanceQ`] | `Lq` | the same along q (the DC d current holds the rotor); at two frequencies `w` and `w/2`, so that the rotor's small oscillation (an apparent `-K/w^2` in `L`) is extrapolated away: `Lq = (4 L(w) - L(w/2)) / 3` |
//! | [`IdentifyStep::Spin`] | `psi_f` | I/f: the test current along a frame that turns with a jerk-limited ramp to `spin_speed_rad_s`; at constant speed the mean frame voltage gives the active-flux EMF `E = u - (Rs + j w Lq) i` (dead-time voltage removed), `|E| = w (psi_f + (Ld - Lq) i_d)`, its angle the load angle and so `i_d`; `w` is the rotor's mean speed over the window, the frame's minus the drift of the load angle (the rotor swings about the frame) |
//! | [`IdentifyStep::Inertia`] | `J` (optional) | the frame accelerates to 1.4 x the spin speed and back at the same rate; every tick gives the rotor angle (frame minus load angle) and the torque (from the load angle and the current); a least-squares fit of the rotor's trajectory to `J theta'' = T - B theta' - T_c`, integrated twice, with the initial angle and speed and the friction as nuisance parameters, gives `J`. The I/f frame holds the rotor like a spring; with little friction the rotor swings about it for seconds (7 Hz on the 2.2 kW motor), and the fit models that swing instead of averaging it (friction is fitted but not reported) |
//!
//! The standstill steps take about 0.8 s with the default durations, the spin about 1.2 s
//! (1.7 s with the inertia).
//!
//! # Faults
//!
//! Checked every tick: non-finite inputs, over-current (`over_current_a`), bus outside
//! `[u_dc_min_v, u_dc_max_v]`. The current loops hitting the voltage limit below 90 % of their
//! reference for `saturation_time` is [`IdentifyError::BusTooLow`]. Implausible results
//! (negative or absurd `Rs`, `L`, `psi_f`, `J`) are [`IdentifyError::Implausible`]; a spin
//! without back-EMF is [`IdentifyError::RotorLocked`], one whose EMF does not turn with the
//! frame is [`IdentifyError::LostSync`]. Every failure turns the PWM off at once.

use core::f32::consts::{FRAC_PI_2, PI, TAU};
use core::fmt;

use ekf_core::MotorParams;

use crate::config::ComputationDelay;
use crate::controller::{PhaseCurrents, TickInput};
use crate::hal::{CurrentSense, Inverter, write_bridge};
use crate::pi::{Pi, PiGains};
use crate::svpwm::{SAFE_DUTIES, svpwm};
use crate::transforms::AlphaBeta;
use crate::trig::{atan2, sin_cos, sqrt, wrap};

const INV_SQRT3: f32 = 0.577_350_26;
const LN_2: f32 = core::f32::consts::LN_2;

/// Settings of the identification (SI units; speeds electrical).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifyConfig {
    /// PWM (tick) period, s.
    pub ts_s: f32,
    /// When the duties of a tick take effect (as for the controller).
    pub delay: ComputationDelay,
    /// Test current: the align, resistance and injection bias level, A.
    pub test_current_a: f32,
    /// Software over-current trip, A (phase-vector magnitude).
    pub over_current_a: f32,
    /// Bus under-voltage trip, V.
    pub u_dc_min_v: f32,
    /// Bus over-voltage trip, V.
    pub u_dc_max_v: f32,
    /// Fraction of the linear range `u_dc / sqrt(3)` the voltage may use, `(0, 1]`.
    pub max_modulation: f32,
    /// Bandwidth of the current loops, rad/s.
    pub current_bw_rad_s: f32,
    /// Injection frequency for the inductances, Hz (rounded to a whole number of ticks per
    /// period, at least 4).
    pub hf_frequency_hz: f32,
    /// Length of the alignment (two halves), s.
    pub align_time_s: f32,
    /// Length of each of the two resistance levels (30 % settling, 70 % averaging), s.
    pub resistance_time_s: f32,
    /// Length of the averaging window of each inductance measurement, s.
    pub inductance_time_s: f32,
    /// Spin speed for `psi_f`, rad/s electrical; 0 skips the spin (`psi_f` not measured).
    pub spin_speed_rad_s: f32,
    /// Acceleration of the I/f ramp, rad/s^2 electrical (the rotor must be able to follow
    /// it with `spin_current_a`).
    pub spin_accel_rad_s2: f32,
    /// Current of the I/f spin, A.
    pub spin_current_a: f32,
    /// Settling time at the spin speed before the averaging, s.
    pub spin_settle_time_s: f32,
    /// Averaging window at the spin speed, s.
    pub spin_measure_time_s: f32,
    /// Measure the inertia after `psi_f` (needs the spin).
    pub measure_inertia: bool,
    /// Pole pairs (for the mechanical quantities), >= 1.
    pub pole_pairs: u32,
}

impl IdentifyConfig {
    /// Defaults for a drive with PWM period `ts_s`, nominal bus `u_dc_nominal_v` and a test
    /// current `test_current_a` (about half the motor's rated current is a good choice): a
    /// 1 kHz injection, 0.3 s alignment, 2 x 0.13 s resistance, 0.08 s per inductance
    /// window, no spin (set `spin_speed_rad_s` and `spin_accel_rad_s2` to measure `psi_f`).
    pub fn new(ts_s: f32, u_dc_nominal_v: f32, test_current_a: f32) -> Self {
        Self {
            ts_s,
            delay: ComputationDelay::OnePeriod,
            test_current_a,
            over_current_a: 2.5 * test_current_a,
            u_dc_min_v: 0.5 * u_dc_nominal_v,
            u_dc_max_v: 1.25 * u_dc_nominal_v,
            max_modulation: 0.95,
            current_bw_rad_s: TAU * 300.0,
            hf_frequency_hz: 1000.0,
            align_time_s: 0.3,
            resistance_time_s: 0.13,
            inductance_time_s: 0.08,
            spin_speed_rad_s: 0.0,
            spin_accel_rad_s2: 0.0,
            spin_current_a: test_current_a,
            spin_settle_time_s: 0.15,
            spin_measure_time_s: 0.2,
            measure_inertia: false,
            pole_pairs: 1,
        }
    }

    /// With a spin to `speed_rad_s` (electrical) at `accel_rad_s2`.
    pub fn with_spin(mut self, speed_rad_s: f32, accel_rad_s2: f32) -> Self {
        self.spin_speed_rad_s = speed_rad_s;
        self.spin_accel_rad_s2 = accel_rad_s2;
        self
    }

    /// Ticks per injection period (the shorter one).
    pub fn hf_period_ticks(&self) -> u32 {
        ticks(1.0 / self.hf_frequency_hz, self.ts_s)
    }

    /// Checks every setting; the error names the field.
    pub fn validate(&self) -> Result<(), IdentifyConfigError> {
        let err = |field: &'static str, problem: &'static str| {
            Err(IdentifyConfigError { field, problem })
        };
        let pos = |v: f32| v.is_finite() && v > 0.0;
        if !(pos(self.ts_s) && (1e-6..=1e-2).contains(&self.ts_s)) {
            return err("ts_s", "must be in [1e-6, 1e-2] s");
        }
        if !pos(self.test_current_a) {
            return err("test_current_a", "must be finite and positive");
        }
        if !pos(self.over_current_a) || self.over_current_a < 1.5 * self.test_current_a {
            return err(
                "over_current_a",
                "must be finite and at least 1.5 x the test current",
            );
        }
        if !pos(self.u_dc_min_v) {
            return err("u_dc_min_v", "must be finite and positive");
        }
        if !(self.u_dc_max_v.is_finite() && self.u_dc_max_v > self.u_dc_min_v) {
            return err("u_dc_max_v", "must be finite and above u_dc_min_v");
        }
        if !(pos(self.max_modulation) && self.max_modulation <= 1.0) {
            return err("max_modulation", "must be in (0, 1]");
        }
        if !(pos(self.current_bw_rad_s) && self.current_bw_rad_s * self.ts_s <= 0.5) {
            return err(
                "current_bw_rad_s",
                "must be positive and at most 0.5 / ts_s",
            );
        }
        if !pos(self.hf_frequency_hz) || self.hf_frequency_hz * self.ts_s > 0.25 {
            return err(
                "hf_frequency_hz",
                "must be positive with at least 4 ticks per period",
            );
        }
        if self.hf_period_ticks() > 2000 {
            return err(
                "hf_frequency_hz",
                "too low: more than 2000 ticks per period",
            );
        }
        let time = |v: f32, min_ticks: f32| pos(v) && v >= min_ticks * self.ts_s && v <= 10.0;
        if !time(self.align_time_s, 20.0) {
            return err("align_time_s", "must be in [20 ticks, 10 s]");
        }
        if !time(self.resistance_time_s, 20.0) {
            return err("resistance_time_s", "must be in [20 ticks, 10 s]");
        }
        let hf = self.hf_period_ticks() as f32;
        if !time(self.inductance_time_s, 2.0 * hf) {
            return err(
                "inductance_time_s",
                "must be in [2 injection periods, 10 s]",
            );
        }
        if !(self.spin_speed_rad_s.is_finite() && self.spin_speed_rad_s >= 0.0) {
            return err("spin_speed_rad_s", "must be finite and >= 0 (0: no spin)");
        }
        if self.spin_speed_rad_s > 0.0 {
            if self.spin_speed_rad_s * self.ts_s > 0.3 {
                return err("spin_speed_rad_s", "must be below 0.3 / ts_s");
            }
            if !pos(self.spin_accel_rad_s2) || self.spin_speed_rad_s / self.spin_accel_rad_s2 > 10.0
            {
                return err(
                    "spin_accel_rad_s2",
                    "must be positive, the ramp at most 10 s",
                );
            }
            if !pos(self.spin_current_a) || self.spin_current_a > 0.8 * self.over_current_a {
                return err(
                    "spin_current_a",
                    "must be positive and at most 0.8 x over_current_a",
                );
            }
            if !time(self.spin_settle_time_s, 1.0) {
                return err("spin_settle_time_s", "must be in [1 tick, 10 s]");
            }
            if !time(self.spin_measure_time_s, 20.0) {
                return err("spin_measure_time_s", "must be in [20 ticks, 10 s]");
            }
        } else if self.measure_inertia {
            return err("measure_inertia", "needs the spin (spin_speed_rad_s > 0)");
        }
        if self.pole_pairs == 0 || self.pole_pairs > 1000 {
            return err("pole_pairs", "must be in [1, 1000]");
        }
        Ok(())
    }
}

/// A refused [`IdentifyConfig`]: the field and what is wrong with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IdentifyConfigError {
    /// The field of [`IdentifyConfig`].
    pub field: &'static str,
    /// The problem.
    pub problem: &'static str,
}

impl fmt::Display for IdentifyConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "identification setting `{}` {}",
            self.field, self.problem
        )
    }
}

impl core::error::Error for IdentifyConfigError {}

/// The steps of the sequence, in order (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum IdentifyStep {
    /// Current-sensor offsets, PWM off.
    Offsets,
    /// Wiring check and rough inductance.
    Probe,
    /// Rotor alignment.
    Align,
    /// Stator resistance and inverter voltage error.
    Resistance,
    /// d-axis inductance.
    InductanceD,
    /// q-axis inductance.
    InductanceQ,
    /// I/f spin for the flux linkage.
    Spin,
    /// Speed up and down for the inertia.
    Inertia,
    /// Finished: PWM off, [`Identifier::result`] set.
    Done,
}

impl IdentifyStep {
    /// The measuring steps, in order.
    pub const ALL: [IdentifyStep; 8] = [
        IdentifyStep::Offsets,
        IdentifyStep::Probe,
        IdentifyStep::Align,
        IdentifyStep::Resistance,
        IdentifyStep::InductanceD,
        IdentifyStep::InductanceQ,
        IdentifyStep::Spin,
        IdentifyStep::Inertia,
    ];

    /// Index in [`ALL`](Self::ALL) (8 for `Done`).
    pub fn index(self) -> usize {
        match self {
            IdentifyStep::Offsets => 0,
            IdentifyStep::Probe => 1,
            IdentifyStep::Align => 2,
            IdentifyStep::Resistance => 3,
            IdentifyStep::InductanceD => 4,
            IdentifyStep::InductanceQ => 5,
            IdentifyStep::Spin => 6,
            IdentifyStep::Inertia => 7,
            IdentifyStep::Done => 8,
        }
    }

    /// A short name (`"offsets"`, `"probe"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            IdentifyStep::Offsets => "offsets",
            IdentifyStep::Probe => "probe",
            IdentifyStep::Align => "align",
            IdentifyStep::Resistance => "resistance",
            IdentifyStep::InductanceD => "inductance_d",
            IdentifyStep::InductanceQ => "inductance_q",
            IdentifyStep::Spin => "spin",
            IdentifyStep::Inertia => "inertia",
            IdentifyStep::Done => "done",
        }
    }
}

/// A measured quantity (for [`IdentifyError::Implausible`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quantity {
    /// Current-sensor offset, A.
    CurrentOffset,
    /// Stator resistance, ohm.
    Resistance,
    /// d-axis inductance, H.
    InductanceD,
    /// q-axis inductance, H.
    InductanceQ,
    /// Flux linkage, Wb.
    FluxLinkage,
    /// Inertia, kg m^2.
    Inertia,
}

/// Why the identification stopped (the PWM is off).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IdentifyError {
    /// The settings were refused.
    Config(IdentifyConfigError),
    /// A current or the bus voltage was NaN or infinite.
    NonFiniteInput,
    /// Phase current above `over_current_a` (value in A).
    OverCurrent {
        /// Current-vector magnitude, A.
        current_a: f32,
    },
    /// Bus below `u_dc_min_v`.
    BusUnderVoltage {
        /// Measured bus, V.
        u_dc_v: f32,
    },
    /// Bus above `u_dc_max_v`.
    BusOverVoltage {
        /// Measured bus, V.
        u_dc_v: f32,
    },
    /// The current loop ran at the voltage limit without reaching its current: the bus is
    /// too low for the requested current (or the spin speed too high for the bus).
    BusTooLow {
        /// The voltage limit, V.
        limit_v: f32,
        /// The current reached, A.
        current_a: f32,
        /// The current asked for, A.
        target_a: f32,
    },
    /// No current flows along any phase axis at the full probe voltage.
    NoMotor,
    /// No current flows along one phase axis: that phase (0 a, 1 b, 2 c) is open.
    OpenPhase {
        /// The open phase: 0 a, 1 b, 2 c.
        phase: u8,
    },
    /// A result outside physical bounds.
    Implausible {
        /// Which.
        quantity: Quantity,
        /// Its value (SI).
        value: f32,
    },
    /// No back-EMF during the spin: the rotor does not turn.
    RotorLocked {
        /// The EMF found, V.
        emf_v: f32,
    },
    /// The back-EMF does not turn with the I/f frame (pulled out of step, or blocked).
    LostSync {
        /// The load angle found, rad.
        load_angle_rad: f32,
    },
}

impl fmt::Display for IdentifyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IdentifyError::Config(e) => write!(f, "{e}"),
            IdentifyError::NonFiniteInput => f.write_str("non-finite current or bus voltage"),
            IdentifyError::OverCurrent { current_a } => {
                write!(f, "over-current: {current_a} A")
            }
            IdentifyError::BusUnderVoltage { u_dc_v } => {
                write!(f, "bus under-voltage: {u_dc_v} V")
            }
            IdentifyError::BusOverVoltage { u_dc_v } => write!(f, "bus over-voltage: {u_dc_v} V"),
            IdentifyError::BusTooLow {
                limit_v,
                current_a,
                target_a,
            } => write!(
                f,
                "bus too low for the test current: {current_a} A of {target_a} A at the \
                 voltage limit {limit_v} V"
            ),
            IdentifyError::NoMotor => {
                f.write_str("no current on any phase at the full probe voltage: no motor?")
            }
            IdentifyError::OpenPhase { phase } => write!(
                f,
                "no current along phase {}: open phase",
                match phase {
                    0 => 'a',
                    1 => 'b',
                    _ => 'c',
                }
            ),
            IdentifyError::Implausible { quantity, value } => {
                write!(f, "implausible {quantity:?}: {value}")
            }
            IdentifyError::RotorLocked { emf_v } => write!(
                f,
                "no back-EMF during the spin ({emf_v} V): the rotor does not turn"
            ),
            IdentifyError::LostSync { load_angle_rad } => write!(
                f,
                "the rotor does not follow the spin (load angle {load_angle_rad} rad)"
            ),
        }
    }
}

impl core::error::Error for IdentifyError {}

/// A failed identification: the error, the step and the tick (since construction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifyFailure {
    /// What went wrong.
    pub error: IdentifyError,
    /// In which step.
    pub step: IdentifyStep,
    /// At which tick.
    pub tick: u32,
}

impl fmt::Display for IdentifyFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} (step {}, tick {})",
            self.error,
            self.step.name(),
            self.tick
        )
    }
}

impl core::error::Error for IdentifyFailure {}

/// Relative difference of `Ld` and `Lq` below which [`Identified::motor_params`] reads the
/// motor as a surface PMSM (measured spread on surface motors is a few per cent).
pub const SURFACE_TOLERANCE: f32 = 0.1;

/// What the identification found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Identified {
    /// Stator resistance per phase, ohm.
    pub rs_ohm: f32,
    /// d-axis inductance, H.
    pub ld_h: f32,
    /// q-axis inductance, H.
    pub lq_h: f32,
    /// Flux linkage, Wb (`None` without the spin).
    pub psi_f_wb: Option<f32>,
    /// Voltage the inverter loses at the test current along the phase-a axis, V (dead
    /// time and switch drops: `U(I) - Rs I` of the resistance step).
    pub inverter_voltage_error_v: f32,
    /// Inertia, kg m^2 (`None` unless measured).
    pub j_kg_m2: Option<f32>,
    /// Current-sensor offsets removed, A (phases a and b, or alpha and beta).
    pub current_offsets_a: [f32; 2],
    /// Ticks spent in each step of [`IdentifyStep::ALL`].
    pub step_ticks: [u32; 8],
    /// Ticks in all.
    pub ticks: u32,
}

impl Identified {
    /// The surface-motor inductance the observer uses, `(Ld + Lq) / 2`, H.
    pub fn ls_mean_h(&self) -> f32 {
        0.5 * (self.ld_h + self.lq_h)
    }

    /// `Ld` and `Lq` differ by more than [`SURFACE_TOLERANCE`] of their mean: an interior
    /// (or inversely salient) motor.
    pub fn is_salient(&self) -> bool {
        (self.lq_h - self.ld_h).abs() > SURFACE_TOLERANCE * self.ls_mean_h()
    }

    /// The observer's motor parameters, when `psi_f` was measured: `Ld`, `Lq` as measured
    /// for a salient motor ([`is_salient`](Self::is_salient)), else both `(Ld + Lq) / 2`
    /// (a surface motor; the difference is measurement noise).
    pub fn motor_params(&self, pole_pairs: u32) -> Option<MotorParams<f32>> {
        let (ld_h, lq_h) = if self.is_salient() {
            (self.ld_h, self.lq_h)
        } else {
            (self.ls_mean_h(), self.ls_mean_h())
        };
        self.psi_f_wb.map(|psi| MotorParams {
            rs_ohm: self.rs_ohm,
            ld_h,
            lq_h,
            psi_f_wb: psi,
            pole_pairs,
        })
    }
}

/// What one tick gives the bridge, and what the sequence is doing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifyOutput {
    /// Duties of phases a, b, c, in `[0, 1]` ([`SAFE_DUTIES`] with the PWM off).
    pub duties: [f32; 3],
    /// Whether the bridge switches.
    pub pwm_enabled: bool,
    /// The step this tick belonged to ([`IdentifyStep::Done`] once finished, also after a
    /// failure).
    pub step: IdentifyStep,
    /// Measured currents, offsets removed, A (alpha, beta).
    pub i_ab: AlphaBeta,
    /// Voltage the duties realize (ideal switches), V.
    pub u_ab: AlphaBeta,
    /// Angle of the current vector's frame, rad (the align / I/f frame).
    pub frame_angle_rad: f32,
    /// Speed of that frame, rad/s electrical.
    pub frame_speed_rad_s: f32,
}

/// Running sums over a window.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sums {
    n: u32,
    s: [f32; 4],
}

impl Sums {
    fn add(&mut self, v: [f32; 4]) {
        self.n += 1;
        for (a, b) in self.s.iter_mut().zip(v) {
            *a += b;
        }
    }

    fn mean(&self) -> [f32; 4] {
        let k = if self.n > 0 { 1.0 / self.n as f32 } else { 0.0 };
        self.s.map(|x| x * k)
    }
}

/// A jerk-limited speed move: acceleration rises over `nj` ticks, holds `nc`, falls over
/// `nj`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Move {
    nj: u32,
    nc: u32,
    accel: f32,
}

impl Move {
    fn new(delta_w: f32, accel: f32, ts: f32) -> Self {
        let a = if delta_w < 0.0 { -accel } else { accel };
        // Total speed change = a (nc + nj) ts; nj about 20 % of the move.
        let total = ticks(delta_w / a, ts).max(2);
        let nj = (total / 5).max(1);
        let nc = total - nj;
        // Re-scale so the change is exact.
        let accel = delta_w / ((nc + nj) as f32 * ts);
        Self { nj, nc, accel }
    }

    fn len(&self) -> u32 {
        2 * self.nj + self.nc
    }

    /// Acceleration during tick `n` of the move.
    fn accel_at(&self, n: u32) -> f32 {
        let nj = self.nj as f32;
        if n < self.nj {
            self.accel * (n as f32 + 0.5) / nj
        } else if n < self.nj + self.nc {
            self.accel
        } else if n < self.len() {
            self.accel * ((self.len() - n) as f32 - 0.5) / nj
        } else {
            0.0
        }
    }
}

/// Linear least squares with `N` regressors, updated one row at a time by Givens rotations
/// (the square-root information form: the triangular `R` and `z = Q^T y` of the QR
/// factorization of the rows so far; Golub & Van Loan, "Matrix Computations", sec. 5.1.8 and
/// 6.5.3). The normal equations are never formed, so `f32` holds the accuracy of a fit over
/// thousands of rows whose columns are close to dependent.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Lsq<const N: usize> {
    /// `N x N` upper triangular factor.
    r: [[f32; N]; N],
    /// `Q^T y`, `N`.
    z: [f32; N],
}

impl<const N: usize> Lsq<N> {
    fn new() -> Self {
        Self {
            r: [[0.0; N]; N],
            z: [0.0; N],
        }
    }

    /// Adds the row `x . beta = y`.
    fn add(&mut self, mut x: [f32; N], mut y: f32) {
        for (i, (row, zi)) in self.r.iter_mut().zip(self.z.iter_mut()).enumerate() {
            let xi = x.get(i).copied().unwrap_or(0.0);
            if xi == 0.0 {
                continue;
            }
            let rii = row.get(i).copied().unwrap_or(0.0);
            let h = sqrt(rii * rii + xi * xi);
            let (c, s) = (rii / h, xi / h);
            for (rj, xj) in row.iter_mut().zip(x.iter_mut()).skip(i) {
                let (a, b) = (*rj, *xj);
                *rj = c * a + s * b;
                *xj = c * b - s * a;
            }
            let (a, b) = (*zi, y);
            *zi = c * a + s * b;
            y = c * b - s * a;
        }
    }

    /// `beta` minimizing `|X beta - y|` (back substitution), `None` when `R` is singular: a
    /// diagonal element below `1e-5` of the largest (a column that is, to `f32` rounding, a
    /// combination of the ones before it).
    fn solve(&self) -> Option<[f32; N]> {
        let tol = 1e-5
            * self
                .r
                .iter()
                .enumerate()
                .map(|(i, row)| row.get(i).map_or(0.0, |d| d.abs()))
                .fold(0.0f32, f32::max);
        let mut beta = [0.0f32; N];
        for i in (0..N).rev() {
            let row = self.r.get(i)?;
            let mut acc = *self.z.get(i)?;
            for (rj, bj) in row.iter().zip(beta.iter()).skip(i + 1) {
                acc -= rj * bj;
            }
            let d = *row.get(i)?;
            let b = acc / d;
            if !(d.abs() > tol && b.is_finite()) {
                return None;
            }
            *beta.get_mut(i)? = b;
        }
        Some(beta)
    }
}

/// The inertia from the rotor's trajectory during the speed move (module docs, step
/// [`IdentifyStep::Inertia`]).
///
/// The rotor's mechanical angle is the frame's minus the load angle, `theta = (phi - g) / p`,
/// and obeys `J theta'' = T - B theta' - T_c` with the torque `T` from the load angle and
/// the current. Integrated twice from the start of the move:
///
/// `y(t) = c0 + c1 s + c2 s^2 + S(t) / J - (B / J) Y(t)`,
///
/// with `y = theta - w0 t / p` (the angle beyond the initial frame speed `w0`), `s = t / T`
/// (`T` the window), `S` the double integral of `T`, `Y` the integral of `y`, and `c0`, `c1`,
/// `c2` the unknown initial angle, speed and constant friction (`T_c` and `B w0`). Fitted by
/// least squares over every tick of the move, the lightly damped oscillation of the rotor
/// about the I/f frame is part of the model, not an error to be averaged away (as it would be
/// by averaging the torque over segments shorter than its period). The load-angle noise
/// enters only `y` (the fitted variable) and, integrated, `S` and `Y`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct InertiaFit {
    /// Frame speed at the start, rad/s electrical.
    w0: f32,
    /// Ticks in the window.
    len: u32,
    /// Ticks so far.
    k: u32,
    ts: f32,
    /// `1 / p`.
    inv_p: f32,
    /// Scale of `S`: `1 / (T_max T^2)`.
    s_scale: f32,
    /// Frame angle beyond `w0 t`, rad electrical.
    dphi: f32,
    /// Integral of the torque, N m s.
    torque_int: f32,
    /// Double integral of the torque, N m s^2.
    torque_int2: f32,
    /// Sum of `y` (rad).
    y_sum: f32,
    lsq: Lsq<5>,
}

impl InertiaFit {
    /// A fit over `len` ticks from the frame speed `w0`; `torque_max` scales the torque
    /// integral (the fit does not depend on it, its conditioning does).
    fn new(w0: f32, len: u32, pole_pairs: u32, ts: f32, torque_max: f32) -> Self {
        let t = len.max(1) as f32 * ts;
        let s_scale = 1.0 / (torque_max * t * t);
        Self {
            w0,
            len: len.max(1),
            k: 0,
            ts,
            inv_p: 1.0 / pole_pairs.max(1) as f32,
            s_scale: if s_scale.is_finite() { s_scale } else { 1.0 },
            dphi: 0.0,
            torque_int: 0.0,
            torque_int2: 0.0,
            y_sum: 0.0,
            lsq: Lsq::new(),
        }
    }

    /// One tick: load angle `g` (rad), torque (N m), and the frame speed of this tick minus
    /// `w0` (rad/s electrical; the frame turns by it after the tick).
    fn push(&mut self, g: f32, torque: f32, dw: f32) {
        let y = (self.dphi - g) * self.inv_p;
        let s = self.k as f32 / self.len as f32;
        let x = [
            1.0,
            s,
            s * s,
            self.torque_int2 * self.s_scale,
            self.y_sum / self.len as f32,
        ];
        self.lsq.add(x, y);
        self.k += 1;
        self.dphi += dw * self.ts;
        self.torque_int2 += self.torque_int * self.ts;
        self.torque_int += torque * self.ts;
        self.y_sum += y;
    }

    /// `J`, kg m^2 (`None` when the fit is singular).
    fn inertia(&self) -> Option<f32> {
        let beta = self.lsq.solve()?;
        let b = *beta.get(3)?;
        Some(1.0 / (b * self.s_scale))
    }
}

/// `round(t / ts)` ticks, at least 1, saturating.
fn ticks(t: f32, ts: f32) -> u32 {
    let x = t / ts + 0.5;
    if x.is_finite() && x >= 1.0 {
        if x < 4.0e9 { x as u32 } else { u32::MAX / 2 }
    } else {
        1
    }
}

/// Natural logarithm of a finite positive `x` (pure `f32`, relative error about 1e-7;
/// exact in relative terms near 1, where the inductance formula needs it).
pub fn ln(x: f32) -> f32 {
    if !(x.is_finite() && x > 1e-30) {
        return f32::NAN;
    }
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let y = (m - 1.0) / (m + 1.0);
    let y2 = y * y;
    let s = y * (2.0 + y2 * (2.0 / 3.0 + y2 * (0.4 + y2 * (2.0 / 7.0 + y2 * (2.0 / 9.0)))));
    s + e as f32 * LN_2
}

/// The identification sequence (module docs).
#[derive(Clone, Debug)]
pub struct Identifier {
    cfg: IdentifyConfig,
    /// Periods of computation delay (0 or 1).
    d: u32,
    hf_n: u32,
    step: IdentifyStep,
    tick: u32,
    /// Ticks in the current phase of the step.
    n: u32,
    /// Phase within the step.
    phase: u32,
    step_start: u32,
    step_ticks: [u32; 8],
    result: Option<Result<Identified, IdentifyFailure>>,
    offsets: [f32; 2],
    sums: Sums,
    sums2: Sums,
    quarter: [Sums; 4],
    /// Sums of the load angle over the first and the last [`Identifier::drift_ticks`] of
    /// the flux window, rad.
    g_ends: [f32; 2],
    // Probe.
    probe_u: f32,
    probe_m: u32,
    probe_axis: u32,
    probe_rep: u32,
    probe_base: f32,
    probe_delta: [f32; 3],
    l_min: f32,
    l_max: f32,
    // Current loops in the frame.
    pi_d: Pi,
    pi_q: Pi,
    frame: f32,
    frame_sc: (f32, f32),
    omega: f32,
    sat_ticks: u32,
    // Results.
    rs: f32,
    v_err: f32,
    ld: f32,
    lq: f32,
    lq_hf: f32,
    psi: Option<f32>,
    j: Option<f32>,
    u_hold: f32,
    hf_u: f32,
    fit: InertiaFit,
    mv: Move,
    u_lim: f32,
}

/// Steps of the probe: the pulse voltage doubles from this fraction of the limit.
const PROBE_START: f32 = 1.0 / 512.0;
/// The probe stops when an axis reaches this fraction of the test current.
const PROBE_TARGET: f32 = 0.4;
/// Longest probe pulse, ticks.
const PROBE_MAX_M: u32 = 64;
/// Repetitions of the deciding probe level.
const PROBE_REPS: u32 = 4;

impl Identifier {
    /// A sequence with the settings `cfg` (checked), not started: the first tick starts it.
    pub fn new(cfg: &IdentifyConfig) -> Result<Self, IdentifyError> {
        cfg.validate().map_err(IdentifyError::Config)?;
        let d = match cfg.delay {
            ComputationDelay::OnePeriod => 1,
            ComputationDelay::None => 0,
        };
        Ok(Self {
            cfg: *cfg,
            d,
            hf_n: cfg.hf_period_ticks(),
            step: IdentifyStep::Offsets,
            tick: 0,
            n: 0,
            phase: 0,
            step_start: 0,
            step_ticks: [0; 8],
            result: None,
            offsets: [0.0; 2],
            sums: Sums::default(),
            sums2: Sums::default(),
            quarter: [Sums::default(); 4],
            g_ends: [0.0; 2],
            probe_u: 0.0,
            probe_m: 1,
            probe_axis: 0,
            probe_rep: 0,
            probe_base: 0.0,
            probe_delta: [0.0; 3],
            l_min: 0.0,
            l_max: 0.0,
            pi_d: Pi::new(PiGains { kp: 0.0, ki: 0.0 }, cfg.ts_s),
            pi_q: Pi::new(PiGains { kp: 0.0, ki: 0.0 }, cfg.ts_s),
            frame: 0.0,
            frame_sc: (0.0, 1.0),
            omega: 0.0,
            sat_ticks: 0,
            rs: 0.0,
            v_err: 0.0,
            ld: 0.0,
            lq: 0.0,
            lq_hf: 0.0,
            psi: None,
            j: None,
            u_hold: 0.0,
            hf_u: 0.0,
            fit: InertiaFit::new(0.0, 1, 1, cfg.ts_s, 1.0),
            mv: Move::default(),
            u_lim: 0.0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &IdentifyConfig {
        &self.cfg
    }

    /// The step in progress ([`IdentifyStep::Done`] when finished).
    pub fn step(&self) -> IdentifyStep {
        self.step
    }

    /// The outcome, once finished.
    pub fn result(&self) -> Option<&Result<Identified, IdentifyFailure>> {
        self.result.as_ref()
    }

    /// Whether the sequence has finished (success or failure).
    pub fn is_done(&self) -> bool {
        self.result.is_some()
    }

    /// Ticks since construction.
    pub fn ticks(&self) -> u32 {
        self.tick
    }

    /// An upper bound of the sequence's length with these settings, s (each step has a
    /// fixed length; the probe's is its worst case).
    pub fn max_duration_s(&self) -> f32 {
        let c = &self.cfg;
        let hf = self.hf_n as f32 * c.ts_s;
        let probe = 3.0 * 18.0 * 6.0 * c.ts_s + 3.0 * 7.0 * 3.0 * PROBE_MAX_M as f32 * c.ts_s;
        let ind = 3.0 * (c.inductance_time_s + 0.05 + 8.0 * hf);
        let mut t = 0.02 + probe + c.align_time_s + 2.0 * c.resistance_time_s + ind;
        if c.spin_speed_rad_s > 0.0 {
            t += 1.3 * c.spin_speed_rad_s / c.spin_accel_rad_s2
                + c.spin_settle_time_s
                + c.spin_measure_time_s;
            if c.measure_inertia {
                t += 3.0 * 0.4 * c.spin_speed_rad_s / c.spin_accel_rad_s2;
            }
        }
        t
    }

    fn enter(&mut self, step: IdentifyStep) {
        if let Some(t) = self.step_ticks.get_mut(self.step.index()) {
            *t = self.tick.wrapping_sub(self.step_start);
        }
        self.step = step;
        self.step_start = self.tick;
        self.n = 0;
        self.phase = 0;
        self.sums = Sums::default();
        self.sums2 = Sums::default();
        self.sat_ticks = 0;
    }

    fn next_phase(&mut self) {
        self.phase += 1;
        self.n = 0;
    }

    fn fail(&mut self, error: IdentifyError) {
        let step = self.step;
        self.enter(IdentifyStep::Done);
        self.result = Some(Err(IdentifyFailure {
            error,
            step,
            tick: self.tick,
        }));
    }

    fn finish(&mut self) {
        self.enter(IdentifyStep::Done);
        self.result = Some(Ok(Identified {
            rs_ohm: self.rs,
            ld_h: self.ld,
            lq_h: self.lq,
            psi_f_wb: self.psi,
            inverter_voltage_error_v: self.v_err,
            j_kg_m2: self.j,
            current_offsets_a: self.offsets,
            step_ticks: self.step_ticks,
            ticks: self.tick,
        }));
    }

    fn off_output(&self, i_ab: AlphaBeta) -> IdentifyOutput {
        IdentifyOutput {
            duties: SAFE_DUTIES,
            pwm_enabled: false,
            step: self.step,
            i_ab,
            u_ab: AlphaBeta::default(),
            frame_angle_rad: self.frame,
            frame_speed_rad_s: self.omega,
        }
    }

    /// One PWM period (module docs).
    pub fn tick(&mut self, input: &TickInput) -> IdentifyOutput {
        self.tick = self.tick.wrapping_add(1);
        self.n = self.n.saturating_add(1);
        if self.result.is_some() {
            return self.off_output(AlphaBeta::default());
        }
        let u_dc = input.u_dc_v;
        let (raw, i_ab) = match input.currents {
            PhaseCurrents::Abc(a) => {
                let (ia, ib) = (a.a - self.offsets[0], a.b - self.offsets[1]);
                (
                    [a.a, a.b],
                    AlphaBeta {
                        alpha: ia,
                        beta: (ia + 2.0 * ib) * INV_SQRT3,
                    },
                )
            }
            PhaseCurrents::AlphaBeta(ab) => (
                [ab.alpha, ab.beta],
                AlphaBeta {
                    alpha: ab.alpha - self.offsets[0],
                    beta: ab.beta - self.offsets[1],
                },
            ),
        };
        if !(u_dc.is_finite() && i_ab.alpha.is_finite() && i_ab.beta.is_finite()) {
            self.fail(IdentifyError::NonFiniteInput);
            return self.off_output(AlphaBeta::default());
        }
        let i_mag = sqrt(i_ab.norm_squared());
        if i_mag > self.cfg.over_current_a {
            self.fail(IdentifyError::OverCurrent { current_a: i_mag });
            return self.off_output(i_ab);
        }
        if u_dc > self.cfg.u_dc_max_v {
            self.fail(IdentifyError::BusOverVoltage { u_dc_v: u_dc });
            return self.off_output(i_ab);
        }
        if u_dc < self.cfg.u_dc_min_v {
            self.fail(IdentifyError::BusUnderVoltage { u_dc_v: u_dc });
            return self.off_output(i_ab);
        }
        self.u_lim = self.cfg.max_modulation * u_dc * INV_SQRT3;
        let cmd = match self.step {
            IdentifyStep::Offsets => self.offsets_step(raw),
            IdentifyStep::Probe => self.probe_step(i_ab),
            IdentifyStep::Align => self.align_step(i_ab),
            IdentifyStep::Resistance => self.resistance_step(i_ab),
            IdentifyStep::InductanceD | IdentifyStep::InductanceQ => self.inductance_step(i_ab),
            IdentifyStep::Spin | IdentifyStep::Inertia => self.spin_step(i_ab),
            IdentifyStep::Done => Ok(None),
        };
        let u = match cmd {
            Ok(Some(u)) if self.result.is_none() => u,
            Ok(_) => return self.off_output(i_ab),
            Err(e) => {
                self.fail(e);
                return self.off_output(i_ab);
            }
        };
        // Voltage limit (circle), then the modulator (hexagon; the circle is inside it).
        let mag2 = u.norm_squared();
        let u = if mag2 > self.u_lim * self.u_lim {
            u * (self.u_lim / sqrt(mag2))
        } else {
            u
        };
        let m = svpwm(u, u_dc);
        IdentifyOutput {
            duties: m.duties,
            pwm_enabled: true,
            step: self.step,
            i_ab,
            u_ab: m.applied,
            frame_angle_rad: self.frame,
            frame_speed_rad_s: self.omega,
        }
    }

    // ---- steps -------------------------------------------------------------------------

    fn offsets_step(&mut self, raw: [f32; 2]) -> Result<Option<AlphaBeta>, IdentifyError> {
        // The first ticks let a bridge that was just turned off settle.
        if self.n > 3 {
            self.sums.add([raw[0], raw[1], 0.0, 0.0]);
        }
        if self.n >= ticks(0.02, self.cfg.ts_s).max(16) {
            let m = self.sums.mean();
            let lim = 0.2 * self.cfg.test_current_a;
            for v in [m[0], m[1]] {
                if v.is_nan() || v.abs() > lim {
                    return Err(IdentifyError::Implausible {
                        quantity: Quantity::CurrentOffset,
                        value: v,
                    });
                }
            }
            self.offsets = [m[0], m[1]];
            self.enter(IdentifyStep::Probe);
            self.probe_u = PROBE_START * self.u_lim;
            self.probe_m = 1;
        }
        Ok(None)
    }

    /// Unit vector of phase axis `x` (0 a, 1 b, 2 c).
    fn axis(x: u32) -> (f32, f32) {
        match x {
            0 => (1.0, 0.0),
            1 => (-0.5, 0.866_025_4),
            _ => (-0.5, -0.866_025_4),
        }
    }

    fn probe_step(&mut self, i_ab: AlphaBeta) -> Result<Option<AlphaBeta>, IdentifyError> {
        // One pulse on one axis: +U for m ticks, -U for m ticks, zero for m + 3 ticks.
        let m = self.probe_m;
        let (ex, ey) = Self::axis(self.probe_axis);
        let i_x = i_ab.alpha * ex + i_ab.beta * ey;
        let k = self.n - 1; // 0-based tick within the pulse
        if k == 0 {
            self.probe_base = i_x;
        }
        if k == m + self.d {
            let delta = (i_x - self.probe_base).abs();
            if let Some(s) = self.probe_delta.get_mut(self.probe_axis as usize) {
                *s += delta;
            }
        }
        let u = if k < m {
            self.probe_u
        } else if k < 2 * m {
            -self.probe_u
        } else {
            0.0
        };
        if k + 1 >= 3 * m + 3 + self.d {
            // Pulse done: next axis, next repetition or next level.
            self.n = 0;
            self.probe_axis += 1;
            if self.probe_axis == 3 {
                self.probe_axis = 0;
                self.probe_level_done()?;
                if self.step != IdentifyStep::Probe {
                    return Ok(Some(AlphaBeta::default()));
                }
            }
        }
        Ok(Some(AlphaBeta {
            alpha: u * ex,
            beta: u * ey,
        }))
    }

    fn probe_level_done(&mut self) -> Result<(), IdentifyError> {
        let target = PROBE_TARGET * self.cfg.test_current_a;
        let reps = (self.probe_rep + 1) as f32;
        let d = self.probe_delta.map(|x| x / reps);
        let dmax = d[0].max(d[1]).max(d[2]);
        let last = self.probe_u >= 0.5 * self.u_lim && self.probe_m >= PROBE_MAX_M;
        if self.probe_rep == 0 && dmax < target && !last {
            // Next level: double the voltage up to half the limit, then the length.
            if self.probe_u < 0.5 * self.u_lim {
                self.probe_u = (2.0 * self.probe_u).min(0.5 * self.u_lim);
            } else {
                self.probe_m *= 2;
            }
            self.probe_delta = [0.0; 3];
            return Ok(());
        }
        if self.probe_rep + 1 < PROBE_REPS {
            self.probe_rep += 1;
            return Ok(());
        }
        // Decide.
        if dmax < 0.1 * target {
            return Err(IdentifyError::NoMotor);
        }
        let (mut imin, mut dmin) = (0u8, d[0]);
        for (i, &x) in d.iter().enumerate() {
            if x < dmin {
                dmin = x;
                imin = i as u8;
            }
        }
        if dmin < 0.1 * dmax {
            return Err(IdentifyError::OpenPhase { phase: imin });
        }
        let ut = self.probe_u * self.probe_m as f32 * self.cfg.ts_s;
        self.l_min = ut / dmax;
        self.l_max = ut / dmin;
        // Current loop from the smallest inductance (the safe side); R unknown yet.
        let kp = self.l_min * self.cfg.current_bw_rad_s;
        let gains = PiGains {
            kp,
            ki: kp * self.cfg.current_bw_rad_s * 0.125,
        };
        self.pi_d = Pi::new(gains, self.cfg.ts_s);
        self.pi_q = Pi::new(gains, self.cfg.ts_s);
        self.set_frame(FRAC_PI_2);
        self.enter(IdentifyStep::Align);
        Ok(())
    }

    fn set_frame(&mut self, angle: f32) {
        self.frame = wrap(angle);
        self.frame_sc = sin_cos(self.frame);
    }

    /// `(d, q)` of `v` in the frame.
    fn to_frame(&self, v: AlphaBeta) -> (f32, f32) {
        let (s, c) = self.frame_sc;
        (c * v.alpha + s * v.beta, -s * v.alpha + c * v.beta)
    }

    fn frame_to_ab(&self, d: f32, q: f32) -> AlphaBeta {
        let (s, c) = self.frame_sc;
        AlphaBeta {
            alpha: c * d - s * q,
            beta: s * d + c * q,
        }
    }

    /// d-axis current loop in the fixed frame, q voltage zero; checks the voltage limit.
    fn hold_d(&mut self, i_ab: AlphaBeta, i_ref: f32) -> Result<AlphaBeta, IdentifyError> {
        let (i_d, _) = self.to_frame(i_ab);
        let lim = self.u_lim;
        let u_d = self.pi_d.step(i_ref - i_d, 0.0, -lim, lim);
        self.check_saturation(u_d.abs() >= 0.999 * lim, i_d, i_ref)?;
        Ok(self.frame_to_ab(u_d, 0.0))
    }

    fn check_saturation(
        &mut self,
        at_limit: bool,
        i: f32,
        i_ref: f32,
    ) -> Result<(), IdentifyError> {
        if at_limit && i.abs() < 0.9 * i_ref.abs() {
            self.sat_ticks += 1;
            if self.sat_ticks > ticks(0.02, self.cfg.ts_s) {
                return Err(IdentifyError::BusTooLow {
                    limit_v: self.u_lim,
                    current_a: i.abs(),
                    target_a: i_ref.abs(),
                });
            }
        } else {
            self.sat_ticks = 0;
        }
        Ok(())
    }

    fn align_step(&mut self, i_ab: AlphaBeta) -> Result<Option<AlphaBeta>, IdentifyError> {
        let half = ticks(0.5 * self.cfg.align_time_s, self.cfg.ts_s);
        let i_t = self.cfg.test_current_a;
        let i_ref = if self.phase == 0 {
            i_t * (self.n as f32 / (0.4 * half as f32)).min(1.0)
        } else {
            i_t
        };
        let u = self.hold_d(i_ab, i_ref)?;
        if self.n >= half {
            if self.phase == 0 {
                self.next_phase();
                // Same voltage vector expressed in the new frame: the d loop starts from it.
                self.set_frame(0.0);
            } else {
                self.enter(IdentifyStep::Resistance);
            }
        }
        Ok(Some(u))
    }

    fn resistance_step(&mut self, i_ab: AlphaBeta) -> Result<Option<AlphaBeta>, IdentifyError> {
        let len = ticks(self.cfg.resistance_time_s, self.cfg.ts_s);
        let settle = (len * 3) / 10;
        let i_t = self.cfg.test_current_a;
        let i_ref = if self.phase == 0 { 0.5 * i_t } else { i_t };
        let u = self.hold_d(i_ab, i_ref)?;
        if self.n > settle {
            let (i_d, _) = self.to_frame(i_ab);
            let (u_d, _) = self.to_frame(u);
            let s = if self.phase == 0 {
                &mut self.sums
            } else {
                &mut self.sums2
            };
            s.add([u_d, i_d, 0.0, 0.0]);
        }
        if self.n >= len {
            if self.phase == 0 {
                self.next_phase();
            } else {
                let [u1, i1, ..] = self.sums.mean();
                let [u2, i2, ..] = self.sums2.mean();
                let rs = (u2 - u1) / (i2 - i1);
                if !(rs.is_finite() && rs > 1e-4 && rs < 1e4) {
                    return Err(IdentifyError::Implausible {
                        quantity: Quantity::Resistance,
                        value: rs,
                    });
                }
                self.rs = rs;
                self.v_err = u2 - rs * i2;
                self.u_hold = u2;
                self.start_injection(IdentifyStep::InductanceD);
            }
        }
        Ok(Some(u))
    }

    fn start_injection(&mut self, step: IdentifyStep) {
        self.enter(step);
        // First voltage: 30 % of the test current at the rough inductance.
        let l = if step == IdentifyStep::InductanceD {
            self.l_max
        } else {
            self.l_max.max(self.ld)
        };
        let w = TAU / self.hf_n as f32;
        let z = self.rs.max(0.0) + l * w / self.cfg.ts_s;
        self.hf_u = self
            .hf_amplitude_limit()
            .min(0.3 * self.cfg.test_current_a * z);
    }

    fn hf_amplitude_limit(&self) -> f32 {
        (0.9 * self.u_lim - self.u_hold.abs()).max(0.0)
    }

    fn inductance_step(&mut self, i_ab: AlphaBeta) -> Result<Option<AlphaBeta>, IdentifyError> {
        // Phases: 0 pre (settle 2 periods, demodulate 4) at frequency 1, to set the amplitude;
        // 1 settle, 2 measure at frequency 1; for q: 3 settle, 4 measure at frequency 2.
        let q = self.step == IdentifyStep::InductanceQ;
        let n_hf = if self.phase >= 3 {
            2 * self.hf_n
        } else {
            self.hf_n
        };
        let k = self.n - 1;
        let (s, c) = sin_cos(TAU * (k % n_hf) as f32 / n_hf as f32);
        let u_x = self.hf_u * c;
        let u = if q {
            self.frame_to_ab(self.u_hold, u_x)
        } else {
            self.frame_to_ab(self.u_hold + u_x, 0.0)
        };
        let (i_d, i_q) = self.to_frame(i_ab);
        let i_x = if q { i_q } else { i_d };
        let tau_ticks = (self.l_max / self.rs / self.cfg.ts_s).min(4.0e5) as u32;
        let settle = {
            let t = (3 * tau_ticks).clamp(2 * n_hf, ticks(0.05, self.cfg.ts_s).max(2 * n_hf));
            t.div_ceil(n_hf) * n_hf
        };
        let measure = (ticks(self.cfg.inductance_time_s, self.cfg.ts_s) / n_hf).max(2) * n_hf;
        let (len, demod) = match self.phase {
            0 => (6 * n_hf, k >= 2 * n_hf),
            1 | 3 => (settle, false),
            _ => (measure, true),
        };
        if demod {
            self.sums.add([i_x * c, i_x * s, u_x * c, u_x * s]);
        }
        if self.n >= len {
            let h = self.sums.mean();
            let (hr, hi) = {
                // H = I / U with I = ic - j is, U = uc - j us.
                let (ir, ii) = (h[0], -h[1]);
                let (ur, ui) = (h[2], -h[3]);
                let den = ur * ur + ui * ui;
                ((ir * ur + ii * ui) / den, (ii * ur - ir * ui) / den)
            };
            self.sums = Sums::default();
            match self.phase {
                0 => {
                    let gain = sqrt(hr * hr + hi * hi);
                    let target = 0.3 * self.cfg.test_current_a;
                    if gain.is_finite() && gain > 0.0 {
                        self.hf_u = (target / gain).min(self.hf_amplitude_limit());
                    }
                    self.next_phase();
                }
                1 | 3 => self.next_phase(),
                _ => {
                    let l = self.fit_inductance(hr, hi, n_hf);
                    let quantity = if q {
                        Quantity::InductanceQ
                    } else {
                        Quantity::InductanceD
                    };
                    if !(l.is_finite() && l > 1e-8 && l < 100.0) {
                        return Err(IdentifyError::Implausible { quantity, value: l });
                    }
                    if !q {
                        self.ld = l;
                        self.start_injection(IdentifyStep::InductanceQ);
                    } else if self.phase == 2 {
                        self.lq_hf = l;
                        // Half the frequency: half the voltage for the same current.
                        self.hf_u *= 0.5;
                        self.next_phase();
                    } else {
                        let lq = (4.0 * self.lq_hf - l) / 3.0;
                        if !(lq.is_finite() && lq > 1e-8 && lq < 100.0) {
                            return Err(IdentifyError::Implausible {
                                quantity,
                                value: lq,
                            });
                        }
                        self.lq = lq;
                        self.start_spin();
                    }
                }
            }
            return Ok(Some(u));
        }
        Ok(Some(u))
    }

    /// `L` from the measured `H = I / U` at `w = 2 pi / n` rad per tick: the exact discrete
    /// model `H = b z^-d / (z - a)`, solved for real `a` and `b` from `a H + b z^-d = H z`.
    fn fit_inductance(&self, hr: f32, hi: f32, n: u32) -> f32 {
        let w = TAU / n as f32;
        let (s1, c1) = sin_cos(w);
        let (sd, cd) = sin_cos(w * self.d as f32);
        let (wr, wi) = (cd, -sd);
        let (zr, zi) = (hr * c1 - hi * s1, hr * s1 + hi * c1);
        let det = hr * wi - hi * wr;
        let a = (zr * wi - zi * wr) / det;
        let b = (hr * zi - hi * zr) / det;
        if !(a > 0.0 && a < 1.0 && b > 0.0) {
            return f32::NAN;
        }
        self.cfg.ts_s * (1.0 - a) / (b * -ln(a))
    }

    fn start_spin(&mut self) {
        if self.cfg.spin_speed_rad_s <= 0.0 {
            self.finish();
            return;
        }
        self.enter(IdentifyStep::Spin);
        let bw = self.cfg.current_bw_rad_s;
        let ki = self.rs * bw;
        self.pi_d = Pi::new(
            PiGains {
                kp: self.ld * bw,
                ki,
            },
            self.cfg.ts_s,
        );
        self.pi_q = Pi::new(
            PiGains {
                kp: self.lq * bw,
                ki,
            },
            self.cfg.ts_s,
        );
        let i_f = self.cfg.spin_current_a;
        self.pi_d.preset_output(
            self.rs * i_f + self.v_err * i_f / self.cfg.test_current_a,
            0.0,
            0.0,
        );
        self.pi_q.set_integrator(0.0);
        self.omega = 0.0;
        self.mv = Move::new(
            self.cfg.spin_speed_rad_s,
            self.cfg.spin_accel_rad_s2,
            self.cfg.ts_s,
        );
    }

    /// The active-flux EMF `E = u - (Rs + j w Lq) i - dead-time voltage` in the frame.
    fn emf(&self, u: (f32, f32), i: (f32, f32)) -> (f32, f32) {
        let imag = sqrt(i.0 * i.0 + i.1 * i.1).max(1e-6);
        // The bridge loses the dead-time voltage along the current (the command includes
        // it): its fundamental is 3/pi of the DC value measured along a phase axis.
        let k = 3.0 / PI * self.v_err / imag;
        (
            u.0 - self.rs * i.0 + self.omega * self.lq * i.1 - k * i.0,
            u.1 - self.rs * i.1 - self.omega * self.lq * i.0 - k * i.1,
        )
    }

    /// Load angle (frame ahead of the rotor) and `psi_a = |E| / w` from a mean EMF.
    fn load_angle(e: (f32, f32)) -> f32 {
        wrap(FRAC_PI_2 - atan2(e.1, e.0))
    }

    /// Rotor-frame `(i_d, i_q)` of a frame current with the load angle `g`.
    fn rotor_current(i: (f32, f32), g: f32) -> (f32, f32) {
        let (s, c) = sin_cos(g);
        (i.0 * c - i.1 * s, i.0 * s + i.1 * c)
    }

    fn torque(&self, psi: f32, i_r: (f32, f32)) -> f32 {
        1.5 * self.cfg.pole_pairs as f32 * (psi + (self.ld - self.lq) * i_r.0) * i_r.1
    }

    fn spin_step(&mut self, i_ab: AlphaBeta) -> Result<Option<AlphaBeta>, IdentifyError> {
        let ts = self.cfg.ts_s;
        let i_f = self.cfg.spin_current_a;
        // Frame speed for this tick.
        let k = self.n - 1;
        let moving = matches!(
            (self.step, self.phase),
            (IdentifyStep::Spin, 0) | (IdentifyStep::Inertia, 0 | 1)
        );
        if moving {
            self.omega += self.mv.accel_at(k) * ts;
        }
        let (i_d, i_q) = self.to_frame(i_ab);
        let lim = self.u_lim;
        let w = self.omega;
        let ff_d = -w * self.lq * i_q;
        let ff_q = w * self.ld * i_d;
        let u_d = self.pi_d.step(i_f - i_d, ff_d, -lim, lim);
        let u_q_lim = sqrt((lim * lim - u_d * u_d).max(0.0));
        let u_q = self.pi_q.step(-i_q, ff_q, -u_q_lim, u_q_lim);
        self.check_saturation(
            u_q.abs() >= 0.999 * u_q_lim,
            sqrt(i_d * i_d + i_q * i_q),
            i_f,
        )?;
        // The voltage acts over [t_k+d, t_k+d+1): rotate it to the middle of that interval.
        let adv = (self.d as f32 + 0.5) * w * ts;
        let (sa, ca) = sin_cos(self.frame + adv);
        let u = AlphaBeta {
            alpha: ca * u_d - sa * u_q,
            beta: sa * u_d + ca * u_q,
        };
        let e = self.emf((u_d, u_q), (i_d, i_q));
        let mut done = false;
        match (self.step, self.phase) {
            (IdentifyStep::Spin, 0) if k + 1 >= self.mv.len() => {
                self.omega = self.cfg.spin_speed_rad_s;
                self.next_phase();
            }
            (IdentifyStep::Spin, 0) => {}
            (IdentifyStep::Spin, 1) if self.n >= ticks(self.cfg.spin_settle_time_s, ts) => {
                self.next_phase();
                self.quarter = [Sums::default(); 4];
                self.g_ends = [0.0; 2];
            }
            (IdentifyStep::Spin, 1) => {}
            (IdentifyStep::Spin, _) => {
                let len = ticks(self.cfg.spin_measure_time_s, ts);
                let qi = ((k * 4) / len).min(3) as usize;
                if let Some(s) = self.quarter.get_mut(qi) {
                    s.add([e.0, e.1, i_d, i_q]);
                }
                let m = Self::drift_ticks(len);
                if k < m {
                    self.g_ends[0] += Self::load_angle(e);
                } else if k >= len - m {
                    self.g_ends[1] += Self::load_angle(e);
                }
                if self.n >= len {
                    self.flux_result()?;
                    if self.cfg.measure_inertia {
                        self.enter(IdentifyStep::Inertia);
                        let w0 = self.cfg.spin_speed_rad_s;
                        self.mv = Move::new(0.4 * w0, self.cfg.spin_accel_rad_s2, ts);
                        let torque_max = 1.5
                            * self.cfg.pole_pairs as f32
                            * self.psi.unwrap_or(0.0)
                            * self.cfg.spin_current_a;
                        self.fit = InertiaFit::new(
                            w0,
                            2 * self.mv.len(),
                            self.cfg.pole_pairs,
                            ts,
                            torque_max,
                        );
                    } else {
                        done = true;
                    }
                }
            }
            (IdentifyStep::Inertia, ph) => {
                let g = Self::load_angle(e);
                let torque =
                    self.torque(self.psi.unwrap_or(0.0), Self::rotor_current((i_d, i_q), g));
                self.fit.push(g, torque, w - self.fit.w0);
                if k + 1 >= self.mv.len() {
                    if ph == 0 {
                        self.mv = Move::new(
                            -0.4 * self.cfg.spin_speed_rad_s,
                            self.cfg.spin_accel_rad_s2,
                            ts,
                        );
                        self.next_phase();
                    } else {
                        let j = self.fit.inertia().unwrap_or(f32::NAN);
                        if !(j.is_finite() && j > 0.0 && j < 1e4) {
                            return Err(IdentifyError::Implausible {
                                quantity: Quantity::Inertia,
                                value: j,
                            });
                        }
                        self.j = Some(j);
                        done = true;
                    }
                }
            }
            _ => {}
        }
        self.set_frame(self.frame + w * ts);
        if done {
            self.finish();
            return Ok(None);
        }
        Ok(Some(u))
    }

    /// Ticks at each end of the flux window over which the load angle is averaged for the
    /// rotor's mean speed: 1/64 of the window, at least 1 and at most a quarter.
    fn drift_ticks(len: u32) -> u32 {
        (len / 64).clamp(1, (len / 4).max(1))
    }

    fn flux_result(&mut self) -> Result<(), IdentifyError> {
        let mut all = Sums::default();
        for q in &self.quarter {
            all.n += q.n;
            for (a, b) in all.s.iter_mut().zip(q.s) {
                *a += b;
            }
        }
        let m = all.mean();
        let e = (m[0], m[1]);
        let e_mag = sqrt(e.0 * e.0 + e.1 * e.1);
        let w = self.cfg.spin_speed_rad_s;
        let i_f = self.cfg.spin_current_a;
        let floor = 0.1 * (self.rs * i_f + w * self.ld.max(self.lq) * i_f);
        if e_mag.is_nan() || e_mag <= floor {
            return Err(IdentifyError::RotorLocked { emf_v: e_mag });
        }
        let g = Self::load_angle(e);
        if g.is_nan() || g.abs() >= 1.3 {
            return Err(IdentifyError::LostSync { load_angle_rad: g });
        }
        // Each quarter of the window must see the same EMF (a rotor that slips or jams
        // does not).
        for q in &self.quarter {
            let [a, b, ..] = q.mean();
            let mag = sqrt(a * a + b * b);
            let gq = Self::load_angle((a, b));
            if !((mag - e_mag).abs() < 0.25 * e_mag && wrap(gq - g).abs() < 0.35) {
                return Err(IdentifyError::LostSync { load_angle_rad: gq });
            }
        }
        let i_r = Self::rotor_current((m[2], m[3]), g);
        // The rotor swings about the frame (lightly damped): over the window it turns by the
        // frame's angle minus the change of the load angle, so its mean speed is not the
        // frame's. The EMF is proportional to the rotor's speed: divide by that mean (load
        // angle from the first and the last 1/64 of the window, their centres `len - m`
        // ticks apart).
        let len = ticks(self.cfg.spin_measure_time_s, self.cfg.ts_s);
        let m = Self::drift_ticks(len);
        let drift = (self.g_ends[1] - self.g_ends[0]) / m as f32;
        let w_rotor = w - drift / ((len - m) as f32 * self.cfg.ts_s);
        let psi = e_mag / w_rotor - (self.ld - self.lq) * i_r.0;
        if !(psi.is_finite() && psi > 1e-5 && psi < 50.0) {
            return Err(IdentifyError::Implausible {
                quantity: Quantity::FluxLinkage,
                value: psi,
            });
        }
        self.psi = Some(psi);
        Ok(())
    }
}

/// One PWM period of the identification with the [`hal`](crate::hal) traits: reads the
/// samples, ticks, writes the outputs (disabled before the duties are written when turning
/// off, as [`run_period`](crate::hal::run_period) does).
pub fn identify_period<S: CurrentSense, I: Inverter>(
    id: &mut Identifier,
    sense: &mut S,
    inverter: &mut I,
) -> IdentifyOutput {
    let input = TickInput {
        currents: sense.currents(),
        u_dc_v: sense.bus_voltage_v(),
        sensor: None,
    };
    let out = id.tick(&input);
    write_bridge(inverter, out.duties, out.pwm_enabled);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_matches_std() {
        for &x in &[
            1e-6f32, 0.01, 0.5, 0.9, 0.99, 0.999_9, 1.0, 1.000_1, 2.0, 10.0, 1e6,
        ] {
            let got = ln(x);
            let want = (x as f64).ln();
            assert!(
                ((got as f64) - want).abs() <= 2e-7 * want.abs().max(1e-3),
                "{x}: {got} vs {want}"
            );
        }
        assert!(ln(0.0).is_nan() && ln(-1.0).is_nan() && ln(f32::NAN).is_nan());
    }

    /// Givens least squares: recovers a model of nearly dependent columns (the inertia fit's
    /// shape: 1, s, s^2 and a cubic) exactly from clean data, and the least-squares solution
    /// (zero mean residual) from noisy data; a rank-deficient fit is `None`.
    #[test]
    fn givens_least_squares() {
        let beta = [0.3f32, -1.2, 0.7, 2.5];
        let row = |k: u32| {
            let s = k as f32 / 4000.0;
            [1.0, s, s * s, s * s * s]
        };
        let dot = |x: [f32; 4]| x.iter().zip(beta).map(|(a, b)| a * b).sum::<f32>();
        let mut fit = Lsq::<4>::new();
        for k in 0..4000 {
            fit.add(row(k), dot(row(k)));
        }
        let got = fit.solve().unwrap_or_else(|| panic!("singular"));
        for (g, b) in got.iter().zip(beta) {
            assert!((g - b).abs() < 2e-3 * b.abs(), "{got:?}");
        }
        // Alternating +-0.01 on y: the cubic coefficient moves by far less than the noise.
        let mut fit = Lsq::<4>::new();
        for k in 0..4000 {
            let n = if k % 2 == 0 { 0.01 } else { -0.01 };
            fit.add(row(k), dot(row(k)) + n);
        }
        let got = fit.solve().unwrap_or_else(|| panic!("singular"));
        assert!((got[3] - beta[3]).abs() < 0.01, "{got:?}");
        // Two equal columns: singular.
        let mut fit = Lsq::<2>::new();
        for k in 0..10 {
            fit.add([1.0, 1.0], k as f32);
        }
        assert_eq!(fit.solve(), None);
    }

    #[test]
    fn bad_settings_are_typed_errors() {
        let ok = IdentifyConfig::new(1e-4, 300.0, 2.0).with_spin(200.0, 500.0);
        assert!(Identifier::new(&ok).is_ok());
        type Edit = fn(&mut IdentifyConfig);
        let cases: [(&str, Edit); 8] = [
            ("ts_s", |c| c.ts_s = f32::NAN),
            ("test_current_a", |c| c.test_current_a = -1.0),
            ("over_current_a", |c| c.over_current_a = 2.0),
            ("u_dc_max_v", |c| c.u_dc_max_v = 10.0),
            ("hf_frequency_hz", |c| c.hf_frequency_hz = 5000.0),
            ("spin_accel_rad_s2", |c| c.spin_accel_rad_s2 = 0.0),
            ("max_modulation", |c| c.max_modulation = 1.5),
            ("pole_pairs", |c| c.pole_pairs = 0),
        ];
        for (field, f) in cases {
            let mut c = ok;
            f(&mut c);
            match Identifier::new(&c) {
                Err(IdentifyError::Config(e)) => assert_eq!(e.field, field),
                other => panic!("{field}: {other:?}"),
            }
        }
        let mut c = IdentifyConfig::new(1e-4, 300.0, 2.0);
        c.measure_inertia = true;
        assert!(matches!(
            Identifier::new(&c),
            Err(IdentifyError::Config(IdentifyConfigError {
                field: "measure_inertia",
                ..
            }))
        ));
    }

    #[test]
    fn non_finite_and_bus_faults_turn_the_pwm_off() {
        let cfg = IdentifyConfig::new(1e-4, 300.0, 2.0);
        let mut id = Identifier::new(&cfg).unwrap_or_else(|e| panic!("{e}"));
        let out = id.tick(&TickInput::abc(0.0, 0.0, 0.0, 100.0));
        assert!(!out.pwm_enabled);
        assert!(matches!(
            id.result(),
            Some(Err(IdentifyFailure {
                error: IdentifyError::BusUnderVoltage { .. },
                step: IdentifyStep::Offsets,
                ..
            }))
        ));
        let mut id = Identifier::new(&cfg).unwrap_or_else(|e| panic!("{e}"));
        let out = id.tick(&TickInput::abc(f32::NAN, 0.0, 0.0, 300.0));
        assert!(!out.pwm_enabled && out.duties == SAFE_DUTIES);
        assert!(matches!(
            id.result(),
            Some(Err(IdentifyFailure {
                error: IdentifyError::NonFiniteInput,
                ..
            }))
        ));
        // Finished: stays off.
        let out = id.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
        assert!(!out.pwm_enabled);
    }

    /// A motor that draws no current: the probe runs to the full voltage and reports it.
    #[test]
    fn no_current_is_no_motor() {
        let cfg = IdentifyConfig::new(1e-4, 300.0, 2.0);
        let mut id = Identifier::new(&cfg).unwrap_or_else(|e| panic!("{e}"));
        let mut on = false;
        for _ in 0..20_000 {
            let out = id.tick(&TickInput::abc(0.0, 0.0, 0.0, 300.0));
            on |= out.pwm_enabled;
            for d in out.duties {
                assert!((0.0..=1.0).contains(&d));
            }
            if id.is_done() {
                assert!(!out.pwm_enabled);
                break;
            }
        }
        assert!(on);
        assert!(
            matches!(
                id.result(),
                Some(Err(IdentifyFailure {
                    error: IdentifyError::NoMotor,
                    step: IdentifyStep::Probe,
                    ..
                }))
            ),
            "{:?}",
            id.result()
        );
        assert!((id.ticks() as f32) * 1e-4 < id.max_duration_s());
    }
}
