#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod analysis;
pub mod board_telemetry;
pub mod drive;
mod error;
pub mod output;
pub mod plant;
pub mod scenario;
pub mod sim;

// The modules' paths before the layers (used by pyfoc and the workspace tests).
pub use analysis::{identify, replay, suite, tune};
pub use output::mcap as mcap_log;

pub use error::{FieldError, SimError};
