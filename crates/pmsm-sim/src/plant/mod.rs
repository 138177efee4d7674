//! The plant layer: what the drive controls and measures, simulated in `f64`.
//!
//! | module | what it models |
//! | --- | --- |
//! | [`machine`] | the PMSM (surface or interior) and its mechanics: the dq equations, one period's integration |
//! | [`inverter`] | the three-leg bridge: computation delay, dead time, bus ripple |
//! | [`sensors`] | the current sensor (gain, offset, noise, ADC) and the bus-voltage sample |
//! | [`load`] | time profiles (speed reference, load tables) and load-torque models |
//! | [`frames`] | the plant's Clarke and Park transforms |
//! | [`fault_injection`] | what a scenario's `[[faults]]` do to the machine, the bridge and the sensors |
//!
//! The items of [`machine`] are re-exported here (`plant::MotorModel`, `plant::Plant`).

pub mod fault_injection;
pub mod frames;
pub mod inverter;
pub mod load;
pub mod machine;
pub mod sensors;

pub use machine::*;
