#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod config;
pub mod controller;
pub mod deadtime;
pub mod fault;
pub mod fieldweak;
#[cfg(not(feature = "hfi"))]
mod gate;
pub mod hal;
pub mod health;
pub mod hfi;
#[cfg(feature = "identify")]
pub mod identify;
pub mod io;
#[cfg(feature = "flux-map")]
pub mod mapdrive;
pub mod mtpa;
pub mod pi;
pub mod startup;
mod state;
pub mod svpwm;
pub mod transforms;
pub mod trig;

pub use config::{
    ComputationDelay, ConfigError, Field, FieldWeakeningConfig, FocConfig, HealthConfig, Mode,
    ObserverLossPolicy, Reversal, SampleCheckConfig, StartupConfig,
};
pub use controller::{CommandError, Foc};
pub use deadtime::DeadTimeCompensation;
pub use fault::{Fault, FaultInfo};
pub use fieldweak::FieldWeakening;
pub use health::{HealthReport, LossReason};
pub use hfi::{
    HFI_TRACKING_SPEED_FACTOR, HfiConfig, HfiError, HfiField, HfiPhase, HfiStatus, HfiTracker,
};
#[cfg(feature = "identify")]
pub use identify::{
    Identified, Identifier, IdentifyConfig, IdentifyConfigError, IdentifyError, IdentifyFailure,
    IdentifyOutput, IdentifyStep, identify_period,
};
pub use io::{PhaseCurrents, RotorSensor, Telemetry, TickInput, TickOutput};
#[cfg(feature = "flux-map")]
pub use mapdrive::{MapFieldWeakening, MapMtpa, MapPoint, MapTableError, MapTables};
pub use mtpa::Mtpa;
pub use pi::{Pi, PiGains};
pub use startup::State;
pub use svpwm::{Modulation, SAFE_DUTIES, duties_to_alpha_beta, svpwm};
pub use transforms::{Abc, AlphaBeta, Dq};

/// Re-export of the observer crate (motor parameters, observer configuration, estimate).
pub use ekf_core;
/// Re-export of the vector library of the two-axis frames ([`AlphaBeta`], [`Dq`] convert to
/// and from `glam::Vec2`).
pub use glam;
