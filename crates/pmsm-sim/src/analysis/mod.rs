//! The analysis layer: commands that run the simulator many times, or read its logs, and
//! turn the results into tables.
//!
//! | module | command | what it does |
//! | --- | --- | --- |
//! | [`suite`] | `pmsm-sim suite` | every observer on every reference motor, scored against goals |
//! | [`fault_suite`] | `pmsm-sim faults` | each injected fault, and how the drive reacts |
//! | [`low_speed`] | `pmsm-sim low-speed` | the observers held at low speed |
//! | [`identify`] | `pmsm-sim identify` | the drive's self-commissioning on a simulated motor |
//! | [`tune`] | `pmsm-sim tune` | the observer's Q and R fitted to a logged run |
//! | [`replay`] | `pmsm-sim replay` | the observers stepped over a recorded log of a real drive |
//! | [`sweep`] | `pmsm-sim sweep` | many runs of a scenario with keys varied (grid, Monte-Carlo), a row each |
//! | [`datasheet`] | `pmsm-sim datasheet` | one motor's datasheet (HTML and markdown), every figure from a sweep |

pub mod datasheet;
pub mod fault_suite;
pub mod identify;
pub mod identify_map;
pub mod low_speed;
pub(crate) mod mcap_input;
pub mod plug_map;
pub mod replay;
pub mod suite;
pub mod sweep;
pub mod tune;
