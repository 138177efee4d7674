#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod controller;
mod error;
pub mod fault_suite;
pub mod faults;
pub mod foc_drive;
pub mod identify;
pub mod inverter;
pub mod lowspeed;
pub mod mcap_log;
pub mod metrics;
pub mod observer;
mod pipeline;
pub mod plant;
pub mod plot;
pub mod profile;
pub mod record;
pub mod replay;
pub mod report;
pub mod scenario;
pub mod sensors;
pub mod sim;
pub mod suite;
pub mod svpwm;
pub mod tune;

pub use error::{FieldError, SimError};
