//! The controller's inputs and outputs: what a board (or the simulator) samples each PWM
//! period, [`TickInput`], and what [`Foc::tick`](crate::Foc::tick) gives back, [`TickOutput`]
//! with its [`Telemetry`].
//!
//! Plain `Copy` data with no behaviour beyond constructors, so that the controller, the
//! HAL glue ([`crate::hal`]) and the identification ([`crate::identify`]) all stand on
//! this module rather than on each other. Units are in the field names' docs: currents in
//! A, voltages in V, angles in rad el., speeds in rad/s el. unless named mechanical.

use ekf_core::Estimate;

use crate::fault::Fault;
use crate::state::State;
use crate::transforms::{Abc, AlphaBeta, Dq};

/// Phase currents as sampled: three (or two plus a computed third) phases, or already in
/// alpha-beta.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhaseCurrents {
    /// Phase currents, A. The controller uses `a` and `b` (Clarke with `c = -a - b`); `c` is
    /// checked for finiteness and over-current only.
    Abc(Abc),
    /// Alpha-beta currents, A.
    AlphaBeta(AlphaBeta),
}

/// Rotor position from a sensor (sensored mode, or for comparison).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RotorSensor {
    /// Electrical rotor angle at `t_k`, rad (any value within `+-1e4`; wrapped internally).
    pub theta_e_rad: f32,
    /// Electrical speed, rad/s.
    pub omega_e_rad_s: f32,
}

/// Everything one tick needs, sampled at `t_k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickInput {
    /// Phase currents sampled at `t_k`, A.
    pub currents: PhaseCurrents,
    /// DC-bus voltage, V.
    pub u_dc_v: f32,
    /// Rotor angle and speed from a sensor: required in [`Mode::Sensored`](crate::Mode::Sensored), ignored (but
    /// checked) in [`Mode::Sensorless`](crate::Mode::Sensorless).
    pub sensor: Option<RotorSensor>,
}

impl TickInput {
    /// Input from phase currents `a`, `b`, `c` (A) and the bus voltage (V).
    pub fn abc(a: f32, b: f32, c: f32, u_dc_v: f32) -> Self {
        Self {
            currents: PhaseCurrents::Abc(Abc { a, b, c }),
            u_dc_v,
            sensor: None,
        }
    }

    /// Input from alpha-beta currents (A) and the bus voltage (V).
    pub fn alpha_beta(alpha: f32, beta: f32, u_dc_v: f32) -> Self {
        Self {
            currents: PhaseCurrents::AlphaBeta(AlphaBeta { alpha, beta }),
            u_dc_v,
            sensor: None,
        }
    }

    /// The same input with a rotor sensor reading (electrical angle, rad; speed, rad/s).
    pub fn with_sensor(mut self, theta_e_rad: f32, omega_e_rad_s: f32) -> Self {
        self.sensor = Some(RotorSensor {
            theta_e_rad,
            omega_e_rad_s,
        });
        self
    }
}

/// Signals worth logging, for this tick (the health monitor's findings:
/// [`Foc::health_report`](crate::Foc::health_report)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Telemetry {
    /// Measured currents in the control frame, A.
    pub i_dq: Dq,
    /// Current references in the control frame, A.
    pub i_dq_ref: Dq,
    /// Voltage the current loops asked for in the control frame (after their limit), V.
    pub u_dq: Dq,
    /// Voltage the duties of this tick apply (after SVPWM clamping; with dead-time
    /// compensation the voltage expected at the motor, the duties net of the compensation),
    /// V. The observer is fed this one when it is applied.
    pub u_ab: AlphaBeta,
    /// Control-frame angle at `t_k` (Park), rad el. The inverse Park used
    /// `theta_rad + angle_advance_periods * omega_rad_s * ts_s`.
    pub theta_rad: f32,
    /// Speed of the control frame, rad/s el.
    pub omega_rad_s: f32,
    /// The (slewed) speed reference of the speed loop, rad/s mech. (the ramp speed under I/f).
    pub speed_ref_mech_rad_s: f32,
    /// The observer's estimate after this tick's step (the previous one if refused).
    pub estimate: Estimate<f32>,
    /// Whether the observer accepted this tick's step.
    pub observer_ok: bool,
    /// Whether this tick's current sample was used: `false` when it was missing or
    /// implausible and the tick rode through (module [`crate::controller`], "Bad current samples").
    pub sample_ok: bool,
}

/// What one tick returns: the duties for the PWM timer and the status.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickOutput {
    /// Duties of phases a, b, c: always finite and in `[0, 1]`; `0.5` each when the PWM is
    /// off or faulted.
    pub duties: [f32; 3],
    /// Whether the bridge must switch. `false`: outputs off (all switches open), which is the
    /// safe state of every fault and of `Idle`.
    pub pwm_enabled: bool,
    /// State after this tick.
    pub state: State,
    /// The latched fault, if any.
    pub fault: Option<Fault>,
    /// Signals for logging.
    pub telemetry: Telemetry,
}
