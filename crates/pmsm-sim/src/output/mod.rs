//! The output layer: what a run records and writes.
//!
//! | module | output |
//! | --- | --- |
//! | [`record`] | one period's record ([`Sample`](record::Sample)): truth, measurements, control, observers |
//! | [`metrics`] | the run's metrics (tracking, observer accuracy, start-up) |
//! | [`mcap`] | the MCAP log (protobuf or JSON period channel, scenario and metrics) |
//! | [`file`](mod@file) | writing files so that an I/O error leaves no cut file: whole files renamed into place, the log cut back to its last complete chunk |
//! | [`plot`] | the SVG plot |
//! | [`report`] | the text and Markdown summaries |
//! | [`startup_log`] | the controller's state changes in words (what the start-up is doing) |

pub mod file;
pub mod mcap;
pub mod metrics;
pub mod plot;
pub mod record;
pub mod report;
pub mod startup_log;

/// Receives every sample as the run makes it (the MCAP log, the plot); the run loop
/// ([`crate::sim`]) hands each period's [`Sample`](record::Sample) to its sinks in order.
pub trait SampleSink {
    /// Takes one sample; an error stops the run
    /// ([`RunEnd::SinkFailed`](crate::sim::RunEnd::SinkFailed)).
    fn record(&mut self, sample: &record::Sample) -> Result<(), String>;
}
