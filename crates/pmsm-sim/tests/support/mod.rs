//! Shared by the MCAP tests: a simulator run written to an MCAP log.

use std::path::Path;

use pmsm_sim::output::mcap::{LogOptions, McapLog};
use pmsm_sim::scenario::Scenario;
use pmsm_sim::sim::{self, RunOptions, SampleSink};

/// Runs `sc` with an MCAP log at `path` (written with `opts`) as its only sink and finishes
/// the log; panics on any error.
pub fn log_run(sc: &Scenario, path: &Path, opts: LogOptions) {
    let mut log = McapLog::create(path, sc, opts).unwrap_or_else(|e| panic!("{e}"));
    {
        let sinks: Vec<&mut dyn SampleSink> = vec![&mut log];
        sim::run_with(
            sc,
            RunOptions {
                sinks,
                ..RunOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
    }
    log.finish(None).unwrap_or_else(|e| panic!("{e}"));
}
