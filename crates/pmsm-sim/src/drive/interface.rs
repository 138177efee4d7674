//! The drive-controller interface: the [`DriveController`] trait the run loop calls once per
//! PWM period, and what goes in and out of one period. The `foc` crate's controller implements
//! it ([`crate::drive::foc_adapter::FocDrive`], sensorless or sensored); a test can plug in its own.
//!
//! A controller sees what a real one sees: the measured phase currents (and their Clarke
//! transform), the measured DC-bus voltage and the speed reference; in sensored mode
//! ([`DriveController::sensored`]) also the true rotor angle and speed. It returns three
//! duties in `[0, 1]`, whether the bridge switches, and telemetry for the log (state, fault,
//! dq currents and references, and the estimate of its own observer, if it has one, which the
//! simulator scores). Everything a controller does happens inside [`DriveController::tick`];
//! the simulator models the inverter (delay, dead time) behind it.

/// The true rotor position and speed, given only to sensored controllers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotorFeedback {
    /// Electrical angle at `t_k`, rad.
    pub theta_e_rad: f64,
    /// Mechanical speed at `t_k`, rad/s.
    pub omega_mech_rad_s: f64,
}

/// What a controller reads in period `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerInput {
    /// Period index.
    pub k: u64,
    /// `t_k`, s.
    pub t_s: f64,
    /// Measured phase currents `[a, b, c]` (`c` reconstructed), A.
    pub i_abc_a: [f64; 3],
    /// Their Clarke transform `[alpha, beta]`, A.
    pub i_ab_a: [f64; 2],
    /// Measured DC-bus voltage, V.
    pub u_dc_v: f64,
    /// Mechanical speed reference, rad/s.
    pub speed_ref_mech_rad_s: f64,
    /// True rotor angle and speed: `Some` only for a [`sensored`](DriveController::sensored)
    /// controller.
    pub rotor: Option<RotorFeedback>,
}

pub use crate::output::record::{ControllerEstimate, ControllerTelemetry};

/// What a controller commands in period `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerOutput {
    /// Duty of each leg, `[0, 1]` (the simulator clamps and checks them).
    pub duties: [f64; 3],
    /// Whether the bridge switches. `false` opens every switch for the coming period at once
    /// (a gate disable is not delayed by the computation delay; see
    /// [`Plant::step_open`](crate::plant::Plant::step_open)).
    pub pwm_enabled: bool,
    /// The alpha-beta voltage (V) the controller expects these duties to realize, when it
    /// knows better than "the duties on the measured bus" (e.g. after its own dead-time
    /// compensation, which the bridge's dead time cancels). The simulator's observers are fed
    /// this voltage (delayed like the duties); `None`: the ideal-switch voltage of the duties.
    pub expected_u_ab_v: Option<[f64; 2]>,
    /// For the log.
    pub telemetry: ControllerTelemetry,
}

/// A drive controller, called once per PWM period (module docs).
pub trait DriveController {
    /// Whether the controller is given the true rotor angle and speed
    /// ([`ControllerInput::rotor`]).
    fn sensored(&self) -> bool;

    /// One control period: measurements in, duties out.
    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput;
}
