//! What the identification reports: the steps, the results, the errors and the output of a
//! tick.

use core::fmt;

use ekf_core::MotorParams;

use crate::transforms::AlphaBeta;

use super::config::IdentifyConfigError;

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
    /// Finished: PWM off, [`Identifier::result`](super::Identifier::result) set.
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
    /// Duties of phases a, b, c, in `[0, 1]` ([`SAFE_DUTIES`](crate::svpwm::SAFE_DUTIES) with the PWM off).
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
