//! The controller's state (the states of the machine in [`startup`](crate::startup)).

/// Controller state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum State {
    /// PWM off, waiting for [`Foc::start`](crate::Foc::start).
    #[default]
    Idle,
    /// Rotor alignment (sensorless start).
    Align,
    /// Open-loop current-controlled ramp (I/f).
    OpenLoop,
    /// Observer frame, d current of the ramp fading out.
    Handover,
    /// Speed and current loops on the observer's (or the sensor's) angle.
    ClosedLoop,
    /// A fault is latched; PWM off.
    Fault,
}
