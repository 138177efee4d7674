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

/// Receives every sample as the run makes it (the MCAP log, the plot); the run loop
/// ([`crate::sim`]) hands each period's [`Sample`](record::Sample) to its sinks in order.
pub trait SampleSink {
    /// Takes one sample; an error stops the run
    /// ([`RunEnd::SinkFailed`](crate::sim::RunEnd::SinkFailed)).
    fn record(&mut self, sample: &record::Sample) -> Result<(), String>;
}
