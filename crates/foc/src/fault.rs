//! Latched faults and their reasons.
//!
//! A fault stops the drive at once: the state becomes [`State::Fault`], every following
//! [`TickOutput`](crate::TickOutput) has `pwm_enabled = false` and the duties
//! [`SAFE_DUTIES`](crate::SAFE_DUTIES) (0.5, 0.5, 0.5: zero line-to-line voltage, should a
//! board keep the bridge switching), and the first fault stays latched, with the value that
//! caused it, until [`Foc::clear_fault`](crate::Foc::clear_fault). Later faults while latched
//! are not recorded (the first cause is the interesting one).
//!
//! Single bad current samples do not trip: they are ridden through
//! ([`SampleCheckConfig`](crate::SampleCheckConfig), module [`controller`](crate::controller)).
//!
//! | fault | trips when | checked |
//! |---|---|---|
//! | [`Fault::NonFiniteInput`] | `u_dc` or a supplied sensor value is NaN or infinite; the sensor angle beyond `+-1e4` rad or its speed beyond `+-1e6` rad/s; the sensor missing in sensored mode; `samples.missing_trip_ticks` current samples in a row missing (NaN, infinite) or implausible (below the over-current level) | every tick, every state |
//! | [`Fault::OverCurrent`] | `|i_alpha_beta|`, or `|i_c|` when given, above `over_current_a` for `samples.over_current_trip_ticks` accepted samples in a row (debounced: the hardware comparator is the real protection), or `missing_trip_ticks` rejected samples in a row above it | every tick, every state |
//! | [`Fault::BusOverVoltage`] | `u_dc > u_dc_max_v` | every tick, every state |
//! | [`Fault::BusUnderVoltage`] | `u_dc < u_dc_min_v` | while the bridge is driven (not in `Idle`) |
//! | [`Fault::ObserverLost`] | health monitor: lost in closed loop with [`ObserverLossPolicy::Trip`](crate::ObserverLossPolicy::Trip); re-acquisitions exhausted; no lock within `acquire_timeout_s` at the hand-over speed | sensorless running states |
//! | [`Fault::CurrentSensor`] | phase `a` or `b` reading repeated bit for bit while the commanded current vector (at least 5 % of the current limit) turned by `samples.stuck_angle_rad` (an eighth of a period) | running states, `Abc` input |
//! | [`Fault::Stall`] | speed loop at its current limit while the rotor speed stays low for `stall_time_s`; or the I/f ramp at speed but the rotor not turning | running states |

use core::fmt;

use crate::state::State;

/// Why the controller stopped (latched until cleared).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fault {
    /// Phase current above the trip level.
    OverCurrent,
    /// DC-bus voltage above its maximum.
    BusOverVoltage,
    /// DC-bus voltage below its minimum while running.
    BusUnderVoltage,
    /// The observer lost the rotor and could not (or was configured not to) re-acquire it.
    ObserverLost,
    /// The rotor does not follow: speed loop saturated at low speed, or no rotation under I/f.
    Stall,
    /// A NaN, an infinity or an absurd value in the inputs (or a missing rotor sensor in
    /// sensored mode).
    NonFiniteInput,
    /// A current-sensor channel stuck: its reading repeats while the current vector turns
    /// (`samples.stuck_angle_rad`).
    CurrentSensor,
}

/// A latched fault with its context.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultInfo {
    /// The fault.
    pub fault: Fault,
    /// The state the controller was in when it tripped.
    pub state: State,
    /// The offending value in SI units: current magnitude (A) for over-current, `u_dc` (V)
    /// for the bus faults, the observer speed (rad/s el.) for observer loss and stall, and
    /// for a bad input the value itself (possibly NaN).
    pub value: f32,
    /// The tick count (calls of `tick` since construction, wrapping) at the trip.
    pub tick: u32,
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Fault::OverCurrent => "phase current above the over-current trip level",
            Fault::BusOverVoltage => "DC-bus voltage above its maximum",
            Fault::BusUnderVoltage => "DC-bus voltage below its minimum",
            Fault::ObserverLost => "observer lost the rotor angle",
            Fault::Stall => "rotor stalled",
            Fault::NonFiniteInput => "non-finite or absurd input",
            Fault::CurrentSensor => "current-sensor channel stuck",
        })
    }
}

impl core::error::Error for Fault {}

impl fmt::Display for FaultInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} (value {}, in state {:?}, tick {})",
            self.fault, self.value, self.state, self.tick
        )
    }
}
