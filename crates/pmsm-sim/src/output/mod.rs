//! The output layer: what a run records and writes.
//!
//! | module | output |
//! | --- | --- |
//! | [`record`] | one period's record ([`Sample`](record::Sample)): truth, measurements, control, observers |
//! | [`metrics`] | the run's metrics (tracking, observer accuracy, start-up) |
//! | [`mcap`] | the MCAP log (protobuf or JSON period channel, scenario and metrics) |
//! | [`plot`] | the SVG plot |
//! | [`report`] | the text and Markdown summaries |

pub mod mcap;
pub mod metrics;
pub mod plot;
pub mod record;
pub mod report;
