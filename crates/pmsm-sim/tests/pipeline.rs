//! The run's own observers stepped on a thread of their own (the default) against the same
//! run with them inline on the simulating thread (`RunOptions::inline_observers`): the same
//! trace, metrics and end, bit for bit, also when a sink stops the run or the reference filter
//! is off.

use pmsm_sim::scenario::Scenario;
use pmsm_sim::sim::{self, RunOptions, RunOutput, Sample, SampleSink};

fn scenario(seed_filter: bool, duration_s: f64) -> Scenario {
    let mut sc = Scenario::preset("default")
        .unwrap_or_else(|e| panic!("{e}"))
        .with_duration(duration_s);
    sc.observer.reference_filter = seed_filter;
    sc
}

/// `Debug` prints every `f64` in its shortest round-trip form (NaN as `NaN`): equal strings
/// mean bit-identical numbers.
fn fingerprint(out: &RunOutput) -> (Vec<String>, String, String) {
    let mut metrics = out.metrics.clone();
    metrics.wall_time_s = 0.0;
    metrics.real_time_factor = 0.0;
    (
        out.trace.samples.iter().map(|s| format!("{s:?}")).collect(),
        format!("{metrics:?}"),
        format!("{:?} {:?}", out.end, out.reference_filter_failure),
    )
}

/// Counts the samples it gets (checking they come in order) and fails at `fail_at`.
struct Counter {
    seen: u64,
    fail_at: Option<u64>,
}

impl SampleSink for Counter {
    fn record(&mut self, sample: &Sample) -> Result<(), String> {
        assert_eq!(sample.k, self.seen, "samples out of order");
        self.seen += 1;
        if Some(sample.k) == self.fail_at {
            return Err(format!("sink refused sample {}", sample.k));
        }
        Ok(())
    }
}

fn run(sc: &Scenario, inline_observers: bool, fail_at: Option<u64>) -> (RunOutput, u64) {
    let mut sink = Counter { seen: 0, fail_at };
    let out = sim::run_with(
        sc,
        RunOptions {
            record_trace: true,
            sinks: vec![&mut sink],
            inline_observers,
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    (out, sink.seen)
}

#[test]
fn pipelined_observers_give_the_sequential_run_bit_for_bit() {
    for seed_filter in [true, false] {
        // 3001 periods: batches of the pipeline and a remainder.
        let sc = scenario(seed_filter, 0.3001);
        let (a, seen_a) = run(&sc, false, None);
        let (b, seen_b) = run(&sc, true, None);
        assert!(a.end.is_completed(), "{}", a.end.describe());
        assert_eq!(a.trace.samples.len(), 3001);
        assert_eq!((seen_a, seen_b), (3001, 3001));
        assert_eq!(a.metrics.seed_filter.is_some(), seed_filter);
        assert_eq!(
            fingerprint(&a),
            fingerprint(&b),
            "seed filter {seed_filter}"
        );
        // The observers' estimates are in the samples (not left at their placeholder).
        let last = &a.trace.samples[3000];
        assert!(last.observer.theta_e_rad != 0.0 && last.observer.p_diag[3] > 0.0);
        assert_eq!(last.seed_filter.is_some(), seed_filter);
    }
}

#[test]
fn a_failing_sink_stops_both_at_the_same_sample() {
    let sc = scenario(true, 0.2);
    for fail_at in [0, 5, 127, 128, 1000] {
        let (a, seen_a) = run(&sc, false, Some(fail_at));
        let (b, seen_b) = run(&sc, true, Some(fail_at));
        match &a.end {
            sim::RunEnd::SinkFailed { k, message, .. } => {
                assert_eq!(*k, fail_at);
                assert_eq!(*message, format!("sink refused sample {fail_at}"));
            }
            other => panic!("expected a sink failure, got {}", other.describe()),
        }
        // The failing sample was the last one handed on; it is in the trace and the
        // metrics, as in a sequential run.
        assert_eq!(seen_a, fail_at + 1);
        assert_eq!(seen_b, fail_at + 1);
        assert_eq!(a.trace.samples.len() as u64, fail_at + 1);
        assert_eq!(a.metrics.periods as u64, fail_at + 1);
        assert_eq!(fingerprint(&a), fingerprint(&b), "fail at {fail_at}");
    }
}
